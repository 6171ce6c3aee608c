"""GOSPA and OSPA: hand-worked values, brute-force optimality, edge cases."""

from __future__ import annotations

import itertools
import math

import numpy as np
import pytest

from trackers.evaluation.gospa import gospa, ospa, track_positions
from trackers.types import TrackSnapshot


def brute_gospa(X: np.ndarray, Y: np.ndarray, c: float, p: float, alpha: float) -> float:
    """The definition: min over injections of the smaller set into the larger."""
    if X.shape[0] > Y.shape[0]:
        X, Y = Y, X
    n, m = X.shape[0], Y.shape[0]
    best = math.inf
    for perm in itertools.permutations(range(m), n):
        cost = sum(min(float(np.linalg.norm(X[i] - Y[j])), c) ** p for i, j in enumerate(perm))
        best = min(best, cost)
    if n == 0:
        best = 0.0
    return (best + c**p / alpha * (m - n)) ** (1 / p)


def brute_gospa_sets(X: np.ndarray, Y: np.ndarray, c: float, p: float) -> float:
    """The α = 2 assignment-set form: min over partial assignments γ (no cut-off)."""
    n, m = X.shape[0], Y.shape[0]
    best = math.inf
    for size in range(min(n, m) + 1):
        for rows in itertools.combinations(range(n), size):
            for cols in itertools.permutations(range(m), size):
                pairs = zip(rows, cols, strict=True)
                loc = sum(float(np.linalg.norm(X[i] - Y[j])) ** p for i, j in pairs)
                best = min(best, loc + c**p / 2 * (n + m - 2 * size))
    return best ** (1 / p)


def brute_ospa(X: np.ndarray, Y: np.ndarray, c: float, p: float) -> float:
    if X.shape[0] > Y.shape[0]:
        X, Y = Y, X
    n, m = X.shape[0], Y.shape[0]
    if m == 0:
        return 0.0
    best = 0.0 if n == 0 else math.inf
    for perm in itertools.permutations(range(m), n):
        cost = sum(min(float(np.linalg.norm(X[i] - Y[j])), c) ** p for i, j in enumerate(perm))
        best = min(best, cost)
    return ((best + c**p * (m - n)) / m) ** (1 / p)


def test_single_pair_within_cutoff() -> None:
    r = gospa(np.array([[0.0, 0.0]]), np.array([[3.0, 0.0]]), c=10.0)
    assert r.distance == pytest.approx(3.0)
    assert r.localisation == pytest.approx(3.0)
    assert (r.missed, r.false) == (0, 0)
    assert r.assignment.tolist() == [0]


def test_missed_target() -> None:
    r = gospa(np.array([[0.0, 0.0]]), np.empty((0, 2)), c=10.0, p=2.0)
    assert r.distance == pytest.approx(math.sqrt(100.0 / 2))
    assert (r.missed, r.false) == (1, 0)
    assert r.localisation == 0.0
    assert r.assignment.tolist() == [-1]


def test_false_track_p1() -> None:
    r = gospa(np.empty((0, 2)), np.array([[5.0, 5.0]]), c=4.0, p=1.0)
    assert r.distance == pytest.approx(2.0)
    assert (r.missed, r.false) == (0, 1)
    assert r.assignment.shape == (0,)


def test_both_empty() -> None:
    r = gospa(np.empty((0, 2)), np.empty((0, 2)), c=10.0)
    assert r.distance == 0.0
    assert (r.missed, r.false) == (0, 0)
    assert ospa(np.empty((0, 2)), np.empty((0, 2)), c=10.0) == 0.0


def test_combination_by_hand() -> None:
    # Truth: a at origin (estimate at distance 3 -> localisation 9),
    # b at (100, 0) with an estimate at distance 20 > c (-> one missed + one false),
    # c at (0, 100) with nothing (missed). One more false estimate far away.
    truth = np.array([[0.0, 0.0], [100.0, 0.0], [0.0, 100.0]])
    est = np.array([[3.0, 0.0], [120.0, 0.0], [-500.0, -500.0]])
    r = gospa(truth, est, c=10.0, p=2.0)
    # 9 + 100/2 * (2 missed + 2 false) = 209
    assert r.distance == pytest.approx(math.sqrt(209.0))
    assert r.localisation == pytest.approx(3.0)
    assert (r.missed, r.false) == (2, 2)
    assert r.assignment.tolist() == [0, -1, -1]


def test_pair_beyond_cutoff_counts_as_missed_and_false() -> None:
    r = gospa(np.array([[0.0, 0.0]]), np.array([[50.0, 0.0]]), c=10.0, p=1.0)
    assert r.distance == pytest.approx(10.0)  # c/2 + c/2
    assert (r.missed, r.false) == (1, 1)


def test_alpha_one_by_hand() -> None:
    # One truth, two estimates at distances 1 and 5, c = 4, p = 1, α = 1:
    # min(1, 4) + 4/1 * 1 = 5.
    r = gospa(np.array([[0.0, 0.0]]), np.array([[1.0, 0.0], [0.0, 5.0]]), 4.0, 1.0, 1.0)
    assert r.distance == pytest.approx(5.0)
    assert r.assignment.tolist() == [0]


def test_optimal_not_greedy() -> None:
    # Greedy nearest neighbour would pair truth 0 with estimate 0 (distance 1) and then
    # truth 1 with estimate 1 (distance 3.5); the optimum pairs them the other way round.
    truth = np.array([[0.0, 0.0], [2.0, 0.0]])
    est = np.array([[1.0, 0.0], [-1.5, 0.0]])
    r = gospa(truth, est, c=10.0, p=2.0)
    assert r.assignment.tolist() == [1, 0]
    assert r.distance == pytest.approx(math.sqrt(1.5**2 + 1.0))


@pytest.mark.parametrize("seed", range(40))
def test_against_brute_force(seed: int) -> None:
    rng = np.random.default_rng(seed)
    n, m = rng.integers(0, 5, size=2)
    X = rng.uniform(0, 20, size=(n, 2))
    Y = rng.uniform(0, 20, size=(m, 2))
    c = float(rng.uniform(2, 15))
    p = float(rng.choice([1.0, 2.0, 3.0]))
    alpha = float(rng.choice([0.5, 1.0, 2.0]))
    r = gospa(X, Y, c, p, alpha)
    assert r.distance == pytest.approx(brute_gospa(X, Y, c, p, alpha), rel=1e-9, abs=1e-12)
    assert r.distance == pytest.approx(gospa(Y, X, c, p, alpha).distance)  # symmetric
    # The assignment is one-to-one, within the cut-off, and the counts follow from it.
    assigned = r.assignment[r.assignment >= 0]
    assert len(set(assigned.tolist())) == assigned.size
    if assigned.size:
        d = np.linalg.norm(X[r.assignment >= 0] - Y[assigned], axis=1)
        assert np.all(d < c)
        assert r.localisation == pytest.approx(float(np.sum(d**p)) ** (1 / p))
    assert r.missed == n - assigned.size
    assert r.false == m - assigned.size
    if alpha == 2.0:
        assert r.distance == pytest.approx(brute_gospa_sets(X, Y, c, p))
        decomposed = r.localisation**p + c**p / 2 * (r.missed + r.false)
        assert r.distance**p == pytest.approx(decomposed)


def test_inputs_not_modified() -> None:
    X = np.array([[0.0, 0.0], [1.0, 1.0]])
    Y = np.array([[0.5, 0.0]])
    X0, Y0 = X.copy(), Y.copy()
    gospa(X, Y, c=3.0)
    ospa(X, Y, c=3.0)
    assert np.array_equal(X, X0) and np.array_equal(Y, Y0)


def test_invalid_parameters() -> None:
    X = np.zeros((1, 2))
    with pytest.raises(ValueError):
        gospa(X, X, c=0.0)
    with pytest.raises(ValueError):
        gospa(X, X, c=1.0, p=0.5)
    with pytest.raises(ValueError):
        gospa(X, X, c=1.0, alpha=3.0)
    with pytest.raises(ValueError):
        gospa(np.zeros((1, 2)), np.zeros((1, 3)), c=1.0)


def test_ospa_known_values() -> None:
    assert ospa(np.array([[0.0, 0.0]]), np.array([[3.0, 4.0]]), c=10.0) == pytest.approx(5.0)
    assert ospa(np.array([[0.0, 0.0]]), np.empty((0, 2)), c=7.0) == pytest.approx(7.0)
    # One perfect estimate plus one false one, p = 1: (0 + c) / 2.
    assert ospa(np.zeros((1, 2)), np.array([[0.0, 0.0], [50.0, 0.0]]), 10.0, 1.0) == 5.0
    # p = 2: sqrt((3² + 10²) / 2).
    value = ospa(np.zeros((1, 2)), np.array([[3.0, 0.0], [50.0, 0.0]]), 10.0, 2.0)
    assert value == pytest.approx(math.sqrt(109.0 / 2))
    # Beyond the cut-off a pair costs c.
    assert ospa(np.zeros((1, 2)), np.array([[30.0, 0.0]]), c=10.0) == pytest.approx(10.0)


@pytest.mark.parametrize("seed", range(20))
def test_ospa_brute_force_and_gospa_relation(seed: int) -> None:
    rng = np.random.default_rng(100 + seed)
    n, m = rng.integers(0, 5, size=2)
    X = rng.uniform(0, 20, size=(n, 2))
    Y = rng.uniform(0, 20, size=(m, 2))
    c, p = float(rng.uniform(2, 15)), float(rng.choice([1.0, 2.0]))
    value = ospa(X, Y, c, p)
    assert value == pytest.approx(brute_ospa(X, Y, c, p), rel=1e-9, abs=1e-12)
    assert 0.0 <= value <= c + 1e-12
    if max(n, m) > 0:
        g = gospa(X, Y, c, p, alpha=1.0).distance
        assert value**p * max(n, m) == pytest.approx(g**p)


def test_track_positions() -> None:
    def snap(track_id: str, status: str, x: float) -> TrackSnapshot:
        return TrackSnapshot(
            id=track_id, kind="point", status=status, time=0.0, position=(x, 1.0),
            velocity=(0.0, 0.0), covariance=np.eye(4), score=0.0, hits=1, created=0.0,
            updated=0.0,
        )  # fmt: skip

    tracks = [snap("a", "confirmed", 1.0), snap("b", "tentative", 2.0)]
    assert track_positions(tracks).tolist() == [[1.0, 1.0]]
    assert track_positions(tracks, confirmed_only=False).shape == (2, 2)
    assert track_positions([]).shape == (0, 2)
