"""GLSE similarity registration (paper 000, eq. 19) against exact transforms."""

from __future__ import annotations

import math

import numpy as np
import pytest

from trackers.pattern.registration import Similarity, fit_similarity, rotation


def _points(k: int, seed: int = 0) -> np.ndarray:
    return np.random.default_rng(seed).uniform(-10.0, 10.0, (k, 2))


@pytest.mark.parametrize(
    ("s", "theta", "t"),
    [
        (1.0, 0.3, (5.0, -2.0)),
        (0.5, -2.9, (-100.0, 40.0)),
        (2.0, math.pi, (0.0, 0.0)),
        (1.7, 1.234, (1e3, -1e3)),
    ],
)
@pytest.mark.parametrize("k", [2, 3, 7])
def test_recovers_an_exact_similarity(s: float, theta: float, t: tuple, k: int) -> None:
    x = _points(k, seed=k)
    G = Similarity(s, theta, np.array(t))
    y = G.apply(x)
    fit = fit_similarity(x, y)
    assert fit.s == pytest.approx(s, abs=1e-9)
    assert math.remainder(fit.theta - theta, 2 * math.pi) == pytest.approx(0.0, abs=1e-9)
    np.testing.assert_allclose(fit.t, t, atol=1e-9 * max(1.0, np.abs(t).max()))
    np.testing.assert_allclose(fit.apply(x), y, atol=1e-9 * max(1.0, np.abs(y).max()))


def test_theta_wrapped_to_open_closed_interval() -> None:
    assert Similarity(1.0, -math.pi, np.zeros(2)).theta == pytest.approx(math.pi)
    assert Similarity(1.0, 3 * math.pi / 2, np.zeros(2)).theta == pytest.approx(-math.pi / 2)
    x = _points(4)
    fit = fit_similarity(x, x @ rotation(math.pi).T)
    assert fit.theta == pytest.approx(math.pi, abs=1e-9)
    assert -math.pi < fit.theta <= math.pi


def test_apply_and_inverse() -> None:
    G = Similarity(1.5, 0.4, np.array([3.0, -1.0]))
    x = _points(5)
    np.testing.assert_allclose(G.apply(x), 1.5 * x @ rotation(0.4).T + [3.0, -1.0])
    np.testing.assert_allclose(G.inverse().apply(G.apply(x)), x, atol=1e-12)
    np.testing.assert_allclose(G.apply(x[0]), G.apply(x[:1])[0])


def test_weights_match_the_weighted_normal_equations() -> None:
    rng = np.random.default_rng(3)
    x = _points(6, seed=3)
    y = Similarity(1.2, -0.7, np.array([4.0, 9.0])).apply(x) + rng.normal(0, 0.3, (6, 2))
    w = rng.uniform(0.2, 3.0, 6)
    fit = fit_similarity(x, y, w)
    # eq. 19 solved directly: r = (C' W C)⁻¹ C' W Y, r = [tx, ty, s cos θ, s sin θ]
    C = np.zeros((12, 4))
    C[0::2] = np.column_stack([np.ones(6), np.zeros(6), x[:, 0], -x[:, 1]])
    C[1::2] = np.column_stack([np.zeros(6), np.ones(6), x[:, 1], x[:, 0]])
    Wd = np.repeat(w, 2)
    r = np.linalg.solve(C.T @ (Wd[:, None] * C), C.T @ (Wd * y.reshape(-1)))
    assert fit.s == pytest.approx(math.hypot(r[2], r[3]), rel=1e-9)
    assert fit.theta == pytest.approx(math.atan2(r[3], r[2]), abs=1e-9)
    np.testing.assert_allclose(fit.t, r[:2], atol=1e-9)
    # noise-free data: any weights give the exact transform
    G = Similarity(0.8, 2.0, np.array([-3.0, 1.0]))
    exact = fit_similarity(x, G.apply(x), w)
    assert exact.s == pytest.approx(0.8, abs=1e-9)
    assert exact.theta == pytest.approx(2.0, abs=1e-9)
    # zero weight: that pair is ignored
    y_bad = G.apply(x)
    y_bad[0] += 50.0
    w0 = np.ones(6)
    w0[0] = 0.0
    ignored = fit_similarity(x, y_bad, w0)
    assert ignored.s == pytest.approx(0.8, abs=1e-9)
    np.testing.assert_allclose(ignored.t, [-3.0, 1.0], atol=1e-9)


def test_unweighted_equals_uniform_weights() -> None:
    x = _points(5, seed=9)
    y = _points(5, seed=10)
    a, b = fit_similarity(x, y), fit_similarity(x, y, np.full(5, 2.5))
    assert a.s == pytest.approx(b.s, rel=1e-12)
    assert a.theta == pytest.approx(b.theta, abs=1e-12)


def test_inputs_not_mutated() -> None:
    x, y = _points(4), _points(4, seed=1)
    x0, y0 = x.copy(), y.copy()
    fit_similarity(x, y, np.ones(4))
    np.testing.assert_array_equal(x, x0)
    np.testing.assert_array_equal(y, y0)


@pytest.mark.parametrize("k", [0, 1])
def test_fewer_than_two_pairs_raise(k: int) -> None:
    with pytest.raises(ValueError, match="k >= 2"):
        fit_similarity(np.zeros((k, 2)), np.zeros((k, 2)))


def test_degenerate_inputs_raise() -> None:
    x = np.array([[1.0, 2.0], [1.0, 2.0], [1.0, 2.0]])
    with pytest.raises(ValueError, match="coincide"):
        fit_similarity(x, _points(3))
    with pytest.raises(ValueError, match="coincide"):
        fit_similarity(_points(3), np.ones((3, 2)))
    with pytest.raises(ValueError, match="weight"):
        fit_similarity(_points(3), _points(3, 1), np.array([1.0, 0.0, 0.0]))
    with pytest.raises(ValueError):
        fit_similarity(_points(3), _points(4))
    with pytest.raises(ValueError):
        fit_similarity(np.array([[0.0, 0.0], [np.nan, 1.0]]), _points(2))
    with pytest.raises(ValueError):
        Similarity(0.0, 0.0, np.zeros(2))
