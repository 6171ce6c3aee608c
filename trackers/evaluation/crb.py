"""Posterior Cramér–Rao bound for a linear-Gaussian system with detection probability 1.

For ``x_{k+1} = F x_k + w_k``, ``w_k ~ N(0, Q)`` and ``z_k = H x_k + v_k``, ``v_k ~ N(0, R)``,
the Fisher information ``J_k`` of the state follows the recursion of Tichavský, Muravchik
and Nehorai ("Posterior Cramér–Rao bounds for discrete-time nonlinear filtering", IEEE TSP
1998), which in the linear-Gaussian case reduces to::

    J_{k+1} = (Q + F J_k⁻¹ Fᵀ)⁻¹ + Hᵀ R⁻¹ H

and any unbiased estimator has ``E[(x̂_k − x_k)(x̂_k − x_k)ᵀ] ≥ P_k = J_k⁻¹``. This is the
information form of the Kalman filter covariance recursion (predict
``P⁻ = F P Fᵀ + Q``, update ``P = (P⁻⁻¹ + Hᵀ R⁻¹ H)⁻¹``), so for a linear-Gaussian system the
PCRB equals the Kalman filter covariance started from ``P_0 = J_0⁻¹``: the Kalman filter is
efficient.
"""

from __future__ import annotations

import numpy as np

__all__ = [
    "POSITION_H",
    "cv_matrices",
    "cv_position_bound",
    "pcrb_linear",
    "straight_line_velocity_bound",
]

POSITION_H = np.array([[1.0, 0.0, 0.0, 0.0], [0.0, 1.0, 0.0, 0.0]])
"""Position measurement matrix for the state ``[x, y, vx, vy]``."""
POSITION_H.setflags(write=False)


def _spd_inverse(A: np.ndarray, name: str) -> np.ndarray:
    """Inverse of a symmetric positive definite matrix, via Cholesky, symmetrised."""
    try:
        L = np.linalg.cholesky(A)
    except np.linalg.LinAlgError as exc:
        raise ValueError(f"{name} must be symmetric positive definite") from exc
    L_inv = np.linalg.solve(L, np.eye(A.shape[0]))
    return L_inv.T @ L_inv


def pcrb_linear(
    F: np.ndarray, Q: np.ndarray, H: np.ndarray, R: np.ndarray, J0: np.ndarray, steps: int
) -> np.ndarray:
    """The PCRB ``P_k = J_k⁻¹`` for ``k = 1..steps`` as a ``(steps, n, n)`` array.

    ``J0`` is the (positive definite) prior information at time 0, before the first
    prediction; ``out[k − 1]`` is the bound after ``k`` predictions and ``k`` measurements::

        J_{k+1} = (Q + F J_k⁻¹ Fᵀ)⁻¹ + Hᵀ R⁻¹ H,      P_k = J_k⁻¹

    Equivalently ``out[k − 1]`` is the updated Kalman filter covariance at step ``k`` for
    ``P_0 = J_0⁻¹``. ``F``, ``Q``, ``J0`` are ``(n, n)``, ``H`` is ``(m, n)``, ``R`` is
    ``(m, m)`` positive definite; ``Q`` may be singular as long as every predicted covariance
    ``Q + F P Fᵀ`` is positive definite.
    """
    F = np.asarray(F, dtype=float)
    Q = np.asarray(Q, dtype=float)
    H = np.asarray(H, dtype=float)
    R = np.asarray(R, dtype=float)
    J0 = np.asarray(J0, dtype=float)
    n = F.shape[0]
    if F.shape != (n, n) or Q.shape != (n, n) or J0.shape != (n, n):
        raise ValueError(f"F, Q, J0 must be ({n}, {n}); got {F.shape}, {Q.shape}, {J0.shape}")
    m = H.shape[0] if H.ndim == 2 else -1
    if H.shape != (m, n) or R.shape != (m, m):
        raise ValueError(f"H must be (m, {n}) and R (m, m); got {H.shape}, {R.shape}")
    if int(steps) != steps or steps < 0:
        raise ValueError(f"steps must be a non-negative integer, got {steps!r}")
    measurement_info = H.T @ _spd_inverse(R, "R") @ H
    P = _spd_inverse(J0, "J0")
    out = np.empty((int(steps), n, n))
    for k in range(int(steps)):
        predicted = Q + F @ P @ F.T
        J = _spd_inverse(0.5 * (predicted + predicted.T), "Q + F P Fᵀ") + measurement_info
        P = _spd_inverse(0.5 * (J + J.T), "J")
        out[k] = P
    return out


def cv_matrices(dt: float, q: float) -> tuple[np.ndarray, np.ndarray]:
    """Nearly constant velocity ``(F, Q)`` over ``dt`` for the state ``[x, y, vx, vy]``.

    Exact discretisation of continuous white-noise acceleration with PSD ``q`` (m²/s³) per
    axis (Bar-Shalom, Li and Kirubarajan 2001, section 6.2.2), with ``T = dt``::

        F = [[1, 0, T, 0], [0, 1, 0, T], [0, 0, 1, 0], [0, 0, 0, 1]]
        Q = q · [[T³/3, T²/2], [T²/2, T]]   for each of the pairs (x, vx) and (y, vy)
    """
    if not (np.isfinite(dt) and dt >= 0):
        raise ValueError(f"dt must be a finite number >= 0, got {dt!r}")
    if not (np.isfinite(q) and q >= 0):
        raise ValueError(f"q must be a finite number >= 0, got {q!r}")
    T = float(dt)
    F = np.eye(4)
    F[0, 2] = F[1, 3] = T
    Q = np.zeros((4, 4))
    Q[0, 0] = Q[1, 1] = q * T**3 / 3.0
    Q[0, 2] = Q[2, 0] = Q[1, 3] = Q[3, 1] = q * T**2 / 2.0
    Q[2, 2] = Q[3, 3] = q * T
    return F, Q


def cv_position_bound(
    dt: float, q: float, sigma: float, velocity_std: float, n_scans: int
) -> np.ndarray:
    """Root position bound ``sqrt(P_k[x,x] + P_k[y,y])`` at scans ``0 .. n_scans − 1`` for a
    nearly-constant-velocity target seen every ``dt`` with Pd = 1 and noise ``σ² I``.

    Scan 0 is the first detection: the information after it is that of the prior
    ``J_0 = diag(σ², σ², σ_v², σ_v²)⁻¹`` (position from the detection, velocity from a
    zero-mean prior of spread ``σ_v``), so the bound there is ``√2 σ``; later scans follow
    :func:`pcrb_linear`.
    """
    if n_scans < 1:
        raise ValueError("n_scans must be >= 1")
    F, Q = cv_matrices(dt, q)
    P0 = np.diag([sigma**2, sigma**2, velocity_std**2, velocity_std**2])
    out = np.empty(n_scans)
    out[0] = np.sqrt(P0[0, 0] + P0[1, 1])
    if n_scans > 1:
        J = pcrb_linear(F, Q, POSITION_H, sigma**2 * np.eye(2), np.linalg.inv(P0), n_scans - 1)
        out[1:] = np.sqrt(J[:, 0, 0] + J[:, 1, 1])
    return out


def straight_line_velocity_bound(
    t: np.ndarray,
    R: np.ndarray,
    member: np.ndarray,
    n_members: int,
    t_query: np.ndarray,
) -> np.ndarray:
    """Cramér–Rao bound on the velocity, ``tr Cov(v̂)`` (m²/s²), at each of ``t_query``, for
    ``n_members`` targets moving in straight lines with one common velocity (no process
    noise, no prior), from the position measurements made up to that time: measurement
    ``k`` at ``t[k]`` with covariance ``R[k] (2, 2)`` of member ``member[k]``. One member
    bounds a lone target's velocity; several, a rigid formation's, its members known.

    The parameters are the members' positions at ``t = 0`` (the first measurement's time:
    the velocity's bound is the same) and the velocity,
    ``θ = [p₁, …, p_N, v]``, measured as ``z_k = p_{m_k} + t_k v + w_k``, so that with
    ``A_k = [0 … I … 0, t_k I]`` the Fisher information of the measurements up to ``τ`` is::

        J(τ) = Σ_{t_k ≤ τ} A_kᵀ R_k⁻¹ A_k,     Cov(v̂) ≥ [J(τ)⁻¹]_vv

    A query time before the information determines ``θ`` (every member measured at two
    times at least) gives ``inf``."""
    t = np.asarray(t, dtype=float).reshape(-1)
    R = np.asarray(R, dtype=float).reshape(-1, 2, 2)
    member = np.asarray(member, dtype=np.intp).reshape(-1)
    t_query = np.asarray(t_query, dtype=float).reshape(-1)
    if not (t.size == R.shape[0] == member.size):
        raise ValueError("t, R and member must have one entry a measurement")
    if n_members < 1 or (member.size and not (member.min() >= 0 and member.max() < n_members)):
        raise ValueError("member must index 0 .. n_members - 1")
    d = 2 * n_members + 2
    order = np.argsort(t, kind="stable")
    t, R, member = t[order], R[order], member[order]
    # the positions at the first measurement's time instead of t = 0 (the same velocity
    # bound): times of a clock's epoch would make J too ill-conditioned to invert
    origin = float(t[0]) if t.size else 0.0
    t, t_query = t - origin, t_query - origin
    A = np.zeros((t.size, 2, d))
    rows = np.arange(t.size)
    A[rows, 0, 2 * member] = 1.0
    A[rows, 1, 2 * member + 1] = 1.0
    A[:, 0, d - 2] = A[:, 1, d - 1] = t
    info = np.cumsum(np.transpose(A, (0, 2, 1)) @ np.linalg.inv(R) @ A, axis=0)
    upto = np.searchsorted(t, t_query, side="right") - 1
    out = np.full(t_query.size, np.inf)
    for i, k in enumerate(upto.tolist()):
        if k < 0:
            continue
        J = info[k]
        diagonal = np.diag(J)
        if not np.all(diagonal > 0.0):
            continue  # a member not measured yet
        scale = 1.0 / np.sqrt(diagonal)  # so that the rank test reads geometry, not units
        Js = J * scale[:, None] * scale[None, :]
        if np.linalg.cond(Js) > 1e12:
            continue
        cov = np.linalg.inv(Js) * scale[:, None] * scale[None, :]
        out[i] = cov[d - 2, d - 2] + cov[d - 1, d - 1]
    return out
