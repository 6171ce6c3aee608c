"""Motion models: closed-form values, Jacobians, continuity at ω = 0, layouts and blocks."""

from __future__ import annotations

import math

import numpy as np
import pytest

from trackers.config import MotionConfig
from trackers.models import motion
from trackers.models.motion import (
    AGILE_MIN_SPEED,
    ConstantVelocity,
    CoordinatedTurn,
    agile_turn_rate,
    along_track_noise,
    batch_major,
    batch_major_cov,
    build_models,
    row_blocks,
    state_major,
    state_major_cov,
)


def random_spd(rng: np.random.Generator, *batch: int, n: int = 5) -> np.ndarray:
    A = rng.normal(size=(*batch, n, n))
    return A @ np.swapaxes(A, -1, -2) + n * np.eye(n)


def random_states(rng: np.random.Generator, n: int) -> np.ndarray:
    return rng.normal(size=(n, 5)) * [500.0, 500.0, 20.0, 20.0, 0.2]


def cv_matrices(q: float, T: float) -> tuple[np.ndarray, np.ndarray]:
    """F and Q of the CV model written out by hand."""
    F = np.array(
        [
            [1, 0, T, 0, 0],
            [0, 1, 0, T, 0],
            [0, 0, 1, 0, 0],
            [0, 0, 0, 1, 0],
            [0, 0, 0, 0, 1],
        ],
        dtype=float,
    )
    a, b, c = q * T**3 / 3, q * T**2 / 2, q * T
    Q = np.array(
        [
            [a, 0, b, 0, 0],
            [0, a, 0, b, 0],
            [b, 0, c, 0, 0],
            [0, b, 0, c, 0],
            [0, 0, 0, 0, 0],
        ]
    )
    return F, Q


# --- constant velocity ---------------------------------------------------------------------


def test_cv_transition_and_noise_match_hand_written() -> None:
    rng = np.random.default_rng(1)
    x = random_states(rng, 4)
    model = ConstantVelocity(q=0.7)
    F_hand, Q_hand = cv_matrices(0.7, 1.3)
    fx, F = model.transition(x, 1.3)
    assert F.shape == (4, 5, 5)
    np.testing.assert_array_equal(F, np.broadcast_to(F_hand, (4, 5, 5)))
    np.testing.assert_allclose(fx, x @ F_hand.T, rtol=1e-15, atol=1e-12)
    Q = model.process_noise(x, 1.3)
    assert Q.shape == (4, 5, 5)
    np.testing.assert_allclose(Q, np.broadcast_to(Q_hand, (4, 5, 5)), rtol=1e-15)


def test_cv_predict_equals_F_P_Ft_plus_Q() -> None:
    rng = np.random.default_rng(2)
    x = random_states(rng, 6)
    P = random_spd(rng, 6)
    T = 0.8
    F, Q = cv_matrices(2.5, T)
    x_pred, P_pred = ConstantVelocity(2.5).predict(x, P, T)
    np.testing.assert_allclose(x_pred, x @ F.T, rtol=1e-14)
    expected = F @ P @ F.T + Q
    np.testing.assert_allclose(P_pred, expected, rtol=1e-13, atol=1e-12)
    np.testing.assert_array_equal(P_pred, np.swapaxes(P_pred, -1, -2))


def test_cv_predict_known_numbers() -> None:
    # Single track: x = [0, 0, 1, 2, 0.1], P = I, q = 1, T = 2 (hand computed).
    x = np.array([[0.0, 0.0, 1.0, 2.0, 0.1]])
    P = np.eye(5)[None]
    x_pred, P_pred = ConstantVelocity(1.0).predict(x, P, 2.0)
    np.testing.assert_allclose(x_pred, [[2.0, 4.0, 1.0, 2.0, 0.1]])
    # Per axis: F P Fᵀ = [[1 + T², T], [T, 1]] = [[5, 2], [2, 1]], Q = [[8/3, 2], [2, 2]].
    expected = np.array(
        [
            [5 + 8 / 3, 0, 4, 0, 0],
            [0, 5 + 8 / 3, 0, 4, 0],
            [4, 0, 3, 0, 0],
            [0, 4, 0, 3, 0],
            [0, 0, 0, 0, 1],
        ]
    )
    np.testing.assert_allclose(P_pred[0], expected, rtol=1e-15)


def test_cv_turn_rate_is_carried_without_noise() -> None:
    rng = np.random.default_rng(3)
    x = random_states(rng, 5)
    P = random_spd(rng, 5)
    x_pred, P_pred = ConstantVelocity(3.0).predict(x, P, 5.0)
    np.testing.assert_array_equal(x_pred[:, 4], x[:, 4])
    np.testing.assert_allclose(P_pred[:, 4, 4], P[:, 4, 4], rtol=1e-15)


def test_cv_with_turn_rate_std_resets_the_turn_rate() -> None:
    # ω⁻ = w, w ~ N(0, σ²): F as for CV except F₄₄ = 0, Q as for CV plus Q₄₄ = σ².
    rng = np.random.default_rng(13)
    x = random_states(rng, 6)
    P = random_spd(rng, 6)
    T, sigma = 1.7, 0.04
    model = ConstantVelocity(0.6, turn_rate_std=sigma)
    F, Q = cv_matrices(0.6, T)
    F[4, 4] = 0.0
    Q[4, 4] = sigma**2
    fx, F_model = model.transition(x, T)
    np.testing.assert_array_equal(F_model, np.broadcast_to(F, (6, 5, 5)))
    np.testing.assert_allclose(fx, x @ F.T, rtol=1e-15, atol=1e-12)
    np.testing.assert_allclose(model.process_noise(x, T), np.broadcast_to(Q, (6, 5, 5)))
    x_pred, P_pred = model.predict(x, P, T)
    np.testing.assert_allclose(x_pred, x @ F.T, rtol=1e-14, atol=1e-12)
    np.testing.assert_allclose(P_pred, F @ P @ F.T + Q, rtol=1e-13, atol=1e-12)
    assert np.all(x_pred[:, 4] == 0.0) and np.all(P_pred[:, 4, :4] == 0.0)
    np.testing.assert_array_equal(P_pred[:, 4, 4], sigma**2)
    with pytest.raises(ValueError, match="turn_rate_std"):
        ConstantVelocity(1.0, turn_rate_std=-0.1)


def test_agile_turn_rate_worked_values() -> None:
    # ω(v) = max(ω₀, min(0.5, a / v, Δψ / T)) from 25 m/s on, ω₀ below.
    v = np.array([0.0, 10.0, 24.9, 25.0, 40.0, 250.0, 700.0])
    np.testing.assert_allclose(
        agile_turn_rate(v, 0.05, 12.0), [0.05, 0.05, 0.05, 0.48, 0.3, 0.05, 0.05]
    )
    # at most 0.2 rad a step: 0.2 rad/s over 1 s; over 4 s ω₀ stands; 0.125 with 0.5 rad
    np.testing.assert_allclose(agile_turn_rate(v[3:5], 0.05, 12.0, 1.0), [0.2, 0.2])
    np.testing.assert_allclose(agile_turn_rate(v[3:5], 0.05, 12.0, 4.0), [0.05, 0.05])
    np.testing.assert_allclose(agile_turn_rate(v[3:5], 0.05, 12.0, 4.0, 0.5), [0.125, 0.125])
    # one step per speed, with its own limit of 1 rad; no acceleration: ω₀ everywhere
    np.testing.assert_allclose(
        agile_turn_rate(np.array([40.0, 40.0, 40.0]), 0.1, 12.0, np.array([0.0, 5.0, 20.0]), 1.0),
        [0.3, 0.2, 0.1],
    )
    np.testing.assert_array_equal(agile_turn_rate(v, 0.05, 0.0), np.full(v.size, 0.05))
    assert AGILE_MIN_SPEED == 25.0


def test_cv_turn_rate_prior_of_an_agile_target_grows_as_its_speed_falls() -> None:
    # Q₄₄ = ω(|v|)² per state, within 0.2 rad a step; the rest as without agility (a = 12).
    x = np.zeros((4, 5))
    x[:, 2] = [10.0, 30.0, 40.0, 250.0]
    P = np.tile(np.eye(5), (4, 1, 1))
    agile = ConstantVelocity(0.5, turn_rate_std=0.05, agile_acceleration=12.0)
    plain = ConstantVelocity(0.5, turn_rate_std=0.05)
    assert agile.agile and not plain.agile
    expected = np.array([0.05, 0.4, 0.3, 0.05]) ** 2  # a 0.25 s step: a / v itself
    _, P_agile = agile.predict(x, P, 0.25)
    _, P_plain = plain.predict(x, P, 0.25)
    np.testing.assert_allclose(P_agile[:, 4, 4], expected, rtol=1e-12)
    np.testing.assert_allclose(agile.process_noise(x, 0.25)[:, 4, 4], expected, rtol=1e-12)
    P_agile[:, 4, 4] = P_plain[:, 4, 4]
    np.testing.assert_array_equal(P_agile, P_plain)
    # over 1 s, 0.2 rad/s; a track seen every 4 s is held to ω₀ even over a 0.25 s step
    _, P1 = agile.predict(x, P, 1.0)
    np.testing.assert_allclose(P1[:, 4, 4], np.array([0.05, 0.2, 0.2, 0.05]) ** 2)
    revisit = np.array([4.0, 4.0, 1.0, 1.0])
    _, Ps = agile.predict_state_major(state_major(x), state_major_cov(P), 0.25, revisit)
    np.testing.assert_allclose(Ps[4, 4], np.array([0.05, 0.05, 0.2, 0.05]) ** 2)
    np.testing.assert_allclose(
        agile.process_noise(x, 0.25, revisit)[:, 4, 4], np.array([0.05, 0.05, 0.2, 0.05]) ** 2
    )
    with pytest.raises(ValueError, match="agile_acceleration"):
        ConstantVelocity(1.0, 0.05, agile_acceleration=-1.0)


def test_build_models_resets_the_cv_turn_rate_only_beside_a_turn_mode() -> None:
    both = build_models(MotionConfig(cv_turn_rate_std=0.02))
    assert both[0].turn_rate_std == 0.02
    assert both[0].agile_acceleration == MotionConfig().agile_acceleration == 12.0
    alone = build_models(
        MotionConfig(models=("cv",), sojourn_times=(30.0,), initial_mode_probabilities=(1.0,))
    )
    assert alone[0].turn_rate_std is None


@pytest.mark.parametrize(
    "model", [ConstantVelocity(1.0), ConstantVelocity(1.0, 0.05), CoordinatedTurn(1.0, 0.01)]
)
def test_zero_dt_returns_inputs_unchanged(model: ConstantVelocity | CoordinatedTurn) -> None:
    rng = np.random.default_rng(4)
    x = random_states(rng, 3)
    P = random_spd(rng, 3)
    x_pred, P_pred = model.predict(x, P, 0.0)
    np.testing.assert_array_equal(x_pred, x)
    np.testing.assert_array_equal(P_pred, P)
    assert not np.shares_memory(x_pred, x) and not np.shares_memory(P_pred, P)


@pytest.mark.parametrize("model", [ConstantVelocity(1.0), CoordinatedTurn(1.0, 0.01)])
def test_predict_does_not_modify_inputs(model: ConstantVelocity | CoordinatedTurn) -> None:
    rng = np.random.default_rng(5)
    x = random_states(rng, 7)
    P = random_spd(rng, 7)
    x0, P0 = x.copy(), P.copy()
    model.predict(x, P, 1.5)
    model.transition(x, 1.5)
    np.testing.assert_array_equal(x, x0)
    np.testing.assert_array_equal(P, P0)


@pytest.mark.parametrize("model", [ConstantVelocity(1.0), CoordinatedTurn(1.0, 0.01)])
def test_predict_shapes_single_and_empty(model: ConstantVelocity | CoordinatedTurn) -> None:
    x = np.array([1.0, 2.0, 3.0, 4.0, 0.05])
    P = np.eye(5)
    x1, P1 = model.predict(x, P, 1.0)
    xb, Pb = model.predict(x[None], P[None], 1.0)
    assert x1.shape == (5,) and P1.shape == (5, 5)
    np.testing.assert_array_equal(x1, xb[0])
    np.testing.assert_array_equal(P1, Pb[0])
    xe, Pe = model.predict(np.zeros((0, 5)), np.zeros((0, 5, 5)), 1.0)
    assert xe.shape == (0, 5) and Pe.shape == (0, 5, 5)


def test_invalid_arguments_raise() -> None:
    with pytest.raises(ValueError):
        ConstantVelocity(-1.0)
    with pytest.raises(ValueError):
        CoordinatedTurn(1.0, float("nan"))
    with pytest.raises(ValueError):
        ConstantVelocity(1.0).predict(np.zeros((1, 5)), np.eye(5)[None], -0.1)
    with pytest.raises(ValueError):
        CoordinatedTurn(1.0, 0.1).transition(np.zeros((1, 5)), float("inf"))


# --- coordinated turn ----------------------------------------------------------------------


def test_ct_transition_known_quarter_turn() -> None:
    # ω = π/2 rad/s for T = 1 s turns v = (10, 0) into (0, 10); the position moves along a
    # quarter circle of radius v/ω = 20/π: Δ = (20/π, 20/π).
    x = np.array([[100.0, -50.0, 10.0, 0.0, math.pi / 2]])
    fx, _ = CoordinatedTurn(1.0, 0.01).transition(x, 1.0)
    r = 20.0 / math.pi
    np.testing.assert_allclose(fx[0], [100.0 + r, -50.0 + r, 0.0, 10.0, math.pi / 2], atol=1e-12)


@pytest.mark.parametrize("omega", [0.0, 1e-3, 0.29, 0.31, 1.0])
def test_ct_single_state_equals_a_batch_of_one(omega: float) -> None:
    """One state without a batch axis, on both sides of the series/closed-form switch."""
    model = CoordinatedTurn(1.0, 0.01)
    x = np.array([10.0, 20.0, 3.0, -4.0, omega])
    fx, F = model.transition(x, 1.0)
    fb, Fb = model.transition(x[None], 1.0)
    assert fx.shape == (5,) and F.shape == (5, 5)
    np.testing.assert_array_equal(fx, fb[0])
    np.testing.assert_array_equal(F, Fb[0])


def numerical_jacobian(model: CoordinatedTurn, x: np.ndarray, dt: float) -> np.ndarray:
    """Central differences, one column per state component (step scaled to the component)."""
    J = np.empty((5, 5))
    for k in range(5):
        h = 1e-6 * max(1.0, abs(x[k])) if k < 4 else 1e-7
        xp, xm = x.copy(), x.copy()
        xp[k] += h
        xm[k] -= h
        fp, _ = model.transition(xp[None], dt)
        fm, _ = model.transition(xm[None], dt)
        J[:, k] = (fp[0] - fm[0]) / (2 * h)
    return J


@pytest.mark.parametrize("omega", [0.0, 1e-9, -1e-9, 1e-4, 0.05, -0.29, 0.31, 0.7, -1.3])
@pytest.mark.parametrize("dt", [0.5, 1.0, 2.0])
def test_ct_jacobian_matches_finite_differences(omega: float, dt: float) -> None:
    model = CoordinatedTurn(1.0, 0.01)
    x = np.array([1200.0, -300.0, 35.0, -12.0, omega])
    _, F = model.transition(x[None], dt)
    J = numerical_jacobian(model, x, dt)
    np.testing.assert_allclose(F[0], J, rtol=1e-6, atol=1e-6)


def test_ct_jacobian_at_zero_turn_rate_closed_form() -> None:
    # At ω = 0: ∂x/∂ω = −vy T²/2, ∂y/∂ω = vx T²/2, ∂vx/∂ω = −T vy, ∂vy/∂ω = T vx.
    vx, vy, T = 30.0, -8.0, 2.0
    _, F = CoordinatedTurn(1.0, 0.01).transition(np.array([[0.0, 0.0, vx, vy, 0.0]]), T)
    F_cv, _ = cv_matrices(1.0, T)
    np.testing.assert_allclose(F[0, :, :4], F_cv[:, :4], atol=1e-15)
    np.testing.assert_allclose(
        F[0, :, 4], [-vy * T**2 / 2, vx * T**2 / 2, -T * vy, T * vx, 1.0], rtol=1e-15
    )


def test_ct_transition_continuous_at_zero_and_equal_to_cv() -> None:
    rng = np.random.default_rng(6)
    x = random_states(rng, 5)
    cv = ConstantVelocity(1.0)
    ct = CoordinatedTurn(1.0, 0.01)
    for omega in (0.0, 1e-15, -1e-12, 1e-9):
        xo = x.copy()
        xo[:, 4] = omega
        f_ct, F_ct = ct.transition(xo, 3.0)
        f_cv, F_cv = cv.transition(xo, 3.0)
        np.testing.assert_allclose(f_ct, f_cv, rtol=1e-12, atol=1e-6)
        np.testing.assert_allclose(F_ct[:, :, :4], F_cv[:, :, :4], atol=1e-8)
    # Values across the series / closed-form switch at |ωT| = 0.3 join smoothly.
    omegas = 0.3 + np.array([-1e-9, -1e-12, 0.0, 1e-12, 1e-9])
    xs = np.repeat(x[:1], omegas.size, axis=0)
    xs[:, 4] = omegas
    f, F = ct.transition(xs, 1.0)
    assert np.ptp(f, axis=0).max() < 1e-6
    assert np.ptp(F, axis=0).max() < 1e-7


def test_turn_functions_accurate_everywhere() -> None:
    """a, b, a', b' against extended-precision closed forms (series and closed branches)."""
    if np.finfo(np.longdouble).eps > 1e-18:
        pytest.skip("no extended precision on this platform")
    phi = np.concatenate(
        [np.linspace(-2.0, 2.0, 401), 0.3 + np.array([-1e-6, -1e-12, 1e-12, 1e-6]), [1e-3]]
    )
    phi = phi[phi != 0.0]
    _, _, a, b, da, db = motion._turn_functions(phi)
    p = phi.astype(np.longdouble)
    sl, cl = np.sin(p), np.cos(p)
    expected = [sl / p, (1 - cl) / p, (p * cl - sl) / p**2, (p * sl - 1 + cl) / p**2]
    for got, want in zip((a, b, da, db), expected, strict=True):
        want = want.astype(float)
        np.testing.assert_allclose(got, want, rtol=2e-13, atol=1e-15)
    # And the limits at φ = 0.
    _, _, a0, b0, da0, db0 = motion._turn_functions(np.zeros(1))
    assert (a0[0], b0[0], da0[0], db0[0]) == (1.0, 0.0, 0.0, 0.5)


@pytest.mark.parametrize("omega", [0.2, -0.05, 1.5])
def test_ct_noise_free_full_turn_returns_to_start(omega: float) -> None:
    x = np.array([[250.0, -75.0, 12.0, 5.0, omega]])
    ct = CoordinatedTurn(1.0, 0.01)
    period = 2 * math.pi / abs(omega)
    one_step, _ = ct.transition(x, period)
    np.testing.assert_allclose(one_step, x, rtol=0, atol=1e-9 * 300)
    steps = 97
    xk = x
    P = np.zeros((1, 5, 5))
    for _ in range(steps):
        xk, _ = ct.predict(xk, P, period / steps)
    np.testing.assert_allclose(xk, x, rtol=0, atol=1e-9 * 300)
    # Halfway round the velocity is reversed and the track is a diameter 2v/|ω| away.
    half, _ = ct.transition(x, period / 2)
    np.testing.assert_allclose(half[0, 2:4], -x[0, 2:4], atol=1e-12)
    speed = math.hypot(12.0, 5.0)
    assert math.hypot(*(half[0, :2] - x[0, :2])) == pytest.approx(2 * speed / abs(omega))


def test_ct_process_noise() -> None:
    T = 1.7
    Q = CoordinatedTurn(0.9, 3e-4).process_noise(np.zeros((2, 5)), T)
    _, Q_cv = cv_matrices(0.9, T)
    Q_cv[4, 4] = 3e-4 * T
    np.testing.assert_allclose(Q, np.broadcast_to(Q_cv, (2, 5, 5)), rtol=1e-15)


def test_ct_predict_equals_jacobian_propagation() -> None:
    rng = np.random.default_rng(7)
    x = random_states(rng, 9)
    P = random_spd(rng, 9)
    ct = CoordinatedTurn(2.0, 1e-3)
    fx, F = ct.transition(x, 1.1)
    Q = ct.process_noise(x, 1.1)
    x_pred, P_pred = ct.predict(x, P, 1.1)
    np.testing.assert_array_equal(x_pred, fx)
    np.testing.assert_allclose(P_pred, F @ P @ np.swapaxes(F, -1, -2) + Q, rtol=1e-12, atol=1e-9)
    np.testing.assert_array_equal(P_pred, np.swapaxes(P_pred, -1, -2))


def test_ct_at_zero_turn_rate_predicts_like_cv() -> None:
    """With ω = 0 and no ω uncertainty the CT prediction is the CV one (plus ω noise)."""
    rng = np.random.default_rng(8)
    x = random_states(rng, 4)
    x[:, 4] = 0.0
    P = random_spd(rng, 4)
    P[:, 4, :] = 0.0
    P[:, :, 4] = 0.0
    x_cv, P_cv = ConstantVelocity(1.5).predict(x, P, 2.0)
    x_ct, P_ct = CoordinatedTurn(1.5, 1e-3).predict(x, P, 2.0)
    np.testing.assert_allclose(x_ct, x_cv, rtol=1e-14, atol=1e-9)
    np.testing.assert_allclose(P_ct[:, :4, :4], P_cv[:, :4, :4], rtol=1e-13)
    np.testing.assert_allclose(P_ct[:, 4, 4], 2e-3)


# --- factory, layouts, blocks ----------------------------------------------------------------


def test_build_models_follows_config() -> None:
    cfg = MotionConfig(q_cv=0.3, q_ct=4.0, q_turn_rate=2e-4)
    cv, ct = build_models(cfg)
    assert isinstance(cv, ConstantVelocity) and cv.name == "cv" and cv.q == 0.3
    assert isinstance(ct, CoordinatedTurn) and ct.name == "ct"
    assert (ct.q, ct.q_turn_rate) == (4.0, 2e-4)
    only_ct = build_models(
        MotionConfig(models=("ct",), sojourn_times=(5.0,), initial_mode_probabilities=(1.0,))
    )
    assert [m.name for m in only_ct] == ["ct"]


def test_layout_round_trips() -> None:
    rng = np.random.default_rng(9)
    x = rng.normal(size=(7, 3, 5))
    P = rng.normal(size=(7, 3, 5, 5))
    xs = state_major(x)
    Ps = state_major_cov(P)
    assert xs.shape == (5, 3, 7) and Ps.shape == (5, 5, 3, 7)
    assert xs.flags.c_contiguous and Ps.flags.c_contiguous
    assert Ps[1, 4, 2, 6] == P[6, 2, 1, 4] and xs[3, 1, 5] == x[5, 1, 3]
    np.testing.assert_array_equal(batch_major(xs), x)
    np.testing.assert_array_equal(batch_major_cov(Ps), P)


def test_row_blocks_cover_everything(monkeypatch: pytest.MonkeyPatch) -> None:
    monkeypatch.setattr(motion, "BLOCK_SIZE", 10)
    blocks = list(row_blocks(23, 2))
    assert [(b.start, b.stop) for b in blocks] == [(0, 5), (5, 10), (10, 15), (15, 20), (20, 23)]
    assert list(row_blocks(0)) == []
    assert [(b.start, b.stop) for b in row_blocks(3, 50)] == [(0, 1), (1, 2), (2, 3)]


@pytest.mark.parametrize("model", [ConstantVelocity(1.0), CoordinatedTurn(1.0, 0.01)])
def test_results_do_not_depend_on_block_size(
    model: ConstantVelocity | CoordinatedTurn, monkeypatch: pytest.MonkeyPatch
) -> None:
    rng = np.random.default_rng(10)
    x = random_states(rng, 50)
    P = random_spd(rng, 50)
    x_one, P_one = model.predict(x, P, 0.9)
    monkeypatch.setattr(motion, "BLOCK_SIZE", 7)
    x_blk, P_blk = model.predict(x, P, 0.9)
    # (einsum may sum in a different order for another block length: last-bit differences)
    np.testing.assert_allclose(x_blk, x_one, rtol=1e-15)
    np.testing.assert_allclose(P_blk, P_one, rtol=1e-14)
    for k in (0, 13, 49):  # and one track at a time
        xk, Pk = model.predict(x[k], P[k], 0.9)
        np.testing.assert_allclose(xk, x_one[k], rtol=1e-15)
        np.testing.assert_allclose(Pk, P_one[k], rtol=1e-14)


def test_along_track_noise_lies_along_the_velocity() -> None:
    """``Q = [[T³/3, T²/2], [T²/2, T]] ⊗ q u uᵀ``: for v = (3, 4), q = 2, T = 2, u uᵀ =
    [[9, 12], [12, 16]] / 25; nothing across the velocity, nothing on ω; a state at rest
    spreads q evenly over both axes."""
    Q = along_track_noise(np.array([[5.0, 6.0, 3.0, 4.0, 0.1], [0, 0, 0, 0, 0]]), 2.0, 2.0)
    uu = np.array([[9.0, 12.0], [12.0, 16.0]]) / 25.0
    np.testing.assert_allclose(Q[0, 0:2, 0:2], 2.0 * 8.0 / 3.0 * uu)
    np.testing.assert_allclose(Q[0, 0:2, 2:4], 2.0 * 2.0 * uu)
    np.testing.assert_allclose(Q[0, 2:4, 0:2], 2.0 * 2.0 * uu)
    np.testing.assert_allclose(Q[0, 2:4, 2:4], 2.0 * 2.0 * uu)
    assert not Q[0, 4].any() and not Q[0, :, 4].any()
    across = np.array([-4.0, 3.0]) / 5.0
    assert across @ Q[0, 2:4, 2:4] @ across == pytest.approx(0.0, abs=1e-12)
    np.testing.assert_allclose(Q[1, 2:4, 2:4], 2.0 * 2.0 * 0.5 * np.eye(2))
    with pytest.raises(ValueError):
        along_track_noise(np.zeros(5), -1.0, 1.0)
