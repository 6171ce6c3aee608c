"""Similarity ("affine") registration of two 2-D point sets (paper 000, section 4.2).

The paper's affine registration ``G_r`` is a similarity: rotation ``R(θ)``, scale ``s > 0``
and translation ``T`` (eq. 13),

    y = G_r(x) = T + s R(θ) x,        R(θ) = [[cos θ, −sin θ], [sin θ, cos θ]],

and a detection is ``y_j = G_r(x_i) + b_i`` with ``b_i ~ N(0, σ² I)`` (eq. 14). Writing
``a = [s cos θ, s sin θ]'`` makes it linear in ``r = [T', a']'`` (eq. 17),

    y_j = C_j r,    C_j = [[1, 0, x¹, −x²], [0, 1, x², x¹]],

so the generalized least-squares estimator (GLSE, eqs. 18-19) is
``r̂ = (C' P⁻¹ C)⁻¹ C' P⁻¹ Y``. :func:`fit_similarity` solves those normal equations in
closed form (see its docstring); it is Umeyama's estimator restricted to proper rotations.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

__all__ = ["Similarity", "fit_similarity", "rotation", "wrap_angle"]

_J = np.array([[0.0, -1.0], [1.0, 0.0]])  # ỹ @ _J = [ỹ², −ỹ¹]


def rotation(theta: float) -> np.ndarray:
    """The rotation matrix ``R(θ) = [[cos θ, −sin θ], [sin θ, cos θ]]``."""
    c, s = math.cos(theta), math.sin(theta)
    return np.array([[c, -s], [s, c]])


def wrap_angle(theta: float) -> float:
    """``θ`` wrapped to ``(−π, π]``."""
    w = math.remainder(theta, 2.0 * math.pi)  # in [−π, π]
    return math.pi if w <= -math.pi else w


@dataclass(frozen=True)
class Similarity:
    """A similarity registration ``G(x) = s R(θ) x + t`` (eq. 13).

    ``s`` the scale (> 0), ``theta`` the rotation in radians, wrapped to ``(−π, π]``,
    ``t`` the ``(2,)`` translation.
    """

    s: float
    theta: float
    t: np.ndarray

    def __post_init__(self) -> None:
        if not (math.isfinite(self.s) and self.s > 0):
            raise ValueError(f"s: must be a finite number > 0, got {self.s!r}")
        if not math.isfinite(self.theta):
            raise ValueError(f"theta: must be finite, got {self.theta!r}")
        t = np.array(self.t, dtype=float).reshape(2)
        if not np.isfinite(t).all():
            raise ValueError(f"t: must be finite, got {t.tolist()}")
        t.setflags(write=False)
        object.__setattr__(self, "s", float(self.s))
        object.__setattr__(self, "theta", wrap_angle(float(self.theta)))
        object.__setattr__(self, "t", t)

    @property
    def matrix(self) -> np.ndarray:
        """The linear part ``s R(θ)``, ``(2, 2)``."""
        return self.s * rotation(self.theta)

    def apply(self, x: np.ndarray) -> np.ndarray:
        """``G(x) = s R(θ) x + t`` for each row of ``x`` (``(k, 2)`` → ``(k, 2)``; a ``(2,)``
        point gives a ``(2,)`` point)."""
        x = np.asarray(x, dtype=float)
        return x @ self.matrix.T + self.t

    def inverse(self) -> Similarity:
        """``G⁻¹(y) = s⁻¹ R(−θ) (y − t)``, itself a similarity."""
        inv = rotation(-self.theta) / self.s
        return Similarity(1.0 / self.s, -self.theta, -(inv @ self.t))


def fit_similarity(x: np.ndarray, y: np.ndarray, w: np.ndarray | None = None) -> Similarity:
    """The GLSE (eq. 19) of the similarity ``y ≈ s R(θ) x + t`` over ``k ≥ 2`` pairs of rows
    of the ``(k, 2)`` arrays ``x`` and ``y``.

    With ``P_bb = σ²/wᵢ · I`` for pair ``i`` (``w`` optional non-negative weights, all ones
    by default: then σ cancels and this is the paper's ``P_bb = σ² I``), eq. 19 minimizes
    ``J = Σᵢ wᵢ ‖yᵢ − t − A xᵢ‖²`` with ``A = [[a₁, −a₂], [a₂, a₁]]`` (eq. 18). Its normal
    equations ``C'P⁻¹C r = C'P⁻¹Y`` separate once the points are centred on their weighted
    means ``x̄ = Σ wᵢ xᵢ / Σ wᵢ`` and ``ȳ`` (``x̃ = x − x̄``, ``ỹ = y − ȳ``):

        a₁ = Σ wᵢ (x̃ᵢ¹ ỹᵢ¹ + x̃ᵢ² ỹᵢ²) / S,   a₂ = Σ wᵢ (x̃ᵢ¹ ỹᵢ² − x̃ᵢ² ỹᵢ¹) / S,
        S = Σ wᵢ ‖x̃ᵢ‖²,   t = ȳ − A x̄,

    and ``s = ‖a‖``, ``θ = atan2(a₂, a₁)``. Raises ``ValueError`` for ``k < 2``, for fewer than
    two pairs of positive weight, for coincident ``x`` (``S = 0``: the rotation and scale are
    not determined) and for a zero fitted scale (all ``y`` coincide).
    """
    x = np.asarray(x, dtype=float)
    y = np.asarray(y, dtype=float)
    if x.ndim != 2 or x.shape[1] != 2 or y.shape != x.shape:
        raise ValueError(f"x, y: must both be (k, 2), got {x.shape} and {y.shape}")
    k = x.shape[0]
    if k < 2:
        raise ValueError(f"need k >= 2 pairs for a similarity, got {k}")
    if not (math.isfinite(float(x.sum())) and math.isfinite(float(y.sum()))):
        raise ValueError("x, y: must be finite")
    if w is None:
        W = float(k)
        xm = x.sum(axis=0) / W
        ym = y.sum(axis=0) / W
        xc = x - xm
        yc = y - ym
        wxc = xc
    else:
        wv = np.asarray(w, dtype=float).reshape(-1)
        if wv.shape[0] != k or not np.isfinite(wv).all() or (wv < 0).any():
            raise ValueError(f"w: must be {k} finite weights >= 0")
        if np.count_nonzero(wv) < 2:
            raise ValueError("w: need at least two pairs of positive weight")
        W = float(wv.sum())
        xm = (wv @ x) / W
        ym = (wv @ y) / W
        xc = x - xm
        yc = y - ym
        wxc = xc * wv[:, None]
    sxx = float(np.vdot(wxc, xc))  # S = Σ wᵢ ‖x̃ᵢ‖²
    scale_x = float(np.abs(x).max()) or 1.0
    if sxx <= (1e-12 * scale_x) ** 2 * W:
        raise ValueError("x: the points coincide, rotation and scale are not determined")
    a1 = float(np.vdot(wxc, yc)) / sxx  # Σ wᵢ (x̃¹ỹ¹ + x̃²ỹ²) / S
    a2 = float(np.vdot(wxc, yc @ _J)) / sxx  # Σ wᵢ (x̃¹ỹ² − x̃²ỹ¹) / S
    s = math.hypot(a1, a2)
    if not s > 0:
        raise ValueError("y: the points coincide, the fitted scale is zero")
    A = np.array([[a1, -a2], [a2, a1]])
    return Similarity(s, math.atan2(a2, a1), ym - A @ xm)
