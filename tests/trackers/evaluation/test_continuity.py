"""Track continuity: breaks and identity swaps on hand-built scan sequences."""

from __future__ import annotations

import numpy as np
import pytest

from trackers.evaluation.continuity import ContinuityCounter, gated_assignment
from trackers.types import TrackSnapshot

ScanSpec = tuple[dict[int, float], dict[str, float]]


def feed(counter: ContinuityCounter, scans: list[ScanSpec]) -> None:
    """Each scan: {target id: x} and {track id: x}, all at y = 0."""
    for targets, tracks in scans:
        tp = np.array([[x, 0.0] for x in targets.values()]).reshape(-1, 2)
        kp = np.array([[x, 0.0] for x in tracks.values()]).reshape(-1, 2)
        counter.add(list(targets), tp, list(tracks), kp)


def test_clean_follow() -> None:
    c = ContinuityCounter(gate=5.0)
    scans = [({1: float(k), 2: 100.0 + k}, {"A": k + 0.5, "B": 100.0 + k - 0.5}) for k in range(10)]
    feed(c, scans)
    r = c.result()
    assert r.breaks == {1: 0, 2: 0}
    assert r.swaps == {1: 0, 2: 0}
    assert (r.total_breaks, r.total_swaps) == (0, 0)
    assert r.track_ids_per_target == {1: ["A"], 2: ["B"]}


def test_initiation_late_is_not_a_break() -> None:
    c = ContinuityCounter(gate=5.0)
    feed(c, [({1: 0.0}, {}), ({1: 1.0}, {}), ({1: 2.0}, {"A": 2.0}), ({1: 3.0}, {"A": 3.0})])
    assert c.result().total_breaks == 0
    assert c.result().track_ids_per_target == {1: ["A"]}


def test_direct_replacement_is_a_break() -> None:
    c = ContinuityCounter(gate=5.0)
    feed(c, [({1: 0.0}, {"A": 0.0}), ({1: 1.0}, {"A": 1.0}), ({1: 2.0}, {"B": 2.0})])
    r = c.result()
    assert r.breaks == {1: 1}
    assert r.swaps == {1: 0}
    assert r.track_ids_per_target == {1: ["A", "B"]}


def test_loss_then_new_track_is_one_break() -> None:
    c = ContinuityCounter(gate=5.0)
    feed(
        c,
        [
            ({1: 0.0}, {"A": 0.0}),
            ({1: 1.0}, {}),
            ({1: 2.0}, {"A": 40.0}),  # A still exists but is outside the gate
            ({1: 3.0}, {"B": 3.0}),
            ({1: 4.0}, {"B": 4.0}),
        ],
    )
    r = c.result()
    assert (r.total_breaks, r.total_swaps) == (1, 0)


def test_loss_then_same_track_is_not_a_break() -> None:
    c = ContinuityCounter(gate=5.0)
    feed(c, [({1: 0.0}, {"A": 0.0}), ({1: 1.0}, {}), ({1: 2.0}, {}), ({1: 3.0}, {"A": 3.0})])
    assert c.result().total_breaks == 0


def test_loss_never_replaced_is_not_counted() -> None:
    c = ContinuityCounter(gate=5.0)
    feed(c, [({1: 0.0}, {"A": 0.0}), ({1: 1.0}, {}), ({1: 2.0}, {})])
    assert (c.result().total_breaks, c.result().total_swaps) == (0, 0)


def test_swap_of_two_crossing_targets() -> None:
    # Targets 1 and 2 cross; at the crossing the tracks exchange targets and stay exchanged.
    scans = []
    for k in range(9):
        x1, x2 = float(k), 8.0 - k
        tracks = {"A": x1, "B": x2} if k < 5 else {"A": x2, "B": x1}
        scans.append(({1: x1, 2: x2}, tracks))
    c = ContinuityCounter(gate=0.5)
    feed(c, scans)
    r = c.result()
    assert r.swaps == {1: 1, 2: 1}
    assert r.breaks == {1: 0, 2: 0}
    assert r.track_ids_per_target == {1: ["A", "B"], 2: ["B", "A"]}


def test_stolen_track_is_a_swap_for_the_thief_and_a_break_later_for_the_victim() -> None:
    c = ContinuityCounter(gate=1.0)
    feed(
        c,
        [
            ({1: 0.0, 2: 10.0}, {"A": 0.0, "B": 10.0}),
            ({1: 0.0, 2: 10.0}, {"A": 10.0}),  # A jumps to target 2, B disappears
            ({1: 0.0, 2: 10.0}, {"A": 10.0, "C": 0.0}),  # target 1 gets a new track
        ],
    )
    r = c.result()
    assert r.swaps == {1: 0, 2: 1}
    assert r.breaks == {1: 1, 2: 0}


def test_swap_needs_the_track_on_another_target_at_the_previous_scan() -> None:
    # B followed target 2 two scans ago, but followed nothing at the previous scan: a break.
    c = ContinuityCounter(gate=1.0)
    feed(
        c,
        [
            ({1: 0.0, 2: 10.0}, {"A": 0.0, "B": 10.0}),
            ({1: 0.0, 2: 10.0}, {"A": 0.0, "B": 50.0}),
            ({1: 0.0, 2: 10.0}, {"B": 0.0}),
        ],
    )
    r = c.result()
    assert (r.total_swaps, r.breaks[1]) == (0, 1)


def test_target_absent_from_some_scans() -> None:
    c = ContinuityCounter(gate=1.0)
    feed(c, [({1: 0.0}, {"A": 0.0}), ({}, {"A": 0.0}), ({1: 0.0}, {"A": 0.0}), ({2: 5.0}, {})])
    r = c.result()
    assert r.breaks == {1: 0, 2: 0}
    assert r.track_ids_per_target == {1: ["A"], 2: []}


def test_assignment_maximises_pairs_then_minimises_distance() -> None:
    truth = np.array([[0.0, 0.0], [2.0, 0.0]])
    tracks = np.array([[1.2, 0.0], [3.5, 0.0]])
    rows, cols = gated_assignment(truth, tracks, gate=1.5)
    # Nearest-first would give target 1 track 0 (0.8) and leave target 0 unfollowed.
    assert sorted(zip(rows.tolist(), cols.tolist(), strict=True)) == [(0, 0), (1, 1)]
    rows, cols = gated_assignment(truth, np.array([[1.0, 0.0], [2.5, 0.0]]), gate=5.0)
    assert sorted(zip(rows.tolist(), cols.tolist(), strict=True)) == [(0, 0), (1, 1)]
    rows, _ = gated_assignment(truth, np.array([[100.0, 0.0]]), gate=5.0)
    assert rows.size == 0


def test_result_is_a_snapshot_and_inputs_unchanged() -> None:
    c = ContinuityCounter(gate=1.0)
    pos = np.array([[0.0, 0.0]])
    before = pos.copy()
    c.add([1], pos, ["A"], pos)
    r = c.result()
    c.add([1], pos, ["B"], pos)
    assert r.total_breaks == 0 and r.track_ids_per_target == {1: ["A"]}
    assert c.result().total_breaks == 1
    assert np.array_equal(pos, before)


def test_add_tracks_uses_confirmed_snapshots() -> None:
    def snap(track_id: str, status: str, x: float) -> TrackSnapshot:
        return TrackSnapshot(
            id=track_id, kind="point", status=status, time=0.0, position=(x, 0.0),
            velocity=(0.0, 0.0), covariance=np.eye(4), score=0.0, hits=1, created=0.0,
            updated=0.0,
        )  # fmt: skip

    c = ContinuityCounter(gate=1.0)
    c.add_tracks([1], np.array([[0.0, 0.0]]), [snap("A", "confirmed", 0.0)])
    c.add_tracks([1], np.array([[0.0, 0.0]]), [snap("B", "tentative", 0.0)])
    c.add_tracks([1], np.array([[0.0, 0.0]]), [snap("A", "confirmed", 0.1)])
    assert c.result().total_breaks == 0


def test_invalid_input() -> None:
    with pytest.raises(ValueError):
        ContinuityCounter(gate=0.0)
    c = ContinuityCounter(gate=1.0)
    with pytest.raises(ValueError):
        c.add([1, 1], np.zeros((2, 2)), [], np.zeros((0, 2)))
    with pytest.raises(ValueError):
        c.add([1], np.zeros((2, 2)), [], np.zeros((0, 2)))


def test_close_parallel_targets_do_not_trade_tracks_on_noise():
    """Two targets 2 m apart, each followed by its own track whose error is larger than the
    spacing: a fresh nearest assignment every scan would flip; kept pairs do not."""
    counter = ContinuityCounter(gate=20.0)
    rng = np.random.default_rng(0)
    for k in range(50):
        truth = np.array([[10.0 * k, 0.0], [10.0 * k, 2.0]])
        tracks = truth + rng.normal(0, 3.0, (2, 2))
        counter.add([1, 2], truth, ["A", "B"], tracks)
    res = counter.result()
    assert res.total_swaps == 0 and res.total_breaks == 0
    assert res.track_ids_per_target == {1: ["A"], 2: ["B"]}


def test_a_real_exchange_is_still_a_swap():
    counter = ContinuityCounter(gate=20.0)
    for k in range(10):
        truth = np.array([[0.0, 0.0], [100.0, 0.0]])
        tracks = truth if k < 5 else truth[::-1]  # A and B jump to the other target
        counter.add([1, 2], truth, ["A", "B"], tracks)
    assert counter.result().total_swaps == 2
