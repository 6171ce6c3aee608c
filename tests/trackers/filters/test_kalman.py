"""Kalman update: hand-computed posteriors, textbook equivalence, scipy oracles, DARE."""

from __future__ import annotations

import math

import numpy as np
import pytest
from scipy.linalg import solve_discrete_are
from scipy.stats import multivariate_normal

from trackers.filters.kalman import innovation, kalman_update, log_gaussian
from trackers.models import motion
from trackers.models.measurement import H_POSITION
from trackers.models.motion import ConstantVelocity


def random_spd(rng: np.random.Generator, *batch: int, n: int) -> np.ndarray:
    A = rng.normal(size=(*batch, n, n))
    return A @ np.swapaxes(A, -1, -2) + n * np.eye(n)


def textbook_update(
    x: np.ndarray, P: np.ndarray, z: np.ndarray, R: np.ndarray, H: np.ndarray
) -> tuple[np.ndarray, np.ndarray, float]:
    """One track, the standard equations with an explicit inverse."""
    nu = z - H @ x
    S = H @ P @ H.T + R
    K = P @ H.T @ np.linalg.inv(S)
    P_post = (np.eye(len(x)) - K @ H) @ P
    ll = float(multivariate_normal(mean=np.zeros(len(z)), cov=S).logpdf(nu))
    return x + K @ nu, P_post, ll


def random_problem(
    rng: np.random.Generator, N: int, n: int = 5, m: int = 2
) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    x = rng.normal(size=(N, n)) * 50
    P = random_spd(rng, N, n=n)
    z = rng.normal(size=(N, m)) * 50
    R = random_spd(rng, N, n=m)
    return x, P, z, R


def test_scalar_static_case() -> None:
    # x = 2, P = 4, z = 3, R = 1: S = 5, K = 0.8, x⁺ = 2.8, P⁺ = 0.8.
    x, P, ll = kalman_update(
        np.array([[2.0]]), np.array([[[4.0]]]), np.array([[3.0]]), np.array([[[1.0]]]), np.eye(1)
    )
    assert x[0, 0] == pytest.approx(2.8, rel=1e-15)
    assert P[0, 0, 0] == pytest.approx(0.8, rel=1e-15)
    assert ll[0] == pytest.approx(-0.5 * (1 / 5 + math.log(5) + math.log(2 * math.pi)), rel=1e-15)


def test_position_velocity_case_by_hand() -> None:
    # State [p, v], P = diag(4, 1), H = [1, 0], R = 4, z − Hx = 2:
    # S = 8, K = [0.5, 0], x⁺ = [1, 3] + [1, 0], P⁺ = diag(2, 1).
    x, P, ll = kalman_update(
        np.array([[1.0, 3.0]]),
        np.diag([4.0, 1.0])[None],
        np.array([[3.0]]),
        np.array([[[4.0]]]),
        np.array([[1.0, 0.0]]),
    )
    np.testing.assert_allclose(x[0], [2.0, 3.0], rtol=1e-15)
    np.testing.assert_allclose(P[0], np.diag([2.0, 1.0]), rtol=1e-15, atol=1e-15)
    assert ll[0] == pytest.approx(-0.5 * (4 / 8 + math.log(8) + math.log(2 * math.pi)))


def test_innovation_by_hand() -> None:
    x = np.array([[1.0, 2.0, 3.0, 4.0, 0.1]])
    P = np.arange(25.0).reshape(1, 5, 5)
    P = P + np.swapaxes(P, -1, -2)
    R = np.array([[[2.0, 0.5], [0.5, 3.0]]])
    nu, S = innovation(x, P, np.array([[4.0, 0.0]]), R, H_POSITION)
    np.testing.assert_array_equal(nu, [[3.0, -2.0]])
    np.testing.assert_array_equal(S, P[:, :2, :2] + R)


@pytest.mark.parametrize(
    "H",
    [
        H_POSITION,
        H_POSITION.copy(),  # detected as a selector without the identity shortcut
        np.array([[0.0, 1.0, 0.0, 0.0, 0.0], [1.0, 0.0, 0.0, 0.0, 0.0]]),  # permuted selector
        np.array([[0.6, -0.8, 0.0, 0.1, 0.0], [0.8, 0.6, 0.2, 0.0, 0.0]]),  # general
        np.array([[1.0, 0.0, 0.0, 0.0, 0.0]]),  # m = 1
        np.array([[1.0, 0, 0, 0, 0], [0, 1.0, 0, 0, 0], [0.1, 0.2, 1.0, 0.3, 0]]),  # m = 3
    ],
)
def test_batched_update_matches_textbook_per_track(H: np.ndarray) -> None:
    rng = np.random.default_rng(11)
    m = H.shape[0]
    x, P, z, R = random_problem(rng, 8, m=m)
    x_post, P_post, ll = kalman_update(x, P, z, R, H)
    assert x_post.shape == (8, 5) and P_post.shape == (8, 5, 5) and ll.shape == (8,)
    for k in range(8):
        xk, Pk, llk = textbook_update(x[k], P[k], z[k], R[k], H)
        np.testing.assert_allclose(x_post[k], xk, rtol=1e-11, atol=1e-9)
        np.testing.assert_allclose(P_post[k], Pk, rtol=1e-9, atol=1e-9)
        assert ll[k] == pytest.approx(llk, rel=1e-12)
    np.testing.assert_array_equal(P_post, np.swapaxes(P_post, -1, -2))


def test_joseph_form_equals_standard_and_covariance_forms() -> None:
    """For the optimal gain: (I−KH)P(I−KH)ᵀ + KRKᵀ = (I−KH)P = P − K S Kᵀ."""
    rng = np.random.default_rng(12)
    x, P, z, R = random_problem(rng, 20)
    _, P_joseph, _ = kalman_update(x, P, z, R, H_POSITION)
    H = H_POSITION
    S = H @ P @ H.T + R
    K = P @ H.T @ np.linalg.inv(S)
    standard = (np.eye(5) - K @ H) @ P
    cov_form = P - K @ S @ np.swapaxes(K, -1, -2)
    np.testing.assert_allclose(P_joseph, standard, rtol=1e-10, atol=1e-10)
    np.testing.assert_allclose(P_joseph, cov_form, rtol=1e-10, atol=1e-10)
    assert np.all(np.linalg.eigvalsh(P_joseph) > 0)


def test_log_gaussian_matches_scipy() -> None:
    rng = np.random.default_rng(13)
    for m in (1, 2, 3, 4):
        nu = rng.normal(size=(6, m)) * 3
        S = random_spd(rng, 6, n=m)
        got = log_gaussian(nu, S)
        want = [multivariate_normal(np.zeros(m), S[k]).logpdf(nu[k]) for k in range(6)]
        np.testing.assert_allclose(got, want, rtol=1e-12)


def test_update_log_likelihood_matches_scipy() -> None:
    rng = np.random.default_rng(14)
    x, P, z, R = random_problem(rng, 10)
    _, _, ll = kalman_update(x, P, z, R, H_POSITION)
    nu, S = innovation(x, P, z, R, H_POSITION)
    want = [multivariate_normal(np.zeros(2), S[k]).logpdf(nu[k]) for k in range(10)]
    np.testing.assert_allclose(ll, want, rtol=1e-12)
    np.testing.assert_allclose(log_gaussian(nu, S), want, rtol=1e-12)


def test_broadcasting_one_measurement_over_modes() -> None:
    rng = np.random.default_rng(15)
    x = rng.normal(size=(4, 3, 5)) * 10
    P = random_spd(rng, 4, 3, n=5)
    z = rng.normal(size=(4, 1, 2)) * 10
    R = random_spd(rng, 4, 1, n=2)
    x_post, P_post, ll = kalman_update(x, P, z, R, H_POSITION)
    assert x_post.shape == (4, 3, 5) and P_post.shape == (4, 3, 5, 5) and ll.shape == (4, 3)
    for i in range(4):
        for j in range(3):
            xk, Pk, llk = textbook_update(x[i, j], P[i, j], z[i, 0], R[i, 0], H_POSITION)
            np.testing.assert_allclose(x_post[i, j], xk, rtol=1e-11, atol=1e-9)
            np.testing.assert_allclose(P_post[i, j], Pk, rtol=1e-9, atol=1e-9)
            assert ll[i, j] == pytest.approx(llk, rel=1e-12)


def test_inputs_untouched_and_block_size_irrelevant(monkeypatch: pytest.MonkeyPatch) -> None:
    rng = np.random.default_rng(16)
    x, P, z, R = random_problem(rng, 30)
    copies = [a.copy() for a in (x, P, z, R)]
    ref = kalman_update(x, P, z, R, H_POSITION)
    for a, b in zip((x, P, z, R), copies, strict=True):
        np.testing.assert_array_equal(a, b)
    monkeypatch.setattr(motion, "BLOCK_SIZE", 4)
    blocked = kalman_update(x, P, z, R, H_POSITION)
    for a, b in zip(ref, blocked, strict=True):
        np.testing.assert_array_equal(a, b)


def test_cv_filter_converges_to_riccati_solution() -> None:
    """Position-only measurements: the CV filter's prior covariance converges to the DARE's."""
    T, q, r = 0.5, 0.8, 9.0
    model = ConstantVelocity(q)
    R = r * np.eye(2)
    x = np.zeros((1, 5))
    P = np.diag([1e4, 1e4, 1e2, 1e2, 0.01])[None]
    rng = np.random.default_rng(17)
    for _ in range(400):
        x, P = model.predict(x, P, T)
        P_prior = P[0].copy()
        x, P, _ = kalman_update(x, P, rng.normal(size=(1, 2)), R[None], H_POSITION)

    # The same model on [x, y, vx, vy] alone.
    F4 = np.eye(4)
    F4[0, 2] = F4[1, 3] = T
    Q4 = model.process_noise(np.zeros((1, 5)), T)[0, :4, :4]
    H4 = np.eye(2, 4)
    X = solve_discrete_are(F4.T, H4.T, Q4, R)  # X = F X Fᵀ − F X Hᵀ(H X Hᵀ + R)⁻¹ H X Fᵀ + Q
    np.testing.assert_allclose(P_prior[:4, :4], X, rtol=1e-9, atol=1e-9)
    posterior = X - X @ H4.T @ np.linalg.solve(H4 @ X @ H4.T + R, H4 @ X)
    np.testing.assert_allclose(P[0, :4, :4], posterior, rtol=1e-9, atol=1e-9)
    # Per axis the [x, vx] block is the two-state DARE solution.
    F2 = np.array([[1.0, T], [0.0, 1.0]])
    Q2 = q * np.array([[T**3 / 3, T**2 / 2], [T**2 / 2, T]])
    X2 = solve_discrete_are(F2.T, np.array([[1.0], [0.0]]), Q2, np.array([[r]]))
    np.testing.assert_allclose(P_prior[np.ix_([0, 2], [0, 2])], X2, rtol=1e-9)
    np.testing.assert_allclose(P_prior[np.ix_([1, 3], [1, 3])], X2, rtol=1e-9)
    # ω is neither observed nor driven by the CV model: its variance never changes.
    assert P[0, 4, 4] == pytest.approx(0.01, rel=1e-12)
