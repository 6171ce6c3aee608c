"""Global nearest neighbour association, one independent cluster at a time.

Each gated pair (i, j) has a gain ``G_ij``: the change in track score of taking the detection
rather than missing it, ``G_ij = ln(P_D g_ij / λ_fa) − ln(1 − P_D)``. GNN picks the one-to-one
assignment that maximises the summed gain, any track or detection being free to stay
unassigned (gain 0). Pairs with ``G_ij ≤ 0`` are never worth taking and are dropped first.
Within a cluster the optimum is found with ``scipy.optimize.linear_sum_assignment``.
"""

from __future__ import annotations

import numpy as np
from scipy.optimize import linear_sum_assignment

from trackers.association.clusters import cluster_pairs

__all__ = ["gnn_assign"]


def gnn_assign(
    track: np.ndarray, detection: np.ndarray, gain: np.ndarray, n_tracks: int, n_dets: int
) -> np.ndarray:
    """The assignment maximising Σ G_ij over chosen pairs, each track and detection used once.

    Returns the indices of the chosen pairs into ``track``, ``detection`` and ``gain``.
    """
    worth = np.flatnonzero(gain > 0)
    track, detection, gain = track[worth], detection[worth], gain[worth]
    clusters = cluster_pairs(track, detection, n_tracks, n_dets)
    chosen = [clusters.singles]
    for pairs in clusters.groups:
        t_local, t_idx = np.unique(track[pairs], return_inverse=True)
        d_local, d_idx = np.unique(detection[pairs], return_inverse=True)
        # Non-gated cells get gain 0: choosing one adds nothing and is discarded below,
        # which makes the forced rectangular assignment equal to the optional one.
        G = np.zeros((t_local.size, d_local.size))
        G[t_idx, d_idx] = gain[pairs]
        pair_of = np.full((t_local.size, d_local.size), -1, dtype=np.intp)
        pair_of[t_idx, d_idx] = pairs
        rows, cols = linear_sum_assignment(G, maximize=True)
        picked = pair_of[rows, cols]
        chosen.append(picked[picked >= 0])
    return worth[np.concatenate(chosen)]
