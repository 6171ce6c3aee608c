"""Motion models, measurement eq. 40, its Jacobian eq. 41 and the EKF of
:mod:`trackers.pattern.bending`."""

from __future__ import annotations

import math

import numpy as np
import pytest

from trackers.pattern.bending import (
    PrincipalModel,
    ProperModel,
    measure,
    measurement_jacobian,
    predict,
    predict_mixture,
    principal_transition,
    proper_transition,
    transition,
    update,
    update_batch,
)

R = np.diag([0.09, 0.09])


def random_cov(rng: np.random.Generator, n: int = 6) -> np.ndarray:
    A = rng.normal(size=(n, n))
    return A @ A.T + 0.1 * np.eye(n)


def stacked_ekf(x, P, pattern, detections, pairs, R):
    """The textbook stacked EKF (eq. 10 with H of eq. 41), for reference."""
    q = pattern[pairs[:, 0]]
    H = measurement_jacobian(x, q)
    nu = (detections[pairs[:, 1]] - measure(x, q)).ravel()
    S = H @ P @ H.T + np.kron(np.eye(len(pairs)), R)
    K = P @ H.T @ np.linalg.inv(S)
    ll = -0.5 * (
        len(nu) * math.log(2 * math.pi) + np.linalg.slogdet(S)[1] + nu @ np.linalg.solve(S, nu)
    )
    return x + K @ nu, P - K @ S @ K.T, ll


def test_jacobian_matches_finite_differences():
    rng = np.random.default_rng(0)
    q = rng.uniform(-10, 10, size=(5, 2))
    for alpha in (0.0, 0.7, 2.5, -1.2):
        x = np.array([3.0, 1.0, -4.0, 2.0, alpha, 0.3])
        H = measurement_jacobian(x, q)
        eps = 1e-6
        num = np.empty_like(H)
        for j in range(6):
            dx = np.zeros(6)
            dx[j] = eps
            num[:, j] = (measure(x + dx, q).ravel() - measure(x - dx, q).ravel()) / (2 * eps)
        np.testing.assert_allclose(H, num, atol=1e-8)


def test_measure_is_rotation_about_the_reference_point():
    x = np.array([10.0, 0.0, 20.0, 0.0, math.pi / 2, 0.0])
    np.testing.assert_allclose(
        measure(x, [[1.0, 0.0], [0.0, 2.0]]), [[10.0, 21.0], [8.0, 20.0]], atol=1e-12
    )


@pytest.mark.parametrize("dt", [0.5, 1.0, 3.0])
def test_turn_with_vanishing_rate_is_constant_velocity(dt):
    F_cv, Q_cv = principal_transition(PrincipalModel("CV", 0.0, 0.004), dt)
    F_ct, Q_ct = principal_transition(PrincipalModel("CT", 1e-9, 0.004), dt)
    np.testing.assert_allclose(F_ct, F_cv, atol=1e-8)
    np.testing.assert_array_equal(Q_ct, Q_cv)
    np.testing.assert_array_equal(F_cv, [[1, dt, 0, 0], [0, 1, 0, 0], [0, 0, 1, dt], [0, 0, 0, 1]])


def test_turn_rotates_the_velocity_by_omega_t():
    w = math.radians(-3.0)
    F, _ = principal_transition(PrincipalModel("CT", w, 0.0), 1.0)
    v = F @ np.array([0.0, 100.0, 0.0, 100.0])
    heading = math.atan2(v[3], v[1])
    assert heading == pytest.approx(math.radians(45.0) + w)
    assert math.hypot(v[1], v[3]) == pytest.approx(100 * math.sqrt(2))
    # the exact arc: chord of length 2 (V/ω) sin(ωT/2)
    assert math.hypot(v[0], v[2]) == pytest.approx(
        2 * (100 * math.sqrt(2) / abs(w)) * math.sin(abs(w) / 2)
    )


def test_null_velocity_keeps_attitude_and_zeroes_rate():
    F, b, Q = proper_transition(ProperModel("NV", 0.0, 0.01), 1.0)
    xp = F @ np.array([0.8, 0.2]) + b
    np.testing.assert_array_equal(xp, [0.8, 0.0])
    F, b, _ = proper_transition(ProperModel("CV", None, 0.01), 2.0)
    np.testing.assert_allclose(F @ np.array([0.8, 0.2]) + b, [1.2, 0.2])
    F, b, _ = proper_transition(ProperModel("R", 0.1, 0.01), 2.0)
    np.testing.assert_allclose(F @ np.array([0.8, 0.2]) + b, [1.0, 0.1])
    np.testing.assert_allclose(Q, 0.01**2 * np.outer([0.5, 1.0], [0.5, 1.0]))


def test_predict_is_kalman_with_block_diagonal_model_and_does_not_mutate():
    rng = np.random.default_rng(1)
    x = rng.normal(size=6)
    P = random_cov(rng)
    x_copy, P_copy = x.copy(), P.copy()
    g, p = PrincipalModel("CT", 0.05, 0.01), ProperModel("CV", None, 0.02)
    F, b, Q = transition(g, p, 1.5)
    xp, Pp = predict(x, P, 1.5, g, p)
    np.testing.assert_allclose(xp, F @ x + b, atol=1e-12)
    np.testing.assert_allclose(Pp, F @ P @ F.T + Q, atol=1e-12)
    np.testing.assert_array_equal(x, x_copy)
    np.testing.assert_array_equal(P, P_copy)


def test_predict_mixture_is_the_moment_matched_mixture():
    rng = np.random.default_rng(2)
    x = rng.normal(size=(1, 6))
    P = random_cov(rng)[None]
    gs = [PrincipalModel("CV", 0.0, 0.004), PrincipalModel("CT", 0.1, 0.001)]
    ps = [ProperModel("NV", 0.0, 0.01), ProperModel("CV", None, 0.01)]
    wg, wp = np.array([[0.3, 0.7]]), np.array([[0.6, 0.4]])
    xm, Pm = predict_mixture(x, P, 1.0, gs, ps, wg, wp)
    comps = []
    for a in range(2):
        for b in range(2):
            comps.append((wg[0, a] * wp[0, b], *predict(x[0], P[0], 1.0, gs[a], ps[b])))
    mean = sum(w * xc for w, xc, _ in comps)
    cov = sum(w * (Pc + np.outer(xc - mean, xc - mean)) for w, xc, Pc in comps)
    np.testing.assert_allclose(xm[0], mean, atol=1e-12)
    np.testing.assert_allclose(Pm[0], cov, atol=1e-10)


def test_update_equals_the_stacked_ekf():
    rng = np.random.default_rng(3)
    x = np.array([10.0, 3.0, -5.0, 2.0, 0.7, 0.1])
    P = random_cov(rng)
    pattern = rng.uniform(-10, 10, (5, 2))
    pairs = np.array([[0, 2], [1, 0], [3, 1], [4, 3]])
    det = measure(x, pattern)[[1, 3, 0, 4]] + rng.normal(0, 0.3, (4, 2))
    Rc = np.array([[0.09, 0.01], [0.01, 0.08]])
    x1, P1, ll1 = update(x, P, pattern, det, pairs, Rc)
    x2, P2, ll2 = stacked_ekf(x, P, pattern, det, pairs, Rc)
    np.testing.assert_allclose(x1, x2, atol=1e-10)
    np.testing.assert_allclose(P1, P2, atol=1e-9)
    assert ll1 == pytest.approx(ll2, abs=1e-9)


def test_update_worked_answer_with_known_attitude():
    """α known (zero variance): the points are linear measurements of the centre, so the
    posterior centre is the prior pulled toward the mean offset-corrected detection with
    gain σ₀² / (σ₀² + r/p) per axis, and velocities (uncorrelated) stay put."""
    alpha = 0.5
    x = np.array([1.0, 2.0, 3.0, 4.0, alpha, 0.0])
    P = np.diag([4.0, 1.0, 4.0, 1.0, 0.0, 0.0])
    pattern = np.array([[1.0, 0.0], [0.0, 2.0], [-3.0, 1.0]])
    truth_centre = np.array([2.0, 1.0])
    c, s = math.cos(alpha), math.sin(alpha)
    det = truth_centre + pattern @ np.array([[c, s], [-s, c]])  # exact points, centre (2, 1)
    pairs = np.array([[0, 0], [1, 1], [2, 2]])
    x1, P1, ll = update(x, P, pattern, det, pairs, R)
    gain = 4.0 / (4.0 + 0.09 / 3)
    np.testing.assert_allclose(x1[[0, 2]], [1 + gain * 1.0, 3 + gain * (-2.0)], atol=1e-12)
    np.testing.assert_allclose(x1[[1, 3, 4, 5]], [2.0, 4.0, alpha, 0.0], atol=1e-12)
    np.testing.assert_allclose(P1[0, 0], 4.0 * (1 - gain), atol=1e-12)
    np.testing.assert_allclose(P1[2, 2], 4.0 * (1 - gain), atol=1e-12)
    assert np.isfinite(ll)


def test_single_point_updates_the_centre_only():
    rng = np.random.default_rng(4)
    x = np.array([0.0, 1.0, 0.0, 1.0, 0.3, 0.05])
    P = random_cov(rng)
    pattern = np.array([[5.0, 1.0], [-2.0, 3.0]])
    det = measure(x, pattern[:1]) + 0.4
    x1, P1, ll = update(x, P, pattern, det, np.array([[0, 0]]), R)
    np.testing.assert_array_equal(x1[4:], x[4:])
    np.testing.assert_array_equal(P1[4:, 4:], P[4:, 4:])
    assert not np.allclose(x1[:4], x[:4])
    assert np.all(np.linalg.eigvalsh(P1) > -1e-9)
    _, _, ll_ref = stacked_ekf(x, P, pattern, det, np.array([[0, 0]]), R)
    assert ll == pytest.approx(ll_ref)  # S keeps the attitude uncertainty


def test_no_points_is_prediction_only():
    rng = np.random.default_rng(5)
    x, P = rng.normal(size=6), random_cov(rng)
    x1, P1, ll = update(x, P, np.ones((3, 2)), np.zeros((0, 2)), np.zeros((0, 2), int), R)
    np.testing.assert_array_equal(x1, x)
    np.testing.assert_allclose(P1, P)
    assert ll == 0.0


def test_update_batch_mixes_point_counts():
    rng = np.random.default_rng(6)
    K = 3
    x = rng.normal(size=(K, 6))
    P = np.stack([random_cov(rng) for _ in range(K)])
    q = rng.uniform(-5, 5, (K, 4, 2))
    z = rng.normal(size=(K, 4, 2))
    mask = np.array([[1, 1, 1, 1], [1, 1, 0, 0], [0, 0, 0, 0]], float)
    xs, Ps, ll = update_batch(x, P, q, z, mask, R)
    for k in range(K):
        p = int(mask[k].sum())
        xk, Pk, llk = update(x[k], P[k], q[k], z[k], np.column_stack([np.arange(p)] * 2), R)
        np.testing.assert_allclose(xs[k], xk, atol=1e-12)
        np.testing.assert_allclose(Ps[k], Pk, atol=1e-12)
        assert ll[k] == pytest.approx(llk)


def test_bad_inputs_raise():
    with pytest.raises(ValueError):
        predict(np.zeros(5), np.eye(5), 1.0, PrincipalModel("CV"), ProperModel("NV"))
    with pytest.raises(ValueError):
        predict(np.zeros(6), np.eye(6), -1.0, PrincipalModel("CV"), ProperModel("NV"))
    with pytest.raises(ValueError):
        update(np.zeros(6), np.eye(6), np.ones((2, 2)), np.ones((2, 2)), np.array([[0, 0]]), -R)
    with pytest.raises(ValueError):
        PrincipalModel("CT", math.inf)
