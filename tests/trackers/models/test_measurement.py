"""The position measurement matrix and the range-rate measurement."""

from __future__ import annotations

import numpy as np
import pytest

from trackers.models.measurement import (
    H_POSITION,
    MEASUREMENT_DIM,
    range_rate,
    range_rate_jacobian,
    range_rate_update,
)


def test_h_position_picks_the_position() -> None:
    assert H_POSITION.shape == (MEASUREMENT_DIM, 5) == (2, 5)
    np.testing.assert_array_equal(H_POSITION, [[1, 0, 0, 0, 0], [0, 1, 0, 0, 0]])
    x = np.array([[3.0, -4.0, 10.0, 20.0, 0.1], [7.0, 8.0, -1.0, 0.0, 0.0]])
    np.testing.assert_array_equal(x @ H_POSITION.T, x[:, :2])


def test_h_position_is_read_only() -> None:
    with pytest.raises(ValueError):
        H_POSITION[0, 0] = 2.0


def _states() -> np.ndarray:
    return np.array(
        [
            [1000.0, 500.0, 30.0, -10.0, 0.01],
            [-2e4, 3e4, -250.0, 120.0, 0.0],
            [50.0, -80.0, 0.0, 0.0, 0.0],
        ]
    )


def test_range_rate_is_the_velocity_along_the_line_of_sight() -> None:
    sensor = np.array([100.0, -200.0])
    x = _states()
    d = x[:, :2] - sensor
    expected = np.sum(d * x[:, 2:4], axis=1) / np.hypot(*d.T)
    np.testing.assert_allclose(range_rate(x, sensor), expected)
    # going straight away at 10 m/s
    away = np.array([[sensor[0] + 3e3, sensor[1], 10.0, 0.0, 0.0]])
    assert range_rate(away, sensor)[0] == pytest.approx(10.0)


def test_range_rate_jacobian_against_finite_differences() -> None:
    sensor = np.array([100.0, -200.0])
    x = _states()
    J = range_rate_jacobian(x, sensor)
    eps = 1e-4
    for i in range(x.shape[1]):
        step = np.zeros_like(x)
        step[:, i] = eps
        fd = (range_rate(x + step, sensor) - range_rate(x - step, sensor)) / (2 * eps)
        np.testing.assert_allclose(J[:, i], fd, rtol=1e-6, atol=1e-9)


def test_a_moving_sensor_sees_the_velocity_relative_to_it() -> None:
    # Sensor at the origin flying east at 100 m/s: a parked target due east closes at
    # 100 m/s, one due north neither closes nor recedes, one 45° off closes at 100/√2.
    sensor, v_s = np.zeros(2), np.array([100.0, 0.0])
    x = np.array([[5e3, 0.0, 0.0, 0.0, 0.0], [0.0, 5e3, 0.0, 0.0, 0.0], [5e3, 5e3, 0.0, 0.0, 0.0]])
    np.testing.assert_allclose(range_rate(x, sensor, v_s), [-100.0, 0.0, -100.0 / np.sqrt(2)])
    # a target flying with the sensor shows no range-rate; at rest, it is the old model
    x[:, 2] = 100.0
    np.testing.assert_allclose(range_rate(x, sensor, v_s), 0.0, atol=1e-12)
    np.testing.assert_allclose(range_rate(x, sensor, np.zeros(2)), range_rate(x, sensor))


def test_range_rate_jacobian_of_a_moving_sensor_against_finite_differences() -> None:
    sensor, v_s = np.array([100.0, -200.0]), np.array([-180.0, 60.0])
    x = _states()
    J = range_rate_jacobian(x, sensor, v_s)
    eps = 1e-4
    for i in range(x.shape[1]):
        step = np.zeros_like(x)
        step[:, i] = eps
        fd = (range_rate(x + step, sensor, v_s) - range_rate(x - step, sensor, v_s)) / (2 * eps)
        np.testing.assert_allclose(J[:, i], fd, rtol=1e-6, atol=1e-9)


def test_range_rate_update_is_the_ekf_step() -> None:
    sensor = np.array([0.0, 0.0])
    x = np.array([[3000.0, 4000.0, 10.0, 0.0, 0.0]])
    P = np.diag([100.0, 100.0, 25.0, 25.0, 1e-4])[None]
    rdot = np.array([9.0])
    xn, Pn, ll = range_rate_update(x, P, rdot, sensor, 0.25)
    J = range_rate_jacobian(x, sensor)[0]
    S = J @ P[0] @ J + 0.25
    K = P[0] @ J / S
    nu = 9.0 - range_rate(x, sensor)[0]
    np.testing.assert_allclose(xn[0], x[0] + K * nu)
    A = np.eye(5) - np.outer(K, J)
    np.testing.assert_allclose(Pn[0], A @ P[0] @ A.T + 0.25 * np.outer(K, K), atol=1e-9)
    assert ll[0] == pytest.approx(-0.5 * (np.log(2 * np.pi * S) + nu * nu / S))
    # the velocity along the line of sight is pinned down; across it, nothing changes
    los = np.array([0.6, 0.8])
    across = np.array([-0.8, 0.6])
    assert los @ Pn[0, 2:4, 2:4] @ los < 0.25 * (los @ P[0, 2:4, 2:4] @ los)
    assert across @ Pn[0, 2:4, 2:4] @ across == pytest.approx(25.0, rel=1e-3)
    assert not np.shares_memory(xn, x) and x[0, 2] == 10.0  # the input is not changed


def test_range_rate_at_the_sensor_changes_nothing() -> None:
    x = np.array([[0.2, 0.1, 5.0, 5.0, 0.0]])
    P = np.eye(5)[None]
    xn, Pn, ll = range_rate_update(x, P, np.array([3.0]), np.zeros(2), 1.0)
    np.testing.assert_array_equal(xn, x)
    np.testing.assert_array_equal(Pn, P)
    assert ll[0] == 0.0
