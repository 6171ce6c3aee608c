"""Posterior Cramér–Rao bound: equals the Kalman covariance, converges to the Riccati limit."""

from __future__ import annotations

import itertools

import numpy as np
import pytest
from scipy.linalg import solve_discrete_are

from trackers.evaluation.crb import (
    POSITION_H,
    cv_matrices,
    pcrb_linear,
    straight_line_velocity_bound,
)


def kalman_covariances(
    F: np.ndarray, Q: np.ndarray, H: np.ndarray, R: np.ndarray, P0: np.ndarray, steps: int
) -> np.ndarray:
    """Covariance form of the Kalman filter with the Joseph update."""
    P = P0.copy()
    out: list[np.ndarray] = []
    eye = np.eye(P.shape[0])
    for _ in range(steps):
        P = F @ P @ F.T + Q
        S = H @ P @ H.T + R
        K = P @ H.T @ np.linalg.inv(S)
        A = eye - K @ H
        P = A @ P @ A.T + K @ R @ K.T
        out.append(P)
    return np.array(out)


def test_cv_matrices() -> None:
    F, Q = cv_matrices(2.0, 0.5)
    assert np.array_equal(F, [[1, 0, 2, 0], [0, 1, 0, 2], [0, 0, 1, 0], [0, 0, 0, 1]])
    expected = 0.5 * np.array(
        [[8 / 3, 0, 2, 0], [0, 8 / 3, 0, 2], [2, 0, 2, 0], [0, 2, 0, 2]], dtype=float
    )
    assert np.allclose(Q, expected)
    assert np.allclose(Q, Q.T)


@pytest.mark.parametrize(
    ("dt", "q", "sigma", "p0"), [(1.0, 0.05, 5.0, 100.0), (0.5, 2.0, 20.0, 1e4)]
)
def test_pcrb_equals_kalman_covariance(dt: float, q: float, sigma: float, p0: float) -> None:
    F, Q = cv_matrices(dt, q)
    R = sigma**2 * np.eye(2)
    P0 = np.diag([p0, 2 * p0, p0 / 10, p0 / 5])
    P0[0, 2] = P0[2, 0] = 0.3 * np.sqrt(P0[0, 0] * P0[2, 2])
    bounds = pcrb_linear(F, Q, POSITION_H, R, np.linalg.inv(P0), 40)
    assert bounds.shape == (40, 4, 4)
    kf = kalman_covariances(F, Q, POSITION_H, R, P0, 40)
    assert np.allclose(bounds, kf, rtol=1e-8, atol=1e-10)


def test_pcrb_decreases_to_the_steady_state() -> None:
    F, Q = cv_matrices(1.0, 0.05)
    H, R = POSITION_H, 25.0 * np.eye(2)
    bounds = pcrb_linear(F, Q, H, R, 1e-6 * np.eye(4), 300)
    # Monotone in the Loewner order from a diffuse prior.
    for before, after in itertools.pairwise(bounds):
        assert np.linalg.eigvalsh(before - after).min() > -1e-9 * np.abs(before).max()
    assert np.trace(bounds[0]) > 10 * np.trace(bounds[-1])
    # Limit: the filtered covariance of the discrete algebraic Riccati equation.
    X = solve_discrete_are(F.T, H.T, Q, R)
    steady = X - X @ H.T @ np.linalg.solve(H @ X @ H.T + R, H @ X)
    assert np.allclose(bounds[-1], steady, rtol=1e-6)
    # The steady-state position bound is below one measurement's variance σ².
    assert bounds[-1][0, 0] < 25.0


def test_zero_steps_and_inputs_unchanged() -> None:
    F, Q = cv_matrices(1.0, 0.1)
    J0 = np.eye(4)
    copies = [a.copy() for a in (F, Q, J0)]
    assert pcrb_linear(F, Q, POSITION_H, np.eye(2), J0, 0).shape == (0, 4, 4)
    pcrb_linear(F, Q, POSITION_H, np.eye(2), J0, 5)
    assert all(np.array_equal(a, b) for a, b in zip((F, Q, J0), copies, strict=True))


def test_invalid_inputs() -> None:
    F, Q = cv_matrices(1.0, 0.1)
    with pytest.raises(ValueError):
        pcrb_linear(F, Q, POSITION_H, np.eye(3), np.eye(4), 3)
    with pytest.raises(ValueError):
        pcrb_linear(F, Q, POSITION_H, np.eye(2), np.zeros((4, 4)), 3)
    with pytest.raises(ValueError):
        pcrb_linear(F, Q, POSITION_H, np.eye(2), np.eye(4), -1)
    with pytest.raises(ValueError):
        cv_matrices(-1.0, 0.1)


def test_cv_position_bound_starts_at_the_detection_and_settles():
    from trackers.evaluation.crb import cv_position_bound

    b = cv_position_bound(dt=1.0, q=0.05, sigma=5.0, velocity_std=10.0, n_scans=80)
    assert b[0] == pytest.approx(np.sqrt(2) * 5.0)
    assert np.all(np.diff(b[1:]) <= 1e-12)  # the bound only tightens after the first update
    assert b[-1] == pytest.approx(b[-2], rel=1e-6)  # steady state
    assert b[-1] < 5.0  # filtering beats a single detection's √2 σ


def test_straight_line_velocity_bound_is_the_least_squares_slope_variance() -> None:
    """N measurements T apart with noise σ² I: the slope of a least-squares line has variance
    12 σ² / (N (N² − 1) T²) per axis; two members measured alike, with a common velocity,
    halve it; before a second time there is no bound (inf)."""
    sigma, T, N = 30.0, 2.0, 12
    t = T * np.arange(N)
    R = np.tile(sigma**2 * np.eye(2), (N, 1, 1))
    queries = t + 0.5
    got = straight_line_velocity_bound(t, R, np.zeros(N), 1, queries)
    n = np.arange(1, N + 1)
    with np.errstate(divide="ignore"):
        expected = 2 * 12 * sigma**2 / (n * (n**2 - 1) * T**2)
    assert got[0] == np.inf and np.allclose(got[1:], expected[1:])
    assert straight_line_velocity_bound(t, R, np.zeros(N), 1, [-1.0])[0] == np.inf
    # a second member measured at the same times (in any order): half the variance
    both = straight_line_velocity_bound(
        np.concatenate([t, t[::-1]]),
        np.concatenate([R, R]),
        np.repeat([0, 1], N),
        2,
        queries,
    )
    assert both[1] == np.inf or np.isclose(both[1], 0.5 * expected[1])
    assert np.allclose(both[2:], 0.5 * expected[2:])
    with pytest.raises(ValueError):
        straight_line_velocity_bound(t, R, np.full(N, 2), 2, queries)
    with pytest.raises(ValueError):
        straight_line_velocity_bound(t, R[:-1], np.zeros(N), 1, queries)
