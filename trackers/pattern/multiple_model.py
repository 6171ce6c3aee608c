"""Multiple-model estimators for a maneuvering and bending extended target.

Two algorithms with the same interface, over the layered mode set of paper 000 (Dezert,
SPIE 1998) and paper 001 (Li and Dezert, the layered multiple-model algorithm): a
*principal* layer (motion of the reference point, :class:`~trackers.pattern.bending.
PrincipalModel`), a *proper* layer (attitude motion, :class:`~trackers.pattern.bending.
ProperModel`) and a *shape* layer (the reference point pattern in effect).

- :func:`imm_step`: the full IMM of paper 000 (eqs. 7-12) over every combination
  ``(g, p, s)``, ``r_g r_p r_s`` filters, with the Markov transition matrix ``π_IJ`` of eq. 5
  over the global modes (:attr:`BendingModes.transition`).
- :func:`lmm_step`: the layered MM of paper 001, one IMM bank per layer
  (``r_g + r_p + r_s`` filters) coupled by the time-varying transition probabilities of
  eqs. 7, 10 (the 2-layer form) / 23, 24 (the N-layer form), optionally iterated (eq. 12).

Global modes are numbered in C order of ``(g, p, s)``: ``I = (g r_p + p) r_s + s``.

Transition matrix (paper 000, section 5). The diagonal is 0.95 and an off-diagonal entry
depends on how many *elementary* modes (layers) change between ``I`` and ``J``: 0.012 for
one, 0.004 for two, 0.002 for three (the paper's example: ``[1,1,2] → [1,1,1]`` is 0.012,
``→ [1,2,1]`` 0.004). With 2 modes per layer each row has 3, 3 and 1 such entries and sums
to ``0.95 + 0.036 + 0.012 + 0.002 = 1`` exactly. For other layer sizes the counts differ;
we keep the diagonal and scale the three off-diagonal values by a common factor so that each
row sums to 1 (:func:`transition_by_changes`; the factor is 1 for 2×2×2).

Per-filter code (both algorithms, so the timing comparison is fair): mixing (eqs. 7-8),
prediction :func:`~trackers.pattern.bending.predict_mixture` (eq. 9), measurement
validation and association once per shape mode per scan, shared by every filter of that
shape (step 3), the EKF update :func:`~trackers.pattern.bending.update_batch` (eq. 10), mode
probabilities (eq. 11) and combination (eq. 12), all vectorized over the filters. The
cycle calls the unvalidated cores of :mod:`trackers.pattern.bending` (inputs are checked
once per step), the model matrices are cached per ``dt``, and the small matrix algebra is
closed form (3x3 inverse by cofactors, 2x2 Cholesky) or batched ``matmul`` rather than
``einsum`` / LAPACK calls, whose fixed cost per call dominated at these sizes.

Likelihood (our form, needed because shape modes match different numbers of points). With
``m`` points in the shape's pattern of which ``p`` are matched::

    Λ = N(ν; 0, S) · (P_d / λ)^p · (1 − P_d)^(m − p)

``λ`` the clutter density (per m²). This is the likelihood of "these ``p`` detections are
the target's matched points, its other ``m − p`` points are missed and every other
detection is clutter", divided by that of "every detection is clutter" (the Poisson clutter
terms of the unmatched detections cancel), so it compares any two association hypotheses of
the same scan. ``p = 0`` gives ``(1 − P_d)^m``. ``p = 1`` uses the Schmidt centre-only
update of :mod:`trackers.pattern.bending`; its ``N`` still carries the attitude uncertainty.

Layered MM, as implemented (reconstruction of paper 001, section 3):

- Each bank holds full-state filters (all of ``[x, vx, y, vy, α, α̇]``), conditioned on its
  own layer's mode; the other layers enter as follows. The other *dynamic* layer moves the
  filter with the moment-matched mixture of its models weighted by that layer's predicted
  mode probabilities (total probability; paper 001's ``f(x̂, ŝ_{k|k−1})`` of eqs. 13, 15 with
  the mode estimate taken as a distribution). Likewise the principal and proper banks'
  filters are updated under the shape layer's predicted probabilities ``c̄^s``: once per
  shape with that shape's (shared) matched points, then collapsed with weights
  ``c̄^s_s Λ_s`` (so ``Λ = Σ_s c̄^s_s Λ_s``). This keeps ``r_g + r_p + r_s`` filters (mixing
  and prediction) but makes ``(r_g + r_p) r_s + r_s`` EKF updates, still fewer than the
  IMM's ``r_g r_p r_s`` for 3 modes a layer; a first version used the most probable shape
  only and lost the centre for a scan or two at every shape switch.
  the shape bank moves with both dynamic layers' mixtures.
- Exchange of estimates (paper 001, eqs. 13-16: each layer's filters use the *other*
  layers' estimates ``x̂^p``, ``x̂^g`` for the parts they do not own). After mixing, every
  filter's part of a dynamic layer with more than one mode that it does not own is replaced
  by that layer's combined estimate of the previous scan (the previous output): a principal
  filter takes the output's proper part, a proper filter the output's principal part (with
  its own proper part), a shape filter both. The replacement keeps the filter's own
  cross-covariance structure: the foreign part ``y`` is mapped by ``M (y − E y) + x̂`` with
  ``M = L̂ L⁻¹`` (Cholesky factors of the target and the old covariance), a linear map, so
  the joint stays positive semi-definite and has exactly the wanted marginal. A part whose
  layer has a single mode is kept (it is already conditioned on that layer's only model,
  as in the IMM; this keeps the IMM/LMM agreement of the degenerate cases exact).
  Without the exchange each bank carried its own estimate of the other layers' parts,
  moved with the moment-matched *mixture* of their models: after a wrong pair at the
  rotation onset (Monte Carlo run 75, k = 18) the proper layer briefly favoured NV, the
  shape filter of the true pattern fell 7° behind the proper bank's attitude, lost the
  shape mode to the empty pattern at k = 20 and the track was lost after the CT→CV switch
  (42 m off at k = 30; the 100-run LMM RMSE was 8.4 m against the IMM's 0.5 m).
- All layers use *predicted* probabilities and the previous scan's estimates of the other
  layers (``Z^{k−1}``), where paper 001 (eqs. 15-16, 18) lets the proper layer use the
  principal layer's ``x̂^g_{k|k}`` and ``ŝ^g_{k|k}`` already updated with ``Z_k``. That way
  the banks are independent within a scan and run as one vectorized batch (numpy's
  per-call overhead dominates here; three sequential passes would cost more than the
  8-model IMM). The transition probabilities themselves are the paper's (they only use
  ``Z^{k−1}``).
- Output: the principal state ``x_g`` and its covariance from the principal bank's
  combination (eq. 12), the proper state ``x_p`` and its covariance from the proper bank's;
  the cross-covariance is the principal bank's, mapped onto the proper bank's marginal as
  in the exchange (positive semi-definite by construction). The shape bank gives the shape
  probabilities.

Time-varying transition probabilities (eqs. 23-24, :func:`layered_transition_matrices`).
For layers ``1..N`` in order (here principal, proper, shape), with ``μ^q`` the layers'
probabilities at ``k − 1`` and ``π̃^q`` those already computed this cycle::

    π̃^r_ij = Σ_{n, m} P{s^r_k = j | s^r_{k−1} = i, S^{≠r}_{k−1} = n, S^{<r}_k = m}
                        · Π_{q<r} π̃^q_{n_q m_q} μ^q_{n_q} · Π_{q>r} μ^q_{n_q}

(eq. 7 for ``r = 1``, where only ``n`` appears; eq. 10 for ``r = 2`` of 2 layers). The
design probabilities ``P{· | ·}`` are conditionals of the global ``π_IJ``: the joint
transition summed over the lower layers' new modes and normalized over ``j``. The joint
probability of the other layers is approximated by the product of their marginals (the LMM
keeps no joint). ``iterations > 0`` adds passes in which every layer conditions on all the
other layers at ``k − 1`` and ``k`` (eq. 12 generalized), weighted with the latest ``π̃^q``.
A conditional with zero denominator (impossible condition) is replaced by the uniform
distribution. If ``π_IJ`` factors into per-layer matrices (``π = π^1 ⊗ … ⊗ π^N``) every pass
returns exactly those factors.

Mode probabilities are floored at :data:`trackers.filters.imm.MU_FLOOR` and renormalized
(per bank); likelihoods are handled as logarithms.

``trackers/`` is pure computation: numpy and the standard library; no clock.
"""

from __future__ import annotations

import functools
import math
import string
from collections.abc import Callable, Mapping, Sequence
from dataclasses import dataclass
from types import MappingProxyType

import numpy as np

from trackers.filters.imm import MU_FLOOR
from trackers.pattern.bending import (
    STATE_DIM,
    PrincipalModel,
    ProperModel,
    _check_R,
    _model_stacks,
    _predict_core,
    _update_core,
)

__all__ = [
    "Associate",
    "BendingModes",
    "MMEstimate",
    "StepInfo",
    "factored_transition",
    "imm_step",
    "initial_estimate",
    "layered_transition_matrices",
    "lmm_step",
    "paper_modes",
    "transition_by_changes",
    "validation_gate",
]

Associate = Callable[[int, np.ndarray, np.ndarray], np.ndarray]
"""``associate(shape_index, x_pred (6,), P_pred (6, 6)) -> (p, 2) int`` pairs ``(i, j)``:
pattern point ``i`` of that shape mode is detection ``j`` of the scan (step 3)."""

PAPER_OFF_DIAGONAL = (0.012, 0.004, 0.002)
"""Paper 000's off-diagonal transition probabilities for 1, 2 and 3 elementary changes."""


# --------------------------------------------------------------------------- transitions


def _change_counts(sizes: Sequence[int]) -> np.ndarray:
    """``(M, M)`` number of layers whose mode differs between global modes I and J."""
    grids = np.indices(tuple(sizes)).reshape(len(sizes), -1)  # (N, M)
    return (grids[:, :, None] != grids[:, None, :]).sum(axis=0)


def transition_by_changes(
    sizes: Sequence[int],
    diagonal: float = 0.95,
    off_diagonal: Sequence[float] = PAPER_OFF_DIAGONAL,
) -> np.ndarray:
    """Global transition matrix ``π_IJ`` (eq. 5) built as in paper 000, section 5.

    ``π_II = diagonal``; for ``I ≠ J`` with ``c`` elementary (per-layer) mode changes,
    ``π_IJ = κ · off_diagonal[c − 1]``, with ``κ`` the one factor that makes every row sum
    to 1 (all rows have the same numbers of 1-, 2-, … change neighbours, so one ``κ`` fits
    all rows; ``κ = 1`` for the paper's 2×2×2 case). A single global mode gives ``[[1]]``.

    Args:
        sizes: number of modes per layer, e.g. ``(2, 2, 2)``.
        diagonal: ``π_II`` in ``(0, 1]``.
        off_diagonal: values for 1, 2, … changes (at least one per layer), ``> 0``.
    """
    sizes = tuple(int(s) for s in sizes)
    if not sizes or min(sizes) < 1:
        raise ValueError(f"sizes: at least one layer, each with >= 1 mode, got {sizes}")
    if len(off_diagonal) < len(sizes) or min(off_diagonal) <= 0:
        raise ValueError("off_diagonal: one positive value per possible number of changes")
    if not (0.0 < diagonal <= 1.0):
        raise ValueError(f"diagonal must be in (0, 1], got {diagonal}")
    changes = _change_counts(sizes)
    M = changes.shape[0]
    if M == 1:
        return np.ones((1, 1))
    values = np.concatenate([[0.0], np.asarray(off_diagonal, dtype=float)])
    raw = values[changes]
    kappa = (1.0 - diagonal) / raw[0].sum()
    Pi = raw * kappa
    np.fill_diagonal(Pi, diagonal)
    return Pi


def factored_transition(*layer_matrices: np.ndarray) -> np.ndarray:
    """``π = π^1 ⊗ π^2 ⊗ …``: the global matrix of independently switching layers."""
    Pi = np.ones((1, 1))
    for m in layer_matrices:
        Pi = np.kron(Pi, np.asarray(m, dtype=float))
    return Pi


def _letters(n: int) -> tuple[str, str]:
    if 2 * n > 26:
        raise ValueError("at most 13 layers")
    return string.ascii_lowercase[:n], string.ascii_lowercase[n : 2 * n]


@functools.lru_cache(maxsize=64)
def _tpm_plan(key: bytes, sizes: tuple[int, ...]) -> tuple[list[tuple], list[tuple]]:
    """The design conditionals and einsum expressions of :func:`layered_transition_matrices`
    for both kinds of pass (they depend on ``π`` and the sizes only; cached)."""
    N = len(sizes)
    T = np.frombuffer(key, dtype=float).reshape(sizes + sizes)
    old, new = _letters(N)
    plans: tuple[list[tuple], list[tuple]] = ([], [])
    for kind in (0, 1):
        for r in range(N):
            if kind == 0:  # eqs. 23-24: condition on the higher layers' new modes only
                A = T.sum(axis=tuple(N + q for q in range(r + 1, N))) if r + 1 < N else T
                cond_new = new[: r + 1]
                others_new = frozenset(range(r))
            else:  # eq. 12: condition on every other layer at k - 1 and k
                A = T
                cond_new = new
                others_new = frozenset(q for q in range(N) if q != r)
            denom = A.sum(axis=N + r, keepdims=True)
            with np.errstate(invalid="ignore", divide="ignore"):
                C = np.where(denom > 0, A / np.where(denom > 0, denom, 1.0), 1.0 / sizes[r])
            subs = [old + cond_new]
            for q in range(N):
                if q == r:
                    continue
                subs.append(old[q])
                if q in others_new:
                    subs.append(old[q] + new[q])
            expr = ",".join(subs) + "->" + old[r] + new[r]
            C.setflags(write=False)
            plans[kind].append((C, expr, others_new))
    return plans


def layered_transition_matrices(
    transition: np.ndarray,
    sizes: Sequence[int],
    layer_probabilities: Sequence[np.ndarray],
    iterations: int = 0,
) -> tuple[np.ndarray, ...]:
    """Time-varying per-layer transition matrices ``π̃^r`` of the LMM (eqs. 7, 10, 12, 23, 24).

    See the module docstring for the formula. Args: the global ``transition (M, M)`` over
    modes in C order of the layers, the layer ``sizes``, the layers' mode probabilities at
    ``k − 1`` (one vector per layer) and the number of extra ``iterations`` (eq. 12).
    Returns one ``(r, r)`` row-stochastic matrix per layer.
    """
    sizes = tuple(int(s) for s in sizes)
    N = len(sizes)
    M = math.prod(sizes)
    Pi = np.asarray(transition, dtype=float)
    if Pi.shape != (M, M):
        raise ValueError(f"transition must be ({M}, {M}) for sizes {sizes}, got {Pi.shape}")
    mus = [
        np.asarray(m, dtype=float).reshape(s)
        for m, s in zip(layer_probabilities, sizes, strict=True)
    ]
    plan = _tpm_plan(Pi.tobytes(), sizes)
    # the first sweep (eqs. 23-24) reads only the layers before r, computed before it
    tilde: list[np.ndarray] = [np.empty((0, 0))] * N
    for sweep in range(int(iterations) + 1):
        for r in range(N):
            C, expr, others_new = plan[min(sweep, 1)][r]
            operands: list[np.ndarray] = [C]
            for q in range(N):
                if q == r:
                    continue
                operands.append(mus[q])
                if q in others_new:
                    operands.append(tilde[q])
            out = np.einsum(expr, *operands)
            tilde[r] = out / out.sum(axis=1, keepdims=True)
    return tuple(tilde)


# --------------------------------------------------------------------------- modes


def _pattern(name: str, points: np.ndarray) -> np.ndarray:
    arr = np.array(points, dtype=float)
    if arr.ndim != 2 or arr.shape[1] != 2 or arr.shape[0] < 1 or not np.all(np.isfinite(arr)):
        raise ValueError(f"shape {name!r}: pattern must be a finite (m, 2) array, m >= 1")
    arr.setflags(write=False)
    return arr


@dataclass(frozen=True, eq=False)
class BendingModes:
    """The layered mode set and the global transition matrix.

    Attributes:
        principal: the principal models (layer 1).
        proper: the proper models (layer 2).
        shapes: shape name → ``(m, 2)`` reference pattern (layer 3), in order.
        transition: ``(M, M)`` global ``π_IJ`` over modes ``(g, p, s)`` in C order; rows
            sum to 1. Default: :func:`transition_by_changes` (paper 000).
    """

    principal: tuple[PrincipalModel, ...]
    proper: tuple[ProperModel, ...]
    shapes: Mapping[str, np.ndarray]
    transition: np.ndarray | None = None

    def __post_init__(self) -> None:
        object.__setattr__(self, "principal", tuple(self.principal))
        object.__setattr__(self, "proper", tuple(self.proper))
        shapes = {str(k): _pattern(str(k), v) for k, v in dict(self.shapes).items()}
        object.__setattr__(self, "shapes", MappingProxyType(shapes))
        if not (self.principal and self.proper and shapes):
            raise ValueError("BendingModes: every layer needs at least one mode")
        Pi = (
            transition_by_changes(self.sizes)
            if self.transition is None
            else np.array(self.transition, dtype=float)
        )
        M = self.n_models
        if Pi.shape != (M, M) or not np.all(np.isfinite(Pi)) or np.any(Pi < 0):
            raise ValueError(f"transition must be a finite non-negative ({M}, {M}) matrix")
        if not np.allclose(Pi.sum(axis=1), 1.0, rtol=0, atol=1e-9):
            raise ValueError("transition: every row must sum to 1")
        Pi.setflags(write=False)
        object.__setattr__(self, "transition", Pi)
        arrays = tuple(shapes.values())
        object.__setattr__(self, "_patterns", arrays)
        radii = np.array([float(np.sqrt((a**2).sum(axis=1)).max()) for a in arrays])
        radii.setflags(write=False)
        object.__setattr__(self, "_radii", radii)

    @property
    def sizes(self) -> tuple[int, int, int]:
        """``(r_g, r_p, r_s)``."""
        return len(self.principal), len(self.proper), len(self.shapes)

    @property
    def n_models(self) -> int:
        """``M = r_g r_p r_s``, the full IMM's number of filters."""
        r_g, r_p, r_s = self.sizes
        return r_g * r_p * r_s

    @property
    def layers(self) -> tuple[tuple[str, ...], ...]:
        """Mode names per layer: principal, proper, shape."""
        return (
            tuple(m.name for m in self.principal),
            tuple(m.name for m in self.proper),
            tuple(self.shapes),
        )

    @property
    def patterns(self) -> tuple[np.ndarray, ...]:
        """The shape patterns in shape-index order."""
        return self._patterns  # type: ignore[attr-defined]

    @property
    def radii(self) -> np.ndarray:
        """``(r_s,)`` each pattern's radius ``max_i |q_i|`` (m)."""
        return self._radii  # type: ignore[attr-defined]

    def global_modes(self) -> np.ndarray:
        """``(M, 3)`` the ``(g, p, s)`` indices of each global mode, in order."""
        return np.indices(self.sizes).reshape(3, -1).T.copy()

    def layer_transitions(
        self, layer_probabilities: Sequence[np.ndarray] | None = None, iterations: int = 0
    ) -> tuple[np.ndarray, ...]:
        """The LMM's per-layer matrices :func:`layered_transition_matrices` at the given
        layer probabilities (uniform by default)."""
        if layer_probabilities is None:
            layer_probabilities = [np.full(s, 1.0 / s) for s in self.sizes]
        return layered_transition_matrices(
            self.transition, self.sizes, layer_probabilities, iterations
        )


def paper_modes(
    patterns: Mapping[str, np.ndarray],
    *,
    turn_rate: float = math.radians(-3.0),
    extra_principal: Sequence[PrincipalModel] = (),
    extra_proper: Sequence[ProperModel] = (),
) -> BendingModes:
    """Paper 000's mode set: principal CV (σ = 0.004 m/s²) and CT at ``turn_rate``
    (σ = 0.001 m/s²), proper NV (rate 0) and CV (estimated rate), both σ = 0.01 rad/s²,
    the given shapes, and :func:`transition_by_changes`. ``extra_*`` append models."""
    principal = (
        PrincipalModel("CV", 0.0, 0.004),
        PrincipalModel("CT", turn_rate, 0.001),
        *extra_principal,
    )
    proper = (ProperModel("NV", 0.0, 0.01), ProperModel("CV", None, 0.01), *extra_proper)
    return BendingModes(principal, proper, patterns)


# --------------------------------------------------------------------------- gate


def validation_gate(
    detections: np.ndarray,
    x_pred: np.ndarray,
    P_pred: np.ndarray,
    R: np.ndarray,
    radius: float,
    *,
    probability: float = 0.999,
) -> np.ndarray:
    """Indices of the detections in the size-aware gate of a shape mode (step 3).

    A detection ``z`` is kept if, once brought ``ρ = radius`` closer to the predicted
    centre ``ĉ = (x̂, ŷ)``, it passes the chi-square test of the centre::

        d = z − ĉ,   d' = d · max(0, 1 − ρ/|d|),   d'ᵀ (P_c + R)⁻¹ d' ≤ γ

    with ``P_c`` the predicted centre covariance and ``γ = −2 ln(1 − probability)`` (the
    2-degree-of-freedom chi-square quantile). This is the centre's gate grown by the
    pattern's radius (a Minkowski sum: every point of the pattern, whatever the attitude,
    lies within ``ρ`` of the centre).
    """
    z = np.asarray(detections, dtype=float).reshape(-1, 2)
    x_pred = np.asarray(x_pred, dtype=float)
    P_pred = np.asarray(P_pred, dtype=float)
    if not (0.0 < probability < 1.0):
        raise ValueError(f"probability must be in (0, 1), got {probability}")
    S = P_pred[np.ix_((0, 2), (0, 2))] + np.asarray(R, dtype=float)
    gamma = -2.0 * math.log1p(-probability)
    d = z - np.array([x_pred[0], x_pred[2]])
    dist = np.sqrt((d * d).sum(axis=1))
    shrink = np.maximum(0.0, 1.0 - float(radius) / np.maximum(dist, 1e-300))
    dd = d * shrink[:, None]
    a, b, c = S[0, 0], 0.5 * (S[0, 1] + S[1, 0]), S[1, 1]
    det = a * c - b * b
    maha = (c * dd[:, 0] ** 2 - 2 * b * dd[:, 0] * dd[:, 1] + a * dd[:, 1] ** 2) / det
    return np.flatnonzero(maha <= gamma)


# --------------------------------------------------------------------------- estimates


def _readonly(a: np.ndarray) -> np.ndarray:
    a = np.array(a, dtype=float)
    a.setflags(write=False)
    return a


@dataclass(frozen=True, eq=False)
class MMEstimate:
    """Output and internal state of either estimator after a scan.

    Attributes:
        x: ``(6,)`` combined estimate ``[x, vx, y, vy, α, α̇]``.
        P: ``(6, 6)`` its covariance.
        layer_probabilities: ``(μ^g (r_g,), μ^p (r_p,), μ^s (r_s,))`` mode probabilities
            per layer (the IMM's marginals; the LMM's banks).
        filter_x: ``(K, 6)`` mode-conditioned estimates (IMM: ``K = M`` in global-mode
            order; LMM: ``K = r_g + r_p + r_s``, principal bank, proper bank, shape bank).
        filter_P: ``(K, 6, 6)``.
        filter_probabilities: ``(K,)`` IMM: the global ``μ_J``; LMM: the banks' ``μ``
            concatenated (each bank sums to 1).
        algorithm: ``"imm"`` or ``"lmm"``.
    """

    x: np.ndarray
    P: np.ndarray
    layer_probabilities: tuple[np.ndarray, ...]
    filter_x: np.ndarray
    filter_P: np.ndarray  # noqa: N815 (matrix name, as P)
    filter_probabilities: np.ndarray
    algorithm: str

    def __post_init__(self) -> None:
        for name in ("x", "P", "filter_x", "filter_P", "filter_probabilities"):
            object.__setattr__(self, name, _readonly(getattr(self, name)))
        object.__setattr__(
            self, "layer_probabilities", tuple(_readonly(m) for m in self.layer_probabilities)
        )
        K = self.filter_x.shape[0]
        if (
            self.x.shape != (STATE_DIM,)
            or self.P.shape != (STATE_DIM, STATE_DIM)
            or self.filter_x.shape != (K, STATE_DIM)
            or self.filter_P.shape != (K, STATE_DIM, STATE_DIM)
            or self.filter_probabilities.shape != (K,)
        ):
            raise ValueError("MMEstimate: inconsistent shapes")
        if self.algorithm not in ("imm", "lmm"):
            raise ValueError(f"MMEstimate.algorithm must be 'imm' or 'lmm', got {self.algorithm!r}")


@dataclass(frozen=True, eq=False)
class StepInfo:
    """What happened in a scan.

    Attributes:
        pairs: per shape mode, the ``(p, 2)`` matched pairs used (``None`` for a shape no
            filter needed this scan).
        log_likelihoods: ``(K,)`` ``ln Λ`` of every filter (the comparable likelihood).
        predicted_layer_probabilities: per layer, ``μ^-`` before the update.
        layer_transitions: per layer, the transition matrix used (IMM: the global ``π``
            as the single entry; LMM: ``π̃^g, π̃^p, π̃^s``).
        associations: number of calls to ``associate`` (at most one per shape mode).
    """

    pairs: tuple[np.ndarray | None, ...]
    log_likelihoods: np.ndarray
    predicted_layer_probabilities: tuple[np.ndarray, ...]
    layer_transitions: tuple[np.ndarray, ...]
    associations: int


def initial_estimate(
    modes: BendingModes,
    x: np.ndarray,
    P: np.ndarray,
    *,
    algorithm: str = "imm",
    layer_probabilities: Sequence[np.ndarray] | None = None,
) -> MMEstimate:
    """Every filter at ``(x, P)``; mode probabilities uniform per layer unless given (the
    IMM's global ``μ`` is then their product)."""
    x = np.asarray(x, dtype=float).reshape(STATE_DIM)
    P = np.asarray(P, dtype=float).reshape(STATE_DIM, STATE_DIM)
    sizes = modes.sizes
    if layer_probabilities is None:
        layer_probabilities = [np.full(s, 1.0 / s) for s in sizes]
    mus = [
        np.asarray(m, dtype=float).reshape(s)
        for m, s in zip(layer_probabilities, sizes, strict=True)
    ]
    mus = [m / m.sum() for m in mus]
    if algorithm == "imm":
        mu = np.einsum("a,b,c->abc", *mus).reshape(-1)
    elif algorithm == "lmm":
        mu = np.concatenate(mus)
    else:
        raise ValueError(f"algorithm must be 'imm' or 'lmm', got {algorithm!r}")
    K = mu.size
    return MMEstimate(
        x=x,
        P=P,
        layer_probabilities=tuple(mus),
        filter_x=np.repeat(x[None], K, axis=0),
        filter_P=np.repeat(P[None], K, axis=0),
        filter_probabilities=mu,
        algorithm=algorithm,
    )


# --------------------------------------------------------------------------- shared cycle


def _floor(mu: np.ndarray, starts: np.ndarray) -> np.ndarray:
    mu = np.maximum(mu, MU_FLOOR)
    return mu / np.repeat(np.add.reduceat(mu, starts), np.diff(np.append(starts, mu.size)))


def _mix(
    xs: np.ndarray, Ps: np.ndarray, mu: np.ndarray, Pi: np.ndarray
) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Eqs. 7-8 over ``K`` filters with a (block-diagonal) ``Pi (K, K)``:
    ``c̄_j = Σ_i π_ij μ_i``, ``μ_{i|j} = π_ij μ_i / c̄_j``, ``x0_j = Σ_i μ_{i|j} x_i``,
    ``P0_j = Σ_i μ_{i|j} (P_i + (x_i − x0_j)(x_i − x0_j)ᵀ)``."""
    joint = Pi * mu[:, None]
    c_bar = joint.sum(axis=0)
    w = joint / c_bar
    wT = w.T  # (j, i)
    x0 = wT @ xs
    K, n = xs.shape
    d = xs[None, :, :] - x0[:, None, :]  # (j, i, n)
    P0 = (wT @ Ps.reshape(K, n * n)).reshape(-1, n, n)
    P0 += (np.swapaxes(d, 1, 2) * wT[:, None, :]) @ d
    return x0, P0, c_bar


def _combine(xs: np.ndarray, Ps: np.ndarray, w: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Eq. 12: ``x̂ = Σ w_j x_j``, ``P̂ = Σ w_j (P_j + (x_j − x̂)(x_j − x̂)ᵀ)`` (Σ w = 1)."""
    x = w @ xs
    d = xs - x
    n = xs.shape[1]
    return x, (w @ Ps.reshape(-1, n * n)).reshape(n, n) + (d.T * w) @ d


def _pairs_array(pairs: np.ndarray, m: int, n: int, shape_index: int) -> np.ndarray:
    arr = np.asarray(pairs, dtype=np.int64).reshape(-1, 2)
    if arr.size and (
        arr[:, 0].min() < 0 or arr[:, 0].max() >= m or arr[:, 1].min() < 0 or arr[:, 1].max() >= n
    ):
        raise ValueError(f"associate({shape_index}): pair indices out of range")
    return arr


def _cycle(
    est: MMEstimate,
    Pi: np.ndarray,
    starts: np.ndarray,
    weights: Callable[[np.ndarray], tuple[np.ndarray, np.ndarray, np.ndarray]],
    sources: Callable[[int], np.ndarray],
    dt: float,
    detections: np.ndarray,
    R: np.ndarray,
    associate: Associate,
    modes: BendingModes,
    pd: float,
    clutter_density: float,
    condition: Callable[[np.ndarray, np.ndarray], tuple[np.ndarray, np.ndarray]] | None = None,
):
    """One cycle of eqs. 7-12 over all filters, banks given by ``starts`` (first filter of
    each group normalized together).

    ``weights(c̄) -> (w_g (K, r_g), w_p (K, r_p), w_s (K, r_s))`` gives each filter's
    probabilities of the principal, proper and shape models (one-hot for a filter
    conditioned on that layer). A filter with several shapes is updated once per shape
    ``s`` with ``w_s > 0`` and collapsed: ``Λ_k = Σ_s w_ks Λ_ks``, and the moment-matched
    mixture of the per-shape updates with weights ``w_ks Λ_ks / Λ_k``. ``sources(s)``: the
    filters whose combined prediction feeds shape ``s``'s association."""
    if not (0.0 < pd <= 1.0):
        raise ValueError(f"pd must be in (0, 1], got {pd}")
    if not (math.isfinite(clutter_density) and clutter_density > 0):
        raise ValueError(f"clutter_density must be finite and > 0, got {clutter_density}")
    z_all = np.asarray(detections, dtype=float).reshape(-1, 2)
    W, logdet_R = _check_R(R)
    if not (math.isfinite(dt) and dt >= 0):
        raise ValueError(f"dt must be a finite number >= 0, got {dt!r}")
    mu = _floor(est.filter_probabilities, starts)
    x0, P0, c_bar = _mix(est.filter_x, est.filter_P, mu, Pi)
    if condition is not None:
        x0, P0 = condition(x0, P0)
    w_g, w_p, w_s = weights(c_bar)
    stacks = _model_stacks(modes.principal, modes.proper, float(dt))
    xp, Pp = _predict_core(x0, P0, stacks, w_g, w_p)
    K = xp.shape[0]
    rows_k, shape_of = np.nonzero(w_s > 0)  # update rows, grouped by filter

    # step 3: one association per shape mode, shared by its filters
    patterns = modes.patterns
    used = np.unique(shape_of)
    pairs: list[np.ndarray | None] = [None] * len(patterns)
    for s in used:
        src = sources(int(s))
        ws = c_bar[src] / c_bar[src].sum()
        xs_, Ps_ = _combine(np.take(xp, src, axis=0), np.take(Pp, src, axis=0), ws)
        pairs[s] = _pairs_array(associate(int(s), xs_, Ps_), len(patterns[s]), len(z_all), int(s))
    p_max = max(1, max(len(pairs[s]) for s in used))
    n_s = len(patterns)
    Q = np.zeros((n_s, p_max, 2))
    Z = np.zeros((n_s, p_max, 2))
    Mk = np.zeros((n_s, p_max))
    counts = np.zeros(n_s)
    sizes_m = np.array([len(p) for p in patterns], dtype=float)
    for s in used:
        pr = pairs[s]
        k = len(pr)
        if k:
            Q[s, :k] = np.take(patterns[s], pr[:, 0], axis=0)
            Z[s, :k] = np.take(z_all, pr[:, 1], axis=0)
            Mk[s, :k] = 1.0
        counts[s] = k
    single = len(rows_k) == K  # one shape per filter: rows are the filters
    xu, Pu, ll = _update_core(
        xp if single else np.take(xp, rows_k, axis=0),
        Pp if single else np.take(Pp, rows_k, axis=0),
        np.take(Q, shape_of, axis=0),
        np.take(Z, shape_of, axis=0),
        np.take(Mk, shape_of, axis=0),
        W,
        logdet_R,
    )
    p = np.take(counts, shape_of)
    m = np.take(sizes_m, shape_of)
    with np.errstate(divide="ignore"):
        log_miss = math.log(1.0 - pd) if pd < 1.0 else -math.inf
    log_lam = ll + p * math.log(pd / clutter_density)
    log_lam = log_lam + np.where(m > p, (m - p) * log_miss, 0.0)
    if not single:  # collapse each filter's per-shape updates (total probability)
        row_starts = np.flatnonzero(np.diff(rows_k, prepend=-1))
        row_len = np.diff(np.append(row_starts, rows_k.size))
        log_v = log_lam + np.log(w_s[rows_k, shape_of])
        peak = np.maximum.reduceat(log_v, row_starts)
        finite = np.isfinite(peak)
        v = np.exp(log_v - np.repeat(np.where(finite, peak, 0.0), row_len))
        v = np.where(np.repeat(finite, row_len), v, w_s[rows_k, shape_of])
        tot = np.add.reduceat(v, row_starts)
        v = v / np.repeat(tot, row_len)
        log_lam = np.where(finite, np.log(tot) + np.where(finite, peak, 0.0), -math.inf)
        xm = np.add.reduceat(v[:, None] * xu, row_starts, axis=0)
        d = xu - np.repeat(xm, row_len, axis=0)
        Pm = np.add.reduceat(
            v[:, None, None] * (Pu + d[:, :, None] * d[:, None, :]), row_starts, axis=0
        )
        xu, Pu = xm, Pm

    # eq. 11 per group, in logarithms
    log_w = log_lam + np.log(np.maximum(c_bar, np.finfo(float).tiny))
    group_len = np.diff(np.append(starts, log_w.size))
    peak = np.repeat(np.maximum.reduceat(log_w, starts), group_len)
    ok = np.isfinite(peak)
    e = np.exp(np.where(ok, log_w - np.where(ok, peak, 0.0), 0.0))
    tot = np.repeat(np.add.reduceat(e, starts), group_len)
    mu_new = np.where(ok, e / tot, c_bar)
    mu_new = _floor(mu_new, starts)
    return xu, Pu, mu_new, c_bar, tuple(pairs), log_lam


# --------------------------------------------------------------------------- the two steps


def imm_step(
    est: MMEstimate,
    dt: float,
    detections: np.ndarray,
    R: np.ndarray,
    associate: Associate,
    modes: BendingModes,
    *,
    pd: float,
    clutter_density: float,
) -> tuple[MMEstimate, StepInfo]:
    """One scan of the full IMM of paper 000 (eqs. 7-12) over the ``M = r_g r_p r_s``
    global modes.

    Each global mode ``J = (g, p, s)`` moves with principal model ``g`` and proper model
    ``p`` (eq. 9) and is updated with the points matched for shape ``s``; ``associate`` is
    called once per shape with the shape-conditional combined prediction
    ``Σ_{J: s_J = s} c̄_J x_J / Σ c̄_J``. ``Λ_J`` is the comparable likelihood of the module
    docstring; ``μ_J ∝ Λ_J c̄_J`` (eq. 11); the output is eq. 12, the layer probabilities
    the marginals of ``μ``.

    Args:
        est: the previous estimate (``algorithm == "imm"``).
        dt: time since it (s). detections: ``(n, 2)``. R: ``(2, 2)`` per-point noise.
        associate: see :data:`Associate`. modes: the mode set.
        pd: detection probability of a pattern point. clutter_density: λ (per m²).

    Returns:
        The new estimate and a :class:`StepInfo`.
    """
    if est.algorithm != "imm":
        raise ValueError("imm_step needs an estimate made for the IMM")
    M = modes.n_models
    if est.filter_x.shape[0] != M:
        raise ValueError(f"estimate has {est.filter_x.shape[0]} filters, modes have {M}")
    r_g, r_p, r_s = modes.sizes
    gm = modes.global_modes()
    w_g = np.eye(r_g)[gm[:, 0]]
    w_p = np.eye(r_p)[gm[:, 1]]
    w_s = np.eye(r_s)[gm[:, 2]]
    starts = np.array([0])
    by_shape = [np.flatnonzero(gm[:, 2] == s) for s in range(r_s)]
    xu, Pu, mu, c_bar, pairs, log_lam = _cycle(
        est,
        modes.transition,
        starts,
        lambda _c: (w_g, w_p, w_s),
        lambda s: by_shape[s],
        dt,
        detections,
        R,
        associate,
        modes,
        pd,
        clutter_density,
    )
    x, P = _combine(xu, Pu, mu)
    cube = mu.reshape(r_g, r_p, r_s)
    pred = c_bar.reshape(r_g, r_p, r_s)
    marg = (cube.sum(axis=(1, 2)), cube.sum(axis=(0, 2)), cube.sum(axis=(0, 1)))
    new = MMEstimate(x, P, marg, xu, Pu, mu, "imm")
    info = StepInfo(
        pairs=pairs,
        log_likelihoods=log_lam,
        predicted_layer_probabilities=(
            pred.sum(axis=(1, 2)),
            pred.sum(axis=(0, 2)),
            pred.sum(axis=(0, 1)),
        ),
        layer_transitions=(modes.transition,),
        associations=sum(p is not None for p in pairs),
    )
    return new, info


_TINY_VAR = 1e-300


def _chol2(P: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Lower Cholesky factors ``[[l11, 0], [l21, l22]]`` of a stack of 2x2 covariances
    (closed form; a zero variance is floored so that the factor stays invertible)."""
    l11 = np.sqrt(np.maximum(P[..., 0, 0], _TINY_VAR))
    l21 = 0.5 * (P[..., 1, 0] + P[..., 0, 1]) / l11
    l22 = np.sqrt(np.maximum(P[..., 1, 1] - l21 * l21, _TINY_VAR))
    return l11, l21, l22


def _replace_proper_part(
    x: np.ndarray, P: np.ndarray, x_p: np.ndarray, P_pp: np.ndarray
) -> tuple[np.ndarray, np.ndarray]:
    """Give ``K`` joint Gaussians ``(x (K, 6), P (K, 6, 6))`` the proper marginal
    ``(x_p (K, 2), P_pp (K, 2, 2))`` and keep their correlation structure.

    The proper part ``y`` is replaced by ``M (y − E y) + x_p`` with ``M = L_t L⁻¹`` (``L``,
    ``L_t`` the Cholesky factors of the old and the target ``P_pp``): a linear map of the
    old joint, so the result is positive semi-definite; its proper block is exactly
    ``P_pp``, its principal block unchanged, the cross block ``P_gp Mᵀ``."""
    a11, a21, a22 = _chol2(P[:, 4:, 4:])
    b11, b21, b22 = _chol2(P_pp)
    # M = B A⁻¹, A⁻¹ = [[1/a11, 0], [−a21/(a11 a22), 1/a22]]
    m11 = b11 / a11
    m21 = b21 / a11 - b22 * a21 / (a11 * a22)
    m22 = b22 / a22
    C = P[:, :4, 4:]
    Cn = np.empty_like(C)
    Cn[..., 0] = C[..., 0] * m11[:, None]
    Cn[..., 1] = C[..., 0] * m21[:, None] + C[..., 1] * m22[:, None]
    x_out = x.copy()
    x_out[:, 4:] = x_p
    P_out = P.copy()
    P_out[:, :4, 4:] = Cn
    P_out[:, 4:, :4] = np.swapaxes(Cn, 1, 2)
    P_out[:, 4:, 4:] = 0.5 * (P_pp + np.swapaxes(P_pp, 1, 2))
    return x_out, P_out


def _exchange(
    x0: np.ndarray,
    P0: np.ndarray,
    out_x: np.ndarray,
    out_P: np.ndarray,
    sizes: tuple[int, int, int],
) -> tuple[np.ndarray, np.ndarray]:
    """The LMM's exchange of estimates between the layers (module docstring), after mixing.

    Each bank keeps its own layer's part; the part of a dynamic layer with more than one
    mode that the bank does not own is taken from that layer's combined estimate (the
    previous output ``out_x, out_P``), with the filter's own cross-covariance structure
    (:func:`_replace_proper_part`). Principal filter: proper part from the output. Proper
    filter: the output with its own proper part. Shape filter: the output's parts of the
    multi-mode dynamic layers. A part whose layer has a single mode is kept: it is already
    conditioned on that layer's (only) model, as in the IMM."""
    r_g, r_p, _ = sizes
    K = x0.shape[0]
    multi_g, multi_p = r_g > 1, r_p > 1
    if not (multi_g or multi_p):
        return x0, P0
    # base joint: the output where the principal part is foreign and exchanged
    base_out = np.zeros(K, dtype=bool)
    if multi_g:
        base_out[r_g:] = True
    # proper marginal: the output's where the proper part is foreign and exchanged
    target_out = np.zeros(K, dtype=bool)
    if multi_p:
        target_out[:r_g] = True
        target_out[r_g + r_p :] = True
    x_b = np.where(base_out[:, None], out_x[None, :], x0)
    P_b = np.where(base_out[:, None, None], out_P[None], P0)
    x_t = np.where(target_out[:, None], out_x[None, 4:], x0[:, 4:])
    P_t = np.where(target_out[:, None, None], out_P[None, 4:, 4:], P0[:, 4:, 4:])
    same = base_out == target_out  # the proper part already is the wanted one
    if np.all(same):
        return x_b, P_b
    x_n, P_n = _replace_proper_part(x_b, P_b, x_t, P_t)
    return (
        np.where(same[:, None], x_b, x_n),
        np.where(same[:, None, None], P_b, P_n),
    )


def lmm_step(
    est: MMEstimate,
    dt: float,
    detections: np.ndarray,
    R: np.ndarray,
    associate: Associate,
    modes: BendingModes,
    *,
    pd: float,
    clutter_density: float,
    iterations: int = 0,
) -> tuple[MMEstimate, StepInfo]:
    """One scan of the layered MM of paper 001: one IMM bank per layer, ``r_g + r_p + r_s``
    filters, coupled through the time-varying transition matrices of eqs. 23-24 (eq. 12
    iterated ``iterations`` more times) and through the other layers' predicted mode
    probabilities (module docstring).

    Principal filter ``a``: principal model ``a``, the proper mixture ``c̄^p``, the shape
    mixture ``c̄^s``. Proper filter ``b``: the principal mixture ``c̄^g``, proper model ``b``,
    the shape mixture. Shape filter ``s``: both dynamic mixtures, shape ``s``'s points.
    ``associate(s, …)`` is called once per shape, with shape filter ``s``'s prediction.
    Same arguments and returns as :func:`imm_step`.
    """
    if est.algorithm != "lmm":
        raise ValueError("lmm_step needs an estimate made for the LMM")
    r_g, r_p, r_s = modes.sizes
    K = r_g + r_p + r_s
    if est.filter_x.shape[0] != K:
        raise ValueError(f"estimate has {est.filter_x.shape[0]} filters, LMM needs {K}")
    starts = np.array([0, r_g, r_g + r_p])
    mu_prev = [
        est.filter_probabilities[:r_g],
        est.filter_probabilities[r_g : r_g + r_p],
        est.filter_probabilities[r_g + r_p :],
    ]
    tilde = layered_transition_matrices(modes.transition, modes.sizes, mu_prev, iterations)
    Pi = np.zeros((K, K))  # the banks' matrices on the diagonal (scipy's block_diag: 20x slower)
    for b, t in zip(starts.tolist(), tilde, strict=True):
        Pi[b : b + len(t), b : b + len(t)] = t
    eye_g, eye_p, eye_s = np.eye(r_g), np.eye(r_p), np.eye(r_s)

    def weights(c_bar: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        cg, cp, cs = c_bar[:r_g], c_bar[r_g : r_g + r_p], c_bar[r_g + r_p :]
        w_g = np.concatenate([eye_g, np.tile(cg, (r_p + r_s, 1))])
        w_p = np.concatenate([np.tile(cp, (r_g, 1)), eye_p, np.tile(cp, (r_s, 1))])
        w_s = np.concatenate([np.tile(cs, (r_g + r_p, 1)), eye_s])
        return w_g, w_p, w_s

    shape_filters = [np.array([r_g + r_p + s]) for s in range(r_s)]
    xu, Pu, mu, c_bar, pairs, log_lam = _cycle(
        est,
        Pi,
        starts,
        weights,
        lambda s: shape_filters[s],
        dt,
        detections,
        R,
        associate,
        modes,
        pd,
        clutter_density,
        lambda x0, P0: _exchange(x0, P0, est.x, est.P, modes.sizes),
    )
    banks = (slice(0, r_g), slice(r_g, r_g + r_p), slice(r_g + r_p, K))
    xg, Pg = _combine(xu[banks[0]], Pu[banks[0]], mu[banks[0]])
    xp, Pp = _combine(xu[banks[1]], Pu[banks[1]], mu[banks[1]])
    # output: principal part from the principal bank, proper part from the proper bank,
    # cross-covariance the principal bank's (mapped onto the proper bank's marginal)
    xo, Po = _replace_proper_part(xg[None], Pg[None], xp[None, 4:], Pp[None, 4:, 4:])
    x, P = xo[0], Po[0]
    new = MMEstimate(x, P, tuple(mu[b] for b in banks), xu, Pu, mu, "lmm")
    info = StepInfo(
        pairs=pairs,
        log_likelihoods=log_lam,
        predicted_layer_probabilities=tuple(c_bar[b] for b in banks),
        layer_transitions=tilde,
        associations=sum(p is not None for p in pairs),
    )
    return new, info
