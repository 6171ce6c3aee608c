"""Motion and measurement models over the state ``[x, y, vx, vy, ω]``."""

from trackers.models.measurement import H_POSITION, MEASUREMENT_DIM
from trackers.models.motion import (
    STATE_DIM,
    ConstantVelocity,
    CoordinatedTurn,
    MotionModel,
    batch_major,
    batch_major_cov,
    build_models,
    state_major,
    state_major_cov,
)

__all__ = [
    "H_POSITION",
    "MEASUREMENT_DIM",
    "STATE_DIM",
    "ConstantVelocity",
    "CoordinatedTurn",
    "MotionModel",
    "batch_major",
    "batch_major_cov",
    "build_models",
    "state_major",
    "state_major_cov",
]
