import numpy as np

from trackers.evaluation.effective_rate import EffectiveRateCounter


def test_held_needs_the_same_track_as_the_scan_before():
    c = EffectiveRateCounter(gate=150.0, warmup=1)
    truth = np.array([[0.0, 0.0], [1000.0, 0.0]])
    c.add([0, 1], truth, ["A"], [[10.0, 0.0]])  # warm-up scan: A on target 0
    c.add([0, 1], truth, ["A", "B"], [[10.0, 0.0], [1000.0, 20.0]])  # 0 held, 1 new
    c.add([0, 1], truth, ["C", "B"], [[5.0, 0.0], [1000.0, 20.0]])  # 0 changed, 1 held
    c.add([0, 1], truth, ["C", "B", "X"], [[5.0, 0.0], [1000.0, 400.0], [9e3, 0]])  # 1 lost
    r = c.result({0: "slow", 1: "fast"})
    assert r.scans == 3
    assert r.rate_by_class == {"fast": 1 / 3, "slow": 2 / 3}
    assert r.rate == 3 / 6
    assert r.false_per_scan == 2 / 3  # B far off and X, in the last scan


def test_a_duplicate_track_is_false():
    c = EffectiveRateCounter(gate=150.0, warmup=0)
    c.add([0], [[0.0, 0.0]], ["A", "B"], [[0.0, 0.0], [30.0, 0.0]])
    assert c.result().false_per_scan == 1.0
