"""Accuracy near its limit: a constant-velocity target, Pd = 1, no clutter, against the
posterior Cramér-Rao bound (for this linear-Gaussian case, the optimal filter's covariance)."""

import math

import numpy as np

from clients.scenarios.multitarget import ScenarioConfig, SensorSpec, simulate
from trackers.config import TrackerConfig
from trackers.evaluation.crb import cv_position_bound
from trackers.pipeline import TrackingPipeline

Q, SIGMA, V_STD, DT = 0.05, 5.0, 10.0, 1.0


def test_position_rmse_is_within_ten_percent_of_the_pcrb():
    runs, scans = 120, 30
    config = TrackerConfig().merged(
        {
            "motion": {"q_cv": Q},
            # The PCRB assumes the Gaussian velocity prior of a single-point start.
            "initiation": {"method": "single_point", "velocity_std": V_STD},
            "track_management": {"pd": 1.0 - 1e-9},
        }
    )
    sq = np.zeros(scans)
    for r in range(runs):
        scenario = ScenarioConfig(
            n_targets=1,
            n_scans=scans,
            dt=DT,
            init_velocity_std=V_STD,
            q=Q,
            sensors=(SensorSpec(pd=1.0, sigma=SIGMA, clutter_mean=0.0),),
            seed=500 + r,
        )
        pipeline = TrackingPipeline(config)
        for k, sim in enumerate(simulate(scenario)):
            (track,) = pipeline.process(sim.to_scan()).tracks
            sq[k] += np.sum((np.asarray(track.position) - sim.truth_states[0, :2]) ** 2)
    rmse = np.sqrt(sq / runs)
    crb = cv_position_bound(DT, Q, SIGMA, V_STD, scans)
    pooled = math.sqrt(np.mean(rmse[10:] ** 2) / np.mean(crb[10:] ** 2))
    # Monte Carlo spread of the pooled ratio is about 1/sqrt(2 · 120 · 20) ≈ 1.4 %.
    assert 0.95 < pooled <= 1.10
    assert abs(rmse[0] / crb[0] - 1) < 0.12  # the first estimate is the detection itself
