"""IMM: FilterPy's IMMEstimator as an oracle, the textbook formulas, edge cases."""

from __future__ import annotations

import math
from collections.abc import Sequence

import numpy as np
import pytest
from filterpy.kalman import IMMEstimator, KalmanFilter
from scipy.stats import multivariate_normal

from trackers.filters.imm import (
    MU_FLOOR,
    imm_combine,
    imm_mix,
    imm_predict,
    imm_range_rate_update,
    imm_update,
    transition_matrix,
)
from trackers.filters.kalman import kalman_update
from trackers.models import motion
from trackers.models.measurement import H_POSITION
from trackers.models.motion import ConstantVelocity, CoordinatedTurn, MotionModel


def random_spd(rng: np.random.Generator, *batch: int, n: int = 5) -> np.ndarray:
    A = rng.normal(size=(*batch, n, n))
    return A @ np.swapaxes(A, -1, -2) + n * np.eye(n)


def random_imm_state(
    rng: np.random.Generator, N: int, M: int
) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    x = rng.normal(size=(N, M, 5)) * [300.0, 300.0, 15.0, 15.0, 0.1]
    P = random_spd(rng, N, M)
    mu = rng.uniform(0.05, 1.0, size=(N, M))
    return x, P, mu / mu.sum(axis=1, keepdims=True)


# --- transition matrix ---------------------------------------------------------------------


def test_transition_matrix_values_and_rows() -> None:
    Pi = transition_matrix([30.0, 10.0], 2.0)
    stay = np.exp(-2.0 / np.array([30.0, 10.0]))
    np.testing.assert_allclose(Pi, [[stay[0], 1 - stay[0]], [1 - stay[1], stay[1]]], rtol=1e-15)
    Pi3 = transition_matrix([5.0, 10.0, 20.0], 1.5)
    np.testing.assert_allclose(Pi3.sum(axis=1), 1.0, rtol=1e-15)
    assert Pi3[0, 1] == Pi3[0, 2] == pytest.approx((1 - math.exp(-1.5 / 5)) / 2)
    np.testing.assert_allclose(np.diag(Pi3), np.exp(-1.5 / np.array([5.0, 10.0, 20.0])))
    np.testing.assert_array_equal(transition_matrix([7.0], 3.0), [[1.0]])
    np.testing.assert_array_equal(transition_matrix([7.0, 3.0], 0.0), np.eye(2))


def test_transition_matrix_is_kept_read_only() -> None:
    """The matrices are cached per interval: a caller cannot change the next caller's."""
    first = transition_matrix((30.0, 10.0), 4.0)
    with pytest.raises(ValueError):
        first[0, 0] = 0.5
    again = transition_matrix(np.array([30.0, 10.0]), 4)
    np.testing.assert_array_equal(again, first)
    assert transition_matrix([30.0, 10.0], 4.5)[0, 0] == pytest.approx(math.exp(-4.5 / 30.0))
    assert not transition_matrix([7.0], 3.0).flags.writeable


@pytest.mark.parametrize("args", [([], 1.0), ([1.0, -2.0], 1.0), ([1.0, 2.0], -1.0)])
def test_transition_matrix_rejects_bad_input(args: tuple[list[float], float]) -> None:
    with pytest.raises(ValueError):
        transition_matrix(*args)


# --- mixing and combination against the textbook formulas -----------------------------------


def test_imm_mix_matches_textbook_loops() -> None:
    rng = np.random.default_rng(20)
    N, M = 6, 3
    x, P, mu = random_imm_state(rng, N, M)
    Pi = transition_matrix([20.0, 8.0, 4.0], 1.0)
    x0, P0, c_bar = imm_mix(x, P, mu, Pi)
    for k in range(N):
        for j in range(M):
            cj = sum(Pi[i, j] * mu[k, i] for i in range(M))
            w = [Pi[i, j] * mu[k, i] / cj for i in range(M)]
            xj = sum(w[i] * x[k, i] for i in range(M))
            Pj = sum(w[i] * (P[k, i] + np.outer(x[k, i] - xj, x[k, i] - xj)) for i in range(M))
            assert c_bar[k, j] == pytest.approx(cj, rel=1e-14)
            np.testing.assert_allclose(x0[k, j], xj, rtol=1e-12, atol=1e-10)
            np.testing.assert_allclose(P0[k, j], Pj, rtol=1e-11, atol=1e-9)
    np.testing.assert_allclose(c_bar.sum(axis=1), 1.0, rtol=1e-14)


def test_imm_combine_matches_textbook_and_identical_modes() -> None:
    rng = np.random.default_rng(21)
    x, P, mu = random_imm_state(rng, 5, 3)
    x_hat, P_hat = imm_combine(x, P, mu)
    for k in range(5):
        xk = mu[k] @ x[k]
        Pk = sum(mu[k, j] * (P[k, j] + np.outer(x[k, j] - xk, x[k, j] - xk)) for j in range(3))
        np.testing.assert_allclose(x_hat[k], xk, rtol=1e-13)
        np.testing.assert_allclose(P_hat[k], Pk, rtol=1e-11, atol=1e-9)
    # Identical modes combine to that mode, whatever the probabilities.
    same_x = np.repeat(x[:, :1], 3, axis=1)
    same_P = np.repeat(P[:, :1], 3, axis=1)
    x1, P1 = imm_combine(same_x, same_P, mu)
    np.testing.assert_allclose(x1, x[:, 0], rtol=1e-15)
    np.testing.assert_allclose(P1, P[:, 0], rtol=1e-14)


# --- FilterPy oracle -------------------------------------------------------------------------


def cv_matrices(q: float, T: float) -> tuple[np.ndarray, np.ndarray]:
    F = np.eye(5)
    F[0, 2] = F[1, 3] = T
    Q = np.zeros((5, 5))
    for p, v in ((0, 2), (1, 3)):
        Q[p, p] = q * T**3 / 3
        Q[p, v] = Q[v, p] = q * T**2 / 2
        Q[v, v] = q * T
    return F, Q


def cv_filter(q: float, T: float, x0: np.ndarray, P0: np.ndarray, R: np.ndarray) -> KalmanFilter:
    kf = KalmanFilter(dim_x=5, dim_z=2)
    kf.F, kf.Q = cv_matrices(q, T)
    kf.H = H_POSITION.copy()
    kf.R = R.copy()
    kf.x = x0.reshape(5, 1).copy()
    kf.P = P0.copy()
    return kf


class CoordinatedTurnEKF(KalmanFilter):
    """FilterPy filter whose predict is the CT EKF, written independently of the code under
    test: f differentiated directly in ω, evaluated in extended precision (ω must not be 0)."""

    def __init__(
        self, q: float, q_turn: float, T: float, x0: np.ndarray, P0: np.ndarray, R: np.ndarray
    ) -> None:
        super().__init__(dim_x=5, dim_z=2)
        self.T = T
        _, self.Q = cv_matrices(q, T)
        self.Q[4, 4] = q_turn * T
        self.H = H_POSITION.copy()
        self.R = R.copy()
        self.x = x0.reshape(5, 1).copy()
        self.P = P0.copy()

    def predict(
        self, u: object = None, B: object = None, F: object = None, Q: object = None
    ) -> None:
        px, py, vx, vy, w = (np.longdouble(v) for v in self.x[:, 0])
        T = np.longdouble(self.T)
        assert w != 0
        s, c = np.sin(w * T), np.cos(w * T)
        A, B_ = s / w, (1 - c) / w
        dA = (T * c * w - s) / w**2  # d/dω (sin ωT / ω)
        dB = (T * s * w - (1 - c)) / w**2  # d/dω ((1 − cos ωT) / ω)
        fx = [px + A * vx - B_ * vy, py + B_ * vx + A * vy, c * vx - s * vy, s * vx + c * vy, w]
        Fj = [
            [1, 0, A, -B_, vx * dA - vy * dB],
            [0, 1, B_, A, vx * dB + vy * dA],
            [0, 0, c, -s, -T * (s * vx + c * vy)],
            [0, 0, s, c, T * (c * vx - s * vy)],
            [0, 0, 0, 0, 1],
        ]
        self.F = np.array(Fj, dtype=np.longdouble).astype(float)
        self.x = np.array(fx, dtype=np.longdouble).astype(float).reshape(5, 1)
        self.P = self.F @ self.P @ self.F.T + self.Q
        self.x_prior = self.x.copy()
        self.P_prior = self.P.copy()


def turning_measurements(n: int, T: float, seed: int) -> np.ndarray:
    """A target flying straight, then turning at 0.12 rad/s, seen with 5 m noise."""
    rng = np.random.default_rng(seed)
    state = np.array([0.0, 0.0, 40.0, 10.0])
    zs = []
    for k in range(n):
        w = 0.0 if k < n // 3 else 0.12
        s, c = math.sin(w * T), math.cos(w * T)
        vx, vy = state[2], state[3]
        if w == 0.0:
            state = state + T * np.array([vx, vy, 0.0, 0.0])
        else:
            state = np.array(
                [
                    state[0] + (s * vx - (1 - c) * vy) / w,
                    state[1] + ((1 - c) * vx + s * vy) / w,
                    c * vx - s * vy,
                    s * vx + c * vy,
                ]
            )
        zs.append(state[:2] + rng.normal(scale=5.0, size=2))
    return np.array(zs)


def assert_close(ours: np.ndarray, theirs: np.ndarray, rtol: float = 1e-9) -> None:
    theirs = np.asarray(theirs, dtype=float)
    scale = max(float(np.abs(theirs).max()), 1e-300)
    np.testing.assert_allclose(ours, theirs, rtol=rtol, atol=rtol * scale)


def run_against_filterpy(
    models: Sequence[MotionModel],
    filters: list[KalmanFilter],
    x0: np.ndarray,
    P0: np.ndarray,
    mu0: np.ndarray,
    Pi: np.ndarray,
    T: float,
    zs: np.ndarray,
    R: np.ndarray,
) -> np.ndarray:
    """Run both estimators over zs, comparing everything at every step; returns our μ history."""
    # FilterPy's docstring calls M[i, j] the probability of switching from j to i, but its code
    # uses cbar = μ M, i.e. M[i, j] = P(i → j): exactly our Pi.
    imm = IMMEstimator(filters, mu0.copy(), Pi)
    M = len(models)
    x = np.repeat(x0[None, None], M, axis=1)
    P = np.repeat(P0[None, None], M, axis=1)
    mu = mu0[None].copy()
    history = []
    for z in zs:
        imm.predict()
        x_pred, P_pred, c_bar = imm_predict(models, x, P, mu, Pi, T)
        for j, f in enumerate(imm.filters):
            assert_close(x_pred[0, j], f.x[:, 0])
            assert_close(P_pred[0, j], f.P)
        assert_close(c_bar[0], imm.cbar, rtol=1e-12)
        c_before = imm.cbar.copy()

        imm.update(z)
        x, P, mu, ll = imm_update(x_pred, P_pred, c_bar, z[None], R[None], H_POSITION)
        for j, f in enumerate(imm.filters):
            assert_close(x[0, j], f.x[:, 0])
            assert_close(P[0, j], f.P)
        assert_close(mu[0], imm.mu)
        assert ll[0] == pytest.approx(math.log(float(c_before @ imm.likelihood)), rel=1e-9)
        x_hat, P_hat = imm_combine(x, P, mu)
        assert_close(x_hat[0], imm.x[:, 0])
        assert_close(P_hat[0], imm.P)
        assert mu.min() > 1e3 * MU_FLOOR  # the floor never acted, so FilterPy is comparable
        history.append(mu[0].copy())
    return np.array(history)


def test_imm_matches_filterpy_two_cv_models() -> None:
    T = 1.0
    q_lo, q_hi = 0.05, 20.0
    R = np.diag([25.0, 25.0])
    x0 = np.array([0.0, 0.0, 35.0, 5.0, 0.0])
    P0 = np.diag([100.0, 100.0, 100.0, 100.0, 0.01])
    zs = turning_measurements(30, T, seed=1)
    Pi = transition_matrix([30.0, 8.0], T)
    mu0 = np.array([0.8, 0.2])
    filters = [cv_filter(q, T, x0, P0, R) for q in (q_lo, q_hi)]
    models = (ConstantVelocity(q_lo), ConstantVelocity(q_hi))
    mus = run_against_filterpy(models, filters, x0, P0, mu0, Pi, T, zs, R)
    # Sanity of the scenario: the high-noise mode takes over during the turn.
    assert mus[:8, 0].mean() > 0.5 and mus[-8:, 1].mean() > 0.5


@pytest.mark.parametrize("sigma_omega", [None, 0.03])
def test_imm_matches_filterpy_cv_and_ct_ekf(sigma_omega: float | None) -> None:
    # With a turn-rate std the CV mode is the linear model ω⁻ = w, w ~ N(0, σ_ω²): row 4 of
    # F zero and Q₄₄ = σ_ω², which a plain FilterPy KalmanFilter runs as written.
    T = 1.0
    q_cv, q_ct, q_turn = 0.1, 1.0, 1e-3
    R = np.diag([25.0, 16.0])
    x0 = np.array([0.0, 0.0, 35.0, 5.0, 0.02])
    P0 = np.diag([100.0, 100.0, 100.0, 100.0, 0.01])
    zs = turning_measurements(30, T, seed=2)
    Pi = transition_matrix([20.0, 10.0], T)
    mu0 = np.array([0.7, 0.3])
    cv = cv_filter(q_cv, T, x0, P0, R)
    if sigma_omega is not None:
        cv.F[4, 4] = 0.0
        cv.Q[4, 4] = sigma_omega**2
    filters = [cv, CoordinatedTurnEKF(q_ct, q_turn, T, x0, P0, R)]
    models = (ConstantVelocity(q_cv, sigma_omega), CoordinatedTurn(q_ct, q_turn))
    mus = run_against_filterpy(models, filters, x0, P0, mu0, Pi, T, zs, R)
    # The turn is recognised: the CT mode dominates at the end, much more than in straight flight.
    assert mus[-5:, 1].mean() > 0.7 and mus[-5:, 1].mean() > mus[3:9, 1].mean() + 0.3


def test_a_finished_turn_does_not_live_on_in_the_cv_mode() -> None:
    # A 0.12 rad/s turn, then 25 s of straight flight. Carried unchanged, the turn's rate stays
    # in the CV mode's state (nothing there observes it) and comes back into the CT mode through
    # the mixing; reset to N(0, σ_ω²) at each prediction it is gone from both modes.
    T, R = 1.0, np.diag([25.0, 25.0])
    rng = np.random.default_rng(8)
    state = np.array([0.0, 0.0, 40.0, 10.0, 0.0])
    truth = []
    for k in range(45):
        state[4] = 0.12 if 5 <= k < 20 else 0.0
        x_next, _ = CoordinatedTurn(1.0, 1e-3).transition(state[None], T)
        state = x_next[0]
        truth.append(state.copy())
    zs = np.array([s[:2] for s in truth]) + rng.normal(scale=5.0, size=(len(truth), 2))
    Pi = transition_matrix([30.0, 10.0], T)

    def final_turn_rates(cv: ConstantVelocity) -> np.ndarray:
        models = (cv, CoordinatedTurn(2.0, 1e-4))
        x = np.array([[[0.0, 0.0, 40.0, 10.0, 0.0]] * 2])
        P = np.diag([100.0, 100.0, 100.0, 100.0, 0.05**2])[None, None].repeat(2, axis=1)
        mu = np.array([[0.9, 0.1]])
        for z in zs:
            xp, Pp, cb = imm_predict(models, x, P, mu, Pi, T)
            x, P, mu, _ = imm_update(xp, Pp, cb, z[None], R[None], H_POSITION)
        return x[0, :, 4]

    carried = final_turn_rates(ConstantVelocity(0.5))
    reset = final_turn_rates(ConstantVelocity(0.5, 0.05))
    # Carried: both modes still hold most of the finished turn's 0.12 rad/s (0.116, 0.109).
    assert carried[0] > 0.08 and carried[1] > 0.08
    # Reset: the CV mode's rate is 0, the CT mode's is its own estimate, near 0 (0.014).
    assert reset[0] == 0.0 and abs(reset[1]) < 0.03


# --- batching, floors, robustness --------------------------------------------------------------


def test_batched_predict_and_update_equal_single_track_calls(
    monkeypatch: pytest.MonkeyPatch,
) -> None:
    rng = np.random.default_rng(22)
    N = 9
    models = (ConstantVelocity(0.5), CoordinatedTurn(2.0, 1e-3))
    x, P, mu = random_imm_state(rng, N, 2)
    Pi = transition_matrix([30.0, 10.0], 0.7)
    z = x[:, 0, :2] + rng.normal(size=(N, 2)) * 10
    R = random_spd(rng, N, n=2) * 5
    xp, Pp, cb = imm_predict(models, x, P, mu, Pi, 0.7)
    xu, Pu, mu_u, ll = imm_update(xp, Pp, cb, z, R, H_POSITION)
    for k in range(N):
        one = slice(k, k + 1)
        single_predict = imm_predict(models, x[one], P[one], mu[one], Pi, 0.7)
        for a, b in zip(single_predict, (xp[one], Pp[one], cb[one]), strict=True):
            assert_close(a, b, rtol=1e-13)
        single_update = imm_update(*single_predict, z[one], R[one], H_POSITION)
        for a, b in zip(single_update, (xu[one], Pu[one], mu_u[one], ll[one]), strict=True):
            assert_close(a, b, rtol=1e-13)
    # Block size does not change anything either.
    monkeypatch.setattr(motion, "BLOCK_SIZE", 5)
    for a, b in zip(imm_update(xp, Pp, cb, z, R, H_POSITION), (xu, Pu, mu_u, ll), strict=True):
        assert_close(a, b, rtol=1e-13)
    for a, b in zip(imm_predict(models, x, P, mu, Pi, 0.7), (xp, Pp, cb), strict=True):
        assert_close(a, b, rtol=1e-13)


def test_imm_update_is_mode_matched_kalman_with_bayes_mode_probabilities() -> None:
    rng = np.random.default_rng(23)
    x, P, _ = random_imm_state(rng, 4, 2)
    x[:, 1] = x[:, 0] + rng.normal(size=(4, 5)) * 4  # modes close enough for both to matter
    c_bar = np.array([[0.3, 0.7], [0.5, 0.5], [0.9, 0.1], [0.01, 0.99]])
    z = x[:, 1, :2] + rng.normal(size=(4, 2)) * 3
    R = np.repeat(np.eye(2)[None] * 9, 4, axis=0)
    xu, Pu, mu, ll = imm_update(x, P, c_bar, z, R, H_POSITION)
    for k in range(4):
        lam = []
        for j in range(2):
            xk, Pk, _ = kalman_update(x[k, j], P[k, j], z[k], R[k], H_POSITION)
            np.testing.assert_allclose(xu[k, j], xk, rtol=1e-13)
            np.testing.assert_allclose(Pu[k, j], Pk, rtol=1e-13)
            S = P[k, j, :2, :2] + R[k]
            lam.append(multivariate_normal(np.zeros(2), S).pdf(z[k] - x[k, j, :2]))
        w = c_bar[k] * np.array(lam)
        np.testing.assert_allclose(mu[k], w / w.sum(), rtol=1e-10)
        assert ll[k] == pytest.approx(math.log(w.sum()), rel=1e-12)


def test_mode_probabilities_never_underflow_or_reach_zero() -> None:
    """A measurement 10⁵ σ away from one mode and 10⁶ σ from the other: the likelihoods
    underflow as numbers but not as logs; μ stays finite, floored and normalized."""
    x = np.zeros((1, 2, 5))
    x[0, 1, 0] = 9e5
    P = np.repeat(np.eye(5)[None, None], 2, axis=1)
    z = np.array([[1e6, 0.0]])
    R = np.eye(2)[None]
    _, _, mu, ll = imm_update(x, P, np.array([[0.5, 0.5]]), z, R, H_POSITION)
    assert np.all(np.isfinite(mu)) and math.isfinite(ll[0])
    assert mu[0, 0] == pytest.approx(MU_FLOOR, rel=1e-3)
    assert mu.sum() == pytest.approx(1.0, rel=1e-15)
    expected = math.log(0.5) - 0.5 * (1e5**2 / 2) - math.log(2 * math.pi * 2)
    assert ll[0] == pytest.approx(expected, rel=1e-12)
    # The floored mode is still mixed back in at the next prediction.
    models = (ConstantVelocity(1.0), ConstantVelocity(1.0))
    _, _, c_bar = imm_predict(models, x, P, np.array([[0.0, 1.0]]), np.eye(2), 1.0)
    assert c_bar[0, 0] > 0.0


def test_zero_dt_prediction_keeps_modes() -> None:
    rng = np.random.default_rng(24)
    x, P, mu = random_imm_state(rng, 3, 2)
    models = (ConstantVelocity(1.0), CoordinatedTurn(1.0, 1e-3))
    Pi = transition_matrix([30.0, 10.0], 0.0)
    xp, Pp, cb = imm_predict(models, x, P, mu, Pi, 0.0)
    np.testing.assert_allclose(xp, x, rtol=1e-15)
    np.testing.assert_allclose(Pp, P, rtol=1e-15)
    np.testing.assert_allclose(cb, mu, rtol=1e-15)


def test_models_without_state_major_predict_work() -> None:
    class OnlyPredict:
        name = "cv"

        def __init__(self) -> None:
            self.inner = ConstantVelocity(0.5)

        def transition(self, x: np.ndarray, dt: float) -> tuple[np.ndarray, np.ndarray]:
            return self.inner.transition(x, dt)

        def process_noise(self, x: np.ndarray, dt: float) -> np.ndarray:
            return self.inner.process_noise(x, dt)

        def predict(self, x: np.ndarray, P: np.ndarray, dt: float) -> tuple[np.ndarray, np.ndarray]:
            return self.inner.predict(x, P, dt)

    rng = np.random.default_rng(25)
    x, P, mu = random_imm_state(rng, 4, 2)
    Pi = transition_matrix([30.0, 10.0], 1.0)
    ct = CoordinatedTurn(2.0, 1e-3)
    ref = imm_predict((ConstantVelocity(0.5), ct), x, P, mu, Pi, 1.0)
    got = imm_predict((OnlyPredict(), ct), x, P, mu, Pi, 1.0)  # type: ignore[arg-type]
    for a, b in zip(got, ref, strict=True):
        np.testing.assert_allclose(a, b, rtol=1e-14)


def test_inputs_are_not_modified() -> None:
    rng = np.random.default_rng(26)
    x, P, mu = random_imm_state(rng, 5, 2)
    z = rng.normal(size=(5, 2))
    R = np.repeat(np.eye(2)[None], 5, axis=0)
    args = [x, P, mu, z, R]
    copies = [a.copy() for a in args]
    Pi = transition_matrix([30.0, 10.0], 1.0)
    models = (ConstantVelocity(1.0), CoordinatedTurn(1.0, 1e-3))
    xp, Pp, cb = imm_predict(models, x, P, mu, Pi, 1.0)
    saved = [xp.copy(), Pp.copy(), cb.copy()]
    imm_update(xp, Pp, cb, z, R, H_POSITION)
    imm_combine(x, P, mu)
    imm_mix(x, P, mu, Pi)
    for a, b in zip([*args, xp, Pp, cb], [*copies, *saved], strict=True):
        np.testing.assert_array_equal(a, b)


def test_cv_mode_turn_rate_stays_bounded() -> None:
    """Long straight flight, then a long turn: the CV mode's ω only ever receives mixed-in
    CT estimates and its variance is never inflated by CV itself, so nothing diverges."""
    T = 1.0
    models = (ConstantVelocity(0.1), CoordinatedTurn(1.0, 1e-4))
    Pi = transition_matrix([30.0, 10.0], T)
    R = np.eye(2)[None] * 25
    x = np.zeros((1, 2, 5))
    x[0, :, 2] = 40.0
    P = np.repeat(np.diag([100.0, 100.0, 100.0, 100.0, 0.0025])[None, None], 2, axis=1)
    mu = np.array([[0.9, 0.1]])
    zs = turning_measurements(300, T, seed=3)
    for z in zs:
        xp, Pp, cb = imm_predict(models, x, P, mu, Pi, T)
        x, P, mu, _ = imm_update(xp, Pp, cb, z[None], R, H_POSITION)
        assert np.all(np.isfinite(x)) and np.all(np.isfinite(P))
        assert np.all(np.abs(x[0, :, 4]) < 0.5)
        assert np.all(P[0, :, 4, 4] < 0.01)
        assert np.all(np.linalg.eigvalsh(P[0]) > 0)
    assert abs(x[0, 1, 4] - 0.12) < 0.02  # the CT mode found the true turn rate


def test_range_rate_update_in_every_mode_and_the_mode_probabilities() -> None:
    """Each mode's posterior gets the EKF range-rate step; μ_j ∝ μ_j Λ_j and
    Δ ln Λ = ln Σ μ_j Λ_j: the mode whose velocity agrees with the range-rate gains."""
    from trackers.models.measurement import range_rate_update

    sensor = np.array([0.0, 0.0])
    x = np.array([[[3000.0, 4000.0, 6.0, 8.0, 0.0], [3000.0, 4000.0, -6.0, -8.0, 0.0]]])
    P = np.tile(np.diag([100.0, 100.0, 4.0, 4.0, 1e-4]), (1, 2, 1, 1))
    mu = np.array([[0.5, 0.5]])
    xn, Pn, mun, dll = imm_range_rate_update(x, P, mu, np.array([10.0]), sensor, 1.0)
    for j in range(2):
        xe, Pe, lle = range_rate_update(x[:, j], P[:, j], np.array([10.0]), sensor, 1.0)
        np.testing.assert_allclose(xn[:, j], xe)
        np.testing.assert_allclose(Pn[:, j], Pe)
        if j == 0:
            ll0 = lle[0]
        else:
            ll1 = lle[0]
    w = 0.5 * np.exp([ll0, ll1])
    floored = np.maximum(w / w.sum(), MU_FLOOR)
    np.testing.assert_allclose(mun[0], floored / floored.sum())
    assert dll[0] == pytest.approx(math.log(w.sum()))
    assert mun[0, 0] > 0.99  # receding at 10 m/s: the first mode
