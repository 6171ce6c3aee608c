"""Bending extended target: motion models and EKF (Dezert, SPIE 1998, "paper 000").

State ``x = [x, vx, y, vy, α, α̇]`` (m, m/s, m, m/s, rad, rad/s): the *principal* state
``x_g = [x, vx, y, vy]`` of the target's reference point (its "centre of mass") and the
*proper* state ``x_p = [α, α̇]``, its attitude and attitude rate. A point ``q`` of the
target's reference pattern is seen at ``(x, y) + R(α) q`` (eq. 40), ``R(α)`` the rotation
by ``α`` (counter-clockwise positive).

Motion (eqs. 1, 3, 4 with ``F = diag(F_g, F_p)``, ``G = diag(G_g, G_p)``), exact for the
deterministic part and linear, so the "EKF" prediction is the Kalman one:

- principal models (:class:`PrincipalModel`): constant velocity (``ω = 0``) and coordinated
  turn with a KNOWN turn rate ``ω`` (rad/s, positive counter-clockwise; the paper's
  clockwise −3°/s is ``ω = −π/60``)::

      F_g(ω) = [[1, sin ωT/ω,       0, −(1 − cos ωT)/ω],
                [0, cos ωT,         0, −sin ωT        ],
                [0, (1 − cos ωT)/ω, 1, sin ωT/ω       ],
                [0, sin ωT,         0, cos ωT         ]]      (→ CV as ω → 0)

- proper models (:class:`ProperModel`): *constant attitude rate* ``F_p = [[1, T], [0, 1]]``
  and *known attitude rate* ``ω_p``: ``α(k+1) = α(k) + T ω_p``, ``α̇(k+1) = ω_p``, i.e.
  ``F_p = [[1, 0], [0, 0]]`` with the known input ``b_p = [T ω_p, ω_p]`` (the paper's
  ``G v̄`` term of eq. 9). The paper's *null velocity* (NV) model is ``ω_p = 0``.

Process noise, discrete form (our choice; the paper gives only the covariances): the
"discrete white noise acceleration" model of Bar-Shalom and Li (1993): one acceleration per
axis, constant over a period, enters through ``Γ = [T²/2, T]ᵀ``. Principal:
``v_g ~ N(0, σ_g² I₂)`` (m/s², the paper's ``Q_g^1 = 0.004² I`` for CV and
``Q_g^2 = 0.001² I`` for CT), ``Q_g = σ_g² diag(ΓΓᵀ, ΓΓᵀ)``, the same ``G_g`` for CV and CT.
Proper: a scalar angular acceleration ``v_p ~ N(0, σ_p²)`` (the paper's ``Q_p = 0.01²``,
read in rad/s², SI like the other noise figures), ``Q_p = σ_p² ΓΓᵀ`` for every proper model;
for the known-rate models this makes ``α̇`` "nearly" ``ω_p`` rather than exactly (and keeps
the covariance regular).

Measurement of matched points (eq. 40, Jacobian eq. 41): for pattern point ``q_i = (x_i,
y_i)`` matched to detection ``z_j``::

    h_i(x) = [x + x_i cos α − y_i sin α,  y + x_i sin α + y_i cos α]
    H_i    = [[1, 0, 0, 0, −x_i sin α − y_i cos α, 0],
              [0, 0, 1, 0,  x_i cos α − y_i sin α, 0]]

The EKF update with ``p`` matched points stacks them (eq. 10 with ``z = [z_1..z_p]``,
``H = [H_1..H_p]``, ``R̄ = diag(R, …, R)``). It is evaluated exactly but without forming the
``2p × 2p`` innovation covariance: ``H`` only touches the observed coordinates
``o = (x, y, α)``, ``H_i = D_i E`` with ``D_i = [I₂ | r_i]`` (``r_i = ∂h_i/∂α``), so with
``W = R⁻¹``, ``J = Σ D_iᵀ W D_i`` (3x3), ``y = Σ D_iᵀ W ν_i`` and ``A = I + J P_oo``::

    K ν            = P_{:,o} A⁻¹ y
    K S Kᵀ         = P_{:,o} A⁻¹ J P_{o,:}
    ln det S       = p ln det R + ln det A                       (Sylvester)
    νᵀ S⁻¹ ν       = Σ ν_iᵀ W ν_i − yᵀ P_oo A⁻¹ y                (Woodbury, no P⁻¹)

which is the stacked EKF to rounding (tested against the explicit one). ``P`` may be
singular (e.g. a zero attitude-rate variance).

Fewer than two matched points: the attitude is unobservable from the points alone (paper
000 after eq. 41). With ``p = 0`` nothing is updated (prediction only, log-likelihood 0).
With ``p = 1`` the point updates the *centre only* with a Schmidt ("consider") update: the
gain rows of ``α, α̇`` are set to zero, so they and their covariance block stay as
predicted, while their uncertainty still enters ``S`` and the log-likelihood
(``P⁺_ee = P_ee − K_e S K_eᵀ``, ``P⁺_ec = P_ec − K_e H P_{:,c}``, ``P⁺_cc = P_cc``, the
Joseph form with that gain, so ``P⁺`` stays positive semi-definite).

Every function returns new arrays and never modifies its inputs. Batched functions take a
leading axis of ``K`` filters; numpy, standard library only.
"""

from __future__ import annotations

import functools
import math
from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np

__all__ = [
    "OBSERVED",
    "STATE_DIM",
    "PrincipalModel",
    "ProperModel",
    "measure",
    "measurement_jacobian",
    "predict",
    "predict_mixture",
    "principal_transition",
    "proper_transition",
    "transition",
    "update",
    "update_batch",
]

STATE_DIM = 6
"""Dimension of ``[x, vx, y, vy, α, α̇]``."""

OBSERVED = (0, 2, 4)
"""Indices of the state components the point measurements depend on: ``x, y, α``."""

_OBS = np.array(OBSERVED)
_LOG_2PI = math.log(2.0 * math.pi)


@dataclass(frozen=True)
class PrincipalModel:
    """Motion of the reference point: coordinated turn at the known rate ``omega`` (rad/s,
    counter-clockwise positive; 0 is constant velocity) with acceleration noise std
    ``accel_std`` (m/s², per axis)."""

    name: str
    omega: float = 0.0
    accel_std: float = 0.004

    def __post_init__(self) -> None:
        for field_name in ("omega", "accel_std"):
            v = float(getattr(self, field_name))
            if not math.isfinite(v):
                raise ValueError(f"PrincipalModel.{field_name} must be finite, got {v}")
            object.__setattr__(self, field_name, v)
        if self.accel_std < 0:
            raise ValueError(f"PrincipalModel.accel_std must be >= 0, got {self.accel_std}")


@dataclass(frozen=True)
class ProperModel:
    """Motion of the attitude: ``rate=None`` is the constant-attitude-rate model (``α̇``
    estimated); a number is a known attitude rate ``ω_p`` (rad/s; 0 is the paper's null
    velocity model). ``accel_std`` is the angular acceleration noise std (rad/s²)."""

    name: str
    rate: float | None = 0.0
    accel_std: float = 0.01

    def __post_init__(self) -> None:
        if self.rate is not None:
            rate = float(self.rate)
            if not math.isfinite(rate):
                raise ValueError(f"ProperModel.rate must be finite or None, got {rate}")
            object.__setattr__(self, "rate", rate)
        std = float(self.accel_std)
        if not (math.isfinite(std) and std >= 0):
            raise ValueError(f"ProperModel.accel_std must be finite and >= 0, got {std}")
        object.__setattr__(self, "accel_std", std)


def _check_dt(dt: float) -> float:
    dt = float(dt)
    if not (math.isfinite(dt) and dt >= 0):
        raise ValueError(f"dt must be a finite number >= 0, got {dt!r}")
    return dt


def _gamma_outer(dt: float) -> np.ndarray:
    """``Γ Γᵀ`` with ``Γ = [T²/2, T]ᵀ`` (discrete white noise acceleration)."""
    g = np.array([0.5 * dt * dt, dt])
    return np.outer(g, g)


def principal_transition(model: PrincipalModel, dt: float) -> tuple[np.ndarray, np.ndarray]:
    """``(F_g (4, 4), Q_g (4, 4))`` of a principal model over ``T = dt``, on ``[x, vx, y, vy]``.

    ``F_g(ω)`` is the coordinated turn matrix of the module docstring, evaluated with
    ``sin ωT/ω = T sinc(ωT/π)`` and ``(1 − cos ωT)/ω = T (ωT/2) sinc²(ωT/2π)`` so that
    ``ω = 0`` (and ``ω → 0``) gives the constant-velocity matrix exactly;
    ``Q_g = σ_g² diag(ΓΓᵀ, ΓΓᵀ)``, ``Γ = [T²/2, T]ᵀ``.
    """
    dt = _check_dt(dt)
    phi = model.omega * dt
    s_over = dt * float(np.sinc(phi / math.pi))  # sin(ωT)/ω
    c_over = dt * 0.5 * phi * float(np.sinc(phi / (2.0 * math.pi))) ** 2  # (1 − cos ωT)/ω
    c, s = math.cos(phi), math.sin(phi)
    F = np.array(
        [
            [1.0, s_over, 0.0, -c_over],
            [0.0, c, 0.0, -s],
            [0.0, c_over, 1.0, s_over],
            [0.0, s, 0.0, c],
        ]
    )
    G2 = _gamma_outer(dt) * model.accel_std**2
    Q = np.zeros((4, 4))
    Q[:2, :2] = G2
    Q[2:, 2:] = G2
    return F, Q


def proper_transition(model: ProperModel, dt: float) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """``(F_p (2, 2), b_p (2,), Q_p (2, 2))`` of a proper model over ``T = dt``, on ``[α, α̇]``::

        constant rate:  F_p = [[1, T], [0, 1]],  b_p = 0
        known rate ω_p: F_p = [[1, 0], [0, 0]],  b_p = [T ω_p, ω_p]
        Q_p = σ_p² Γ Γᵀ,  Γ = [T²/2, T]ᵀ

    so ``x_p(k+1) = F_p x_p(k) + b_p + Γ v_p``.
    """
    dt = _check_dt(dt)
    if model.rate is None:
        F = np.array([[1.0, dt], [0.0, 1.0]])
        b = np.zeros(2)
    else:
        F = np.array([[1.0, 0.0], [0.0, 0.0]])
        b = np.array([dt * model.rate, model.rate])
    return F, b, _gamma_outer(dt) * model.accel_std**2


def transition(
    principal: PrincipalModel, proper: ProperModel, dt: float
) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """``(F (6, 6), b (6,), Q (6, 6))`` of the global model: ``F = diag(F_g, F_p)``,
    ``b = [0, 0, 0, 0, b_p]``, ``Q = diag(Q_g, Q_p)`` (eqs. 1, 3, 4)."""
    Fg, Qg = principal_transition(principal, dt)
    Fp, bp, Qp = proper_transition(proper, dt)
    F = np.zeros((6, 6))
    Q = np.zeros((6, 6))
    F[:4, :4], F[4:, 4:] = Fg, Fp
    Q[:4, :4], Q[4:, 4:] = Qg, Qp
    b = np.zeros(6)
    b[4:] = bp
    return F, b, Q


def _check_state(x: np.ndarray, P: np.ndarray, batched: bool) -> tuple[np.ndarray, np.ndarray]:
    x = np.asarray(x, dtype=float)
    P = np.asarray(P, dtype=float)
    want = 2 if batched else 1
    if x.ndim != want or x.shape[-1] != STATE_DIM or P.shape != (*x.shape, STATE_DIM):
        lead = "(K, 6) and (K, 6, 6)" if batched else "(6,) and (6, 6)"
        raise ValueError(f"expected x, P of shapes {lead}, got {x.shape}, {P.shape}")
    return x, P


def predict(
    x: np.ndarray, P: np.ndarray, dt: float, principal: PrincipalModel, proper: ProperModel
) -> tuple[np.ndarray, np.ndarray]:
    """Mode-conditioned prediction (eq. 9): ``x⁻ = F x + b``, ``P⁻ = F P Fᵀ + Q`` with the
    global model ``(principal, proper)`` of :func:`transition`. x (6,), P (6, 6)."""
    x, P = _check_state(x, P, batched=False)
    xs, Ps = predict_mixture(
        x[None], P[None], dt, [principal], [proper], np.ones((1, 1)), np.ones((1, 1))
    )
    return xs[0], Ps[0]


@functools.lru_cache(maxsize=256)
def _model_stacks(
    principal: tuple[PrincipalModel, ...], proper: tuple[ProperModel, ...], dt: float
) -> tuple[np.ndarray, ...]:
    """``(F_g (a, 4, 4), Q_g, F_p (b, 2, 2), b_p (b, 2), Q_p, F_gᵀ, F_pᵀ)`` stacked over the models
    (cached: the models are frozen, so the matrices depend on ``(models, T)`` only)."""
    g_mats = [principal_transition(m, dt) for m in principal]
    p_mats = [proper_transition(m, dt) for m in proper]
    out = (
        np.stack([f for f, _ in g_mats]),
        np.stack([q for _, q in g_mats]),
        np.stack([f for f, _, _ in p_mats]),
        np.stack([b for _, b, _ in p_mats]),
        np.stack([q for _, _, q in p_mats]),
    )
    out = (*out, np.swapaxes(out[0], 1, 2).copy(), np.swapaxes(out[2], 1, 2).copy())
    for a in out:
        a.setflags(write=False)
    return out


def predict_mixture(
    x: np.ndarray,
    P: np.ndarray,
    dt: float,
    principal: Sequence[PrincipalModel],
    proper: Sequence[ProperModel],
    w_g: np.ndarray,
    w_p: np.ndarray,
) -> tuple[np.ndarray, np.ndarray]:
    """Batched prediction of ``K`` filters, each under a probability mixture of models.

    Filter ``k`` moves with principal model ``a`` with probability ``w_g[k, a]`` and,
    independently, with proper model ``b`` with probability ``w_p[k, b]``; its prediction is
    the moment-matched mixture (total probability) of the predictions ``F_ab x + b_ab``::

        x⁻_g = Σ_a w_a F_g^a x_g                 x⁻_p = Σ_b w_b (F_p^b x_p + b_p^b)
        P⁻_gg = Σ_a w_a [F_g^a P_gg F_g^aᵀ + Q_g^a + (y_a − x⁻_g)(y_a − x⁻_g)ᵀ]
        P⁻_pp = Σ_b w_b [F_p^b P_pp F_p^bᵀ + Q_p^b + (y_b − x⁻_p)(y_b − x⁻_p)ᵀ]
        P⁻_gp = F̄_g P_gp F̄_pᵀ,   F̄ = Σ w F         (the mixture factorizes across the blocks)

    With one-hot weights this is exactly (bit for bit) eq. 9 with one model; the IMM uses
    it so, the layered MM with the other layers' mode probabilities.

    Args:
        x: ``(K, 6)``; P: ``(K, 6, 6)``.
        dt: period ``T`` (s), ``>= 0``.
        principal, proper: the models (``r_g``, ``r_p`` of them).
        w_g: ``(K, r_g)``; w_p: ``(K, r_p)``; rows are probability vectors.

    Returns:
        New ``x⁻ (K, 6)``, ``P⁻ (K, 6, 6)``.
    """
    x, P = _check_state(x, P, batched=True)
    K = x.shape[0]
    w_g = np.asarray(w_g, dtype=float).reshape(K, len(principal))
    w_p = np.asarray(w_p, dtype=float).reshape(K, len(proper))
    stacks = _model_stacks(tuple(principal), tuple(proper), _check_dt(dt))
    return _predict_core(x, P, stacks, w_g, w_p)


def _predict_core(
    x: np.ndarray,
    P: np.ndarray,
    stacks: tuple[np.ndarray, ...],
    w_g: np.ndarray,
    w_p: np.ndarray,
) -> tuple[np.ndarray, np.ndarray]:
    """:func:`predict_mixture` on validated arrays with the cached model stacks."""
    Fg, Qg, Fp, bp, Qp, FgT, FpT = stacks
    K = x.shape[0]
    Pgg, Ppp, Pgp = P[:, :4, :4], P[:, 4:, 4:], P[:, :4, 4:]
    yg = (Fg[None] @ x[:, None, :4, None])[..., 0]  # (K, a, 4)
    yp = (Fp[None] @ x[:, None, 4:, None])[..., 0] + bp  # (K, b, 2)
    wg = w_g[:, :, None]
    wp = w_p[:, :, None]
    mg = (wg * yg).sum(axis=1)
    mp = (wp * yp).sum(axis=1)
    dg = yg - mg[:, None]
    dp = yp - mp[:, None]
    Cg = Fg[None] @ Pgg[:, None] @ FgT[None] + Qg + dg[..., :, None] * dg[..., None, :]
    Cp = Fp[None] @ Ppp[:, None] @ FpT[None] + Qp + dp[..., :, None] * dp[..., None, :]
    Fg_bar = (wg[..., None] * Fg).sum(axis=1)
    Fp_bar = (wp[..., None] * Fp).sum(axis=1)
    Pc = Fg_bar @ Pgp @ np.swapaxes(Fp_bar, 1, 2)

    x_out = np.empty((K, 6))
    x_out[:, :4] = mg
    x_out[:, 4:] = mp
    P_out = np.empty((K, 6, 6))
    P_out[:, :4, :4] = (wg[..., None] * Cg).sum(axis=1)
    P_out[:, 4:, 4:] = (wp[..., None] * Cp).sum(axis=1)
    P_out[:, :4, 4:] = Pc
    P_out[:, 4:, :4] = np.swapaxes(Pc, 1, 2)
    return x_out, P_out


def measure(x: np.ndarray, points: np.ndarray) -> np.ndarray:
    """Predicted positions of pattern points (eq. 40): ``h_i(x) = (x, y) + R(α) q_i``.

    x (6,), points (p, 2) → (p, 2).
    """
    x = np.asarray(x, dtype=float)
    q = np.asarray(points, dtype=float).reshape(-1, 2)
    c, s = math.cos(x[4]), math.sin(x[4])
    return np.column_stack([x[0] + c * q[:, 0] - s * q[:, 1], x[2] + s * q[:, 0] + c * q[:, 1]])


def measurement_jacobian(x: np.ndarray, points: np.ndarray) -> np.ndarray:
    """Stacked Jacobian ``H = [H_1; …; H_p]`` (2p, 6) of eq. 41 at ``x``::

    H_i = [[1, 0, 0, 0, −x_i sin α − y_i cos α, 0],
           [0, 0, 1, 0,  x_i cos α − y_i sin α, 0]]
    """
    x = np.asarray(x, dtype=float)
    q = np.asarray(points, dtype=float).reshape(-1, 2)
    c, s = math.cos(x[4]), math.sin(x[4])
    H = np.zeros((2 * q.shape[0], STATE_DIM))
    H[0::2, 0] = 1.0
    H[1::2, 2] = 1.0
    H[0::2, 4] = -s * q[:, 0] - c * q[:, 1]
    H[1::2, 4] = c * q[:, 0] - s * q[:, 1]
    return H


def _check_R(R: np.ndarray) -> tuple[np.ndarray, float]:
    R = np.asarray(R, dtype=float)
    if R.shape != (2, 2):
        raise ValueError(f"R must have shape (2, 2), got {R.shape}")
    det = R[0, 0] * R[1, 1] - R[0, 1] * R[1, 0]
    if not (np.all(np.isfinite(R)) and det > 0 and R[0, 0] > 0):
        raise ValueError("R must be finite and positive definite")
    W = np.array([[R[1, 1], -R[0, 1]], [-R[1, 0], R[0, 0]]]) / det
    return 0.5 * (W + W.T), math.log(det)


def update_batch(
    x: np.ndarray,
    P: np.ndarray,
    points: np.ndarray,
    z: np.ndarray,
    mask: np.ndarray,
    R: np.ndarray,
) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """EKF update of ``K`` filters, each with its own (padded) set of matched points.

    Eq. 10 with the stacked eq. 40/41 measurement, in the reduced form of the module
    docstring (3x3 algebra whatever the number of points). Filters with one matched point
    get the Schmidt centre-only update, filters with none are returned unchanged with
    log-likelihood 0.

    Args:
        x: ``(K, 6)`` predicted states; P: ``(K, 6, 6)`` their covariances.
        points: ``(K, p_max, 2)`` matched pattern points ``q_i`` (pattern frame, m).
        z: ``(K, p_max, 2)`` the detections they are matched to.
        mask: ``(K, p_max)`` 1 for a real pair, 0 for padding.
        R: ``(2, 2)`` per-axis detection noise covariance, the same for every point.

    Returns:
        New ``x (K, 6)``, ``P (K, 6, 6)`` and ``ln N(ν; 0, S)`` ``(K,)`` (0 for ``p = 0``).
    """
    x, P = _check_state(x, P, batched=True)
    W, logdet_R = _check_R(R)
    K = x.shape[0]
    mask = np.asarray(mask, dtype=float).reshape(K, -1)
    q = np.asarray(points, dtype=float).reshape(K, -1, 2)
    z = np.asarray(z, dtype=float).reshape(K, -1, 2)
    return _update_core(x, P, q, z, mask, W, logdet_R)


_P1 = np.array([1, 2, 0])
_P2 = np.array([2, 0, 1])


def _inv3(A: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """``(A⁻¹, det A)`` of a stack of 3x3 matrices by cofactors (closed form; a handful of
    numpy calls instead of LAPACK's per-call overhead): row ``i`` of the cofactor matrix is
    ``row_{i+1} × row_{i+2}``."""
    r1 = A[:, _P1]
    r2 = A[:, _P2]
    C = r1[..., _P1] * r2[..., _P2] - r1[..., _P2] * r2[..., _P1]
    det = (A[:, 0] * C[:, 0]).sum(axis=1)
    return np.swapaxes(C, 1, 2) / det[:, None, None], det


def _update_core(
    x: np.ndarray,
    P: np.ndarray,
    q: np.ndarray,
    z: np.ndarray,
    mask: np.ndarray,
    W: np.ndarray,
    logdet_R: float,
) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """:func:`update_batch` on validated arrays (``W = R⁻¹``); the multiple-model cycle
    calls it directly."""
    p = mask.sum(axis=1)  # (K,)
    c = np.cos(x[:, 4])[:, None]
    s = np.sin(x[:, 4])[:, None]
    q0, q1 = q[..., 0], q[..., 1]
    nu = np.empty_like(z)
    nu[..., 0] = (z[..., 0] - x[:, 0, None] - c * q0 + s * q1) * mask
    nu[..., 1] = (z[..., 1] - x[:, 2, None] - s * q0 - c * q1) * mask
    r = np.empty_like(z)
    r[..., 0] = (-s * q0 - c * q1) * mask
    r[..., 1] = (c * q0 - s * q1) * mask
    Wnu = nu @ W  # W symmetric: rows are (W ν_i)ᵀ
    Wr = r @ W
    J = np.empty((x.shape[0], 3, 3))
    J[:, :2, :2] = p[:, None, None] * W
    J[:, :2, 2] = Wr.sum(axis=1)
    J[:, 2, :2] = J[:, :2, 2]
    J[:, 2, 2] = (r * Wr).sum(axis=(1, 2))
    y = np.empty((x.shape[0], 3))
    y[:, :2] = Wnu.sum(axis=1)
    y[:, 2] = (r * Wnu).sum(axis=(1, 2))
    quad = (nu * Wnu).sum(axis=(1, 2))

    P_o_all = P[:, _OBS]  # (K, 3, 6) = P_{o,:}
    P_oo = P_o_all[:, :, _OBS]  # (K, 3, 3)
    A = J @ P_oo
    A[:, 0, 0] += 1.0
    A[:, 1, 1] += 1.0
    A[:, 2, 2] += 1.0
    A_inv, det_A = _inv3(A)
    u = (A_inv @ y[..., None])[..., 0]  # A⁻¹ y
    G = np.swapaxes(P_o_all, 1, 2) @ A_inv  # P_{:,o} A⁻¹  (K, 6, 3)
    delta = (G @ y[..., None])[..., 0]
    Delta = G @ (J @ P_o_all)
    single = p == 1
    if single.any():  # Schmidt: α, α̇ gain rows set to zero
        delta[single, 4:] = 0.0
        Delta[np.ix_(single, [4, 5], [4, 5])] = 0.0
    x_new = x + delta
    P_new = P - Delta
    P_new = 0.5 * (P_new + np.swapaxes(P_new, 1, 2))
    maha = quad - (y * (P_oo @ u[..., None])[..., 0]).sum(axis=1)
    ll = -0.5 * (p * (2.0 * _LOG_2PI + logdet_R) + np.log(det_A) + maha)
    return x_new, P_new, ll


def update(
    x: np.ndarray,
    P: np.ndarray,
    pattern: np.ndarray,
    detections: np.ndarray,
    pairs: np.ndarray,
    R: np.ndarray,
) -> tuple[np.ndarray, np.ndarray, float]:
    """EKF update of one filter with matched points (eqs. 10, 40, 41).

    Args:
        x: ``(6,)`` predicted state; P: ``(6, 6)``.
        pattern: ``(m, 2)`` the shape mode's reference pattern.
        detections: ``(n, 2)`` the scan's detections.
        pairs: ``(p, 2)`` int, rows ``(i, j)``: pattern point ``i`` is detection ``j``.
        R: ``(2, 2)`` per-axis detection noise covariance.

    Returns:
        ``(x (6,), P (6, 6), ln N(ν; 0, S))``. ``p = 0``: the prediction and 0; ``p = 1``:
        the Schmidt centre-only update (module docstring).
    """
    x, P = _check_state(x, P, batched=False)
    pattern = np.asarray(pattern, dtype=float).reshape(-1, 2)
    detections = np.asarray(detections, dtype=float).reshape(-1, 2)
    pairs = np.asarray(pairs, dtype=np.int64).reshape(-1, 2)
    q = np.take(pattern, pairs[:, 0], axis=0)
    zz = np.take(detections, pairs[:, 1], axis=0)
    xs, Ps, ll = update_batch(x[None], P[None], q[None], zz[None], np.ones((1, len(pairs))), R)
    return xs[0], Ps[0], float(ll[0])
