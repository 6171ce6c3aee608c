"""Which points lie near which centres: the spatial pre-gate of gating and initiation.

``pairs_within(c, r, p)`` gives every pair (i, j) with ``|p_j − c_i| ≤ r_i``. Small problems
(at most ``BRUTE_FORCE_CELLS`` centre-point pairs) are answered by computing every distance,
which costs a few array operations. Larger ones first sort the points by x: the points of
each centre's strip ``|x − c_x| ≤ r_i`` are one slice of that order (two binary searches), so
when the strips hold few points in all (at most ``STRIP_POINTS_PER_ITEM`` per centre and
point on average, the usual case of scattered radar scenes) every distance within them is
computed; otherwise k-d trees over centres and points are searched, whose cost grows with the
number of nearby pairs. Every path gives the pairs ordered by centre, then by point.
"""

from __future__ import annotations

import numpy as np
from scipy.spatial import cKDTree

__all__ = ["BRUTE_FORCE_CELLS", "STRIP_POINTS_PER_ITEM", "pairs_within"]

#: Up to this many centre-point pairs every distance is computed.
BRUTE_FORCE_CELLS = 10_000
#: Beyond that, the x strips are searched when they hold at most this many points per centre
#: and point on average; denser scenes go to k-d trees (measured crossover about 10-30).
STRIP_POINTS_PER_ITEM = 8


def pairs_within(
    centres: np.ndarray, radius: np.ndarray, points: np.ndarray
) -> tuple[np.ndarray, np.ndarray]:
    """Indices ``(i, j)`` of every centre ``c_i (n, 2)`` and point ``p_j (m, 2)`` with
    ``|p_j − c_i| ≤ r_i``, sorted by ``i`` then ``j``."""
    n, m = centres.shape[0], points.shape[0]
    if n == 0 or m == 0:
        empty = np.zeros(0, dtype=np.intp)
        return empty, empty
    if n * m <= BRUTE_FORCE_CELLS:
        dx = points[None, :, 0] - centres[:, 0, None]
        dy = points[None, :, 1] - centres[:, 1, None]
        i, j = np.nonzero(dx * dx + dy * dy <= (radius * radius)[:, None])
        return i.astype(np.intp), j.astype(np.intp)
    order = np.argsort(points[:, 0], kind="stable")
    xs = np.take(points[:, 0], order)
    cx = centres[:, 0]
    start = np.searchsorted(xs, cx - radius, "left")
    count = np.searchsorted(xs, cx + radius, "right") - start
    total = int(count.sum())
    if total <= STRIP_POINTS_PER_ITEM * (n + m):
        return _strip_pairs(centres, radius, points, order, start, count, total)
    # One search with the largest radius between two trees, then each centre's own radius.
    near = cKDTree(centres).sparse_distance_matrix(
        cKDTree(points), float(radius.max()), output_type="ndarray"
    )
    i = near["i"].astype(np.intp)
    keep = near["v"] <= radius[i]
    i, j = i[keep], near["j"].astype(np.intp)[keep]
    order = np.argsort(i * m + j)
    return i[order], j[order]


def _strip_pairs(
    centres: np.ndarray,
    radius: np.ndarray,
    points: np.ndarray,
    order: np.ndarray,
    start: np.ndarray,
    count: np.ndarray,
    total: int,
) -> tuple[np.ndarray, np.ndarray]:
    """The pairs of :func:`pairs_within` among the points of each centre's x strip: the
    ``count[i]`` points from ``start[i]`` in ``order`` (the points sorted by x)."""
    if total == 0:
        empty = np.zeros(0, dtype=np.intp)
        return empty, empty
    i = np.repeat(np.arange(centres.shape[0], dtype=np.intp), count)
    first = np.repeat(start - (np.cumsum(count) - count), count)
    j = np.take(order, first + np.arange(total, dtype=np.intp))
    d = np.take(points, j, axis=0) - np.take(centres, i, axis=0)
    r = np.take(radius, i)
    keep = np.flatnonzero(np.einsum("ij,ij->i", d, d) <= r * r)
    i, j = np.take(i, keep), np.take(j, keep)
    by_point = np.lexsort((j, i))  # within a centre, the strip is in x order
    return np.take(i, by_point).astype(np.intp), np.take(j, by_point).astype(np.intp)
