import math

import numpy as np
import pytest

from trackers.config import TrackManagementConfig
from trackers.scoring import (
    MIN_NEW_TARGET_ODDS,
    hit_increment,
    initial_score,
    initial_score_each,
    miss_increment,
    new_target_odds_density,
    sequential_test,
)


def test_initial_score_is_log_density_ratio():
    assert initial_score(1e-7, 1e-6) == pytest.approx(math.log(0.1))


def test_initial_score_never_starts_a_track_at_odds_below_the_floor():
    """λ_nt counts as max(λ_nt, κ λ_fa): a radar's 1e-7 against a camera's 5.6e-4 false
    alarms per m² (ln ratio −8.6, below the deletion threshold ln 1e-3) starts at ln κ."""
    assert MIN_NEW_TARGET_ODDS == 0.01
    assert initial_score(1e-7, 5.6e-4) == pytest.approx(math.log(0.01))
    assert initial_score(1e-7, 1e-5) == pytest.approx(math.log(0.01))  # exactly at the floor
    assert initial_score(1e-7, 2e-5) == pytest.approx(math.log(0.01))
    assert initial_score(1e-7, 5e-6) == pytest.approx(math.log(0.02))  # above it: unchanged
    each = initial_score_each(1e-7, np.array([1e-9, 1e-6, 1e-3]))
    np.testing.assert_allclose(each, [math.log(100.0), math.log(0.1), math.log(0.01)])
    # the density in force, which the relink test of young tracks compares against too
    assert new_target_odds_density(1e-7, 1e-6) == 1e-7
    assert new_target_odds_density(1e-7, 5.6e-4) == pytest.approx(5.6e-6)


def test_hit_increment_worked_example():
    # Pd = 0.9, innovation 0 with S = 25 I: g = 1 / (2π · 25); λ_fa = 1e-6
    g = 1.0 / (2 * math.pi * 25.0)
    expected = math.log(0.9 * g / 1e-6)
    assert float(hit_increment(0.9, np.log(g), 1e-6)) == pytest.approx(expected)


def test_miss_increment():
    assert float(miss_increment(0.9)) == pytest.approx(math.log(0.1))
    assert np.isfinite(miss_increment(1.0))
    assert float(miss_increment(1.0)) < -20


def test_wald_thresholds():
    c = TrackManagementConfig(p_false_confirm=1e-4, p_true_delete=1e-2)
    assert c.confirm_threshold == pytest.approx(math.log(0.99 / 1e-4))
    assert c.delete_threshold == pytest.approx(math.log(1e-2 / (1 - 1e-4)))


def test_sequential_test_rules():
    c = TrackManagementConfig(
        p_false_confirm=1e-4, p_true_delete=1e-2, delete_drop_from_peak=10.0, max_coast_time=5.0
    )
    score = np.array([10.0, -5.0, 0.0, 20.0, 20.0, 0.0])
    peak = np.array([10.0, 0.0, 0.0, 25.0, 35.0, 0.0])
    confirmed = np.array([False, False, False, True, True, False])
    coast = np.array([0.0, 0.0, 0.0, 0.0, 0.0, 6.0])
    s = sequential_test(score, peak, confirmed, coast, c)
    # 0: crosses T_c = 9.2 -> confirmed; 1: below T_d = -4.6 -> deleted; 2: stays tentative;
    # 3: 5 below peak -> kept; 4: 15 below peak -> deleted; 5: coasted 6 s > 5 s -> deleted.
    assert s.confirmed.tolist() == [True, False, False, True, False, False]
    assert s.delete.tolist() == [False, True, False, False, True, True]
