"""Random-matrix extended-object filter (Feldmann, Fränken and Koch, IEEE Trans. Signal
Processing 59(4), 2011).

An extended object (or a group of closely spaced targets) is a centroid with kinematic state
``x = [x, y, vx, vy]`` (m, m/s) and covariance ``P (4, 4)``, and an *extent* ``X (2, 2)``: a
symmetric positive definite (SPD) matrix in m² describing its elliptical shape, carried as
an inverse-Wishart-like estimate with ``α`` degrees of freedom (its "memory", in
detections). Each of the ``n`` detections of a scan is modelled as

    yʲ ~ N(H x, z X + R),    H = [[1, 0, 0, 0], [0, 1, 0, 0]],

where ``R`` is the sensor's measurement covariance and ``z`` a scaling factor (``z = 1/4``
for scatterers spread uniformly over the ellipse ``{p : pᵀ X⁻¹ p ≤ 1}``, whose covariance
is ``X / 4``).

Motion is nearly constant velocity (discretized continuous white-noise acceleration, power
spectral density ``q`` in m²/s³), the extent is predicted unchanged and its degrees of
freedom decay towards 2 with time constant ``τ``.

Matrix square roots are the SYMMETRIC (principal) square roots throughout: for SPD ``A``,
``A^½`` is the unique SPD matrix with ``A^½ A^½ = A``, so ``A^½ᵀ = A^½`` and
``A^−½ = (A^½)⁻¹`` is SPD too. For 2x2 matrices it has the closed form of
:func:`sqrtm_2x2`; no general-purpose ``sqrtm`` is used.

The functions work on one track, are written for a per-track, per-scan hot path (2x2
algebra written out on floats, no scipy.linalg), return new arrays and never modify their
inputs. Inputs are validated cheaply (shapes, finiteness, SPD through the 2x2 determinant
and trace); invalid input raises :class:`ValueError`.
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import dataclass
from typing import NamedTuple

import numpy as np

__all__ = [
    "ExtendedEstimate",
    "Moments",
    "gate_covariance",
    "innovation_covariance",
    "innovation_entries",
    "inv_sqrtm_2x2",
    "merged",
    "moments",
    "moments_log_likelihood",
    "predict",
    "sqrtm_2x2",
    "subset_log_likelihood",
    "update",
    "update_moments",
]

_LOG_2PI = math.log(2.0 * math.pi)

# Relative tolerance on the asymmetry |A01 − A10| / (|A00| + |A11|) of a matrix that should
# be symmetric; its symmetric part is used.
_SYMMETRY_RTOL = 1e-9


@dataclass(frozen=True)
class ExtendedEstimate:
    """Estimate of one extended object.

    Attributes:
        x: ``(4,)`` centroid kinematics ``[x, y, vx, vy]`` in m and m/s.
        P: ``(4, 4)`` covariance of ``x``.
        X: ``(2, 2)`` extent estimate in m², SPD (for ``z = 1/4``, the shape matrix of the
            ellipse ``{p : pᵀ X⁻¹ p ≤ 1}`` about the centroid).
        alpha: degrees of freedom of the extent estimate (its memory in detections; ``> 2``
            typically).

    The arrays are stored as read-only float copies; shapes are checked here, finiteness
    and positive definiteness by the filter functions.
    """

    x: np.ndarray
    P: np.ndarray
    X: np.ndarray
    alpha: float

    def __post_init__(self) -> None:
        for name, shape in (("x", (4,)), ("P", (4, 4)), ("X", (2, 2))):
            arr = np.array(getattr(self, name), dtype=float)
            if arr.shape != shape:
                raise ValueError(
                    f"ExtendedEstimate.{name} must have shape {shape}, got {arr.shape}"
                )
            arr.setflags(write=False)
            object.__setattr__(self, name, arr)
        object.__setattr__(self, "alpha", float(self.alpha))

    @classmethod
    def _of(cls, x: np.ndarray, P: np.ndarray, X: np.ndarray, alpha: float) -> ExtendedEstimate:
        """An estimate from arrays this module has just made (float, right shapes, owned by
        nobody else; or an estimate's own read-only array): they are made read-only and kept,
        not copied. The filter functions' per-scan path."""
        est = object.__new__(cls)
        for name, arr in (("x", x), ("P", P), ("X", X)):
            if arr.flags.writeable:
                arr.setflags(write=False)
            object.__setattr__(est, name, arr)
        object.__setattr__(est, "alpha", float(alpha))
        return est


# --- 2x2 symmetric matrix roots ----------------------------------------------------------------


def _check_batch_2x2(A: np.ndarray) -> np.ndarray:
    A = np.asarray(A, dtype=float)
    if A.ndim < 2 or A.shape[-2:] != (2, 2):
        raise ValueError(f"expected an array of shape (..., 2, 2), got {A.shape}")
    return A


def _root_terms(A: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """``(tr A, s, t)`` with ``s = √det A`` and ``t = √(tr A + 2 s)``, for SPD ``A``."""
    a, b, c, d = A[..., 0, 0], A[..., 0, 1], A[..., 1, 0], A[..., 1, 1]
    det = a * d - b * c
    tr = a + d
    if not (np.all(det > 0.0) and np.all(tr > 0.0)):
        raise ValueError("matrix is not positive definite (needs det > 0 and trace > 0)")
    s = np.sqrt(det)
    return tr, s, np.sqrt(tr + 2.0 * s)


def sqrtm_2x2(A: np.ndarray) -> np.ndarray:
    """Symmetric (principal) square root of SPD 2x2 matrices, batched over leading dims.

    ``A^½ = (A + s I) / t`` with ``s = √det A`` and ``t = √(tr A + 2 s)``: by Cayley-Hamilton
    ``A² = (tr A) A − (det A) I``, so ``(A + s I)² = (tr A + 2 s) A = t² A``; ``A + s I`` is
    SPD, so this is the unique SPD root and it is symmetric.

    Args:
        A: ``(..., 2, 2)`` SPD matrices.

    Returns:
        ``(..., 2, 2)`` new array of their symmetric square roots.

    Raises:
        ValueError: wrong shape, or a matrix with ``det ≤ 0`` or ``trace ≤ 0``.
    """
    A = _check_batch_2x2(A)
    _, s, t = _root_terms(A)
    out = A.copy()
    out[..., 0, 0] += s
    out[..., 1, 1] += s
    return out / t[..., None, None]


def inv_sqrtm_2x2(A: np.ndarray) -> np.ndarray:
    """Inverse of the symmetric square root of SPD 2x2 matrices, batched over leading dims.

    ``A^−½ = (A^½)⁻¹ = ((tr A + s) I − A) / (s t)`` with ``s = √det A`` and
    ``t = √(tr A + 2 s)``: the 2x2 adjugate of ``B = A + s I`` is ``(tr B) I − B`` and
    ``det B = s t²``, so ``(B / t)⁻¹ = ((tr A + s) I − A) / (s t)``. The result is SPD.

    Args:
        A: ``(..., 2, 2)`` SPD matrices.

    Returns:
        ``(..., 2, 2)`` new array of the inverses of their symmetric square roots.

    Raises:
        ValueError: wrong shape, or a matrix with ``det ≤ 0`` or ``trace ≤ 0``.
    """
    A = _check_batch_2x2(A)
    tr, s, t = _root_terms(A)
    out = -A
    out[..., 0, 0] += tr + s
    out[..., 1, 1] += tr + s
    return out / (s * t)[..., None, None]


# Scalar versions for the per-track hot path. A symmetric 2x2 matrix [[a, b], [b, c]] is
# the float triple (a, b, c); a general one [[m00, m01], [m10, m11]] a 4-tuple.

Sym = tuple[float, float, float]


def _sym_sqrt(a: float, b: float, c: float) -> Sym:
    s = math.sqrt(a * c - b * b)
    t = math.sqrt(a + c + 2.0 * s)
    return (a + s) / t, b / t, (c + s) / t


def _sym_inv_sqrt(a: float, b: float, c: float) -> Sym:
    s = math.sqrt(a * c - b * b)
    k = 1.0 / (s * math.sqrt(a + c + 2.0 * s))
    return (c + s) * k, -b * k, (a + s) * k


def _sym_inv(a: float, b: float, c: float) -> Sym:
    k = 1.0 / (a * c - b * b)
    return c * k, -b * k, a * k


# --- validation ----------------------------------------------------------------------------------


def _finite(value: float, name: str) -> float:
    try:
        v = float(value)
    except (TypeError, ValueError):
        raise ValueError(f"{name} must be a real number, got {value!r}") from None
    if not math.isfinite(v):
        raise ValueError(f"{name} must be finite, got {v}")
    return v


def _spd(A: np.ndarray, name: str) -> Sym:
    """The symmetric SPD 2x2 matrix ``A`` as ``(a, b, c)``; ValueError if it is not one."""
    A = np.asarray(A, dtype=float)
    if A.shape != (2, 2):
        raise ValueError(f"{name} must have shape (2, 2), got {A.shape}")
    a, b01, b10, c = A.ravel().tolist()
    if not (math.isfinite(a) and math.isfinite(b01) and math.isfinite(b10) and math.isfinite(c)):
        raise ValueError(f"{name} must be finite, got {A.tolist()}")
    if abs(b01 - b10) > _SYMMETRY_RTOL * (abs(a) + abs(c)):
        raise ValueError(f"{name} must be symmetric, got {A.tolist()}")
    b = 0.5 * (b01 + b10)
    if not (a > 0.0 and a * c - b * b > 0.0):
        raise ValueError(f"{name} must be positive definite (det > 0, trace > 0), got {A.tolist()}")
    return a, b, c


def _estimate(est: ExtendedEstimate) -> Sym:
    """Checks ``est`` (finite x and P, SPD X, α > 0); returns X as ``(a, b, c)``."""
    if not isinstance(est, ExtendedEstimate):
        raise ValueError(f"expected an ExtendedEstimate, got {type(est).__name__}")
    # (on Python floats: faster than numpy reductions for 20 values)
    if not all(map(math.isfinite, est.x.tolist() + est.P.ravel().tolist())):
        raise ValueError("ExtendedEstimate x and P must be finite")
    if not (math.isfinite(est.alpha) and est.alpha > 0.0):
        raise ValueError(f"ExtendedEstimate.alpha must be finite and > 0, got {est.alpha}")
    return _spd(est.X, "ExtendedEstimate.X")


def _z_scale(z_scale: float) -> float:
    z = _finite(z_scale, "z_scale")
    if z <= 0.0:
        raise ValueError(f"z_scale must be > 0, got {z}")
    return z


def _detections(Z: np.ndarray) -> np.ndarray:
    """``Z`` as a float ``(n, 2)`` array (an empty input of any 1-d or 2-d shape is n = 0)."""
    Z = np.asarray(Z, dtype=float)
    if Z.ndim == 1 and Z.size == 0:
        return Z.reshape(0, 2)
    if Z.ndim != 2 or Z.shape[1] != 2:
        raise ValueError(f"Z must have shape (n, 2), got {Z.shape}")
    if not np.isfinite(Z).all():
        raise ValueError("Z must be finite")
    return Z


def _set_inputs(
    est: ExtendedEstimate, Z: np.ndarray, R: np.ndarray, z_scale: float
) -> tuple[np.ndarray, Sym, float, Sym]:
    """The checked inputs of a set of detections: ``Z (n, 2)``, R's entries, z and X's
    entries (raises ``ValueError`` as :func:`update` documents)."""
    return _detections(Z), _spd(R, "R"), _z_scale(z_scale), _estimate(est)


class Moments(NamedTuple):
    """What the filter needs of ``n ≥ 1`` detections ``yʲ``: ``n``, their mean
    ``ȳ = (1/n) Σ yʲ`` and their scatter ``Ȳ = Σ (yʲ − ȳ)(yʲ − ȳ)ᵀ`` as ``(a, b, c)``."""

    n: int
    mean: tuple[float, float]
    scatter: Sym


def moments(Z: np.ndarray) -> Moments:
    """The :class:`Moments` of the detections ``Z (n ≥ 1, 2)``; ValueError for bad or no
    detections."""
    Z = _detections(Z)
    if Z.shape[0] == 0:
        raise ValueError("moments need at least one detection")
    y0, y1, scatter = _scatter(Z)
    return Moments(Z.shape[0], (y0, y1), scatter)


def _scatter(Z: np.ndarray) -> tuple[float, float, Sym]:
    """Mean ``ȳ`` and scatter ``Ȳ = Σ (yʲ − ȳ)(yʲ − ȳ)ᵀ`` of the rows of ``Z (n ≥ 1, 2)``."""
    ybar = Z.mean(axis=0)
    D = Z - ybar
    Yb = D.T @ D
    return float(ybar[0]), float(ybar[1]), (float(Yb[0, 0]), float(Yb[0, 1]), float(Yb[1, 1]))


# --- filter ---------------------------------------------------------------------------------------


def predict(est: ExtendedEstimate, dt: float, q: float, tau: float) -> ExtendedEstimate:
    """Time update over ``dt`` seconds.

    ``x⁻ = F x``, ``P⁻ = F P Fᵀ + Q``, ``X⁻ = X``, ``α⁻ = 2 + e^(−T/τ) (α − 2)``, with
    ``T = dt``, ``F = [[1, 0, T, 0], [0, 1, 0, T], [0, 0, 1, 0], [0, 0, 0, 1]]`` and per axis
    ``Q = q [[T³/3, T²/2], [T²/2, T]]`` (nearly constant velocity).

    Args:
        est: estimate at the previous scan.
        dt: time step T in s, ``≥ 0``.
        q: white acceleration power spectral density in m²/s³, ``≥ 0``.
        tau: time constant τ of the extent's memory in s, ``> 0``.

    Returns:
        The predicted estimate (new arrays).

    Raises:
        ValueError: non-finite inputs, ``dt < 0``, ``q < 0``, ``tau ≤ 0``, a non-SPD X or
            ``α ≤ 0``.
    """
    T = _finite(dt, "dt")
    q = _finite(q, "q")
    tau = _finite(tau, "tau")
    if T < 0.0:
        raise ValueError(f"dt must be >= 0, got {T}")
    if q < 0.0:
        raise ValueError(f"q must be >= 0, got {q}")
    if tau <= 0.0:
        raise ValueError(f"tau must be > 0, got {tau}")
    _estimate(est)

    # On Python floats (a 4x4 is too small for numpy to pay), operation for operation as
    # F P Fᵀ + Q written out: rows, then columns, of the position block gain T·velocity.
    x0, x1, x2, x3 = est.x.tolist()
    p = est.P.tolist()
    fp = [[p[i][j] + T * p[i + 2][j] for j in range(4)] for i in range(2)] + p[2:]
    pn = [[r[0] + T * r[2], r[1] + T * r[3], r[2], r[3]] for r in fp]
    q11, q12, q22 = q * T**3 / 3.0, q * T**2 / 2.0, q * T
    pn[0][0] += q11
    pn[1][1] += q11
    pn[0][2] += q12
    pn[2][0] += q12
    pn[1][3] += q12
    pn[3][1] += q12
    pn[2][2] += q22
    pn[3][3] += q22
    P_new = [[0.5 * (pn[i][j] + pn[j][i]) for j in range(4)] for i in range(4)]
    alpha = 2.0 + math.exp(-T / tau) * (est.alpha - 2.0)
    return ExtendedEstimate._of(
        np.array([x0 + T * x2, x1 + T * x3, x2, x3]), np.array(P_new), est.X, alpha
    )


def update(
    est: ExtendedEstimate, Z: np.ndarray, R: np.ndarray, z_scale: float = 0.25
) -> ExtendedEstimate:
    """Measurement update with the ``n`` detections ``y¹..yⁿ`` of one scan.

    With ``ȳ = (1/n) Σ yʲ``, ``Ȳ = Σ (yʲ − ȳ)(yʲ − ȳ)ᵀ``, ``Y = z X⁻ + R``,
    ``S = H P⁻ Hᵀ + Y / n``, ``K = P⁻ Hᵀ S⁻¹`` and ``ν = ȳ − H x⁻``::

        x = x⁻ + K ν
        P = P⁻ − K S Kᵀ
        N̂ = X⁻^½ S^−½ ν νᵀ S^−½ᵀ X⁻^½ᵀ
        Ẑ = X⁻^½ Y^−½ Ȳ Y^−½ᵀ X⁻^½ᵀ
        X = (α⁻ X⁻ + N̂ + Ẑ) / (α⁻ + n)
        α = α⁻ + n

    All square roots are the symmetric ones (so the transposes are the roots themselves).
    ``n = 0`` returns ``est`` unchanged; ``n = 1`` has ``Ȳ = 0``, so ``Ẑ = 0``.

    Args:
        est: predicted estimate ``(x⁻, P⁻, X⁻, α⁻)``.
        Z: ``(n, 2)`` detections (m), ``n ≥ 0``.
        R: ``(2, 2)`` SPD measurement covariance (m²); when the detections have different
            covariances, their mean.
        z_scale: scaling factor ``z > 0`` (1/4 for scatterers uniform over the ellipse).

    Returns:
        The updated estimate (new arrays), or ``est`` itself when ``n = 0``.

    Raises:
        ValueError: wrong shapes, non-finite values, non-SPD R or X, ``z_scale ≤ 0``,
            ``α ≤ 0``.
    """
    Z, R_entries, z, X_entries = _set_inputs(est, Z, R, z_scale)
    if Z.shape[0] == 0:
        return est
    return _update(est, moments(Z), R_entries, z, X_entries)


def update_moments(
    est: ExtendedEstimate, m: Moments, R: np.ndarray, z_scale: float = 0.25
) -> ExtendedEstimate:
    """:func:`update` from the detections' :func:`moments` (found once for both this and
    :func:`moments_log_likelihood`): the same estimate, to the bit."""
    return _update(est, m, _spd(R, "R"), _z_scale(z_scale), _estimate(est))


def _update(est: ExtendedEstimate, mom: Moments, R: Sym, z: float, X: Sym) -> ExtendedEstimate:
    """:func:`update` on checked inputs (``R`` and ``X`` as ``(a, b, c)``)."""
    (ra, rb, rc), (xa, xb, xc) = R, X
    n, (y0, y1), (ba, bb, bc) = mom
    x, P, alpha = est.x, est.P, est.alpha
    # Y = z X + R; S = H P Hᵀ + Y / n.
    ya, yb, yc = z * xa + ra, z * xb + rb, z * xc + rc
    sa = float(P[0, 0]) + ya / n
    sb = 0.5 * float(P[0, 1] + P[1, 0]) + yb / n
    sc = float(P[1, 1]) + yc / n
    if not (sa > 0.0 and sa * sc - sb * sb > 0.0):
        raise ValueError("innovation covariance is not positive definite (check P)")
    ia, ib, ic = _sym_inv(sa, sb, sc)
    n0, n1 = y0 - float(x[0]), y1 - float(x[1])

    PHt = P[:, :2]
    K = PHt @ np.array([[ia, ib], [ib, ic]])
    x_new = x + K @ np.array([n0, n1])
    # K S Kᵀ = P Hᵀ S⁻¹ H P = K (P Hᵀ)ᵀ.
    P_new = P - K @ PHt.T
    P_new = 0.5 * (P_new + P_new.T)

    # N̂ = w wᵀ with w = X^½ S^−½ ν.
    ha, hb, hc = _sym_sqrt(xa, xb, xc)
    pa, pb, pc = _sym_inv_sqrt(sa, sb, sc)
    u0, u1 = pa * n0 + pb * n1, pb * n0 + pc * n1
    w0, w1 = ha * u0 + hb * u1, hb * u0 + hc * u1
    # Ẑ = M Ȳ Mᵀ with M = X^½ Y^−½.
    ga, gb, gc = _sym_inv_sqrt(ya, yb, yc)
    m00, m01 = ha * ga + hb * gb, ha * gb + hb * gc
    m10, m11 = hb * ga + hc * gb, hb * gb + hc * gc
    # rows of M Ȳ
    t00, t01 = m00 * ba + m01 * bb, m00 * bb + m01 * bc
    t10, t11 = m10 * ba + m11 * bb, m10 * bb + m11 * bc
    za = t00 * m00 + t01 * m01
    zb = t00 * m10 + t01 * m11
    zc = t10 * m10 + t11 * m11

    k = 1.0 / (alpha + n)
    Xa = (alpha * xa + w0 * w0 + za) * k
    Xb = (alpha * xb + w0 * w1 + zb) * k
    Xc = (alpha * xc + w1 * w1 + zc) * k
    return ExtendedEstimate._of(x_new, P_new, np.array([[Xa, Xb], [Xb, Xc]]), alpha + n)


def innovation_covariance(
    est: ExtendedEstimate, n: int, R: np.ndarray, z_scale: float = 0.25
) -> np.ndarray:
    """Covariance of the mean ``ȳ`` of ``n`` detections about ``H x``.

    ``S = H P Hᵀ + (z X + R) / n``.

    Args:
        est: predicted estimate.
        n: number of detections, ``≥ 1``.
        R: ``(2, 2)`` SPD measurement covariance.
        z_scale: scaling factor ``z > 0``.

    Returns:
        ``(2, 2)`` new array S.

    Raises:
        ValueError: ``n < 1`` or not an integer, non-SPD R or X, non-finite values,
            ``z_scale ≤ 0``.
    """
    sa, sb, sc = innovation_entries(est, n, R, z_scale)
    return np.array([[sa, sb], [sb, sc]])


def innovation_entries(est: ExtendedEstimate, n: int, R: np.ndarray, z_scale: float = 0.25) -> Sym:
    """:func:`innovation_covariance` as the floats ``(S₀₀, S₀₁, S₁₁)`` of the symmetric
    ``S = ½ (H P Hᵀ + (H P Hᵀ)ᵀ) + (z X + R) / n``; same checks and errors."""
    if isinstance(n, bool) or not isinstance(n, int | np.integer) or n < 1:
        raise ValueError(f"n must be an integer >= 1, got {n!r}")
    ra, rb, rc = _spd(R, "R")
    z = _z_scale(z_scale)
    xa, xb, xc = _estimate(est)
    (p00, p01), (p10, p11) = est.P[:2, :2].tolist()
    k = int(n)
    return (
        0.5 * (p00 + p00) + (z * xa + ra) / k,
        0.5 * (p01 + p10) + (z * xb + rb) / k,
        0.5 * (p11 + p11) + (z * xc + rc) / k,
    )


def gate_covariance(est: ExtendedEstimate, R: np.ndarray, z_scale: float = 0.25) -> np.ndarray:
    """Covariance of ONE detection about the predicted centroid, for gating single detections.

    ``H P Hᵀ + z X + R`` (:func:`innovation_covariance` with ``n = 1``).

    Args:
        est: predicted estimate.
        R: ``(2, 2)`` SPD measurement covariance.
        z_scale: scaling factor ``z > 0``.

    Returns:
        ``(2, 2)`` new array.

    Raises:
        ValueError: non-SPD R or X, non-finite values, ``z_scale ≤ 0``.
    """
    return innovation_covariance(est, 1, R, z_scale)


def subset_log_likelihood(
    est: ExtendedEstimate,
    Z: np.ndarray,
    R: np.ndarray,
    z_scale: float = 0.25,
    extent_uncertain: bool = False,
) -> float:
    """Log density of the ``n ≥ 1`` detections ``Z`` under the predicted estimate.

    The extent is taken at its predicted value (plug-in) unless ``extent_uncertain``; the
    centroid is integrated out:
    given ``x``, the detections are i.i.d. ``yʲ ~ N(H x, Y)`` with ``Y = z X + R``, and
    ``x ~ N(x⁻, P)``, so the stacked ``2n``-vector ``y = [y¹; …; yⁿ]`` is Gaussian with mean
    ``1 ⊗ H x`` and covariance ``11ᵀ ⊗ H P Hᵀ + I ⊗ Y``.

    Derivation. Let ``Q`` be the ``n × n`` orthogonal Helmert matrix whose first row is
    ``1ᵀ/√n`` (its other rows are orthogonal to 1). The transform ``u = (Q ⊗ I₂) y`` has
    unit Jacobian; ``u⁰ = √n ȳ`` and the ``n − 1`` contrasts ``hᵢ`` satisfy
    ``Σᵢ hᵢ hᵢᵀ = Σⱼ yʲ yʲᵀ − n ȳ ȳᵀ = Ȳ``. Since ``Q 1 = √n e₁``, the covariance of u is
    ``n e₁e₁ᵀ ⊗ H P Hᵀ + I ⊗ Y``: ``u⁰ ~ N(√n H x, n S)`` with ``S = H P Hᵀ + Y / n`` and the
    ``hᵢ ~ N(0, Y)`` are independent of it and of each other. With
    ``N(√n ȳ; √n H x, n S) = n^(−d/2) N(ȳ; H x, S)`` and
    ``Σᵢ hᵢᵀ Y⁻¹ hᵢ = tr(Y⁻¹ Ȳ)``::

        log p(Z) = −(d/2) log n + log N(ȳ; H x, S) − ((n − 1)/2) log|2π Y| − ½ tr(Y⁻¹ Ȳ)

    with ``d = 2``, ``ȳ`` the mean and ``Ȳ = Σ (yʲ − ȳ)(yʲ − ȳ)ᵀ`` the scatter of the
    detections.

    With ``extent_uncertain``, the spread ``Y`` is not known but inverse-Wishart with
    ``ν = α + d + 1`` degrees of freedom and mean ``Ŷ = z X + R`` (scale ``Ψ = α Ŷ``; the
    extent's own memory α, so a young or long-coasted extent is loose and a well-fed one
    tends to the plug-in), and is integrated out of the ``m = n − 1`` contrasts (a
    matrix-variate t)::

        log p(h) = −(m d/2) log π + log Γ₂((ν + m)/2) − log Γ₂(ν/2)
                   + (ν/2) log|Ψ| − ((ν + m)/2) log|Ψ + Ȳ|

    with ``Γ₂(a) = √π Γ(a) Γ(a − ½)``. A column of vehicles bending round a corner, whose
    scatter the predicted ellipse no longer fits, then costs a few nats, not hundreds.

    Args:
        est: predicted estimate.
        Z: ``(n, 2)`` detections, ``n ≥ 1``.
        R: ``(2, 2)`` SPD measurement covariance.
        z_scale: scaling factor ``z > 0``.
        extent_uncertain: integrate the spread over its inverse-Wishart uncertainty.

    Returns:
        ``log p(Z)`` (natural log, density in m^(−2n)).

    Raises:
        ValueError: ``n = 0``, wrong shapes, non-finite values, non-SPD R or X,
            ``z_scale ≤ 0``.
    """
    Z, R_entries, z, X_entries = _set_inputs(est, Z, R, z_scale)
    if Z.shape[0] == 0:
        raise ValueError("subset_log_likelihood needs at least one detection")
    return _log_likelihood(est, moments(Z), R_entries, z, X_entries, extent_uncertain)


def moments_log_likelihood(
    est: ExtendedEstimate,
    m: Moments,
    R: np.ndarray,
    z_scale: float = 0.25,
    extent_uncertain: bool = False,
) -> float:
    """:func:`subset_log_likelihood` from the detections' :func:`moments`: the same value,
    to the bit."""
    return _log_likelihood(
        est, m, _spd(R, "R"), _z_scale(z_scale), _estimate(est), extent_uncertain
    )


def _log_likelihood(
    est: ExtendedEstimate, mom: Moments, R: Sym, z: float, X: Sym, extent_uncertain: bool
) -> float:
    """:func:`subset_log_likelihood` on checked inputs (``R`` and ``X`` as ``(a, b, c)``)."""
    (ra, rb, rc), (xa, xb, xc) = R, X
    n, (y0, y1), (ba, bb, bc) = mom
    x, P = est.x, est.P
    ya, yb, yc = z * xa + ra, z * xb + rb, z * xc + rc
    sa = float(P[0, 0]) + ya / n
    sb = 0.5 * float(P[0, 1] + P[1, 0]) + yb / n
    sc = float(P[1, 1]) + yc / n
    det_s = sa * sc - sb * sb
    if not det_s > 0.0:
        raise ValueError("innovation covariance is not positive definite (check P)")
    n0, n1 = y0 - float(x[0]), y1 - float(x[1])
    maha = (sc * n0 * n0 - 2.0 * sb * n0 * n1 + sa * n1 * n1) / det_s
    log_n_mean = -_LOG_2PI - 0.5 * math.log(det_s) - 0.5 * maha
    det_y = ya * yc - yb * yb
    if extent_uncertain:
        m, alpha = n - 1, float(est.alpha)
        nu = alpha + 3.0
        det_psi = alpha * alpha * det_y
        pa, pb, pc = alpha * ya + ba, alpha * yb + bb, alpha * yc + bc
        det_post = pa * pc - pb * pb
        return (
            -math.log(n)
            + log_n_mean
            - m * math.log(math.pi)
            + _log_gamma_2(0.5 * (nu + m))
            - _log_gamma_2(0.5 * nu)
            + 0.5 * nu * math.log(det_psi)
            - 0.5 * (nu + m) * math.log(det_post)
        )
    tr_yinv_scatter = (yc * ba - 2.0 * yb * bb + ya * bc) / det_y
    return (
        -math.log(n)
        + log_n_mean
        - 0.5 * (n - 1) * (2.0 * _LOG_2PI + math.log(det_y))
        - 0.5 * tr_yinv_scatter
    )


def _log_gamma_2(a: float) -> float:
    """ln Γ₂(a) = ½ ln π + ln Γ(a) + ln Γ(a − ½), the bivariate gamma function."""
    return 0.5 * math.log(math.pi) + math.lgamma(a) + math.lgamma(a - 0.5)


def merged(
    estimates: Sequence[ExtendedEstimate], weights: Sequence[float], z_scale: float = 0.25
) -> ExtendedEstimate:
    """One estimate for several tracks of the same object or group (moment matching).

    With normalized weights ``wᵢ`` (e.g. each track's expected detections a scan):

        x = Σ wᵢ xᵢ,   P = Σ wᵢ (Pᵢ + (xᵢ − x)(xᵢ − x)ᵀ),
        X = Σ wᵢ (Xᵢ + (cᵢ − c)(cᵢ − c)ᵀ / z),   α = min αᵢ

    (``c`` the centroid part of ``x``): the detections' spread about the common centroid is
    the weighted spread of each part, ``z Xᵢ``, plus the parts' own offsets.
    """
    if not estimates or len(estimates) != len(weights):
        raise ValueError("one weight per estimate, at least one estimate")
    w = np.asarray(weights, dtype=float)
    if not (np.isfinite(w).all() and (w >= 0).all() and w.sum() > 0):
        raise ValueError(f"weights: must be finite, ≥ 0 and not all 0, got {weights!r}")
    z = _z_scale(z_scale)
    w = w / w.sum()
    xs = np.stack([e.x for e in estimates])
    x = w @ xs
    d = xs - x
    P = sum(wi * (e.P + np.outer(di, di)) for wi, e, di in zip(w, estimates, d, strict=True))
    X = sum(
        wi * (e.X + np.outer(di[:2], di[:2]) / z) for wi, e, di in zip(w, estimates, d, strict=True)
    )
    return ExtendedEstimate(
        x=x,
        P=0.5 * (P + P.T),
        X=0.5 * (X + X.T),
        alpha=min(e.alpha for e in estimates),
    )
