"""The spatial pre-gate: every pair within reach, the same from both search methods."""

import numpy as np
import pytest

from trackers.association import spatial
from trackers.association.spatial import pairs_within


def brute_force(centres, radius, points):
    return [
        (i, j)
        for i in range(len(centres))
        for j in range(len(points))
        if np.hypot(*(points[j] - centres[i])) <= radius[i]
    ]


@pytest.mark.parametrize("cells", [spatial.BRUTE_FORCE_CELLS, 0])
@pytest.mark.parametrize(("n", "m"), [(0, 5), (5, 0), (1, 1), (40, 60), (150, 90)])
def test_pairs_within_finds_every_pair_in_order(n, m, cells, monkeypatch):
    """Distances computed outright and the k-d tree (``BRUTE_FORCE_CELLS = 0``) give exactly
    the pairs within each centre's radius, sorted by centre then point."""
    monkeypatch.setattr(spatial, "BRUTE_FORCE_CELLS", cells)
    rng = np.random.default_rng(n * 1000 + m)
    centres = rng.uniform(0, 1000, (n, 2))
    points = rng.uniform(0, 1000, (m, 2))
    radius = rng.uniform(0, 150, n)
    i, j = pairs_within(centres, radius, points)
    assert i.dtype == j.dtype == np.intp
    assert list(zip(i.tolist(), j.tolist(), strict=True)) == brute_force(centres, radius, points)
