import json
import re
import warnings
from dataclasses import fields, is_dataclass
from typing import get_type_hints

import numpy as np
import pytest

from clients.scenarios.multitarget import reference_scenario, simulate
from trackers.config import TrackerConfig
from trackers.pipeline import TrackingPipeline, check_scan
from trackers.types import Scan


def test_defaults_round_trip_through_json():
    c = TrackerConfig()
    again = TrackerConfig.from_dict(json.loads(json.dumps(c.to_dict())))
    assert again == c


def test_merged_changes_only_the_patched_field():
    c = TrackerConfig().merged({"track_management": {"pd": 0.7}})
    assert c.track_management.pd == 0.7
    assert c.track_management.clutter_density == TrackerConfig().track_management.clutter_density
    assert c.motion == TrackerConfig().motion


@pytest.mark.parametrize(
    ("patch", "field"),
    [
        ({"track_management": {"pd": 0.0}}, "track_management.pd"),
        ({"track_management": {"pd": 1.5}}, "track_management.pd"),
        ({"track_management": {"clutter_density": -1}}, "track_management.clutter_density"),
        ({"motion": {"q_cv": float("nan")}}, "motion.q_cv"),
        ({"motion": {"models": ["cv", "xx"]}}, "motion.models"),
        ({"motion": {"models": ["cv"]}}, "motion.sojourn_times"),
        ({"gating": {"gate_probability": 1.0}}, "gating.gate_probability"),
        ({"track_management": {"p_false_confirm": 5e-324}}, "track_management.p_false_confirm"),
        ({"gating": {"nope": 1.0}}, "gating"),
        ({"measurement": {"position_std": "ten"}}, "measurement.position_std"),
        ({"measurement": {"position_std": True}}, "measurement.position_std"),
        ({"track_management": {"pd": "0.8"}}, "track_management.pd: expected a number"),
        ({"track_management": {"pd": [0.8]}}, "track_management.pd: expected a number"),
        ({"motion": {"sojourn_times": ["30", "10"]}}, "motion.sojourn_times[0]: expected a number"),
        ({"motion": {"sojourn_times": [True, True]}}, "motion.sojourn_times[0]: expected a number"),
        ({"motion": {"initial_mode_probabilities": 1.0}}, "motion.initial_mode_probabilities"),
        ({"motion": {"models": "cv"}}, "motion.models: expected a list"),
        ({"motion": {"models": ["cv", 2]}}, "motion.models[1]: expected a string"),
        ({"initiation": 3}, "initiation"),
        ({"initiation": {"method": "three_point"}}, "initiation.method"),
        ({"initiation": {"max_speed": 0}}, "initiation.max_speed"),
        ({"initiation": {"max_speed": 1e9}}, "initiation.max_speed"),
        ({"initiation": {"slow_target_fraction": 1.0}}, "initiation.slow_target_fraction"),
        ({"initiation": {"candidate_max_age": -1}}, "initiation.candidate_max_age"),
        ({"initiation": {"max_pairs_per_candidate": 0}}, "initiation.max_pairs_per_candidate"),
        ({"initiation": {"max_pairs_per_candidate": 2.5}}, "expected an integer"),
        ({"initiation": {"max_pairs_per_candidate": True}}, "expected an integer"),
    ],
)
def test_invalid_values_name_the_field(patch, field):
    with pytest.raises(ValueError, match=re.escape(field)):
        TrackerConfig().merged(patch)


def test_single_model_configuration_is_valid():
    c = TrackerConfig().merged(
        {"motion": {"models": ["cv"], "sojourn_times": [10.0], "initial_mode_probabilities": [1.0]}}
    )
    assert c.motion.models == ("cv",)


def test_integer_field_takes_an_integer_or_an_integral_number():
    c = TrackerConfig().merged({"initiation": {"max_pairs_per_candidate": 3}})
    assert c.initiation.max_pairs_per_candidate == 3
    c = TrackerConfig().merged({"initiation": {"max_pairs_per_candidate": 4.0}})
    assert c.initiation.max_pairs_per_candidate == 4
    assert isinstance(c.initiation.max_pairs_per_candidate, int)


def _leaves(cls, prefix=""):
    hints = get_type_hints(cls)
    for f in fields(cls):
        if is_dataclass(hints[f.name]):
            yield from _leaves(hints[f.name], f"{prefix}{f.name}.")
        else:
            yield prefix + f.name, f


def _at_bound(f, end):
    """The field's value at its lowest or highest allowed end (just inside an open bound)."""
    m = f.metadata
    closed, open_ = ("ge", "gt") if end == "low" else ("le", "lt")
    if closed in m:
        return m[closed]
    if open_ not in m:
        return None
    b = m[open_]
    if end == "low":
        return 1e-300 if b == 0 else b * (1 + 1e-9)
    return b * (1 - 1e-9)


BOUNDED = [
    (path, end)
    for path, f in _leaves(TrackerConfig)
    for end in ("low", "high")
    if _at_bound(f, end) is not None and not path.endswith("initial_mode_probabilities")
]


@pytest.mark.parametrize(("path", "end"), BOUNDED)
def test_a_configuration_that_validates_is_one_the_tracker_runs(path, end):
    """Every number at either end of its bounds: the tracker runs a scenario with finite
    tracks, including detections whose covariance comes from ``measurement.position_std``."""
    f = dict(_leaves(TrackerConfig))[path]
    value = _at_bound(f, end)
    section, name = path.split(".")
    if name == "sojourn_times":
        value = [value, value]
    try:
        config = TrackerConfig().merged({section: {name: value}})
    except ValueError as exc:
        assert "threshold" in str(exc)  # α, β near 1: the two thresholds cross
        return
    pipeline = TrackingPipeline(config)
    std = config.measurement.position_std
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        for k, sim in enumerate(simulate(reference_scenario(0))[:10]):
            scan = sim.to_scan()
            if k % 2:  # as the service builds a batch without covariances
                scan = Scan(
                    scan.sensor_id,
                    scan.time,
                    scan.z,
                    np.tile(std**2 * np.eye(2), (scan.size, 1, 1)),
                )
            check_scan(scan, pipeline.last_time)
            for t in pipeline.process(scan).tracks:
                assert np.isfinite(t.covariance).all() and np.isfinite(t.position).all()
                assert np.isfinite(t.score)
