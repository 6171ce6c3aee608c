"""Whole scenarios through the tracking pipeline, scored with GOSPA and track continuity."""

from dataclasses import replace

import numpy as np
import pytest

from clients.scenarios.multitarget import (
    ScenarioConfig,
    SensorSpec,
    crossing_scenario,
    reference_scenario,
    simulate,
)
from trackers.config import TrackerConfig
from trackers.evaluation.continuity import ContinuityCounter
from trackers.evaluation.gospa import gospa
from trackers.pipeline import TrackingPipeline


def run(scenario: ScenarioConfig, config: TrackerConfig, first_scored: int = 10):
    pipeline = TrackingPipeline(config)
    distances, missed, false = [], 0, 0
    continuity = ContinuityCounter(gate=25.0)
    for k, sim in enumerate(simulate(scenario)):
        confirmed = pipeline.process(sim.to_scan()).confirmed()
        est = np.array([t.position for t in confirmed]).reshape(-1, 2)
        truth = sim.truth_states[:, :2]
        continuity.add(sim.truth_ids, truth, [t.id for t in confirmed], est)
        if k >= first_scored:
            g = gospa(truth, est, c=100.0)
            distances.append(g.distance)
            missed += g.missed
            false += g.false
    return float(np.mean(distances)), missed, false, continuity.result()


def tuned(scenario: ScenarioConfig) -> TrackerConfig:
    return TrackerConfig().merged(
        {
            "motion": {"q_cv": max(scenario.q, 0.01)},
            "initiation": {"velocity_std": 2.0 * max(scenario.init_velocity_std, 5.0)},
        }
    )


@pytest.mark.parametrize("seed", [0, 1])
def test_reference_scenario_gospa(seed):
    """The issue's reference: Stone Soup's GNN reached 31.5 m mean GOSPA on it."""
    scenario = reference_scenario(seed)
    mean_gospa, missed, false, cont = run(scenario, tuned(scenario))
    assert mean_gospa < 31.5
    assert missed + false <= 10  # cardinality errors, summed over 90 scans
    assert cont.total_swaps + cont.total_breaks <= 3


def test_reference_scenario_with_default_configuration_still_tracks_everything():
    scenario = reference_scenario(2)
    mean_gospa, missed, false, _ = run(scenario, TrackerConfig())
    assert mean_gospa < 40.0
    assert missed + false <= 20


def test_crossing_targets_keep_their_tracks():
    scenario = crossing_scenario(n_targets=4, seed=3)
    mean_gospa, _missed, _false, cont = run(scenario, tuned(scenario))
    assert cont.total_breaks == 0
    assert cont.total_swaps <= 2  # four tracks through one point at 30° spacing
    assert mean_gospa < 25.0


def test_manoeuvring_targets_are_held_by_the_imm():
    scenario = replace(reference_scenario(4), n_targets=20, turn_rate_std=0.1)
    imm = TrackerConfig().merged({"initiation": {"velocity_std": 10.0}})
    cv_only = imm.merged(
        {"motion": {"models": ["cv"], "sojourn_times": [10.0], "initial_mode_probabilities": [1.0]}}
    )
    g_imm, m_imm, f_imm, c_imm = run(scenario, imm)
    g_cv, *_ = run(scenario, cv_only)
    assert m_imm + f_imm <= 10
    assert c_imm.total_breaks <= 2
    assert g_imm <= g_cv  # the turn model earns its keep on turning targets


def test_two_sensors_are_fused():
    """Two sensors of different quality, interleaved in time, feed the same tracks."""
    sensors = (
        SensorSpec(sensor_id="radar-a", pd=0.8, sigma=5.0, clutter_mean=10.0),
        SensorSpec(
            sensor_id="radar-b",
            pd=0.7,
            sigma=15.0,
            clutter_mean=20.0,
            time_offset=0.5,
            position=(1000.0, 0.0),
        ),
    )
    scenario = replace(reference_scenario(5), n_targets=30, n_scans=60, sensors=sensors)
    mean_gospa, missed, false, cont = run(scenario, tuned(scenario), first_scored=20)
    assert mean_gospa < 30.0
    assert missed + false <= 10
    assert cont.total_breaks + cont.total_swaps <= 3


# --- targets of every speed, default configuration (clients.scenarios.airspace) ----------------


def held(scenario):
    from clients.scenarios.airspace import simulate_scripted
    from trackers.evaluation.effective_rate import EffectiveRateCounter

    pipeline = TrackingPipeline(TrackerConfig())
    counter = EffectiveRateCounter(gate=150.0, warmup=8)
    for sim in simulate_scripted(scenario):
        confirmed = pipeline.process(sim.to_scan()).confirmed()
        est = np.array([t.position for t in confirmed]).reshape(-1, 2)
        counter.add(sim.truth_ids, sim.truth_states[:, :2], [t.id for t in confirmed], est)
    return counter.result(scenario.classes)


@pytest.mark.parametrize("period", [4.0, 1.0])
def test_mixed_speeds_from_parked_cars_to_jets_are_held_with_defaults(period):
    from clients.scenarios.airspace import mixed_speed_scenario

    r = held(mixed_speed_scenario(period=period, seed=0))
    assert r.rate >= 0.95
    assert min(r.rate_by_class.values()) >= 0.85, r.rate_by_class
    assert r.false_per_scan <= 0.2


def test_at_a_10_s_revisit_no_track_runs_away_faster_than_any_target():
    """Mixed speeds at a 10 s revisit: a jet's track that lost its target in a 5 g turn took
    a false alarm in its grown gate at every scan and ran on at up to 1600 m/s for 70 s (of
    0.93 false confirmed tracks a scan over six runs, 0.3 were such; 0.63 now). No reported
    track is now faster than 1.25 times ``initiation.max_speed``."""
    from clients.scenarios.airspace import mixed_speed_scenario, simulate_scripted

    config = TrackerConfig()
    limit = 1.25 * config.initiation.max_speed
    pipeline = TrackingPipeline(config)
    fastest = 0.0
    for sim in simulate_scripted(mixed_speed_scenario(period=10.0, seed=0)):
        for track in pipeline.process(sim.to_scan()).confirmed():
            fastest = max(fastest, float(np.hypot(*track.velocity)))
    assert fastest <= limit


def test_paper_003_formations_seen_by_three_unsynchronized_radars():
    from clients.scenarios.airspace import formation_scenario

    r = held(formation_scenario(seed=0))
    assert r.rate >= 0.9, r.rate_by_class
    assert r.false_per_scan <= 0.1


def test_a_4g_turn_at_450_m_s_is_held_at_a_2_s_revisit():
    from clients.scenarios.airspace import manoeuvre_scenario

    r = held(manoeuvre_scenario(speed=450.0, g_load=4.0, period=2.0, seed=1))
    assert r.rate >= 0.9


def test_aircraft_that_brake_or_speed_up_keep_their_tracks_with_defaults():
    """Landings braking at 2 m/s² from 80 to 10 m/s and take-offs speeding up at 2.5 m/s² from
    10 to 80 m/s, T = 4 s, 50 m range noise: the turn mode's noise along the velocity
    (``motion.q_ct_along``) holds them (3 seeds: 0.94 held, 0.12 false tracks a scan;
    without it 0.81 and 0.68, a braking aircraft's track running on ahead of it)."""
    from clients.scenarios.airspace import runway_scenario

    runs = [held(runway_scenario(seed=s)) for s in range(3)]
    assert np.mean([r.rate for r in runs]) >= 0.88
    assert min(min(r.rate_by_class.values()) for r in runs) >= 0.75
    assert np.mean([r.false_per_scan for r in runs]) <= 0.3


def test_targets_setting_off_from_rest_near_the_radar_keep_their_tracks_with_defaults():
    """Aircraft (2.5 m/s²) and vehicles (2 m/s²) at rest 1-3 km from a radar of 1 mrad set
    off across the beam, out of their stopped tracks' gates (a few metres wide across it) a
    scan later: the manoeuvre search's change of speed (``gating.manoeuvre_speed_change``)
    finds them (3 seeds: take-off rolls 0.98 held by the same track, 0.81 without it)."""
    from clients.scenarios.airspace import apron_scenario, simulate_scripted
    from trackers.evaluation.effective_rate import EffectiveRateCounter

    def rates(config):
        out = []
        for seed in range(3):
            scenario = apron_scenario(seed=seed)
            pipeline = TrackingPipeline(config)
            counter = EffectiveRateCounter(gate=150.0, warmup=8)
            for sim in simulate_scripted(scenario):
                confirmed = pipeline.process(sim.to_scan()).confirmed()
                est = np.array([t.position for t in confirmed]).reshape(-1, 2)
                ids = [t.id for t in confirmed]
                counter.add(sim.truth_ids, sim.truth_states[:, :2], ids, est)
            out.append(counter.result(scenario.classes))
        return out

    runs = rates(TrackerConfig())
    assert np.mean([r.rate for r in runs]) >= 0.92
    assert np.mean([r.rate_by_class["take-off roll"] for r in runs]) >= 0.93
    assert np.mean([r.false_per_scan for r in runs]) <= 0.2
    without = rates(TrackerConfig().merged({"gating": {"manoeuvre_speed_change": 0.0}}))
    assert np.mean([r.rate_by_class["take-off roll"] for r in without]) <= 0.9


def test_a_weaving_drone_keeps_more_of_its_track_with_agile_turns():
    """A 40 m/s drone weaving with 3 s turns at 20°/s, 3 km from a radar of 5 mrad at 1 s:
    the turn-rate prior of ``motion.agile_acceleration`` (0.2 rad/s at 40 m/s and 1 s)
    follows the turns (seeds 0-3: 0.90 held within 60 m, 2.0 tracks on it in 150 s, 0.11
    false tracks a scan; without it 0.75, 9.5 and 0.57; seeds 4-7 alike)."""
    from clients.scenarios.airspace import simulate_scripted, weaving_scenario
    from trackers.evaluation.effective_rate import EffectiveRateCounter

    def run(config):
        held, tracks, false = [], [], []
        for seed in range(4):
            scenario = weaving_scenario(seed=seed)
            pipeline = TrackingPipeline(config)
            counter = EffectiveRateCounter(gate=60.0, warmup=8)
            ids = set()
            for sim in simulate_scripted(scenario):
                confirmed = pipeline.process(sim.to_scan()).confirmed()
                est = np.array([t.position for t in confirmed]).reshape(-1, 2)
                pairs = counter.add(
                    sim.truth_ids, sim.truth_states[:, :2], [t.id for t in confirmed], est
                )
                if 0 in pairs:
                    ids.add(pairs[0])
            result = counter.result(scenario.classes)
            held.append(result.rate_by_class["weaving"])
            tracks.append(len(ids))
            false.append(result.false_per_scan)
        return np.mean(held), np.mean(tracks), np.mean(false)

    held, tracks, false = run(TrackerConfig())
    assert held >= 0.85 and tracks <= 4 and false <= 0.25
    held_off, tracks_off, false_off = run(
        TrackerConfig().merged({"motion": {"agile_acceleration": 0}})
    )
    assert held_off < held - 0.08 and tracks_off > tracks + 4 and false_off > false + 0.2
