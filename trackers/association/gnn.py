"""Global nearest neighbour association, one independent cluster at a time.

Each gated pair (i, j) has a gain ``G_ij``: the change in track score of taking the detection
rather than missing it, ``G_ij = ln(P_D g_ij / λ_fa) − ln(1 − P_D)``. GNN picks the one-to-one
assignment that maximises the summed gain, any track or detection being free to stay
unassigned (gain 0). Pairs with ``G_ij ≤ 0`` are never worth taking and are dropped first.

A pair whose track and detection appear in no other pair is taken as it is. The other pairs
form clusters (:mod:`trackers.association.clusters`) that cannot change each other's answer;
``scipy.optimize.linear_sum_assignment`` solves them. When the tracks and detections of all
clusters together make a small matrix (at most ``JOINT_CELLS`` cells) they are solved in one
call, the non-gated cells at gain 0: the optimum of that block-diagonal problem is the union
of the clusters' optima, and one call costs less than one per cluster. Larger problems are
solved cluster by cluster, so the cost grows with the clusters' sizes, not the scene's.
"""

from __future__ import annotations

import numpy as np
from scipy.optimize import linear_sum_assignment

from trackers.association.clusters import cluster_pairs, lone_pairs

__all__ = ["JOINT_CELLS", "gnn_assign"]

#: The largest (tracks × detections) matrix solved in one assignment call.
JOINT_CELLS = 4096


def gnn_assign(
    track: np.ndarray, detection: np.ndarray, gain: np.ndarray, n_tracks: int, n_dets: int
) -> np.ndarray:
    """The assignment maximising Σ G_ij over chosen pairs, each track and detection used once.

    Returns the indices of the chosen pairs into ``track``, ``detection`` and ``gain``.
    """
    worth = np.flatnonzero(gain > 0)
    if worth.size == 0:
        return worth
    track, detection, gain = track[worth], detection[worth], gain[worth]
    lone = lone_pairs(track, detection, n_tracks, n_dets)
    rest = np.flatnonzero(~lone)
    if rest.size == 0:
        return worth
    chosen = [lone.nonzero()[0]]
    # (each of the rest's tracks and detections is one of its pairs: few pairs, few cells)
    few = rest.size * rest.size <= JOINT_CELLS
    if few or _count_distinct(track[rest]) * _count_distinct(detection[rest]) <= JOINT_CELLS:
        groups: tuple[np.ndarray, ...] = (rest,)
    else:  # removing lone pairs leaves the others' degrees as they were: no singles here
        groups = tuple(
            rest[g] for g in cluster_pairs(track[rest], detection[rest], n_tracks, n_dets).groups
        )
    for pairs in groups:
        chosen.append(_solve(track[pairs], detection[pairs], gain[pairs], pairs))
    return worth[np.concatenate(chosen)]


def _solve(
    track: np.ndarray, detection: np.ndarray, gain: np.ndarray, pairs: np.ndarray
) -> np.ndarray:
    """The ``pairs`` chosen by the optimal assignment of one or more clusters. Non-gated cells
    get gain 0: choosing one adds nothing and is discarded, which makes the forced rectangular
    assignment equal to the optional one."""
    t_idx, n_t = _compact(track)
    d_idx, n_d = _compact(detection)
    G = np.zeros((n_t, n_d))
    G[t_idx, d_idx] = gain
    pair_of = np.full((n_t, n_d), -1, dtype=np.intp)
    pair_of[t_idx, d_idx] = pairs
    rows, cols = linear_sum_assignment(G, maximize=True)
    picked = pair_of[rows, cols]
    return picked[picked >= 0]


def _count_distinct(index: np.ndarray) -> int:
    """The number of distinct values in ``index`` (non-negative integers)."""
    present = np.zeros(int(index.max()) + 1, dtype=bool)
    present[index] = True
    return int(np.count_nonzero(present))


def _compact(index: np.ndarray) -> tuple[np.ndarray, int]:
    """``index`` renumbered 0, 1, … in increasing order of its distinct values, and their
    count (``np.unique(index, return_inverse=True)`` without its sort)."""
    present = np.zeros(int(index.max()) + 1, dtype=bool)
    present[index] = True
    rank = np.cumsum(present) - 1
    return rank[index], int(rank[-1]) + 1
