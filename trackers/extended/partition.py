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

import numpy as np
from scipy.sparse import coo_matrix
from scipy.sparse.csgraph import connected_components
from scipy.spatial import cKDTree

__all__ = ["nested_unions", "resolution_subsets"]


def resolution_subsets(Z: np.ndarray, d_res: float) -> list[np.ndarray]:
    """The subsets of the ``(n, 2)`` points ``Z`` that chains of points closer than ``d_res``
    join, as arrays of row indices (ascending within a subset; subsets ordered by their first
    row). A point with no neighbour within ``d_res`` is a subset of its own.

    Single linkage: ``i ~ j`` when ``‖zᵢ − zⱼ‖ < d_res``, closed transitively.
    """
    Z = np.asarray(Z, dtype=float).reshape(-1, 2)
    n = Z.shape[0]
    if not (np.isfinite(d_res) and d_res > 0):
        raise ValueError(f"d_res: must be a finite number > 0, got {d_res!r}")
    if n == 0:
        return []
    if n == 1:
        return [np.zeros(1, dtype=np.intp)]
    pairs = cKDTree(Z).query_pairs(r=float(d_res), output_type="ndarray")
    if pairs.size == 0:
        return [np.array([i], dtype=np.intp) for i in range(n)]
    graph = coo_matrix((np.ones(pairs.shape[0]), (pairs[:, 0], pairs[:, 1])), shape=(n, n))
    _, labels = connected_components(graph, directed=False)
    order = np.argsort(labels, kind="stable")
    bounds = np.flatnonzero(np.diff(labels[order])) + 1
    groups = np.split(order, bounds)
    groups.sort(key=lambda g: int(g[0]))
    return [g.astype(np.intp) for g in groups]


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
