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


@pytest.mark.parametrize(
    ("cells", "strip"),
    [(spatial.BRUTE_FORCE_CELLS, 8), (0, 10**9), (0, 0)],
    ids=["every-distance", "x-strips", "k-d-trees"],
)
@pytest.mark.parametrize(("n", "m"), [(0, 5), (5, 0), (1, 1), (40, 60), (150, 90)])
def test_pairs_within_finds_every_pair_in_order(n, m, cells, strip, monkeypatch):
    """Distances computed outright, the x strips and the k-d trees give exactly the pairs
    within each centre's radius, sorted by centre then point."""
    monkeypatch.setattr(spatial, "BRUTE_FORCE_CELLS", cells)
    monkeypatch.setattr(spatial, "STRIP_POINTS_PER_ITEM", strip)
    rng = np.random.default_rng(n * 1000 + m)
    centres = rng.uniform(0, 1000, (n, 2))
    points = rng.uniform(0, 1000, (m, 2))
    radius = rng.uniform(0, 150, n)
    i, j = pairs_within(centres, radius, points)
    assert i.dtype == j.dtype == np.intp
    assert list(zip(i.tolist(), j.tolist(), strict=True)) == brute_force(centres, radius, points)


def test_points_sharing_an_x_keep_the_order_by_point(monkeypatch):
    """Points with equal x (a column of detections) come back sorted by index in the strips."""
    monkeypatch.setattr(spatial, "BRUTE_FORCE_CELLS", 0)
    monkeypatch.setattr(spatial, "STRIP_POINTS_PER_ITEM", 10**9)
    points = np.array([[0.0, 3.0], [5.0, 0.0], [0.0, 1.0], [0.0, 2.0], [-1.0, 0.0]])
    i, j = pairs_within(np.array([[0.0, 2.0], [0.0, 0.0]]), np.array([1.0, 10.0]), points)
    assert list(zip(i.tolist(), j.tolist(), strict=True)) == [
        (0, 0),
        (0, 2),
        (0, 3),
        (1, 0),
        (1, 1),
        (1, 2),
        (1, 3),
        (1, 4),
    ]
