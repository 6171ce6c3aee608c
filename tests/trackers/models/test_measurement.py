"""The position measurement matrix."""

from __future__ import annotations

import numpy as np
import pytest

from trackers.models.measurement import H_POSITION, MEASUREMENT_DIM


def test_h_position_picks_the_position() -> None:
    assert H_POSITION.shape == (MEASUREMENT_DIM, 5) == (2, 5)
    np.testing.assert_array_equal(H_POSITION, [[1, 0, 0, 0, 0], [0, 1, 0, 0, 0]])
    x = np.array([[3.0, -4.0, 10.0, 20.0, 0.1], [7.0, 8.0, -1.0, 0.0, 0.0]])
    np.testing.assert_array_equal(x @ H_POSITION.T, x[:, :2])


def test_h_position_is_read_only() -> None:
    with pytest.raises(ValueError):
        H_POSITION[0, 0] = 2.0
