import json
import re

import pytest

from trackers.config import TrackerConfig


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
