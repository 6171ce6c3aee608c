"""Batched linear Kalman measurement update.

All functions take batch-major arrays with any leading batch dimensions (typically ``N``
tracks, or ``N`` tracks by ``M`` IMM modes); the batch dimensions of the state and of the
measurement broadcast against each other as in numpy, so one measurement ``z (N, 1, m)``
updates ``x (N, M, n)``. Inputs are never modified.

For speed the update runs in the state-major layout of :mod:`trackers.models.motion`
(matrix entries outermost, tracks innermost), where a batch of small matrix products is a
few long vector operations. When H selects state components (rows are unit vectors, as
``H_POSITION``) its products are slices; any other H is applied as one matrix product over
the whole batch. For ``m ≤ 2`` the innovation covariance is inverted in closed form,
otherwise by a batched general inverse and Cholesky factorization.
"""

from __future__ import annotations

import math

import numpy as np

from trackers.models.measurement import H_POSITION
from trackers.models.motion import (
    batch_major,
    batch_major_cov,
    row_blocks,
    state_major,
    state_major_cov,
)

__all__ = ["innovation", "kalman_update", "log_gaussian"]

_LOG_2PI = math.log(2.0 * math.pi)

Selector = slice | np.ndarray | None


def _selector(H: np.ndarray) -> Selector:
    """The state components H picks, when every row of H is a unit vector; else ``None``.

    A slice when they are consecutive and increasing (``H_POSITION``: ``slice(0, 2)``).
    """
    if H is H_POSITION:
        return slice(0, 2)
    if not (np.all((H == 0.0) | (H == 1.0)) and np.all(np.sum(H, axis=1) == 1.0)):
        return None
    idx = np.argmax(H, axis=1)
    if np.all(np.diff(idx) == 1):
        return slice(int(idx[0]), int(idx[0]) + H.shape[0])
    return idx


def _apply_rows(H: np.ndarray, sel: Selector, A: np.ndarray) -> np.ndarray:
    """``H A`` contracting H's columns with axis 0 of the state-major array A."""
    if sel is not None:
        return A[sel]
    m, n = H.shape
    return (H @ A.reshape(n, -1)).reshape(m, *A.shape[1:])


def _inverse_and_logdet(S: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """``(S⁻¹, ln det S)`` for state-major symmetric positive definite ``S (m, m, ...)``.

    m = 2: ``S⁻¹ = [[d, −b], [−c, a]] / (ad − bc)``; m = 1: ``1/s``; otherwise Cholesky
    ``S = L Lᵀ``, ``ln det S = 2 Σ ln L_ii`` and a batched general inverse.
    """
    m = S.shape[0]
    if m == 2:
        det = S[0, 0] * S[1, 1] - S[0, 1] * S[1, 0]
        inv_det = 1.0 / det
        S_inv = np.empty_like(S)
        S_inv[0, 0] = S[1, 1] * inv_det
        S_inv[0, 1] = -S[0, 1] * inv_det
        S_inv[1, 0] = -S[1, 0] * inv_det
        S_inv[1, 1] = S[0, 0] * inv_det
        return S_inv, np.log(det)
    if m == 1:
        return 1.0 / S, np.log(S[0, 0])
    Sb = np.moveaxis(S, (0, 1), (-2, -1))
    L = np.linalg.cholesky(Sb)
    logdet = 2.0 * np.sum(np.log(np.diagonal(L, axis1=-2, axis2=-1)), axis=-1)
    return np.moveaxis(np.linalg.inv(Sb), (-2, -1), (0, 1)), logdet


def update_state_major(
    xs: np.ndarray, Ps: np.ndarray, zs: np.ndarray, Rs: np.ndarray, H: np.ndarray
) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """:func:`kalman_update` on state-major arrays.

    ``xs (n, ...)``, ``Ps (n, n, ...)``, ``zs (m, ...)``, ``Rs (m, m, ...)`` whose trailing
    batch axes broadcast; returns ``xs⁺ (n, ...)``, ``Ps⁺ (n, n, ...)``, ``ln Λ (...)``.
    With ``Kᵀ = S⁻¹ H P`` (P symmetric) the Joseph form is evaluated as::

        B  = (I − K H) P = P − K (H P)
        P⁺ = B (I − K H)ᵀ + K R Kᵀ = B + (K R − B Hᵀ) Kᵀ
    """
    H = np.asarray(H, dtype=float)
    m = H.shape[0]
    sel = _selector(H)

    HP = _apply_rows(H, sel, Ps)  # (m, n, ...)
    S = _apply_rows(H, sel, HP.swapaxes(0, 1)).swapaxes(0, 1) + Rs  # H P Hᵀ + R
    S_inv, logdet = _inverse_and_logdet(S)
    nu = zs - _apply_rows(H, sel, xs)  # (m, ...)

    Kt = S_inv[:, 0, None] * HP[0]  # Kᵀ = S⁻¹ H P, (m, n, ...)
    S_inv_nu = S_inv[:, 0] * nu[0]
    for c in range(1, m):
        Kt += S_inv[:, c, None] * HP[c]
        S_inv_nu += S_inv[:, c] * nu[c]

    x_post = xs + Kt[0] * nu[0]  # x + K ν
    for a in range(1, m):
        x_post += Kt[a] * nu[a]

    # B = P − K (H P) accumulated in place; tmp holds one outer product at a time.
    B = np.multiply(Kt[0][:, None], HP[0])
    tmp = np.empty_like(B)
    for a in range(1, m):
        B += np.multiply(Kt[a][:, None], HP[a], out=tmp)
    np.subtract(Ps, B, out=B)

    Ct = Rs[:, 0, None] * Kt[0]  # (K R − B Hᵀ)ᵀ = R Kᵀ − H Bᵀ, (m, n, ...)
    for c in range(1, m):
        Ct += Rs[:, c, None] * Kt[c]
    Ct -= _apply_rows(H, sel, B.swapaxes(0, 1))

    for a in range(m):  # P⁺ = B + C Kᵀ, in place in B
        B += np.multiply(Ct[a][:, None], Kt[a], out=tmp)
    P_post = np.add(B, B.swapaxes(0, 1), out=tmp)  # symmetrize
    P_post *= 0.5

    maha = nu[0] * S_inv_nu[0]
    for a in range(1, m):
        maha += nu[a] * S_inv_nu[a]
    log_likelihood = -0.5 * (maha + logdet + m * _LOG_2PI)
    return x_post, P_post, log_likelihood


def kalman_update(
    x: np.ndarray, P: np.ndarray, z: np.ndarray, R: np.ndarray, H: np.ndarray
) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Kalman measurement update in Joseph form, batched.

    x (N, n), P (N, n, n), z (N, m), R (N, m, m), H (m, n)::

        ν  = z − H x                 S = H P Hᵀ + R              K = P Hᵀ S⁻¹
        x⁺ = x + K ν                 P⁺ = (I − K H) P (I − K H)ᵀ + K R Kᵀ
        ln Λ = ln N(ν; 0, S) = −½ (νᵀ S⁻¹ ν + ln det S + m ln 2π)

    Returns ``(x⁺ (N, n), P⁺ (N, n, n), ln Λ (N,))``; P⁺ is symmetrized. P and R must be
    symmetric. Leading batch dimensions of (x, P) and (z, R) broadcast against each other.
    """
    x = np.asarray(x, dtype=float)
    P = np.asarray(P, dtype=float)
    z = np.asarray(z, dtype=float)
    R = np.asarray(R, dtype=float)
    H = np.asarray(H, dtype=float)
    m, n = H.shape
    batch = np.broadcast_shapes(x.shape[:-1], P.shape[:-2], z.shape[:-1], R.shape[:-2])
    # Broadcast views (no copies), flattened to one batch axis processed block by block.
    xb = np.broadcast_to(x, (*batch, n)).reshape(-1, n)
    Pb = np.broadcast_to(P, (*batch, n, n)).reshape(-1, n, n)
    zb = np.broadcast_to(z, (*batch, m)).reshape(-1, m)
    Rb = np.broadcast_to(R, (*batch, m, m)).reshape(-1, m, m)
    x_out = np.empty(xb.shape)
    P_out = np.empty(Pb.shape)
    ll_out = np.empty(xb.shape[0])
    for rows in row_blocks(xb.shape[0]):
        xs, Ps, ll = update_state_major(
            state_major(xb[rows]),
            state_major_cov(Pb[rows]),
            state_major(zb[rows]),
            state_major_cov(Rb[rows]),
            H,
        )
        x_out[rows] = batch_major(xs)
        P_out[rows] = batch_major_cov(Ps)
        ll_out[rows] = ll
    return x_out.reshape(*batch, n), P_out.reshape(*batch, n, n), ll_out.reshape(batch)


def innovation(
    x: np.ndarray, P: np.ndarray, z: np.ndarray, R: np.ndarray, H: np.ndarray
) -> tuple[np.ndarray, np.ndarray]:
    """Innovation ``ν = z − H x`` and its covariance ``S = H P Hᵀ + R``.

    x (N, n), P (N, n, n), z (N, m), R (N, m, m), H (m, n) → ν (N, m), S (N, m, m); leading
    batch dimensions broadcast (e.g. x (N, 1, n) against z (1, D, m) gives (N, D, ...)).
    """
    x = np.asarray(x, dtype=float)
    P = np.asarray(P, dtype=float)
    H = np.asarray(H, dtype=float)
    sel = _selector(H)
    if sel is not None:
        Hx = x[..., sel]
        HPHt = P[..., sel, :][..., :, sel]
    else:
        Hx = x @ H.T
        HPHt = H @ P @ H.T
    return np.asarray(z, dtype=float) - Hx, HPHt + np.asarray(R, dtype=float)


def log_gaussian(nu: np.ndarray, S: np.ndarray) -> np.ndarray:
    """``ln N(ν; 0, S) = −½ (νᵀ S⁻¹ ν + ln det S + m ln 2π)``, batched: (N, m), (N, m, m) → (N,).

    m = 2 in closed form (``det S = s₀₀ s₁₁ − s₀₁ s₁₀``), otherwise via the Cholesky factor
    ``S = L Lᵀ``: ``νᵀ S⁻¹ ν = |L⁻¹ ν|²`` and ``ln det S = 2 Σ ln L_ii``.
    """
    nu = np.asarray(nu, dtype=float)
    S = np.asarray(S, dtype=float)
    m = S.shape[-1]
    if m == 2:
        a = S[..., 0, 0]
        b = S[..., 0, 1]
        c = S[..., 1, 0]
        d = S[..., 1, 1]
        det = a * d - b * c
        n0 = nu[..., 0]
        n1 = nu[..., 1]
        maha = (d * n0 * n0 - (b + c) * n0 * n1 + a * n1 * n1) / det
        return -0.5 * (maha + np.log(det) + 2.0 * _LOG_2PI)
    L = np.linalg.cholesky(S)
    batch = np.broadcast_shapes(nu.shape[:-1], L.shape[:-2])
    L_b = np.broadcast_to(L, (*batch, m, m))
    nu_b = np.broadcast_to(nu, (*batch, m))
    y = np.linalg.solve(L_b, nu_b[..., None])[..., 0]  # L y = ν
    logdet = 2.0 * np.sum(np.log(np.diagonal(L, axis1=-2, axis2=-1)), axis=-1)
    return -0.5 * (np.sum(y * y, axis=-1) + logdet + m * _LOG_2PI)
