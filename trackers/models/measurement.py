"""Measurement models for the state ``[x, y, vx, vy, ω]``.

Detections are positions ``z = [x, y]`` in metres: ``z = H s + v`` with ``v ~ N(0, R)`` and
``H = H_POSITION``. A detection may also carry a range-rate ``ṙ`` (m/s, Doppler) seen from
the sensor at ``p_s`` moving at ``v_s`` (zero for a sensor on the ground):
``ṙ = h(s) + w``, ``w ~ N(0, σ_ṙ²)``, with

    h(s) = ((x − x_s)(vx − vx_s) + (y − y_s)(vy − vy_s)) / ρ,   ρ = ‖(x − x_s, y − y_s)‖

applied after the position by an extended Kalman update (:func:`range_rate_update`).
"""

from __future__ import annotations

import numpy as np

__all__ = [
    "H_POSITION",
    "MEASUREMENT_DIM",
    "range_rate",
    "range_rate_innovation",
    "range_rate_jacobian",
    "range_rate_update",
]

MEASUREMENT_DIM = 2
"""Dimension of a position measurement ``[x, y]``."""

H_POSITION: np.ndarray = np.array(
    [
        [1.0, 0.0, 0.0, 0.0, 0.0],
        [0.0, 1.0, 0.0, 0.0, 0.0],
    ]
)
"""(2, 5) position measurement matrix ``z = [x, y] = H s``. Read-only."""
H_POSITION.setflags(write=False)


#: Below this range (m) from the sensor a range-rate says little about the velocity: unused.
MIN_RANGE = 1.0


def _relative(
    x: np.ndarray, sensor: np.ndarray, sensor_velocity: np.ndarray | None
) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """``x − x_s``, ``y − y_s``, ``ρ`` (at least :data:`MIN_RANGE`) and the velocity relative
    to the sensor ``vx − vx_s``, ``vy − vy_s`` of states ``x (K, n)``."""
    dx, dy = x[:, 0] - sensor[0], x[:, 1] - sensor[1]
    rho = np.maximum(np.hypot(dx, dy), MIN_RANGE)
    if sensor_velocity is None:
        return dx, dy, rho, x[:, 2], x[:, 3]
    return dx, dy, rho, x[:, 2] - sensor_velocity[0], x[:, 3] - sensor_velocity[1]


def range_rate(
    x: np.ndarray, sensor: np.ndarray, sensor_velocity: np.ndarray | None = None
) -> np.ndarray:
    """``h(s) = ((x − x_s)(vx − vx_s) + (y − y_s)(vy − vy_s)) / ρ`` of states ``x (K, n)``: the
    range-rate the sensor at ``sensor (2,)`` moving at ``sensor_velocity (2,)`` (None: at
    rest) sees (m/s, positive going away)."""
    dx, dy, rho, wx, wy = _relative(x, sensor, sensor_velocity)
    return (dx * wx + dy * wy) / rho


def range_rate_jacobian(
    x: np.ndarray, sensor: np.ndarray, sensor_velocity: np.ndarray | None = None
) -> np.ndarray:
    """``∂h/∂s`` of :func:`range_rate`, ``(K, n)``, with ``w = v − v_s`` the velocity relative
    to the sensor::

    ∂h/∂x = wx/ρ − h (x − x_s)/ρ²,   ∂h/∂y = wy/ρ − h (y − y_s)/ρ²,
    ∂h/∂vx = (x − x_s)/ρ,            ∂h/∂vy = (y − y_s)/ρ,   ∂h/∂ω = 0
    """
    dx, dy, rho, wx, wy = _relative(x, sensor, sensor_velocity)
    h = (dx * wx + dy * wy) / rho
    J = np.zeros_like(x)
    J[:, 0] = wx / rho - h * dx / rho**2
    J[:, 1] = wy / rho - h * dy / rho**2
    J[:, 2] = dx / rho
    J[:, 3] = dy / rho
    return J


def _innovation_terms(
    x: np.ndarray,
    P: np.ndarray,
    rdot: np.ndarray,
    sensor: np.ndarray,
    variance: float,
    sensor_velocity: np.ndarray | None,
) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """``J``, ``P Jᵀ``, ``S = J P Jᵀ + σ_ṙ²`` and ``ν = ṙ − h(x)``."""
    J = range_rate_jacobian(x, sensor, sensor_velocity)
    PJ = np.einsum("kij,kj->ki", P, J)
    S = np.einsum("ki,ki->k", J, PJ) + float(variance)
    return J, PJ, S, rdot - range_rate(x, sensor, sensor_velocity)


def _velocity(sensor_velocity: np.ndarray | None) -> np.ndarray | None:
    return None if sensor_velocity is None else np.asarray(sensor_velocity, float).reshape(2)


def range_rate_innovation(
    x: np.ndarray,
    P: np.ndarray,
    rdot: np.ndarray,
    sensor: np.ndarray,
    variance: float,
    sensor_velocity: np.ndarray | None = None,
) -> tuple[np.ndarray, np.ndarray]:
    """``ν = ṙ − h(x)`` and ``S = J P Jᵀ + σ_ṙ²`` of states ``x (K, n)``, ``P (K, n, n)``: the
    range-rate innovation and its variance, for gating (``ν²/S ≤ γ₁``)."""
    _, _, S, nu = _innovation_terms(
        np.asarray(x, dtype=float),
        np.asarray(P, dtype=float),
        np.asarray(rdot, dtype=float),
        np.asarray(sensor, dtype=float).reshape(2),
        variance,
        _velocity(sensor_velocity),
    )
    return nu, S


def range_rate_update(
    x: np.ndarray,
    P: np.ndarray,
    rdot: np.ndarray,
    sensor: np.ndarray,
    variance: float,
    sensor_velocity: np.ndarray | None = None,
) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Extended Kalman update of states ``x (K, n)``, ``P (K, n, n)`` with range-rates
    ``rdot (K,)`` of variance ``σ_ṙ²`` seen from ``sensor (2,)`` moving at
    ``sensor_velocity (2,)`` (None: at rest)::

        ν = ṙ − h(x),  J = ∂h/∂s (x),  S = J P Jᵀ + σ_ṙ²,  K = P Jᵀ / S
        x⁺ = x + K ν,  P⁺ = (I − K J) P (I − K J)ᵀ + K σ_ṙ² Kᵀ  (Joseph form)
        ln Λ = −½ (ln 2πS + ν² / S)

    Returns new arrays ``x⁺``, ``P⁺`` and ``ln Λ (K,)``. A state within :data:`MIN_RANGE` of
    the sensor is returned unchanged with ``ln Λ = 0``."""
    x = np.asarray(x, dtype=float)
    P = np.asarray(P, dtype=float)
    rdot = np.asarray(rdot, dtype=float)
    sensor = np.asarray(sensor, dtype=float).reshape(2)
    J, PJ, S, nu = _innovation_terms(x, P, rdot, sensor, variance, _velocity(sensor_velocity))
    gain = PJ / S[:, None]
    x_new = x + gain * nu[:, None]
    n = x.shape[1]
    A = np.eye(n)[None] - gain[:, :, None] * J[:, None, :]
    P_new = A @ P @ A.transpose(0, 2, 1) + float(variance) * gain[:, :, None] * gain[:, None, :]
    P_new = 0.5 * (P_new + P_new.transpose(0, 2, 1))
    ll = -0.5 * (np.log(2.0 * np.pi * S) + nu * nu / S)
    near = np.hypot(x[:, 0] - sensor[0], x[:, 1] - sensor[1]) < MIN_RANGE
    if near.any():
        x_new[near], P_new[near], ll[near] = x[near], P[near], 0.0
    return x_new, P_new, ll
