"""Template matching of a formation to one sensor's detections (paper 003, section III.B).

All points are in one frame (the tracker rotates them into the formation's own frame first,
so that the grid's axes follow the formation's). The *template* is the formation's members
as points; the detections to match are those pre-associated with it.

1. Cell sizes (eq. 7): per axis, ``μ = min(4 σ, d_min)``, with ``σ`` the largest detection
   noise standard deviation along the axis and ``d_min`` the smallest difference of two
   members along it (see :func:`cell_sizes` for the floor that keeps the grid finite).
2. Shape matrices (eqs. 8-11): rectangle A holds the template, rectangle B the detections;
   each is cut into cells of ``μ_x × μ_y`` and ``e_ij = 1`` where a point falls in cell
   ``(i, j)`` (:func:`shape_matrix`).
3. Matching search (eqs. 12-15): A slides over B; placement ``(i, j)`` scores
   ``p_ij = Σ_{i'j'} e^m_{i'j'} · ẽ^p_{i+i', j+j'}`` (:func:`match_counts`).
4. Least cost (eqs. 16-18): among the placements with the most matched members, the one
   whose matched detections lie nearest the members' predicted positions,
   ``ζ_ij = Σ_{i'j'} min_l ‖z_l − ẑ_{i'j'}‖`` over the matched cells (:func:`match_template`).

Where this departs from the paper, and why:

- eq. 15 asks every cell of A, empty or not, to equal its cell of B; here only A's occupied
  cells count, and one is matched when B has a detection in the same cell or a neighbour
  (``tolerance`` cells, ``ẽ^p`` is ``e^p`` dilated). A clutter detection inside the
  formation then cannot veto the true placement, a missed member costs one count instead of
  the whole match, and a detection that noise pushed over a cell border still matches.
  The best placement is the one with the most matches, then the least cost (eq. 17's zero
  cost of a non-matching placement would otherwise favour placements matching nothing).
- B is the detections' rectangle grown by A's size on each side, so that a formation whose
  edge member was missed (B smaller than A) still has placements (eq. 13 would give none).
- The template is the members' positions predicted to the detections' time, not their last
  estimates ``G(k−1)``: the placement then measures only the prediction error, which bounds
  the search (``max_shift``).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from scipy.optimize import linear_sum_assignment

__all__ = [
    "MAX_CELLS",
    "TemplateMatch",
    "cell_sizes",
    "cells_of",
    "match_counts",
    "match_template",
    "shape_matrix",
]

#: The most cells along one axis of a shape matrix; the cells grow to keep within it.
MAX_CELLS = 256

_FAR = 1e30


def cell_sizes(template: np.ndarray, sigma: np.ndarray) -> np.ndarray:
    """Grid cell sizes ``(μ_x, μ_y)`` (eq. 7).

    ``μ_a = min(4 σ_a, max(2 σ_a, d_a))`` for axis ``a``, where ``σ_a`` is the largest noise
    standard deviation along the axis and ``d_a`` the smallest difference along it between
    two template points that differ by at least ``2 σ_a`` (closer ones cannot be told apart
    along that axis; the other axis separates them, or nothing does). The floor ``2 σ_a``
    keeps the grid finite and lets a one-cell tolerance hold a ±2σ error.
    """
    pts = np.asarray(template, dtype=float).reshape(-1, 2)
    sigma = np.asarray(sigma, dtype=float).reshape(2)
    if not (np.isfinite(sigma).all() and (sigma > 0).all()):
        raise ValueError(f"sigma: must be finite and > 0, got {sigma.tolist()}")
    mu = 4.0 * sigma
    if pts.shape[0] >= 2:
        diff = np.abs(pts[:, None, :] - pts[None, :, :]).reshape(-1, 2)
        for a in range(2):
            d = diff[:, a]
            d = d[d >= 2.0 * sigma[a]]
            if d.size:
                mu[a] = min(mu[a], float(d.min()))
    return np.maximum(mu, 2.0 * sigma)


def cells_of(points: np.ndarray, origin: np.ndarray, mu: np.ndarray) -> np.ndarray:
    """Integer cell ``(i, j) = ⌊(p − origin) / μ⌋`` of each point, ``(n, 2)``."""
    p = np.asarray(points, dtype=float).reshape(-1, 2)
    return np.floor((p - np.reshape(origin, 2)) / np.reshape(mu, 2)).astype(np.int64)


def shape_matrix(
    points: np.ndarray, origin: np.ndarray, mu: np.ndarray, shape: tuple[int, int]
) -> np.ndarray:
    """The shape matrix (eqs. 8-10): ``e_ij = 1`` where a point falls in cell ``(i, j)`` of
    the rectangle of ``shape`` cells from ``origin``; points outside are left out."""
    c = cells_of(points, origin, mu)
    inside = (c >= 0).all(axis=1) & (c[:, 0] < shape[0]) & (c[:, 1] < shape[1])
    E = np.zeros(shape, dtype=bool)
    E[c[inside, 0], c[inside, 1]] = True
    return E


def _dilated(E: np.ndarray, tolerance: int) -> np.ndarray:
    """``E`` with every occupied cell spread to its neighbours within ``tolerance`` cells."""
    if tolerance <= 0:
        return E
    out = E.copy()
    for _ in range(tolerance):
        grown = out.copy()
        grown[1:, :] |= out[:-1, :]
        grown[:-1, :] |= out[1:, :]
        grown[:, 1:] |= out[:, :-1]
        grown[:, :-1] |= out[:, 1:]
        grown[1:, 1:] |= out[:-1, :-1]
        grown[:-1, :-1] |= out[1:, 1:]
        grown[1:, :-1] |= out[:-1, 1:]
        grown[:-1, 1:] |= out[1:, :-1]
        out = grown
    return out


def match_counts(E_m: np.ndarray, E_p: np.ndarray, tolerance: int = 1) -> np.ndarray:
    """The matching matrix (eqs. 12-15): for each placement ``(i, j)`` of A in B, with
    ``m_x = l_x^p − l_x^m + 1`` and ``m_y = l_y^p − l_y^m + 1`` placements per axis (eq. 13),
    the number of A's occupied cells whose cell of B, or a neighbour within ``tolerance``,
    is occupied: ``p_ij = Σ_{i'j'} e^m_{i'j'} · ẽ^p_{i+i', j+j'}``. Empty when A does not fit
    in B."""
    E_m = np.asarray(E_m, dtype=bool)
    E_p = np.asarray(E_p, dtype=bool)
    m_x = E_p.shape[0] - E_m.shape[0] + 1
    m_y = E_p.shape[1] - E_m.shape[1] + 1
    if m_x <= 0 or m_y <= 0:
        return np.zeros((max(m_x, 0), max(m_y, 0)), dtype=np.int64)
    D = _dilated(E_p, tolerance).astype(np.int64)
    counts = np.zeros((m_x, m_y), dtype=np.int64)
    for a, b in np.argwhere(E_m).tolist():
        counts += D[a : a + m_x, b : b + m_y]
    return counts


@dataclass(frozen=True)
class TemplateMatch:
    """The chosen placement: ``count`` template points matched, their ``cost`` (eq. 17, m),
    ``shift`` the translation from A to its place in B (m, to within a cell), and
    ``assignment[n]`` the detection matched to template point ``n`` (−1 for none)."""

    count: int
    cost: float
    shift: np.ndarray
    assignment: np.ndarray


def match_template(
    template: np.ndarray,
    detections: np.ndarray,
    mu: np.ndarray,
    *,
    predicted: np.ndarray | None = None,
    tolerance: int = 1,
    max_shift: np.ndarray | None = None,
    miss_cost: float | None = None,
) -> TemplateMatch | None:
    """Match ``template (N, 2)`` to ``detections (K, 2)`` on the grid of cell sizes ``mu``.

    The placement with the most matched template points wins; ties go to the least cost
    ``Σ_n min_l ‖z_l − ẑ_n‖`` over the matched points ``n`` and the detections ``l`` in the
    cells matched to them (eqs. 16-18), with ``ẑ_n`` the ``predicted`` positions (the
    template itself by default). Placements that move A by more than ``max_shift`` (per
    axis, m) plus one cell from where it is are not searched. Then each matched point gets
    one detection of its cells, no detection two points (least total distance). ``None``
    when nothing matches.

    With ``miss_cost`` (m), the count and the cost are weighed together instead: the
    placement of least ``Σ_n min(d_n, miss_cost)``, an unmatched point costing
    ``miss_cost``, among those within two of the most matches; a detection farther than
    ``miss_cost`` from its point's prediction is no match. Then a false alarm that completes
    the pattern one member along (a formation in line, a member missed) cannot outweigh
    detections where the members were predicted.
    """
    A = np.asarray(template, dtype=float).reshape(-1, 2)
    Z = np.asarray(detections, dtype=float).reshape(-1, 2)
    zhat = A if predicted is None else np.asarray(predicted, dtype=float).reshape(-1, 2)
    if A.shape[0] == 0 or Z.shape[0] == 0:
        return None
    mu = np.asarray(mu, dtype=float).reshape(2).copy()
    lo_a, hi_a = A.min(axis=0), A.max(axis=0)
    lo_z, hi_z = Z.min(axis=0), Z.max(axis=0)
    # Grow the cells until both rectangles (B padded by A on each side) fit MAX_CELLS.
    span = np.maximum(hi_a - lo_a, 0.0)
    mu = np.maximum(mu, (hi_z - lo_z + 2.0 * span) / (MAX_CELLS - 3))
    l_m = np.floor(span / mu).astype(np.int64) + 1
    b0 = lo_z - (l_m - 1) * mu
    l_p = np.floor((hi_z - b0) / mu).astype(np.int64) + 1 + (l_m - 1)
    cells_a = cells_of(A, lo_a, mu)
    cells_a = np.minimum(cells_a, l_m - 1)  # a point on A's far edge stays in A
    E_m = np.zeros(tuple(l_m.tolist()), dtype=bool)
    E_m[cells_a[:, 0], cells_a[:, 1]] = True
    cells_z = cells_of(Z, b0, mu)
    E_p = np.zeros(tuple(l_p.tolist()), dtype=bool)
    E_p[cells_z[:, 0], cells_z[:, 1]] = True
    counts = match_counts(E_m, E_p, tolerance)
    if max_shift is not None:
        # Placement o moves A by b0 + o μ − lo_a.
        lim = np.reshape(max_shift, 2) + mu
        ox = b0[0] + np.arange(counts.shape[0]) * mu[0] - lo_a[0]
        oy = b0[1] + np.arange(counts.shape[1]) * mu[1] - lo_a[1]
        counts = counts * ((np.abs(ox) <= lim[0])[:, None] & (np.abs(oy) <= lim[1])[None, :])
    best = int(counts.max(initial=0))
    if best == 0:
        return None
    floor = best if miss_cost is None else max(1, best - 2)
    placements = np.argwhere(counts >= floor)  # (Q, 2)
    # Costs of the placements (eq. 17-18), all at once: (Q, N, K).
    target = placements[:, None, :] + cells_a[None, :, :]  # (Q, N, 2)
    near = (np.abs(cells_z[None, None, :, :] - target[:, :, None, :]) <= tolerance).all(axis=3)
    dist = np.hypot(zhat[:, None, 0] - Z[None, :, 0], zhat[:, None, 1] - Z[None, :, 1])  # (N, K)
    if miss_cost is not None:
        near &= (dist <= miss_cost)[None]
        return _least_exclusive(near, dist, float(miss_cost), placements, b0, mu, lo_a)
    d = np.where(near, dist[None], np.inf).min(axis=2)  # (Q, N)
    cost = np.where(np.isfinite(d), d, 0.0).sum(axis=1)
    q = int(np.argmin(cost))
    mask = near[q]
    if not mask.any():
        return None
    rows, cols = linear_sum_assignment(np.where(mask, dist, _FAR))
    assignment = np.full(A.shape[0], -1, dtype=np.int64)
    ok = mask[rows, cols]
    assignment[rows[ok]] = cols[ok]
    shift = b0 + placements[q] * mu - lo_a
    return TemplateMatch(
        count=int(ok.sum()), cost=float(cost[q]), shift=shift, assignment=assignment
    )


def _least_exclusive(
    near: np.ndarray,
    dist: np.ndarray,
    miss_cost: float,
    placements: np.ndarray,
    b0: np.ndarray,
    mu: np.ndarray,
    lo_a: np.ndarray,
) -> TemplateMatch | None:
    """The placement of least cost when each detection serves one template point: for
    placement ``q`` the least ``Σ_n c_n`` over one-to-one assignments of points to the
    detections ``near[q] (N, K)`` (``c_n = dist[n, k]``, or ``miss_cost`` for a point left
    without), by the Hungarian method on the points against the detections and ``N`` misses.

    Each placement's cost without the one-to-one rule, ``Σ_n min(min_k d_nk, miss_cost)``, is
    a lower bound of its cost with it; the placements are tried in order of that bound and
    the search stops once the bound reaches the best cost found. Without the rule, two points
    could both count one detection, and a placement that slides a line formation one member
    along (its end member missed) would cost as little as the true one."""
    N, K = dist.shape
    d = np.where(near, dist[None], np.inf).min(axis=2)  # (Q, N)
    bound = np.minimum(d, miss_cost).sum(axis=1)
    best: tuple[float, int, np.ndarray] | None = None
    misses = np.full((N, N), miss_cost)
    for q in np.argsort(bound, kind="stable").tolist():
        if best is not None and bound[q] >= best[0]:
            break
        if not near[q].any():
            continue
        table = np.hstack([np.where(near[q], dist, miss_cost), misses])
        rows, cols = linear_sum_assignment(table)
        cost = float(table[rows, cols].sum())
        if best is None or cost < best[0]:
            real = cols < K
            real[real] = near[q][rows[real], cols[real]]
            chosen = np.full(N, -1, dtype=np.int64)
            chosen[rows[real]] = cols[real]
            best = (cost, q, chosen)
    if best is None:
        return None
    cost, q, assignment = best
    shift = b0 + placements[q] * mu - lo_a
    return TemplateMatch(
        count=int((assignment >= 0).sum()), cost=cost, shift=shift, assignment=assignment
    )
