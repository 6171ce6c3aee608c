"""Batched Kalman and IMM filtering."""

from trackers.filters.imm import (
    MU_FLOOR,
    imm_combine,
    imm_mix,
    imm_predict,
    imm_update,
    transition_matrix,
)
from trackers.filters.kalman import innovation, kalman_update, log_gaussian

__all__ = [
    "MU_FLOOR",
    "imm_combine",
    "imm_mix",
    "imm_predict",
    "imm_update",
    "innovation",
    "kalman_update",
    "log_gaussian",
    "transition_matrix",
]
