"""FPPM with the chi-square similarity test (paper 000, sections 4.3.2-4.3.4)."""

from __future__ import annotations

import math

import numpy as np
import pytest
from scipy import stats

from trackers.pattern.fppm import (
    PatternMatch,
    chi2_threshold,
    match_fppm,
    pattern_match,
    similar,
    similarity_statistic,
)
from trackers.pattern.registration import Similarity

PATTERN = np.array([[-8.0, -6.0], [7.0, -7.5], [9.0, 6.0], [-2.0, 8.5], [1.0, -1.0]])
G = Similarity(1.4, 2.2, np.array([120.0, -35.0]))


def _pairs(match: PatternMatch | None) -> set[tuple[int, int]]:
    assert match is not None
    return {(int(i), int(j)) for i, j in match.pairs.tolist()}


# --- the similarity test ------------------------------------------------------------------


def _draw_true_pairs(rng: np.random.Generator, draws: int, N: int, sigma: float):
    """``draws`` clusters of N pairs plus one new pair, all under one random similarity."""
    x = rng.uniform(-10.0, 10.0, (draws, N + 1, 2))
    th = rng.uniform(-math.pi, math.pi, draws)
    s = rng.uniform(0.5, 2.0, draws)
    c, sn = s * np.cos(th), s * np.sin(th)
    A = np.stack([np.stack([c, -sn], -1), np.stack([sn, c], -1)], -2)
    y = np.einsum("dij,dkj->dki", A, x) + rng.uniform(-100, 100, (draws, 1, 2))
    y = y + rng.normal(0.0, sigma, y.shape)
    return x[:, :N], y[:, :N], x[:, N], y[:, N]


def _gls_statistic(xc, yc, xn, yn, sigma):
    """Eq. 36 the long way: GLS of a = [s cos θ, s sin θ] from the anchor's vectors with their
    full correlated covariance (eq. 37), the statistic being the increase of the GLS cost
    when the new vector joins (anchor = the cluster's first pair)."""

    def cost(xs, ys):
        u = xs[1:] - xs[0]
        v = (ys[1:] - ys[0]).reshape(-1)
        k = u.shape[0]
        B = np.zeros((2 * k, 2))
        B[0::2] = np.column_stack([u[:, 0], -u[:, 1]])
        B[1::2] = np.column_stack([u[:, 1], u[:, 0]])
        Pyy = sigma**2 * np.kron(np.eye(k) + np.ones((k, k)), np.eye(2))
        Pi = np.linalg.inv(Pyy)
        a = np.linalg.solve(B.T @ Pi @ B, B.T @ Pi @ v)
        r = v - B @ a
        return float(r @ Pi @ r)

    return cost(np.vstack([xc, xn]), np.vstack([yc, yn])) - cost(xc, yc)


def _paper_statistic(xc, yc, xn, yn, sigma):
    """Eq. 36 with the case-2 decorrelation of eqs. 38-39: z̃ᵢ = vᵢ − (1/i) Σ_{k<i} v_k,
    tᵢ = uᵢ − (1/i) Σ_{k<i} u_k, z̃ᵢ ~ N(tᵢ a, (i+1)/i σ²) (complex form)."""
    X = np.vstack([xc, xn])
    Y = np.vstack([yc, yn])
    u = (X[1:, 0] - X[0, 0]) + 1j * (X[1:, 1] - X[0, 1])
    v = (Y[1:, 0] - Y[0, 0]) + 1j * (Y[1:, 1] - Y[0, 1])
    N = u.shape[0]
    t = np.array([u[i] - u[:i].sum() / (i + 1) for i in range(N)])
    z = np.array([v[i] - v[:i].sum() / (i + 1) for i in range(N)])
    D = np.array([(i + 2) / (i + 1) for i in range(N)]) * sigma**2
    W = np.sum(np.abs(t[:-1]) ** 2 / D[:-1])
    a_hat = np.sum(np.conj(t[:-1]) * z[:-1] / D[:-1]) / W
    e = z[-1] / t[-1] - a_hat
    return float(abs(e) ** 2 / (1.0 / W + D[-1] / abs(t[-1]) ** 2))


@pytest.mark.parametrize("N", [2, 3, 6])
def test_statistic_equals_gls_and_the_papers_decorrelated_form(N: int) -> None:
    rng = np.random.default_rng(N)
    xc, yc, xn, yn = _draw_true_pairs(rng, 5, N, 0.7)
    eps = similarity_statistic(xc, yc, xn, yn, 0.7)
    assert eps.shape == (5,)
    for d in range(5):
        assert eps[d] == pytest.approx(_gls_statistic(xc[d], yc[d], xn[d], yn[d], 0.7), rel=1e-8)
        assert eps[d] == pytest.approx(_paper_statistic(xc[d], yc[d], xn[d], yn[d], 0.7), rel=1e-8)
    # which pair is the anchor does not matter
    perm = rng.permutation(N)
    np.testing.assert_allclose(
        similarity_statistic(xc[:, perm], yc[:, perm], xn, yn, 0.7), eps, rtol=1e-10
    )


def test_chi2_threshold_is_the_chi_square_quantile() -> None:
    for alpha in (0.001, 0.01, 0.05, 0.3):
        assert chi2_threshold(alpha) == pytest.approx(stats.chi2.ppf(1 - alpha, 2), rel=1e-12)
    with pytest.raises(ValueError):
        chi2_threshold(0.0)
    with pytest.raises(ValueError):
        chi2_threshold(1.0)


@pytest.mark.parametrize("alpha", [0.01, 0.05])
def test_false_rejection_rate_of_the_similarity_test(alpha: float) -> None:
    rng = np.random.default_rng(12)
    draws = 20000
    rejected = 0
    for N in (2, 3, 5):  # clusters of the anchor and 1, 2, 4 vectors
        xc, yc, xn, yn = _draw_true_pairs(rng, draws // 3 + 1, N, 0.5)
        rejected += int(np.count_nonzero(~similar(xc, yc, xn, yn, 0.5, alpha)))
    total = 3 * (draws // 3 + 1)
    rate = rejected / total
    tol = 4.0 * math.sqrt(alpha * (1 - alpha) / total)  # binomial, 4 standard deviations
    assert abs(rate - alpha) < tol, (rate, alpha, tol)
    # the statistic is χ²₂: its mean is 2
    xc, yc, xn, yn = _draw_true_pairs(rng, 20000, 4, 0.5)
    assert similarity_statistic(xc, yc, xn, yn, 0.5).mean() == pytest.approx(2.0, abs=0.1)


def test_similarity_test_rejects_a_wrong_pair() -> None:
    x = PATTERN[:3]
    y = G.apply(x)
    wrong = G.apply(PATTERN[3]) + np.array([3.0, 0.0])
    assert similar(x, y, PATTERN[3], G.apply(PATTERN[3]), 0.1)
    assert not similar(x, y, PATTERN[3], wrong, 0.1)
    with pytest.raises(ValueError):
        similarity_statistic(x[:1], y[:1], PATTERN[3], wrong, 0.1)


# --- FPPM -------------------------------------------------------------------------------


def test_exact_pattern_rotated_scaled_translated() -> None:
    Q = G.apply(PATTERN)[[3, 0, 4, 1, 2]]
    match = match_fppm(PATTERN, Q, 0.05)
    assert _pairs(match) == {(0, 1), (1, 3), (2, 4), (3, 0), (4, 2)}
    assert match is not None and match.support == 5
    assert match.registration.s == pytest.approx(1.4, abs=1e-9)
    assert match.registration.theta == pytest.approx(2.2, abs=1e-9)
    np.testing.assert_allclose(match.registration.t, G.t, atol=1e-7)
    assert match.mse == pytest.approx(0.0, abs=1e-12)
    assert match.pairs.dtype == np.int64
    assert np.all(np.diff(match.pairs[:, 0]) > 0)


def test_missed_points() -> None:
    Q = G.apply(PATTERN[[0, 2, 4]])
    assert _pairs(match_fppm(PATTERN, Q, 0.05)) == {(0, 0), (2, 1), (4, 2)}
    Q = G.apply(PATTERN[[1, 2, 3, 4]])
    assert _pairs(match_fppm(PATTERN, Q, 0.05)) == {(1, 0), (2, 1), (3, 2), (4, 3)}


def _cluttered(seed: int, sigma: float, keep=(0, 1, 2, 3, 4), n_clutter: int = 15):
    rng = np.random.default_rng(seed)
    noise = np.clip(rng.normal(0.0, sigma, (len(keep), 2)), -2 * sigma, 2 * sigma)  # no outliers
    true_y = G.apply(PATTERN[list(keep)]) + noise
    clutter = G.t + rng.uniform(-40.0, 40.0, (n_clutter, 2))
    Q = np.vstack([clutter[: n_clutter // 2], true_y, clutter[n_clutter // 2 :]])
    first = n_clutter // 2
    return Q, {(i, first + r) for r, i in enumerate(keep)}


@pytest.mark.parametrize("seed", range(5))
def test_clutter_and_missed_points(seed: int) -> None:
    Q, truth = _cluttered(seed, 0.02, keep=(0, 1, 3, 4))
    assert _pairs(match_fppm(PATTERN, Q, 0.02)) == truth
    assert _pairs(match_fppm(PATTERN, Q, 0.02, scale_range=(1.3, 1.5))) == truth


@pytest.mark.parametrize("seed", range(5))
def test_noise(seed: int) -> None:
    Q, truth = _cluttered(seed, 0.3, n_clutter=6)
    match = match_fppm(PATTERN, Q, 0.3)
    assert _pairs(match) == truth
    assert match is not None
    assert match.registration.s == pytest.approx(1.4, abs=0.05)
    assert 0.0 < match.mse < 9 * 0.3**2


def test_scale_range_excludes_registrations() -> None:
    Q = G.apply(PATTERN)
    assert match_fppm(PATTERN, Q, 0.05, scale_range=(0.9, 1.1)) is None
    assert match_fppm(PATTERN, Q, 0.05, scale_range=(1.3, 1.5)) is not None


def test_pure_clutter_gives_no_match() -> None:
    rng = np.random.default_rng(7)
    for _ in range(5):
        Q = rng.uniform(-60.0, 60.0, (15, 2))
        match = match_fppm(PATTERN, Q, 0.01)
        assert match is None or match.support - 1 < 2
    assert match_fppm(PATTERN, G.apply(PATTERN[:2]), 0.01) is None  # 2 points: w = 1 < w_min
    assert match_fppm(PATTERN, G.apply(PATTERN[:3]), 0.01, w_min=3) is None


def test_ties_go_to_the_smallest_mse() -> None:
    pattern = PATTERN[:3]
    rng = np.random.default_rng(0)
    noisy = G.apply(pattern) + rng.normal(0.0, 0.05, (3, 2))
    H = Similarity(1.4, -1.0, np.array([-300.0, 200.0]))
    exact = H.apply(pattern)
    Q = np.vstack([noisy, exact])  # the noisy copy comes first in every scan order
    match = match_fppm(pattern, Q, 0.1)
    assert _pairs(match) == {(0, 3), (1, 4), (2, 5)}
    assert match is not None and match.mse == pytest.approx(0.0, abs=1e-12)
    Q = np.vstack([exact, noisy])
    assert _pairs(match_fppm(pattern, Q, 0.1)) == {(0, 0), (1, 1), (2, 2)}
    # with the exact copy flagged out, the noisy one is the answer
    flags = np.ones((3, 6), dtype=bool)
    flags[:, :3] = False
    assert _pairs(match_fppm(pattern, Q, 0.1, mflag=flags)) == {(0, 3), (1, 4), (2, 5)}


def test_larger_support_beats_smaller_mse() -> None:
    rng = np.random.default_rng(1)
    four = G.apply(PATTERN[:4]) + rng.normal(0.0, 0.05, (4, 2))
    three = Similarity(1.4, 0.5, np.array([500.0, 0.0])).apply(PATTERN[:3])
    match = match_fppm(PATTERN, np.vstack([three, four]), 0.1)
    assert match is not None and match.support == 4


def test_w_max_stops_early_with_a_valid_match() -> None:
    Q, truth = _cluttered(3, 0.02)
    match = match_fppm(PATTERN, Q, 0.02, w_max=2)
    assert match is not None and match.support >= 3
    assert _pairs(match) <= truth


def test_deterministic_and_inputs_unchanged() -> None:
    Q, _ = _cluttered(4, 0.2)
    P0, Q0 = PATTERN.copy(), Q.copy()
    a = match_fppm(PATTERN, Q, 0.2)
    b = match_fppm(PATTERN, Q, 0.2)
    assert a is not None and b is not None
    np.testing.assert_array_equal(a.pairs, b.pairs)
    assert a.mse == b.mse
    np.testing.assert_array_equal(PATTERN, P0)
    np.testing.assert_array_equal(Q, Q0)
    with pytest.raises(ValueError):
        a.pairs[0, 0] = 3  # read-only


def test_bad_arguments_raise() -> None:
    Q = G.apply(PATTERN)
    with pytest.raises(ValueError):
        match_fppm(PATTERN, Q, 0.0)
    with pytest.raises(ValueError):
        match_fppm(PATTERN, Q, 0.1, w_min=1)
    with pytest.raises(ValueError):
        match_fppm(PATTERN, Q, 0.1, false_rejection=1.5)
    with pytest.raises(ValueError):
        match_fppm(PATTERN, Q, 0.1, scale_range=(2.0, 1.0))
    with pytest.raises(ValueError):
        match_fppm(np.vstack([PATTERN, PATTERN[:1]]), Q, 0.1)
    with pytest.raises(ValueError):
        match_fppm(PATTERN, Q, 0.1, mflag=np.ones((5, 4), dtype=bool))


def test_pattern_match_fits_and_checks_pairs() -> None:
    Q = G.apply(PATTERN)
    m = pattern_match(PATTERN, Q, np.array([[2, 2], [0, 0], [1, 1]]))
    np.testing.assert_array_equal(m.pairs, [[0, 0], [1, 1], [2, 2]])
    assert m.registration.s == pytest.approx(1.4)
    with pytest.raises(ValueError):
        pattern_match(PATTERN, Q, np.array([[0, 0], [0, 1]]))
    with pytest.raises(ValueError):
        pattern_match(PATTERN, Q, np.array([[0, 0], [1, 0]]))
