"""Evaluation metrics: GOSPA/OSPA distances, track continuity, posterior Cramér–Rao bounds."""

from trackers.evaluation.continuity import ContinuityCounter, ContinuityResult, gated_assignment
from trackers.evaluation.crb import POSITION_H, cv_matrices, pcrb_linear
from trackers.evaluation.gospa import GospaResult, gospa, ospa, track_positions

__all__ = [
    "POSITION_H",
    "ContinuityCounter",
    "ContinuityResult",
    "GospaResult",
    "cv_matrices",
    "gated_assignment",
    "gospa",
    "ospa",
    "pcrb_linear",
    "track_positions",
]
