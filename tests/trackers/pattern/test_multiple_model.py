"""Full IMM and layered MM of :mod:`trackers.pattern.multiple_model`."""

from __future__ import annotations

import math

import numpy as np
import pytest

from trackers.pattern.bending import PrincipalModel, ProperModel, measure
from trackers.pattern.multiple_model import (
    BendingModes,
    factored_transition,
    imm_step,
    initial_estimate,
    layered_transition_matrices,
    lmm_step,
    paper_modes,
    transition_by_changes,
    validation_gate,
)

R = np.eye(2) * 0.09
PD, LAM = 0.9, 0.005
PAT_A = np.array([[-6.0, 2.0], [4.0, 7.0], [8.0, -5.0], [-3.0, -8.0], [1.0, 1.5]])
PAT_B = np.array([[5.0, 5.0], [-7.0, 3.0], [2.0, -9.0], [-4.0, -4.0]])
X0 = np.array([0.0, 100.0, 0.0, 100.0, math.radians(45.0), 0.0])
P0 = np.diag([1.0, 1.0, 1.0, 1.0, 1e-3, 1e-3])


def true_associate(patterns, detections, truth_pairs):
    """An association that returns the true pairs of the scan's shape, none for others."""

    def associate(s, x_pred, P_pred):
        assert x_pred.shape == (6,) and P_pred.shape == (6, 6)
        return truth_pairs.get(s, np.zeros((0, 2), int))

    return associate


def simulate(steps=8, seed=0, rate=0.0, shape=0):
    rng = np.random.default_rng(seed)
    x = X0.copy()
    pat = (PAT_A, PAT_B)[shape]
    out = []
    for _ in range(steps):
        x = x + np.array([x[1], 0, x[3], 0, rate, 0.0])
        x[5] = rate
        z = measure(x, pat) + rng.normal(0, 0.3, pat.shape)
        out.append((x.copy(), z))
    return out


def run(step, modes, scans, algorithm, shapes_same=False, **kw):
    est = initial_estimate(modes, X0, P0, algorithm=algorithm)
    history = []
    for _, z in scans:
        pairs = np.column_stack([np.arange(len(z))] * 2)
        truth_pairs = {s: pairs for s in range(len(modes.shapes))} if shapes_same else {0: pairs}
        est, info = step(
            est,
            1.0,
            z,
            R,
            true_associate(modes.patterns, z, truth_pairs),
            modes,
            pd=PD,
            clutter_density=LAM,
            **kw,
        )
        history.append((est, info))
    return history


def test_transition_matrix_rows_sum_to_one_and_follow_the_paper():
    Pi = transition_by_changes((2, 2, 2))
    np.testing.assert_allclose(Pi.sum(axis=1), 1.0, atol=1e-15)
    assert np.all(np.diag(Pi) == 0.95)
    # [1,1,2] -> [1,1,1]: one change, 0.012; -> [1,2,1]: two changes, 0.004; all three: 0.002
    idx = lambda g, p, s: (g * 2 + p) * 2 + s  # noqa: E731
    assert Pi[idx(0, 0, 1), idx(0, 0, 0)] == pytest.approx(0.012)
    assert Pi[idx(0, 0, 1), idx(0, 1, 0)] == pytest.approx(0.004)
    assert Pi[idx(0, 0, 1), idx(1, 1, 0)] == pytest.approx(0.002)
    for sizes in [(3, 3, 3), (2, 3, 1), (1, 1, 4), (2,)]:
        Pi = transition_by_changes(sizes, off_diagonal=(0.012, 0.004, 0.002))
        np.testing.assert_allclose(Pi.sum(axis=1), 1.0, atol=1e-14)
        assert np.all(Pi >= 0)


def test_layered_transitions_of_a_factored_matrix_are_its_factors():
    rng = np.random.default_rng(0)
    mats = []
    for r in (2, 3, 2):
        m = rng.uniform(0.1, 1.0, (r, r))
        mats.append(m / m.sum(axis=1, keepdims=True))
    Pi = factored_transition(*mats)
    mus = [rng.dirichlet(np.ones(r)) for r in (2, 3, 2)]
    for iterations in (0, 1, 3):
        tilde = layered_transition_matrices(Pi, (2, 3, 2), mus, iterations)
        for t, m in zip(tilde, mats, strict=True):
            np.testing.assert_allclose(t, m, atol=1e-14)


def test_layered_transitions_are_stochastic_and_coupled():
    Pi = transition_by_changes((2, 2, 2))
    for mus in ([np.array([1.0, 0.0])] * 3, [np.array([0.2, 0.8])] * 3):
        for it in (0, 2):
            tilde = layered_transition_matrices(Pi, (2, 2, 2), mus, it)
            for t in tilde:
                np.testing.assert_allclose(t.sum(axis=1), 1.0, atol=1e-14)
                assert np.all(t > 0)
    # eq. 7 by hand for the top layer: sum over the other layers' old modes of
    # P(g_k = j | g_{k-1} = i, p_{k-1} = n, s_{k-1} = l) mu^p_n mu^s_l
    mus = [np.array([0.3, 0.7]), np.array([0.6, 0.4]), np.array([0.9, 0.1])]
    T = Pi.reshape(2, 2, 2, 2, 2, 2)
    expect = np.zeros((2, 2))
    for i in range(2):
        for j in range(2):
            for n in range(2):
                for o in range(2):
                    expect[i, j] += T[i, n, o, j].sum() * mus[1][n] * mus[2][o]
    np.testing.assert_allclose(
        layered_transition_matrices(Pi, (2, 2, 2), mus)[0], expect, atol=1e-15
    )


def test_gate_accounts_for_the_pattern_radius():
    x = np.array([0.0, 0.0, 0.0, 0.0, 0.0, 0.0])
    P = np.diag([0.01, 0, 0.01, 0, 0, 0])
    z = np.array([[9.9, 0.0], [10.5, 0.0], [13.0, 0.0], [0.0, -10.2]])
    idx = validation_gate(z, x, P, R, radius=10.0)
    np.testing.assert_array_equal(idx, [0, 1, 3])
    assert len(validation_gate(z, x, P, R, radius=1.0)) == 0


@pytest.mark.parametrize(
    "principal, proper, layer",
    [
        (
            (PrincipalModel("CV", 0, 0.004), PrincipalModel("CT", -0.05, 0.001)),
            (ProperModel("NV", 0.0),),
            0,
        ),
        ((PrincipalModel("CV", 0, 0.004),), (ProperModel("NV", 0.0), ProperModel("CV", None)), 1),
    ],
)
def test_imm_and_lmm_agree_when_other_layers_have_one_mode(principal, proper, layer):
    """With a single mode in two of the layers, the LMM's bank for the third layer runs the
    same filters with the same transition matrix (eq. 23/24 collapses to π) and the same
    association as the full IMM, whose global modes are exactly that layer's modes; so that
    bank's mode probabilities and its state part (the LMM's output for that layer) must equal
    the IMM's to rounding."""
    modes = BendingModes(principal, proper, {"A": PAT_A})
    scans = simulate(steps=10, rate=0.05)
    h_imm = run(imm_step, modes, scans, "imm")
    h_lmm = run(lmm_step, modes, scans, "lmm", iterations=1)
    part = slice(0, 4) if layer == 0 else slice(4, 6)
    for (ei, ii), (el, il) in zip(h_imm, h_lmm, strict=True):
        np.testing.assert_allclose(
            el.layer_probabilities[layer], ei.layer_probabilities[layer], rtol=1e-9, atol=1e-12
        )
        np.testing.assert_allclose(el.x[part], ei.x[part], rtol=1e-10, atol=1e-9)
        np.testing.assert_allclose(el.P[part, part], ei.P[part, part], rtol=1e-8, atol=1e-12)
        assert ii.associations == il.associations == 1


def test_imm_and_lmm_shape_layer_agree_when_dynamics_have_one_mode():
    """One principal and one proper mode: the shape bank's filters are the IMM's filters
    (the mixtures over the dynamic layers have a single component), so the shape
    probabilities agree to rounding."""
    modes = BendingModes((PrincipalModel("CV"),), (ProperModel("NV"),), {"A": PAT_A, "B": PAT_B})
    scans = simulate(steps=6)
    h_imm = run(imm_step, modes, scans, "imm")
    h_lmm = run(lmm_step, modes, scans, "lmm")
    for (ei, _), (el, _) in zip(h_imm, h_lmm, strict=True):
        np.testing.assert_allclose(el.layer_probabilities[2], ei.layer_probabilities[2], atol=1e-12)
    assert h_imm[-1][0].layer_probabilities[2][0] > 0.999


def test_paper_modes_track_a_rotating_target_and_do_not_mutate():
    patterns = {"A": PAT_A, "B": PAT_B}
    modes = paper_modes(patterns)
    assert modes.n_models == 8 and modes.sizes == (2, 2, 2)
    scans = simulate(steps=12, rate=math.radians(5.0))
    for step, alg in ((imm_step, "imm"), (lmm_step, "lmm")):
        est0 = initial_estimate(modes, X0, P0, algorithm=alg)
        snapshot = est0.filter_x.copy()
        hist = run(step, modes, scans, alg)
        np.testing.assert_array_equal(est0.filter_x, snapshot)
        est, _ = hist[-1]
        truth = scans[-1][0]
        assert abs(est.x[4] - truth[4]) < math.radians(1.5)
        assert est.layer_probabilities[1][1] > 0.9  # proper CV (rotating)
        assert est.layer_probabilities[2][0] > 0.99  # shape A
        with pytest.raises(ValueError):
            est.x[0] = 1.0  # read-only


@pytest.mark.parametrize("algorithm", ["imm", "lmm"])
@pytest.mark.parametrize("case", ["none", "one", "clutter"])
def test_probabilities_stay_normalized_with_poor_data(algorithm, case):
    modes = paper_modes({"A": PAT_A, "B": PAT_B})
    step = imm_step if algorithm == "imm" else lmm_step
    est = initial_estimate(modes, X0, P0, algorithm=algorithm)
    rng = np.random.default_rng(1)
    for k in range(6):
        if case == "none":
            z, pairs = np.zeros((0, 2)), np.zeros((0, 2), int)
        elif case == "one":
            z = measure(est.x, PAT_A[:1]) + 0.1
            pairs = np.array([[0, 0]])
        else:
            z = rng.uniform(-15, 15, (5, 2)) + np.array([est.x[0], est.x[2]])
            pairs = np.array([[0, 1], [2, 3], [3, 0]]) if k % 2 else np.zeros((0, 2), int)
        est, info = step(
            est, 1.0, z, R, lambda s, x, P, p=pairs: p, modes, pd=PD, clutter_density=LAM
        )
        for mu in est.layer_probabilities:
            assert np.all(np.isfinite(mu)) and np.all(mu > 0)
            assert mu.sum() == pytest.approx(1.0)
        assert np.all(np.isfinite(est.x)) and np.all(np.isfinite(est.P))
        assert np.all(np.isfinite(info.log_likelihoods))
        assert info.associations <= 2


def test_association_called_once_per_shape():
    modes = paper_modes({"A": PAT_A, "B": PAT_B})
    for step, alg in ((imm_step, "imm"), (lmm_step, "lmm")):
        calls = []

        def assoc(s, x, P, calls=calls):
            calls.append(s)
            return np.zeros((0, 2), int)

        est = initial_estimate(modes, X0, P0, algorithm=alg)
        step(est, 1.0, np.zeros((0, 2)), R, assoc, modes, pd=PD, clutter_density=LAM)
        assert sorted(calls) == [0, 1]


def test_likelihood_prefers_the_shape_with_more_matched_points():
    """Λ = N · (Pd/λ)^p · (1 − Pd)^(m − p): a shape whose points are all matched beats one
    with none, though the Gaussian factor alone would favour the empty update (ln N = 0)."""
    modes = BendingModes((PrincipalModel("CV"),), (ProperModel("NV"),), {"A": PAT_A, "B": PAT_B})
    ((_, z),) = simulate(steps=1)
    est = initial_estimate(modes, X0, P0, algorithm="imm")
    pairs = np.column_stack([np.arange(5)] * 2)
    est, info = imm_step(
        est,
        1.0,
        z,
        R,
        lambda s, x, P: pairs if s == 0 else np.zeros((0, 2), int),
        modes,
        pd=PD,
        clutter_density=LAM,
    )
    assert info.log_likelihoods[0] > info.log_likelihoods[1]
    assert info.log_likelihoods[1] == pytest.approx(4 * math.log(1 - PD))


def test_bad_inputs_raise():
    modes = paper_modes({"A": PAT_A})
    est = initial_estimate(modes, X0, P0, algorithm="imm")
    none = lambda s, x, P: np.zeros((0, 2), int)  # noqa: E731
    with pytest.raises(ValueError):
        lmm_step(est, 1.0, np.zeros((0, 2)), R, none, modes, pd=PD, clutter_density=LAM)
    with pytest.raises(ValueError):
        imm_step(est, 1.0, np.zeros((0, 2)), R, none, modes, pd=PD, clutter_density=0.0)
    with pytest.raises(ValueError):
        imm_step(
            est,
            1.0,
            np.zeros((1, 2)),
            R,
            lambda s, x, P: np.array([[9, 0]]),
            modes,
            pd=PD,
            clutter_density=LAM,
        )
    with pytest.raises(ValueError):
        BendingModes(
            (PrincipalModel("CV"),),
            (ProperModel("NV"),),
            {"A": PAT_A},
            transition=np.array([[0.5]]),
        )


def test_exchange_keeps_the_own_part_and_gives_the_other_layers_marginal():
    """The LMM's exchange of estimates: a principal filter's proper part becomes the
    proper layer's combined estimate, its principal block stays, the joint stays positive
    semi-definite and the correlation structure is a linear map of the old one."""
    from trackers.pattern.multiple_model import _replace_proper_part

    rng = np.random.default_rng(7)
    A = rng.normal(size=(3, 6, 6))
    P = A @ np.swapaxes(A, 1, 2) + 0.01 * np.eye(6)
    x = rng.normal(size=(3, 6))
    B = rng.normal(size=(3, 2, 2))
    P_t = B @ np.swapaxes(B, 1, 2) + 1e-3 * np.eye(2)
    x_t = rng.normal(size=(3, 2))
    xn, Pn = _replace_proper_part(x, P, x_t, P_t)
    np.testing.assert_array_equal(xn[:, :4], x[:, :4])
    np.testing.assert_array_equal(xn[:, 4:], x_t)
    np.testing.assert_array_equal(Pn[:, :4, :4], P[:, :4, :4])
    np.testing.assert_allclose(Pn[:, 4:, 4:], P_t, rtol=1e-12)
    assert np.all(np.linalg.eigvalsh(Pn) > -1e-10)
    # P_gp M^T with M = L_t L^-1: the regression of the principal on the proper part is
    # mapped, the principal part's conditional covariance given the proper part unchanged
    for k in range(3):
        cond_old = P[k, :4, :4] - P[k, :4, 4:] @ np.linalg.solve(P[k, 4:, 4:], P[k, 4:, :4])
        cond_new = Pn[k, :4, :4] - Pn[k, :4, 4:] @ np.linalg.solve(Pn[k, 4:, 4:], Pn[k, 4:, :4])
        np.testing.assert_allclose(cond_new, cond_old, atol=1e-9)
    # the same marginal in, the same joint out
    _, Ps = _replace_proper_part(x, P, x[:, 4:], P[:, 4:, 4:])
    np.testing.assert_allclose(Ps, P, atol=1e-12)
