"""Measurement models for the state ``[x, y, vx, vy, ω]``.

Detections are positions ``z = [x, y]`` in metres: ``z = H s + v`` with ``v ~ N(0, R)`` and
``H = H_POSITION``.
"""

from __future__ import annotations

import numpy as np

__all__ = ["H_POSITION", "MEASUREMENT_DIM"]

MEASUREMENT_DIM = 2
"""Dimension of a position measurement ``[x, y]``."""

H_POSITION: np.ndarray = np.array(
    [
        [1.0, 0.0, 0.0, 0.0, 0.0],
        [0.0, 1.0, 0.0, 0.0, 0.0],
    ]
)
"""(2, 5) position measurement matrix ``z = [x, y] = H s``. Read-only."""
H_POSITION.setflags(write=False)
