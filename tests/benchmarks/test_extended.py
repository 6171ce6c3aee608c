"""The extended-object benchmark's own figures (benchmarks/extended.py)."""

from __future__ import annotations

from dataclasses import replace
from pathlib import Path

import numpy as np

from benchmarks.extended import centroid_floor, write_plots
from clients.scenarios.extended import ExtendedScenarioRun, convoy_scenario


def _every_member_seen_exactly(run: ExtendedScenarioRun) -> ExtendedScenarioRun:
    """``run`` with each scan's detections replaced by the true positions of all members."""
    members = [i for i, c in run.target_class.items() if c == "convoy"]
    scans = []
    for ts in run.scans:
        sim = ts.scan
        ids = list(sim.truth_ids)
        z = sim.truth_states[[ids.index(i) for i in members], :2]
        scans.append(replace(ts, scan=replace(sim, z=z, target_of_detection=np.array(members))))
    return replace(run, scans=tuple(scans))


def test_centroid_floor_is_the_filter_lag_alone_when_every_member_is_seen_exactly():
    run = convoy_scenario(0)
    assert centroid_floor(_every_member_seen_exactly(run)) < 10.0
    # as simulated (Pd 0.7 per member, merged returns), the mean of what a scan shows
    # wanders by tens of metres: no tracker of the detections gets near 15 m
    assert 20.0 < centroid_floor(run) < 40.0


def test_plots_show_both_scenarios_for_both_trackers(tmp_path: Path) -> None:
    paths = write_plots(tmp_path)
    assert [p.name for p in paths] == ["convoy.png", "harbour.png"]
    for path in paths:
        assert path.stat().st_size > 20_000
        assert path.read_bytes()[:4] == b"\x89PNG"
