import json

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
        ({"initiation": 3}, "initiation"),
    ],
)
def test_invalid_values_name_the_field(patch, field):
    with pytest.raises(ValueError, match=field.replace(".", r"\.")):
        TrackerConfig().merged(patch)


def test_single_model_configuration_is_valid():
    c = TrackerConfig().merged(
        {"motion": {"models": ["cv"], "sojourn_times": [10.0], "initial_mode_probabilities": [1.0]}}
    )
    assert c.motion.models == ("cv",)
