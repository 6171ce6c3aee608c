"""Independent clusters of tracks and detections.

Two tracks belong to one cluster when a chain of gated pairs links them through shared
detections. Association in one cluster cannot change the best answer in another, so each
cluster is solved on its own, and the many clusters of one track and one detection need no
solver at all.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

__all__ = ["PairClusters", "cluster_pairs", "lone_pairs"]


@dataclass(frozen=True)
class PairClusters:
    """Gated pairs split by cluster.

    ``singles`` indexes the pairs whose track and detection appear in no other pair (solved
    trivially). ``groups`` holds, for each remaining cluster, the indices of its pairs.
    """

    singles: np.ndarray
    groups: tuple[np.ndarray, ...]


def lone_pairs(track: np.ndarray, detection: np.ndarray, n_tracks: int, n_dets: int) -> np.ndarray:
    """Mask of the pairs whose track and detection appear in no other pair: clusters of
    one pair each."""
    track_degree = np.bincount(track, minlength=n_tracks)
    det_degree = np.bincount(detection, minlength=n_dets)
    return (track_degree[track] == 1) & (det_degree[detection] == 1)


def cluster_pairs(
    track: np.ndarray, detection: np.ndarray, n_tracks: int, n_dets: int
) -> PairClusters:
    """Split pairs (``track[k]``, ``detection[k]``) into connected components of the bipartite
    graph tracks ↔ detections."""
    if track.size == 0:
        return PairClusters(np.zeros(0, dtype=np.intp), ())
    lone = lone_pairs(track, detection, n_tracks, n_dets)
    singles = lone.nonzero()[0]
    rest = np.flatnonzero(~lone)
    if rest.size == 0:
        return PairClusters(singles, ())
    pair_label = _component_labels(track[rest], detection[rest], n_tracks, n_dets)
    order = np.argsort(pair_label, kind="stable")
    sorted_labels = pair_label[order]
    cuts = np.flatnonzero(np.diff(sorted_labels)) + 1
    groups = tuple(rest[idx] for idx in np.split(order, cuts))
    return PairClusters(singles, groups)


def _component_labels(
    track: np.ndarray, detection: np.ndarray, n_tracks: int, n_dets: int
) -> np.ndarray:
    """Connected-component label of each pair, by min-label propagation.

    Each track starts with its own index as label; detections take the least label of their
    tracks, tracks the least label of their detections, until nothing changes. Every pass is
    two vectorized scatter-minimums, and the number of passes is the diameter of the largest
    cluster (two or three in practice).
    """
    track_label = np.arange(n_tracks)
    big = np.iinfo(np.int64).max
    while True:
        det_label = np.full(n_dets, big)
        np.minimum.at(det_label, detection, track_label[track])
        new_label = track_label.copy()
        np.minimum.at(new_label, track, det_label[detection])
        if np.array_equal(new_label, track_label):
            return track_label[track]
        track_label = new_label
