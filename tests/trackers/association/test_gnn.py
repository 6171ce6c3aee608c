import itertools

import numpy as np
import pytest

from trackers.association import gnn
from trackers.association.clusters import cluster_pairs
from trackers.association.gnn import gnn_assign


def brute_force_best(track, det, gain):
    """Best total gain over all one-to-one subsets of the pairs."""
    best = 0.0
    k = len(track)
    for r in range(1, k + 1):
        for subset in itertools.combinations(range(k), r):
            ts = [track[s] for s in subset]
            ds = [det[s] for s in subset]
            if len(set(ts)) == r and len(set(ds)) == r:
                best = max(best, sum(max(gain[s], 0) for s in subset))
    return best


def test_clusters_split_independent_groups():
    # tracks 0,1 share detection 1; track 2 alone with detection 3; track 3 with dets 4, 5
    track = np.array([0, 0, 1, 2, 3, 3])
    det = np.array([0, 1, 1, 3, 4, 5])
    c = cluster_pairs(track, det, 4, 6)
    assert c.singles.tolist() == [3]
    groups = sorted(sorted(g.tolist()) for g in c.groups)
    assert groups == [[0, 1, 2], [4, 5]]


def test_gnn_prefers_the_global_optimum_to_greedy():
    # Greedy would give track 0 detection 0 (gain 10) and leave track 1 with nothing (total 10);
    # the optimum is 0->1 and 1->0 (9 + 9 = 18).
    track = np.array([0, 0, 1])
    det = np.array([0, 1, 0])
    gain = np.array([10.0, 9.0, 9.0])
    sel = gnn_assign(track, det, gain, 2, 2)
    t, d = track[sel], det[sel]
    assert sorted(zip(t.tolist(), d.tolist(), strict=True)) == [(0, 1), (1, 0)]


def test_gnn_leaves_pairs_with_no_gain_unassigned():
    assert gnn_assign(np.array([0, 1]), np.array([0, 1]), np.array([-1.0, 2.0]), 2, 2).tolist() == [
        1
    ]


@pytest.mark.parametrize("joint_cells", [gnn.JOINT_CELLS, 0])
@pytest.mark.parametrize("seed", range(20))
def test_gnn_matches_brute_force_on_random_problems(seed, joint_cells, monkeypatch):
    """The optimum, whether the clusters are solved together (the default for small problems)
    or one by one (``JOINT_CELLS = 0``, as for large ones)."""
    monkeypatch.setattr(gnn, "JOINT_CELLS", joint_cells)
    rng = np.random.default_rng(seed)
    n_t, n_d = 4, 5
    pairs = [(i, j) for i in range(n_t) for j in range(n_d) if rng.random() < 0.4]
    if not pairs:
        pytest.skip("empty draw")
    track = np.array([p[0] for p in pairs])
    det = np.array([p[1] for p in pairs])
    gain = rng.normal(3, 3, size=len(pairs))
    sel = gnn_assign(track, det, gain, n_t, n_d)
    t, d = track[sel], det[sel]
    assert len(set(t.tolist())) == t.size and len(set(d.tolist())) == d.size
    lookup = {(a, b): g for a, b, g in zip(track.tolist(), det.tolist(), gain, strict=True)}
    total = sum(lookup[(a, b)] for a, b in zip(t.tolist(), d.tolist(), strict=True))
    assert total == pytest.approx(brute_force_best(track.tolist(), det.tolist(), gain.tolist()))


def test_joint_and_per_cluster_solutions_take_the_same_gain(monkeypatch):
    """Many small clusters of a large scene: solving them together and one by one gives the
    same summed gain, and each track and detection at most once."""
    rng = np.random.default_rng(7)
    n = 300
    track = np.repeat(np.arange(n), 3)
    det = np.clip(track + rng.integers(-2, 3, track.size), 0, n - 1)
    pairs = np.unique(np.stack([track, det], axis=1), axis=0)
    track, det = pairs[:, 0], pairs[:, 1]
    gain = rng.normal(2.0, 2.0, track.size)
    totals = []
    for cells in (10**9, 0):
        monkeypatch.setattr(gnn, "JOINT_CELLS", cells)
        sel = gnn_assign(track, det, gain, n, n)
        assert np.unique(track[sel]).size == sel.size == np.unique(det[sel]).size
        totals.append(gain[sel].sum())
    assert totals[0] == pytest.approx(totals[1])
