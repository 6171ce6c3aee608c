"""The floor of displaced tracks in benchmarks.speeds, on hand-made scenarios."""

from __future__ import annotations

from benchmarks.speeds import WARMUP_SCANS, coasting_floor
from clients.scenarios.airspace import (
    Manoeuvre,
    PolarRadar,
    ScriptedScenario,
    ScriptedTarget,
    simulate_scripted,
)


def _scenario(manoeuvres: tuple[Manoeuvre, ...], pd: float) -> ScriptedScenario:
    target = ScriptedTarget("jet", (20_000.0, 0.0, 0.0, 600.0), manoeuvres, q=0.0)
    radar = PolarRadar(
        sensor_id="r",
        position=(0.0, 0.0),
        period=4.0,
        range_std=50.0,
        bearing_std=1e-3,
        pd=pd,
        clutter_mean=0.0,
        clutter_area=((-1.0, 1.0), (-1.0, 1.0)),
    )
    return ScriptedScenario(targets=(target,), radars=(radar,), duration=80.0, seed=1)


def test_straight_flight_has_no_floor_and_a_turn_between_detections_has_one() -> None:
    assert coasting_floor(_scenario((), pd=0.5)) == (0.0, 0.0)
    # A 0.1 rad/s turn at 600 m/s all along: a 4 s coast ends about 480 m off the straight
    # line, and on the true turn.
    turning = _scenario((Manoeuvre(start=0.0, duration=1e3, turn_rate=0.1),), pd=0.5)
    scans = simulate_scripted(turning)
    seen = [0 in s.target_of_detection.tolist() for s in scans]
    missed_after_a_detection = sum(
        not seen[k] and any(seen[:k]) for k in range(WARMUP_SCANS, len(scans))
    )
    assert missed_after_a_detection > 0
    assert coasting_floor(turning) == (0.0, missed_after_a_detection / (len(scans) - WARMUP_SCANS))
