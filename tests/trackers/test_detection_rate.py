"""Each sensor's learned detection probability and the coasting limit it sets."""

import math

import pytest

from trackers.detection_rate import (
    FADE,
    MAX_MISSES,
    MAX_SENSORS,
    MIN_MISSES,
    PRIOR_LOOKS,
    DetectionRates,
    coast_revisits,
)


@pytest.mark.parametrize(
    ("pd", "revisits"),
    [
        (0.9, 2.5),  # deleted at the third miss: (0.1)^3 = β
        (0.8, math.log(1e-3) / math.log(0.2) - 0.5),  # 3.79: at the fourth
        (0.7, math.log(1e-3) / math.log(0.3) - 0.5),  # 5.24: at the sixth
        (0.99, MIN_MISSES - 0.5),  # never below the rule of 2.5 revisits
        (0.2, MAX_MISSES - 0.5),  # nor above 9.5
        (1.0, MIN_MISSES - 0.5),
    ],
)
def test_coast_revisits_give_beta_for_the_misses_in_a_row(pd, revisits):
    assert coast_revisits(pd, 1e-3) == pytest.approx(revisits)


def test_a_true_track_is_deleted_by_coasting_with_probability_beta():
    for pd in (0.75, 0.8, 0.85):
        m = coast_revisits(pd, 1e-3) + 0.5
        assert (1 - pd) ** m == pytest.approx(1e-3)


def test_the_estimate_starts_at_the_prior_and_moves_to_what_is_seen():
    rates = DetectionRates()
    assert rates.estimate("r", 0.9) == 0.9
    rates = rates.learned("r", 0.0, looks=10, detected=7)
    assert rates.estimate("r", 0.9) == pytest.approx((7 + PRIOR_LOOKS * 0.9) / (10 + PRIOR_LOOKS))
    for k in range(1, 400):
        rates = rates.learned("r", float(k), looks=10, detected=7)
    assert rates.estimate("r", 0.9) == pytest.approx(0.7, abs=0.01)
    assert rates.of("r").time == 399.0
    assert rates.of("r").looks == pytest.approx(10 / (1 - FADE), rel=1e-3)
    assert rates.estimate("other", 0.9) == 0.9  # per sensor


def test_learning_returns_a_new_record():
    empty = DetectionRates()
    once = empty.learned("r", 1.0, 3, 2)
    assert empty.of("r") is None and once.of("r").time == 1.0


def test_a_scan_without_looks_fades_the_counts_and_records_its_time():
    rates = DetectionRates().learned("r", 0.0, 10, 5).learned("r", 1.0, 0, 0)
    r = rates.of("r")
    assert (r.time, r.looks, r.detected) == (1.0, 10 * FADE, 5 * FADE)


def test_the_interval_between_a_sensors_scans_is_learned():
    rates = DetectionRates().learned("r", 0.0, 1, 1)
    assert rates.interval("r") == 0.0 and rates.interval("other") == 0.0  # unknown yet
    rates = rates.learned("r", 10.0, 1, 1).learned("r", 20.0, 1, 1)
    assert rates.interval("r") == pytest.approx(10.0)
    # a longer gap moves the faded mean a fifth of the way; a repeated time leaves it
    rates = rates.learned("r", 40.0, 1, 1).learned("r", 40.0, 1, 1)
    assert rates.interval("r") == pytest.approx(0.8 * 10.0 + 0.2 * 20.0)
    # an hour's silence counts as three intervals, not as an hour
    after = rates.learned("r", 3640.0, 1, 1).interval("r")
    assert after == pytest.approx(0.8 * 12.0 + 0.2 * 36.0)


@pytest.mark.parametrize(("looks", "detected"), [(3, 4), (2, -1)])
def test_impossible_counts_are_refused(looks, detected):
    with pytest.raises(ValueError, match="detected"):
        DetectionRates().learned("r", 0.0, looks, detected)


def test_the_least_recently_heard_sensor_is_forgotten():
    rates = DetectionRates()
    for k in range(MAX_SENSORS + 1):
        rates = rates.learned(f"s{k}", float(k), 1, 0)
    assert len(rates.sensors) == MAX_SENSORS
    assert rates.of("s0") is None and rates.of(f"s{MAX_SENSORS}") is not None
    rates = rates.learned("s1", 1e3, 1, 1)  # heard again: now the most recent
    rates = rates.learned("new", 1e3, 1, 1)
    assert rates.of("s1") is not None and rates.of("s2") is None
