"""Resolution-distance subsets and their nested unions (trackers/extended/partition.py)."""

import numpy as np
import pytest

from trackers.extended.partition import (
    BRUTE_FORCE_POINTS,
    close_pairs,
    component_labels,
    nested_unions,
    resolution_subsets,
)


def test_chains_closer_than_the_resolution_distance_are_one_subset():
    Z = np.array([[0, 0], [90, 0], [180, 0], [500, 0], [590, 0], [2000, 0]], dtype=float)
    subsets = resolution_subsets(Z, 100.0)
    assert [s.tolist() for s in subsets] == [[0, 1, 2], [3, 4], [5]]


def test_empty_single_and_all_apart():
    assert resolution_subsets(np.zeros((0, 2)), 10.0) == []
    assert [s.tolist() for s in resolution_subsets(np.array([[1.0, 2.0]]), 10.0)] == [[0]]
    Z = np.array([[0, 0], [0, 50], [50, 0]], dtype=float)
    assert [s.tolist() for s in resolution_subsets(Z, 10.0)] == [[0], [1], [2]]


def test_subsets_cover_every_point_once_in_a_large_random_scan():
    rng = np.random.default_rng(3)
    Z = rng.uniform(0, 10_000, size=(3000, 2))
    subsets = resolution_subsets(Z, 150.0)
    rows = np.sort(np.concatenate(subsets))
    assert rows.tolist() == list(range(3000))
    # no two points of different subsets are closer than the resolution distance
    label = np.empty(3000, dtype=int)
    for k, s in enumerate(subsets):
        label[s] = k
    from scipy.spatial import cKDTree

    pairs = cKDTree(Z).query_pairs(149.9, output_type="ndarray")
    assert (label[pairs[:, 0]] == label[pairs[:, 1]]).all()


def test_nested_unions_add_the_best_fitting_subsets_first():
    subsets = [np.array([0, 1]), np.array([2]), np.array([3, 4])]
    unions = nested_unions(subsets, np.array([5.0, 9.0, 1.0]))
    assert [u.tolist() for u in unions] == [[3, 4], [0, 1, 3, 4], [0, 1, 2, 3, 4]]


def test_bad_resolution_distance_and_fit_count():
    with pytest.raises(ValueError, match="d_res"):
        resolution_subsets(np.zeros((2, 2)), 0.0)
    with pytest.raises(ValueError, match="one fit"):
        nested_unions([np.array([0])], np.array([1.0, 2.0]))


def _components_by_scipy(n: int, i: np.ndarray, j: np.ndarray) -> list[tuple[int, ...]]:
    from scipy.sparse import coo_matrix
    from scipy.sparse.csgraph import connected_components

    graph = coo_matrix((np.ones(len(i)), (i, j)), shape=(n, n))
    _, label = connected_components(graph, directed=False)
    return sorted(tuple(np.flatnonzero(label == k).tolist()) for k in set(label.tolist()))


@pytest.mark.parametrize("n_edges", [30, 3000])  # the union-find loop and the array rounds
def test_component_labels_are_each_components_smallest_node(n_edges):
    rng = np.random.default_rng(n_edges)
    n = 4000
    i, j = rng.integers(0, n, n_edges), rng.integers(0, n, n_edges)
    i, j = np.r_[i, i[:5], 7, 7], np.r_[j, j[:5], 7, 8]  # repeated edges and a loop
    labels = component_labels(n, i, j)
    got = sorted(tuple(np.flatnonzero(labels == k).tolist()) for k in set(labels.tolist()))
    assert got == _components_by_scipy(n, i, j)
    assert all(labels[v] == min(np.flatnonzero(labels == labels[v])) for v in range(0, n, 97))


@pytest.mark.parametrize("n", [40, 300])  # every pair tested, and the k-d tree
def test_subsets_match_connected_components_and_min_size_keeps_the_large_ones(n):
    rng = np.random.default_rng(n)
    Z = rng.uniform(0, 2000, size=(n, 2))
    from scipy.spatial import cKDTree

    pairs = cKDTree(Z).query_pairs(150.0, output_type="ndarray").reshape(-1, 2)
    expected = _components_by_scipy(n, pairs[:, 0], pairs[:, 1])
    assert [tuple(s.tolist()) for s in resolution_subsets(Z, 150.0)] == expected
    big = [tuple(s.tolist()) for s in resolution_subsets(Z, 150.0, min_size=3)]
    assert big == [s for s in expected if len(s) >= 3] and big


@pytest.mark.parametrize("n", [0, 1, 2, 17, BRUTE_FORCE_POINTS])
def test_close_pairs_of_a_few_points_are_every_pair_within_the_distance_in_order(n):
    """The pairs of a few points (every distance) are those of a plain double loop, ``i < j``
    in row order; points exactly at the distance count; many points (a k-d tree) give the
    same set."""
    rng = np.random.default_rng(n)
    Z = rng.uniform(0, 1000, (n, 2))
    if n >= 2:
        Z[1] = Z[0] + [120.0, 160.0]  # exactly 200 m apart
    i, j = close_pairs(Z, 200.0)
    want = [
        (a, b)
        for a in range(n)
        for b in range(a + 1, n)
        if (Z[a, 0] - Z[b, 0]) ** 2 + (Z[a, 1] - Z[b, 1]) ** 2 <= 200.0**2
    ]
    assert list(zip(i.tolist(), j.tolist(), strict=True)) == want
    assert n < 2 or (0, 1) in want
    many = np.vstack([Z, rng.uniform(5000, 9000, (BRUTE_FORCE_POINTS, 2))])
    ti, tj = close_pairs(many, 200.0)
    inside = ti < n
    assert sorted(zip(ti[inside].tolist(), tj[inside].tolist(), strict=True)) == want
