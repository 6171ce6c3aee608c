"""The Stone Soup tracker the issue's reference figures were measured with.

A GNN tracker (2-D assignment over Mahalanobis-distance hypotheses, gate at 3 standard
deviations), Kalman predictor and updater on a nearly-constant-velocity model, 3-point
initiation (``MultiMeasurementInitiator(min_points=3)``) and deletion after 5 scans without
an update. Stone Soup is an optional dependency (``pip install -e '.[bench]'``).
"""

from __future__ import annotations

import datetime as dt
import time
from collections.abc import Sequence

import numpy as np


class StoneSoupGNN:
    """Feeds simulated scans to Stone Soup's ``MultiTargetTracker`` one at a time."""

    def __init__(self, q: float, sigma: float, velocity_std: float, epoch: float = 0.0) -> None:
        from stonesoup.dataassociator.neighbour import GNNWith2DAssignment
        from stonesoup.deleter.time import UpdateTimeStepsDeleter
        from stonesoup.hypothesiser.distance import DistanceHypothesiser
        from stonesoup.initiator.simple import MultiMeasurementInitiator
        from stonesoup.measures import Mahalanobis
        from stonesoup.models.measurement.linear import LinearGaussian
        from stonesoup.models.transition.linear import (
            CombinedLinearGaussianTransitionModel,
            ConstantVelocity,
        )
        from stonesoup.predictor.kalman import KalmanPredictor
        from stonesoup.tracker.simple import MultiTargetTracker
        from stonesoup.types.state import GaussianState
        from stonesoup.updater.kalman import KalmanUpdater

        transition = CombinedLinearGaussianTransitionModel(
            [ConstantVelocity(q), ConstantVelocity(q)]
        )
        self.measurement_model = LinearGaussian(
            ndim_state=4, mapping=(0, 2), noise_covar=np.diag([sigma**2, sigma**2])
        )
        predictor = KalmanPredictor(transition)
        updater = KalmanUpdater(self.measurement_model)
        hypothesiser = DistanceHypothesiser(
            predictor, updater, measure=Mahalanobis(), missed_distance=3
        )
        associator = GNNWith2DAssignment(hypothesiser)
        deleter = UpdateTimeStepsDeleter(time_steps_since_update=5)
        initiator = MultiMeasurementInitiator(
            prior_state=GaussianState(
                np.zeros((4, 1)), np.diag([0.0, velocity_std**2, 0.0, velocity_std**2])
            ),
            measurement_model=self.measurement_model,
            deleter=deleter,
            data_associator=associator,
            updater=updater,
            min_points=3,
        )
        self.tracker = MultiTargetTracker(
            initiator=initiator,
            deleter=deleter,
            detector=None,
            data_associator=associator,
            updater=updater,
        )
        self._epoch = dt.datetime(2026, 1, 1) - dt.timedelta(seconds=epoch)

    def step(self, t: float, z: Sequence[np.ndarray]) -> tuple[np.ndarray, float]:
        """Process one scan; returns the positions of all tracks (n, 2) and the seconds taken."""
        from stonesoup.types.detection import Detection

        timestamp = self._epoch + dt.timedelta(seconds=float(t))
        detections = {
            Detection(
                np.asarray(p, dtype=float).reshape(2, 1),
                timestamp=timestamp,
                measurement_model=self.measurement_model,
            )
            for p in z
        }
        start = time.perf_counter()
        _, tracks = self.tracker.update_tracker(timestamp, detections)
        elapsed = time.perf_counter() - start
        pos = np.array([[tr.state_vector[0, 0], tr.state_vector[2, 0]] for tr in tracks]).reshape(
            -1, 2
        )
        return pos, elapsed
