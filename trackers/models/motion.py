"""Motion models over the common state ``s = [x, y, vx, vy, ω]``.

Every model uses the same 5-dimensional state so that the modes of an IMM estimator can be
mixed: positions in m, velocities in m/s, turn rate ω in rad/s (positive = counter-clockwise).
All functions are batched over any leading dimensions (typically ``N`` tracks), return new
arrays and never modify their inputs.

- :class:`ConstantVelocity`: nearly constant velocity, discretized continuous white-noise
  acceleration (Bar-Shalom, Li and Kirubarajan 2001, section 6.2). ω does not influence the
  motion; it is carried unchanged, or, in an IMM beside a coordinated turn, reset to
  ``N(0, σ_ω²)``: the prior turn rate of a turn that starts from straight flight.
- :class:`CoordinatedTurn`: coordinated turn with the turn rate in the state, linearized with
  its exact Jacobian for an EKF (ibid., section 11.7).

Layouts. The public arrays are *batch-major*: ``x (..., 5)``, ``P (..., 5, 5)``. numpy is slow
on many tiny matrices laid out that way, so the arithmetic runs on *state-major* copies in
which the state axes come first and the batch axes follow, reversed, innermost and
contiguous: ``xs (5, ...)``, ``Ps (5, 5, ...)`` (see :func:`state_major`). Every entry
``Ps[i, j]`` is then one contiguous vector over all tracks and the matrix algebra is a handful
of long vector operations. ``predict_state_major`` exposes this layout to the IMM.
"""

from __future__ import annotations

import math
from collections.abc import Callable, Iterator
from typing import Protocol

import numpy as np

from trackers.config import MotionConfig

__all__ = [
    "AGILE_MIN_SPEED",
    "BLOCK_SIZE",
    "MAX_AGILE_TURN",
    "MAX_AGILE_TURN_RATE",
    "STATE_DIM",
    "ConstantVelocity",
    "CoordinatedTurn",
    "MotionModel",
    "agile_turn_rate",
    "along_track_block",
    "along_track_noise",
    "batch_major",
    "batch_major_cov",
    "build_models",
    "row_blocks",
    "state_major",
    "state_major_cov",
]

STATE_DIM = 5
"""Dimension of the state ``[x, y, vx, vy, ω]`` shared by all motion models."""

#: The highest turn rate (rad/s) an agile target's prior allows (:func:`agile_turn_rate`).
MAX_AGILE_TURN_RATE = 0.5

#: Agility counts from this speed (m/s, 90 km/h) on (:func:`agile_turn_rate`): a ship, a
#: walker or a car in town turns its path by a few metres a revisit, well within the noise of
#: the sensors that watch them, and the wider prior only made its velocity noisier (a coastal
#: radar's ship scatterers, 4 seeds: 35 -> 47 id changes; a convoy's overtaker at 17 m/s).
AGILE_MIN_SPEED = 25.0

#: The largest heading change (rad) that one std of an agile target's turn-rate prior gives in
#: one revisit of its track (:class:`ConstantVelocity`).
MAX_AGILE_TURN = 0.2

# |ωT| below which the turn functions are evaluated from their Taylor series instead of the
# closed forms, whose numerators cancel as ωT → 0: at 0.3 the closed forms keep about 14
# significant digits and the six-term series (next term ~ φ¹²/13!) about 16.
_SERIES_LIMIT = 0.3

# Taylor coefficients in p = φ² of a(φ) = sin φ/φ, b(φ)/φ = (1 − cos φ)/φ², a'(φ)/φ and b'(φ).
_TURN_SERIES = np.array(
    [
        [1.0, -1 / 6, 1 / 120, -1 / 5040, 1 / 362880, -1 / 39916800],
        [1 / 2, -1 / 24, 1 / 720, -1 / 40320, 1 / 3628800, -1 / 479001600],
        [-1 / 3, 1 / 30, -1 / 840, 1 / 45360, -1 / 3991680, 1 / 518918400],
        [1 / 2, -1 / 8, 1 / 144, -1 / 5760, 1 / 403200, -1 / 43545600],
    ]
)


# --- layouts ---------------------------------------------------------------------------------

BLOCK_SIZE = 1024
"""Batched functions work through their batch in blocks of about this many state vectors.

Blocks keep every temporary array small (a block's covariances take 200 kB). With glibc,
freeing many large numpy temporaries at once returns their memory to the operating system
and the next call page-faults it back in; on the development VM that doubled the time of an
IMM cycle over 3000 tracks.
"""


def row_blocks(n_rows: int, row_size: int = 1) -> Iterator[slice]:
    """Consecutive slices of ``range(n_rows)``, each covering at most ``BLOCK_SIZE`` state
    vectors when a row holds ``row_size`` of them (at least one row per block)."""
    step = max(1, BLOCK_SIZE // max(1, row_size))
    for start in range(0, n_rows, step):
        yield slice(start, min(n_rows, start + step))


def state_major(x: np.ndarray) -> np.ndarray:
    """Batch-major vectors ``(b₁, …, b_k, n)`` → contiguous state-major ``(n, b_k, …, b₁)``."""
    return np.ascontiguousarray(np.asarray(x, dtype=float).T)


def state_major_cov(P: np.ndarray) -> np.ndarray:
    """Batch-major matrices ``(b₁, …, b_k, n, n)`` → contiguous ``(n, n, b_k, …, b₁)``."""
    P = np.asarray(P, dtype=float)
    d = P.ndim
    return np.ascontiguousarray(P.transpose(d - 2, d - 1, *range(d - 3, -1, -1)))


def batch_major(xs: np.ndarray) -> np.ndarray:
    """Inverse of :func:`state_major` as a view: ``(n, b_k, …, b₁)`` → ``(b₁, …, b_k, n)``."""
    return xs.T


def batch_major_cov(Ps: np.ndarray) -> np.ndarray:
    """Inverse of :func:`state_major_cov` as a view: ``(n, n, b_k, …, b₁)`` →
    ``(b₁, …, b_k, n, n)``."""
    d = Ps.ndim
    return Ps.transpose(*range(d - 1, 1, -1), 0, 1)


# --- common pieces ---------------------------------------------------------------------------


def _check_dt(dt: float) -> float:
    dt = float(dt)
    if not (math.isfinite(dt) and dt >= 0.0):
        raise ValueError(f"dt: must be a finite number >= 0, got {dt!r}")
    return dt


def _check_psd(name: str, value: float) -> float:
    if not (isinstance(value, int | float) and math.isfinite(value) and value >= 0):
        raise ValueError(f"{name}: must be a finite number >= 0, got {value!r}")
    return float(value)


def _acceleration_noise(q: float, dt: float) -> np.ndarray:
    """The (5, 5) discretized continuous white-noise acceleration covariance.

    Per axis ``q [[T³/3, T²/2], [T²/2, T]]`` on (x, vx) and on (y, vy); ω row and column 0.
    """
    Q = np.zeros((STATE_DIM, STATE_DIM))
    t2 = dt * dt
    Q[0, 0] = Q[1, 1] = q * t2 * dt / 3.0
    Q[0, 2] = Q[2, 0] = Q[1, 3] = Q[3, 1] = q * t2 / 2.0
    Q[2, 2] = Q[3, 3] = q * dt
    return Q


def _broadcast_noise(Q: np.ndarray, x: np.ndarray) -> np.ndarray:
    shape = np.shape(x)[:-1]
    return np.broadcast_to(Q, (*shape, STATE_DIM, STATE_DIM)).copy()


def _add_noise(Ps: np.ndarray, Q: np.ndarray) -> None:
    """``Ps += Q`` in place, state-major Ps and a constant (5, 5) Q."""
    Ps += Q.reshape(STATE_DIM, STATE_DIM, *(1,) * (Ps.ndim - 2))


def agile_turn_rate(
    speed: np.ndarray,
    base: float,
    acceleration: float,
    step: float | np.ndarray = 0.0,
    max_turn: float = MAX_AGILE_TURN,
) -> np.ndarray:
    """The turn rate (rad/s) that a target at ``speed`` (m/s, any shape) can start a turn
    with over a ``step`` (s; 0: any): the larger of ``base`` and the rate of a lateral
    ``acceleration`` (m/s²), at most :data:`MAX_AGILE_TURN_RATE` and ``max_turn`` radians
    over the step::

        ω(v) = max(ω₀, min(ω_max, a / v, Δψ_max / T))   for v ≥ AGILE_MIN_SPEED, else ω₀

    A turn's lateral acceleration is ``ω v``, so a slower target turns faster on the same
    acceleration: a 40 m/s drone pulling 12 m/s² turns at 0.3 rad/s, an airliner at 250 m/s
    at 0.048, less than ``base``, which it keeps (as does a target slower than
    :data:`AGILE_MIN_SPEED`). Over a long step the linearization
    of the turn in ω (the EKF's, the manoeuvre search's Gaussian) no longer holds for a wide
    fan of headings, and a car seen every 10 s is not searched for kilometres across its
    road: ``max_turn`` radians a step at most (the prior's 0.2 leaves an aircraft braking on
    a runway at a 4 s revisit its 0.05 rad/s: 0.5 gave it 0.19 false tracks a scan against
    0.13, 12 seeds).
    ``acceleration`` 0 gives ``base`` everywhere."""
    v = np.abs(np.asarray(speed, dtype=float))
    T = np.asarray(step, dtype=float)
    same = T.ndim == 0 or T.shape == v.shape
    shape = v.shape if same else np.broadcast_shapes(v.shape, T.shape)
    if acceleration <= 0.0:
        return np.full(shape, float(base))
    fast = v >= AGILE_MIN_SPEED
    # nothing above ω₀ when no target is fast enough or a / v ≤ ω₀ for every one
    if acceleration <= base * float(v.min(initial=np.inf, where=fast)):
        return np.full(shape, float(base))
    if T.ndim == 0:
        cap = MAX_AGILE_TURN_RATE if not T > 0.0 else min(MAX_AGILE_TURN_RATE, max_turn / float(T))
        if cap <= base:  # (a 4 s revisit, defaults)
            return np.full(shape, float(base))
    else:
        with np.errstate(divide="ignore", invalid="ignore"):
            cap = np.minimum(MAX_AGILE_TURN_RATE, np.where(T > 0.0, max_turn / T, np.inf))
    # a / v for the fast enough (a / ∞ = 0 for the others), within [ω₀, the caps]
    rate = acceleration / np.where(fast, v, np.inf)
    return np.maximum(np.minimum(rate, cap), base)


def along_track_noise(x: np.ndarray, q: float, dt: float | np.ndarray) -> np.ndarray:
    """White acceleration noise of PSD ``q`` (m²/s³) along each state's velocity over ``dt``:

        Q = [[T³/3, T²/2], [T²/2, T]] ⊗ q u uᵀ,    u = (vx, vy) / ‖(vx, vy)‖

    on ``[x, y, vx, vy]`` (ω untouched), for states ``x (..., 5)`` and one ``dt`` or one per
    state (``(...)``): a target speeding up or slowing down along its path. A state at rest
    has no direction: its ``q`` is split evenly over both axes (``u uᵀ = I / 2``). Returns
    ``Q (..., 5, 5)``."""
    x = np.asarray(x, dtype=float)
    q = _check_psd("q", q)
    T = np.asarray(dt, dtype=float)
    if not (np.isfinite(T).all() and (T >= 0.0).all()):
        raise ValueError(f"dt: must be finite numbers >= 0, got {dt!r}")
    Q = np.zeros((*x.shape[:-1], STATE_DIM, STATE_DIM))
    Q[..., 0:4, 0:4] = along_track_block(x[..., 2:4], q, np.broadcast_to(T, x.shape[:-1]))
    return Q


def along_track_block(v: np.ndarray, q: float, T: np.ndarray) -> np.ndarray:
    """The ``[x, y, vx, vy]`` block ``(..., 4, 4)`` of :func:`along_track_noise` for
    velocities ``v (..., 2)`` and intervals ``T (...)``, unchecked (the update's hot path)."""
    v2 = v[..., 0] * v[..., 0] + v[..., 1] * v[..., 1]
    uu = (v[..., :, None] * v[..., None, :]) * (q / np.maximum(v2, 1e-300))[..., None, None]
    rest = v2 < 1e-18
    if rest.any():
        uu[rest] = 0.5 * q * np.eye(2)
    t2 = T * T
    C = np.empty((*T.shape, 2, 2))
    C[..., 0, 0] = t2 * T / 3.0
    C[..., 0, 1] = C[..., 1, 0] = 0.5 * t2
    C[..., 1, 1] = T
    # Q[2a + i, 2b + j] = C[a, b] uu[i, j]
    block = C[..., :, None, :, None] * uu[..., None, :, None, :]
    return block.reshape(*T.shape, 4, 4)


class MotionModel(Protocol):
    """What the IMM needs from a motion model (see :class:`ConstantVelocity`)."""

    name: str

    def transition(self, x: np.ndarray, dt: float) -> tuple[np.ndarray, np.ndarray]: ...

    def process_noise(self, x: np.ndarray, dt: float) -> np.ndarray: ...

    def predict(self, x: np.ndarray, P: np.ndarray, dt: float) -> tuple[np.ndarray, np.ndarray]: ...

    def predict_state_major(
        self, xs: np.ndarray, Ps: np.ndarray, dt: float
    ) -> tuple[np.ndarray, np.ndarray]: ...


PredictStateMajor = Callable[[np.ndarray, np.ndarray, float], tuple[np.ndarray, np.ndarray]]


def _predict_batch_major(
    predict_state_major: PredictStateMajor, x: np.ndarray, P: np.ndarray, dt: float
) -> tuple[np.ndarray, np.ndarray]:
    """Run a state-major prediction on batch-major x (..., n), P (..., n, n), block by block."""
    x = np.asarray(x, dtype=float)
    P = np.asarray(P, dtype=float)
    n = x.shape[-1]
    batch = np.broadcast_shapes(x.shape[:-1], P.shape[:-2])
    if _check_dt(dt) == 0.0:
        return np.broadcast_to(x, (*batch, n)).copy(), np.broadcast_to(P, (*batch, n, n)).copy()
    xb = np.broadcast_to(x, (*batch, n)).reshape(-1, n)
    Pb = np.broadcast_to(P, (*batch, n, n)).reshape(-1, n, n)
    x_out = np.empty(xb.shape)
    P_out = np.empty(Pb.shape)
    for rows in row_blocks(xb.shape[0]):
        xs, Ps = predict_state_major(state_major(xb[rows]), state_major_cov(Pb[rows]), dt)
        x_out[rows] = batch_major(xs)
        P_out[rows] = batch_major_cov(Ps)
    return x_out.reshape(*batch, n), P_out.reshape(*batch, n, n)


# --- constant velocity -----------------------------------------------------------------------


class ConstantVelocity:
    """Nearly constant velocity (white-noise acceleration) on ``[x, y, vx, vy, ω]``.

    ``q`` is the continuous white-noise acceleration power spectral density in m²/s³, the
    same on both axes. Without ``turn_rate_std`` the turn rate ω is carried unchanged with no
    process noise. With it (σ_ω, rad/s) the mode says what it means, that the target does not
    turn: ``ω⁻ = w``, ``w ~ N(0, σ_ω²)`` (row 4 of F zero, ``Q₄₄ = σ_ω²``). In an IMM this
    keeps a finished turn's rate from living on in the constant-velocity mode and coming back
    into the coordinated-turn mode through the mixing; σ_ω is then the prior rate of the
    next turn.
    """

    name = "cv"

    def __init__(
        self, q: float, turn_rate_std: float | None = None, agile_acceleration: float = 0.0
    ) -> None:
        self.q = _check_psd("q", q)
        self.turn_rate_std = (
            None if turn_rate_std is None else _check_psd("turn_rate_std", turn_rate_std)
        )
        self.agile_acceleration = _check_psd("agile_acceleration", agile_acceleration)

    def __repr__(self) -> str:
        if self.turn_rate_std is None:
            return f"ConstantVelocity(q={self.q!r})"
        agile = (
            f", agile_acceleration={self.agile_acceleration!r}" if self.agile_acceleration else ""
        )
        return f"ConstantVelocity(q={self.q!r}, turn_rate_std={self.turn_rate_std!r}{agile})"

    @property
    def agile(self) -> bool:
        """Whether the turn-rate reset depends on the speed (and on a revisit)."""
        return self.turn_rate_std is not None and self.agile_acceleration > 0.0

    def _turn_rate_variance(
        self, vx: np.ndarray, vy: np.ndarray, step: float | np.ndarray
    ) -> np.ndarray:
        """``σ_ω²`` of each state over a ``step`` (its revisit): ``σ_ω = agile_turn_rate(|v|,
        σ₀, agile_acceleration, step)`` (:func:`agile_turn_rate`), ``σ₀`` = ``turn_rate_std``:
        the turn of one std in one revisit stays within :data:`MAX_AGILE_TURN` radians (a
        vehicle seen every 4 s is not given ±0.5 rad/s, a two-radian fan of headings)."""
        assert self.turn_rate_std is not None
        rate = agile_turn_rate(np.hypot(vx, vy), self.turn_rate_std, self.agile_acceleration, step)
        return rate * rate

    def _noise(self, dt: float) -> np.ndarray:
        Q = _acceleration_noise(self.q, dt)
        if self.turn_rate_std is not None and dt > 0.0:
            Q[4, 4] = self.turn_rate_std**2
        return Q

    def transition(self, x: np.ndarray, dt: float) -> tuple[np.ndarray, np.ndarray]:
        """The transition ``f(x) = F x`` and its Jacobian ``F`` (one copy per track).

        ``F = [[1,0,T,0,0], [0,1,0,T,0], [0,0,1,0,0], [0,0,0,1,0], [0,0,0,0,f]]``, i.e.
        ``x⁻ = x + T vx``, ``y⁻ = y + T vy``, velocities unchanged, ``ω⁻ = f ω`` with ``f = 1``,
        or ``f = 0`` when the mode has a ``turn_rate_std`` (and ``T > 0``).
        x ``(..., 5)`` → ``(f(x) (..., 5), F (..., 5, 5))``.
        """
        dt = _check_dt(dt)
        x = np.asarray(x, dtype=float)
        x_new = x.copy()
        x_new[..., 0:2] += dt * x[..., 2:4]
        F = np.eye(STATE_DIM)
        F[0, 2] = F[1, 3] = dt
        if self.turn_rate_std is not None and dt > 0.0:
            x_new[..., 4] = 0.0
            F[4, 4] = 0.0
        return x_new, np.broadcast_to(F, (*x.shape[:-1], STATE_DIM, STATE_DIM)).copy()

    def process_noise(
        self, x: np.ndarray, dt: float, revisit: float | np.ndarray = 0.0
    ) -> np.ndarray:
        """``Q = q [[T³/3, T²/2], [T²/2, T]]`` on (x, vx) and (y, vy); ``Q₄₄ = σ_ω²`` (or 0
        without a ``turn_rate_std``), the rest 0; (..., 5, 5). With an
        ``agile_acceleration`` ``a``, ``σ_ω`` is each state's ``agile_turn_rate(|v|,
        turn_rate_std, a, max(T, revisit))`` (:func:`agile_turn_rate`; ``revisit`` one per
        state or one for all): a target of 25 m/s or more may start a sharper turn."""
        dt = _check_dt(dt)
        Q = _broadcast_noise(self._noise(dt), x)
        if self.agile and dt > 0.0:
            x = np.asarray(x, dtype=float)
            Q[..., 4, 4] = self._turn_rate_variance(x[..., 2], x[..., 3], np.maximum(dt, revisit))
        return Q

    def predict(self, x: np.ndarray, P: np.ndarray, dt: float) -> tuple[np.ndarray, np.ndarray]:
        """``x⁻ = F x``, ``P⁻ = F P Fᵀ + Q`` (symmetrized); x (..., 5), P (..., 5, 5).

        With ``dt = 0`` the inputs are returned unchanged (as copies).
        """
        return _predict_batch_major(self.predict_state_major, x, P, dt)

    def predict_state_major(
        self, xs: np.ndarray, Ps: np.ndarray, dt: float, revisit: float | np.ndarray = 0.0
    ) -> tuple[np.ndarray, np.ndarray]:
        """:meth:`predict` on state-major arrays ``xs (5, ...)``, ``Ps (5, 5, ...)``; an agile
        mode's turn-rate prior is per ``max(dt, revisit)`` (:meth:`process_noise`).

        ``F = I + T E`` with E moving velocity into position, so ``F P Fᵀ`` is two row and
        column operations: ``rows₀,₁ += T rows₂,₃``, then ``cols₀,₁ += T cols₂,₃``.
        """
        dt = _check_dt(dt)
        if dt == 0.0:
            return xs.copy(), Ps.copy()
        x_pred = xs.copy()
        x_pred[0:2] += dt * xs[2:4]
        out = Ps.copy()
        out[0:2] += dt * Ps[2:4]  # F P
        out[:, 0:2] += dt * out[:, 2:4]  # (F P) Fᵀ
        # For a symmetric P only the (0, 1) and (1, 0) entries differ, in the last bits.
        corner = out[0, 1] + out[1, 0]
        corner *= 0.5
        out[0, 1] = corner
        out[1, 0] = corner
        if self.turn_rate_std is not None:  # row and column 4 of F are zero
            x_pred[4] = 0.0
            out[4] = 0.0
            out[:, 4] = 0.0
        _add_noise(out, self._noise(dt))
        if self.agile:
            out[4, 4] = self._turn_rate_variance(xs[2], xs[3], np.maximum(dt, revisit))
        return x_pred, out


# --- coordinated turn ------------------------------------------------------------------------


def _turn_functions(
    phi: np.ndarray,
) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """The dimensionless turn functions of ``φ = ωT`` and their derivatives.

    Returns ``(sin φ, cos φ, a, b, a', b')`` with ``a = sin φ / φ``, ``b = (1 − cos φ)/φ``,
    ``a' = da/dφ = (φ cos φ − sin φ)/φ²`` and ``b' = db/dφ = (φ sin φ − 1 + cos φ)/φ²``.
    For ``|φ| < 0.3`` a, b, a', b' come from their Taylor series (six terms), so they are
    finite and smooth through φ = 0, where ``a = 1``, ``b = 0``, ``a' = 0``, ``b' = 1/2``.
    """
    phi = np.asarray(phi, dtype=float)
    s = np.sin(phi)
    c = np.cos(phi)
    small = np.abs(phi) < _SERIES_LIMIT
    n_small = int(np.count_nonzero(small))
    if n_small < small.size or n_small == 0:  # closed forms (also for an empty batch)
        half = np.sin(0.5 * phi)
        one_minus_c = 2.0 * half * half  # 1 − cos φ without cancellation
        inv = 1.0 / (np.where(small, 1.0, phi) if n_small else phi)  # a safe divisor
        a = s * inv
        b = one_minus_c * inv
        inv *= inv
        da = (phi * c - s) * inv
        db = (phi * s - one_minus_c) * inv
    if n_small:  # all four series at once, Horner in p = φ²
        p = phi * phi
        series = _TURN_SERIES[:, -1, None] * p[None]
        series += _TURN_SERIES[:, -2, None]
        for k in range(_TURN_SERIES.shape[1] - 3, -1, -1):
            series *= p
            series += _TURN_SERIES[:, k, None]
        series[1:3] *= phi
        series = series.reshape(4, *phi.shape)  # a 0-d φ came back as (4, 1)
        if n_small == small.size:
            return s, c, series[0], series[1], series[2], series[3]
        a = np.where(small, series[0], a)
        b = np.where(small, series[1], b)
        da = np.where(small, series[2], da)
        db = np.where(small, series[3], db)
    return s, c, a, b, da, db


def _ct_core(xs: np.ndarray, dt: float) -> tuple[np.ndarray, np.ndarray]:
    """State-major CT transition: ``f(xs) (5, ...)`` and ``G = F[0:4, 2:5] (4, 3, ...)``.

    The rest of the Jacobian F is the identity on (x, y) and ω and zero elsewhere.
    """
    vx = xs[2]
    vy = xs[3]
    s, c, a, b, da, db = _turn_functions(xs[4] * dt)
    A = dt * a
    B = dt * b
    t2 = dt * dt
    dA = t2 * da
    dB = t2 * db

    x_new = np.empty_like(xs)
    x_new[0] = xs[0] + A * vx - B * vy
    x_new[1] = xs[1] + B * vx + A * vy
    x_new[2] = c * vx - s * vy
    x_new[3] = s * vx + c * vy
    x_new[4] = xs[4]

    G = np.empty((4, 3, *xs.shape[1:]))
    G[0, 0] = A
    G[0, 1] = -B
    G[0, 2] = vx * dA - vy * dB
    G[1, 0] = B
    G[1, 1] = A
    G[1, 2] = vx * dB + vy * dA
    G[2, 0] = c
    G[2, 1] = -s
    G[2, 2] = -dt * x_new[3]
    G[3, 0] = s
    G[3, 1] = c
    G[3, 2] = dt * x_new[2]
    return x_new, G


class CoordinatedTurn:
    """Coordinated turn with unknown turn rate ω in the state, for an EKF.

    ``q`` is the white-noise acceleration PSD (m²/s³) on both axes and ``q_turn_rate`` the
    white-noise turn-rate PSD (rad²/s³). For ω → 0 the transition tends continuously to the
    constant-velocity one.
    """

    name = "ct"

    def __init__(self, q: float, q_turn_rate: float) -> None:
        self.q = _check_psd("q", q)
        self.q_turn_rate = _check_psd("q_turn_rate", q_turn_rate)

    def __repr__(self) -> str:
        return f"CoordinatedTurn(q={self.q!r}, q_turn_rate={self.q_turn_rate!r})"

    def transition(self, x: np.ndarray, dt: float) -> tuple[np.ndarray, np.ndarray]:
        """The coordinated-turn transition ``f(x)`` and its exact Jacobian ``F = ∂f/∂x``.

        With ``φ = ωT``, ``A = sin φ / ω = T a(φ)`` and ``B = (1 − cos φ)/ω = T b(φ)``::

            x⁻  = x + A vx − B vy          vx⁻ = cos φ vx − sin φ vy
            y⁻  = y + B vx + A vy          vy⁻ = sin φ vx + cos φ vy
            ω⁻  = ω

        and the ω column of F, with ``∂A/∂ω = T² a'(φ)``, ``∂B/∂ω = T² b'(φ)``::

            ∂x⁻/∂ω  = vx ∂A/∂ω − vy ∂B/∂ω     ∂vx⁻/∂ω = −T (sin φ vx + cos φ vy) = −T vy⁻
            ∂y⁻/∂ω  = vx ∂B/∂ω + vy ∂A/∂ω     ∂vy⁻/∂ω =  T (cos φ vx − sin φ vy) =  T vx⁻

        (at ω = 0: A = T, B = 0, ∂A/∂ω = 0, ∂B/∂ω = T²/2). x (..., 5) → (..., 5), (..., 5, 5).
        """
        dt = _check_dt(dt)
        xs = state_major(x)
        x_new, G = _ct_core(xs, dt)
        F = np.zeros((STATE_DIM, STATE_DIM, *xs.shape[1:]))
        for i in range(STATE_DIM):
            F[i, i] = 1.0
        F[0:4, 2:5] = G
        return np.ascontiguousarray(batch_major(x_new)), np.ascontiguousarray(batch_major_cov(F))

    def _noise(self, dt: float) -> np.ndarray:
        Q = _acceleration_noise(self.q, dt)
        Q[4, 4] = self.q_turn_rate * dt
        return Q

    def process_noise(self, x: np.ndarray, dt: float) -> np.ndarray:
        """``Q = q [[T³/3, T²/2], [T²/2, T]]`` on (x, vx) and (y, vy) plus ``q_ω T`` on ω.

        Turn-rate noise enters ω only, as in the usual discretization; carried through the
        turn it would add about ``q_ω v² T³/3`` across the track in velocity. That fuller Q
        was tried (quadrature of the linearized flow): in a 250 m/s, T = 4 s manoeuvre test
        it gave no better RMSE or consistency in the IMM and cost 25 % more per scan."""
        return _broadcast_noise(self._noise(_check_dt(dt)), x)

    def predict(self, x: np.ndarray, P: np.ndarray, dt: float) -> tuple[np.ndarray, np.ndarray]:
        """EKF prediction ``x⁻ = f(x)``, ``P⁻ = F P Fᵀ + Q`` (symmetrized), F the Jacobian at x.

        With ``dt = 0`` the inputs are returned unchanged (as copies).
        """
        return _predict_batch_major(self.predict_state_major, x, P, dt)

    def predict_state_major(
        self, xs: np.ndarray, Ps: np.ndarray, dt: float
    ) -> tuple[np.ndarray, np.ndarray]:
        """:meth:`predict` on state-major arrays ``xs (5, ...)``, ``Ps (5, 5, ...)``.

        F is the identity except its block ``G = F[0:4, 2:5]``, so
        ``(F P)[0:4] = G P[2:5] + [P[0]; P[1]; 0; 0]`` and ``(F P)[4] = P[4]``, and the same
        on the columns for ``(F P) Fᵀ``; the result is symmetrized.
        """
        dt = _check_dt(dt)
        if dt == 0.0:
            return xs.copy(), Ps.copy()
        x_pred, G = _ct_core(xs, dt)
        FP = np.empty_like(Ps)  # F P: rows 0-3 are G P[2:5] (+ P[0:2] on rows 0-1), row 4 P[4]
        np.einsum("ik...,kj...->ij...", G, Ps[2:5], out=FP[0:4])
        FP[0:2] += Ps[0:2]
        FP[4] = Ps[4]
        out = np.empty_like(Ps)  # (F P) Fᵀ, the same on the columns
        np.einsum("ik...,jk...->ij...", FP[:, 2:5], G, out=out[:, 0:4])
        out[:, 0:2] += FP[:, 0:2]
        out[:, 4] = FP[:, 4]
        _add_noise(out, self._noise(dt))
        np.add(out, out.swapaxes(0, 1), out=FP)  # symmetrize into the FP buffer
        FP *= 0.5
        return x_pred, FP


def build_models(
    config: MotionConfig, q_cv: float | None = None
) -> tuple[ConstantVelocity | CoordinatedTurn, ...]:
    """The motion models named by ``config.models``, in that order; ``q_cv`` (if given)
    replaces ``config.q_cv``. Beside a coordinated-turn mode the constant-velocity mode
    resets the turn rate with ``config.cv_turn_rate_std`` (at least the turn rate of
    ``config.agile_acceleration`` for a target of 25 m/s or more); alone it carries it."""
    cv_turn_rate_std = config.cv_turn_rate_std if "ct" in config.models else None
    models: list[ConstantVelocity | CoordinatedTurn] = []
    for name in config.models:
        if name == "cv":
            models.append(
                ConstantVelocity(
                    config.q_cv if q_cv is None else q_cv,
                    cv_turn_rate_std,
                    config.agile_acceleration if cv_turn_rate_std is not None else 0.0,
                )
            )
        elif name == "ct":
            models.append(CoordinatedTurn(config.q_ct, config.q_turn_rate))
        else:  # MotionConfig validates the names; guard against a hand-built one
            raise ValueError(f"motion.models: unknown model {name!r}")
    return tuple(models)
