"""Gating: a spatial pre-gate, then the chi-square gate on each candidate pair.

For a track with predicted position ``ẑ_i`` and predicted position covariance ``P_i`` (the
position block of ``H P⁻ Hᵀ``), and a detection ``z_j`` with covariance ``R_j``, the pair is in
the gate when

    d²_ij = ν_ijᵀ S_ij⁻¹ ν_ij ≤ γ,   ν_ij = z_j − ẑ_i,   S_ij = P_i + R_j.

Since ``d² ≥ |ν|² / λ_max(S)`` and ``λ_max(S) ≤ λ_max(P_i) + max_j λ_max(R_j)``, no pair with
``|ν| > r_i = sqrt(γ (λ_max(P_i) + max_j λ_max(R_j)))`` can pass: the search with that
radius (:func:`trackers.association.spatial.pairs_within`, a k-d tree in large scenes) finds
every candidate, so the cost grows with the number of nearby pairs rather than with the
product of the numbers of tracks and detections.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from trackers.association.spatial import pairs_within

__all__ = [
    "GatedPairs",
    "expected_false_alarms",
    "gate",
    "inverse_2x2",
    "log_gaussian_2d",
    "max_eigenvalue_2x2",
    "position_noise",
]

_LOG_2PI = float(np.log(2.0 * np.pi))


@dataclass(frozen=True)
class GatedPairs:
    """Track-detection pairs that passed the gate, as parallel arrays.

    ``track`` and ``detection`` are indices, ``d2`` the squared Mahalanobis distances.
    """

    track: np.ndarray
    detection: np.ndarray
    d2: np.ndarray

    @property
    def size(self) -> int:
        return int(self.track.size)


def max_eigenvalue_2x2(A: np.ndarray) -> np.ndarray:
    """Largest eigenvalue of each symmetric 2x2 matrix in ``A`` (…, 2, 2):
    λ_max = (a + d)/2 + sqrt(((a − d)/2)² + b²)."""
    a, b, d = A[..., 0, 0], A[..., 0, 1], A[..., 1, 1]
    return 0.5 * (a + d) + np.sqrt(0.25 * (a - d) ** 2 + b * b)


def position_noise(R: np.ndarray) -> float | None:
    """The position noise of a batch's detections: ``σ̃ = median_i sqrt(λ_max(R_i))`` (m) of
    their covariances ``R (n, 2, 2)``; ``None`` for none."""
    if len(R) == 0:
        return None
    # The median by a sort: np.median costs ten times more on a batch's few detections.
    s = np.sort(max_eigenvalue_2x2(R))
    n = s.size
    return float(0.5 * (math.sqrt(s[(n - 1) // 2]) + math.sqrt(s[n // 2])))


def expected_false_alarms(lam: float | np.ndarray, det: np.ndarray, gamma: float) -> np.ndarray:
    """The false alarms a chi-square gate ``mᵀ S⁻¹ m ≤ γ`` of ``det S`` expects at density
    ``lam`` (per m²): ``λ V``, ``V = π γ √det S`` its area."""
    return lam * np.pi * gamma * np.sqrt(np.maximum(det, 0.0))


def inverse_2x2(S: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Inverse and determinant of each 2x2 matrix: S⁻¹ = [[d, −b], [−c, a]] / (ad − bc)."""
    a, b, c, d = S[..., 0, 0], S[..., 0, 1], S[..., 1, 0], S[..., 1, 1]
    det = a * d - b * c
    inv = np.empty_like(S)
    inv[..., 0, 0] = d / det
    inv[..., 0, 1] = -b / det
    inv[..., 1, 0] = -c / det
    inv[..., 1, 1] = a / det
    return inv, det


def log_gaussian_2d(nu: np.ndarray, S: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Squared Mahalanobis distance and log density of 2-D Gaussians, batched:
    d² = νᵀ S⁻¹ ν,  ln N(ν; 0, S) = −d²/2 − ln(2π) − ½ ln|S|."""
    S_inv, det = inverse_2x2(S)
    d2 = np.einsum("...i,...ij,...j->...", nu, S_inv, nu)
    return d2, -0.5 * d2 - _LOG_2PI - 0.5 * np.log(det)


def gate(
    z_pred: np.ndarray,
    P_pred: np.ndarray,
    z: np.ndarray,
    R: np.ndarray,
    gamma: float,
) -> GatedPairs:
    """All pairs (i, j) with d²_ij ≤ γ.

    Parameters
    ----------
    z_pred : (N, 2) predicted track positions ẑ_i.
    P_pred : (N, 2, 2) predicted position covariances (H P⁻ Hᵀ).
    z : (n, 2) detection positions.
    R : (n, 2, 2) detection covariances.
    gamma : the chi-square threshold γ.
    """
    empty = np.zeros(0, dtype=np.intp)
    if z_pred.shape[0] == 0 or z.shape[0] == 0:
        return GatedPairs(empty, empty, np.zeros(0))
    radius = np.sqrt(gamma * (max_eigenvalue_2x2(P_pred) + float(max_eigenvalue_2x2(R).max())))
    ti, dj = pairs_within(z_pred, radius, z)
    if ti.size == 0:
        return GatedPairs(empty, empty, np.zeros(0))
    nu = z[dj] - z_pred[ti]
    S_inv, _ = inverse_2x2(P_pred[ti] + R[dj])
    d2 = np.einsum("ki,kij,kj->k", nu, S_inv, nu)
    keep = d2 <= gamma
    return GatedPairs(ti[keep], dj[keep], d2[keep])
