"""Which points lie near which centres: the spatial pre-gate of gating and initiation.

``pairs_within(c, r, p)`` gives every pair (i, j) with ``|p_j − c_i| ≤ r_i``. Small problems
(at most ``BRUTE_FORCE_CELLS`` centre-point pairs) are answered by computing every distance,
which costs a few array operations; larger ones by k-d trees over centres and points, whose
cost grows with the number of nearby pairs rather than with the product of the two counts.
Both give the pairs ordered by centre, then by point.
"""

from __future__ import annotations

import numpy as np
from scipy.spatial import cKDTree

__all__ = ["BRUTE_FORCE_CELLS", "pairs_within"]

#: Up to this many centre-point pairs every distance is computed; beyond, a k-d tree is used.
BRUTE_FORCE_CELLS = 10_000


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
    # One search with the largest radius between two trees, then each centre's own radius.
    near = cKDTree(centres).sparse_distance_matrix(
        cKDTree(points), float(radius.max()), output_type="ndarray"
    )
    i = near["i"].astype(np.intp)
    keep = near["v"] <= radius[i]
    i, j = i[keep], near["j"].astype(np.intp)[keep]
    order = np.argsort(i * m + j)
    return i[order], j[order]
