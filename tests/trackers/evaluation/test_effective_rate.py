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


def test_a_target_s_own_track_gone_astray_is_false_and_displaced_clutter_is_spurious():
    c = EffectiveRateCounter(gate=150.0, warmup=1, displaced_gate=1000.0)
    truth = np.array([[0.0, 0.0], [5000.0, 0.0]])
    c.add([0, 1], truth, ["A", "B"], [[10.0, 0.0], [5000.0, 0.0]])  # warm-up: A on 0, B on 1
    # A coasts 400 m off its target (displaced); B is 2 km off (too far: spurious); X is clutter
    c.add([0, 1], truth, ["A", "B", "X"], [[400.0, 0.0], [7000.0, 0.0], [-9e3, 0.0]])
    # A is back on its target; a new track C took target 1, so B is spurious whatever its distance
    c.add([0, 1], truth, ["A", "B", "C"], [[0.0, 0.0], [5300.0, 0.0], [5000.0, 50.0]])
    r = c.result()
    assert r.scans == 2
    assert r.false_per_scan == 4 / 2
    assert r.displaced_per_scan == 1 / 2
    assert r.spurious_per_scan == 3 / 2
    assert r.rate == 0.0  # A came back, but target 0 had no track at the scan before


def test_a_duplicate_is_never_displaced():
    c = EffectiveRateCounter(gate=150.0, warmup=0)
    c.add([0], [[0.0, 0.0]], ["A", "B"], [[0.0, 0.0], [30.0, 0.0]])
    c.add([0], [[0.0, 0.0]], ["A", "B"], [[0.0, 0.0], [200.0, 0.0]])
    r = c.result()
    assert r.false_per_scan == 2 / 2
    assert r.displaced_per_scan == 0.0
