"""Measurement-set partitioning by resolution distance (paper 002, section III.D).

The detections validated by an extended track's gate are split into *subsets*: two detections
closer than the resolution distance ``d_res`` belong to the same subset, and so, transitively,
do chains of them (single-linkage clustering, the connected components of the graph whose
edges join detections less than ``d_res`` apart). The candidate partitions are then the nested
unions ``{S₁}, {S₁ ∪ S₂}, …, {S₁ ∪ … ∪ S_p}`` of the subsets taken in order of how well each
fits the track on its own, and the likeliest is the track's.

The pairs closer than ``d_res`` come from a k-d tree (:class:`scipy.spatial.cKDTree`), so the
cost grows with the number of close pairs, not with the square of the number of detections.
"""

from __future__ import annotations

import functools
import math

import numpy as np
from scipy.spatial import cKDTree

__all__ = [
    "close_pairs",
    "component_labels",
    "edge_groups",
    "nested_unions",
    "pair_subsets",
    "point_subsets",
    "resolution_subsets",
]

#: Up to this many points, every pair's distance is computed (a k-d tree's set-up costs more).
BRUTE_FORCE_POINTS = 64
#: Up to this many edges, components come from a union-find loop; above, from array rounds.
UNION_FIND_EDGES = 512
#: Up to this many points, :func:`point_subsets` tests every pair in plain Python.
PYTHON_POINTS = 32


def resolution_subsets(Z: np.ndarray, d_res: float, min_size: int = 1) -> list[np.ndarray]:
    """The subsets of the ``(n, 2)`` points ``Z`` that chains of points closer than ``d_res``
    join, as arrays of row indices (ascending within a subset; subsets ordered by their first
    row). A point with no neighbour within ``d_res`` is a subset of its own. Only subsets of
    at least ``min_size`` points are returned.

    Single linkage: ``i ~ j`` when ``‖zᵢ − zⱼ‖ ≤ d_res``, closed transitively.
    """
    Z = np.asarray(Z, dtype=float).reshape(-1, 2)
    n = Z.shape[0]
    if not (math.isfinite(d_res) and d_res > 0):
        raise ValueError(f"d_res: must be a finite number > 0, got {d_res!r}")
    if n < max(min_size, 1):
        return []
    if n == 1:
        return [np.zeros(1, dtype=np.intp)]
    i, j = close_pairs(Z, d_res)
    return pair_subsets(n, i, j, min_size)


def close_pairs(Z: np.ndarray, d_res: float) -> tuple[np.ndarray, np.ndarray]:
    """The pairs ``i < j`` of rows of the ``(n, 2)`` points ``Z`` with ``‖zᵢ − zⱼ‖ ≤ d_res``,
    as two index arrays: every pair's distance for a few points, a k-d tree for more."""
    n = Z.shape[0]
    if n <= BRUTE_FORCE_POINTS:  # every pair: cheaper than a k-d tree for a few points
        # (the pairs i < j listed once per n, so that no (n, n) matrix is searched: numpy's
        # nonzero of a matrix costs more than the distances)
        i, j = _upper_pairs(n)
        x, y = Z[:, 0], Z[:, 1]  # (columns: numpy reduces a length-2 axis slowly)
        dx, dy = x.take(i) - x.take(j), y.take(i) - y.take(j)
        dx *= dx
        dy *= dy
        dx += dy
        close = np.flatnonzero(dx <= float(d_res) ** 2)
        return i.take(close), j.take(close)
    pairs = cKDTree(Z).query_pairs(r=float(d_res), output_type="ndarray")
    return pairs[:, 0], pairs[:, 1]


@functools.lru_cache(maxsize=BRUTE_FORCE_POINTS + 1)
def _upper_pairs(n: int) -> tuple[np.ndarray, np.ndarray]:
    """Every pair ``i < j`` of ``n`` points, row by row (read-only index arrays)."""
    i, j = np.triu_indices(n, 1)
    i, j = i.astype(np.intp), j.astype(np.intp)
    i.flags.writeable = j.flags.writeable = False
    return i, j


def pair_subsets(n: int, i: np.ndarray, j: np.ndarray, min_size: int = 1) -> list[np.ndarray]:
    """The connected components of the undirected graph on ``n`` nodes with edges
    ``(iₖ, jₖ)`` as arrays of nodes (ascending within a component; components ordered by
    their smallest node), only those of at least ``min_size`` nodes: the subsets of
    :func:`resolution_subsets` from the pairs closer than the resolution distance."""
    if n == 0 or n < min_size:
        return []
    if len(i) <= UNION_FIND_EDGES and (min_size > 1 or n <= BRUTE_FORCE_POINTS):
        # A few edges: grouped in plain Python. With min_size > 1 a node without an edge (a
        # component of one) is never wanted.
        groups = edge_groups(i.tolist(), j.tolist())
        if min_size > 1:
            big = sorted(sorted(g) for g in groups if len(g) >= min_size)
            return [np.array(g, dtype=np.intp) for g in big]
        return [np.array(g, dtype=np.intp) for g in _components(n, groups)]
    labels = component_labels(n, i, j)
    counts = np.bincount(labels, minlength=n)
    if min_size > 1:
        big = np.flatnonzero(counts >= min_size)
        return [np.flatnonzero(labels == k) for k in big.tolist()]
    order = np.argsort(labels, kind="stable").astype(np.intp)
    ends = np.cumsum(counts[counts > 0]).tolist()
    return [order[a:b] for a, b in zip([0, *ends[:-1]], ends, strict=True)]


def edge_groups(i: list[int], j: list[int]) -> list[list[int]]:
    """The connected components of the graph with edges ``(iₖ, jₖ)`` that have an edge, each
    a list of its nodes in no particular order: every node points at its component's list,
    and an edge between two components moves the smaller list's nodes into the larger (each
    node moves at most ``log₂ n`` times). A plain loop without calls: for the few hundred
    edges of a scan, several times faster than a union-find of nested root searches. A loop
    ``(a, a)`` joins nothing."""
    group: dict[int, list[int]] = {}
    made: list[list[int]] = []
    for a, b in zip(i, j, strict=True):
        if a == b:  # a loop joins nothing
            continue
        ga = group.get(a)
        gb = group.get(b)
        if ga is None:
            if gb is None:
                g = [a, b]
                group[a] = g
                group[b] = g
                made.append(g)
            else:
                gb.append(a)
                group[a] = gb
        elif gb is None:
            ga.append(b)
            group[b] = ga
        elif ga is not gb:
            if len(ga) < len(gb):
                ga, gb = gb, ga
            ga.extend(gb)
            for c in gb:
                group[c] = ga
    return [g for g in made if group[g[0]] is g]  # those not merged into another


def component_labels(n: int, i: np.ndarray, j: np.ndarray) -> np.ndarray:
    """The connected components of the undirected graph on ``n`` nodes with edges
    ``(iₖ, jₖ)``: each node's label is the smallest node of its component.

    Min-label propagation with pointer jumping: ``ℓ(v) ← min(ℓ(v), min_{(v,u)} ℓ(u))``, then
    ``ℓ ← ℓ(ℓ)``, until nothing changes. Every label is a node of the same component and never
    grows, so it ends at the component's minimum; pointer jumping keeps the rounds few.
    """
    if len(i) <= UNION_FIND_EDGES:
        return _union_find_labels(n, i, j)
    labels = np.arange(n, dtype=np.intp)
    while True:
        new = labels.copy()
        np.minimum.at(new, i, labels[j])
        np.minimum.at(new, j, labels[i])
        new = new[new]
        if np.array_equal(new, labels):
            return labels
        labels = new


def nested_unions(subsets: list[np.ndarray], fit: np.ndarray) -> list[np.ndarray]:
    """The candidate partitions ``{S₁}, {S₁ ∪ S₂}, …`` with the subsets ranked by ``fit``
    (smaller is better, e.g. the Mahalanobis distance of a subset's centroid to the track's
    predicted centroid): candidate ``k`` holds the rows of the ``k + 1`` best subsets."""
    if len(subsets) != len(fit):
        raise ValueError("one fit value per subset")
    out: list[np.ndarray] = []
    rows = np.zeros(0, dtype=np.intp)
    for k in np.argsort(np.asarray(fit, dtype=float), kind="stable").tolist():
        rows = np.concatenate([rows, subsets[k]])
        out.append(np.sort(rows))
    return out


def _union_find_labels(n: int, i: np.ndarray, j: np.ndarray) -> np.ndarray:
    """:func:`component_labels` by :func:`edge_groups` (a plain loop: faster than array
    rounds for a few hundred edges). Nodes without an edge are their own label."""
    labels = np.arange(n, dtype=np.intp)
    for g in edge_groups(i.tolist(), j.tolist()):
        labels[g] = min(g)
    return labels


def point_subsets(points: list[tuple[float, float]], d_res: float) -> list[list[int]]:
    """:func:`resolution_subsets` (every subset) of a few points given as ``(x, y)`` floats,
    as lists of their positions: for a handful of points, plain Python beats array set-up.
    The same arithmetic as the array path (``Δx² + Δy² ≤ d_res²``), so the same subsets;
    the points are swept in order of x, each against the next ones until ``Δx² > d_res²``."""
    n = len(points)
    if n > PYTHON_POINTS:
        Z = np.array(points, dtype=float).reshape(-1, 2)
        return [s.tolist() for s in resolution_subsets(Z, d_res)]
    if not (math.isfinite(d_res) and d_res > 0):
        raise ValueError(f"d_res: must be a finite number > 0, got {d_res!r}")
    d2 = float(d_res) ** 2
    ei: list[int] = []
    ej: list[int] = []
    by_x = sorted(range(n), key=lambda k: points[k][0])
    for p, a in enumerate(by_x):
        xa, ya = points[a]
        for b in by_x[p + 1 :]:
            xb, yb = points[b]
            dx = xa - xb  # (xb − xa)² grows along the sweep and never exceeds the sum
            if dx * dx > d2:
                break
            dy = ya - yb
            if dx * dx + dy * dy <= d2:
                ei.append(a)
                ej.append(b)
    return _components(n, edge_groups(ei, ej))


def _components(n: int, groups: list[list[int]]) -> list[list[int]]:
    """The nodes ``0 … n − 1`` grouped as ``groups`` (:func:`edge_groups`; a node in none is
    alone), ascending within a group, the groups in order of their smallest node."""
    first = list(range(n))  # each node's group's smallest node
    for g in groups:
        m = min(g)
        for a in g:
            first[a] = m
    out: dict[int, list[int]] = {}
    for a in range(n):
        out.setdefault(first[a], []).append(a)
    return list(out.values())
