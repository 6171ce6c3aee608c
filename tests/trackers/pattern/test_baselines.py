"""Baseline matchers (Chang et al.'s vote, RANSAC) on the FPPM's easy cases."""

from __future__ import annotations

import numpy as np
import pytest

from trackers.pattern.baselines import match_ransac, match_vote, ransac_iterations
from trackers.pattern.fppm import PatternMatch
from trackers.pattern.registration import Similarity

PATTERN = np.array([[-8.0, -6.0], [7.0, -7.5], [9.0, 6.0], [-2.0, 8.5], [1.0, -1.0]])
G = Similarity(1.4, 2.2, np.array([120.0, -35.0]))
MATCHERS = [match_vote, match_ransac]


def _pairs(match: PatternMatch | None) -> set[tuple[int, int]]:
    assert match is not None
    return {(int(i), int(j)) for i, j in match.pairs.tolist()}


def _cluttered(seed: int, sigma: float, keep=(0, 1, 2, 3, 4), n_clutter: int = 15):
    rng = np.random.default_rng(seed)
    noise = np.clip(rng.normal(0.0, sigma, (len(keep), 2)), -2 * sigma, 2 * sigma)
    true_y = G.apply(PATTERN[list(keep)]) + noise
    clutter = G.t + rng.uniform(-40.0, 40.0, (n_clutter, 2))
    first = n_clutter // 2
    Q = np.vstack([clutter[:first], true_y, clutter[first:]])
    return Q, {(i, first + r) for r, i in enumerate(keep)}


@pytest.mark.parametrize("matcher", MATCHERS)
def test_exact_pattern_rotated_scaled_translated(matcher) -> None:
    Q = G.apply(PATTERN)[[3, 0, 4, 1, 2]]
    match = matcher(PATTERN, Q, 0.05)
    assert _pairs(match) == {(0, 1), (1, 3), (2, 4), (3, 0), (4, 2)}
    assert match is not None
    assert match.registration.s == pytest.approx(1.4, abs=1e-9)
    assert match.registration.theta == pytest.approx(2.2, abs=1e-9)
    assert match.mse == pytest.approx(0.0, abs=1e-12)


@pytest.mark.parametrize("matcher", MATCHERS)
def test_missed_points(matcher) -> None:
    Q = G.apply(PATTERN[[0, 2, 4]])
    assert _pairs(matcher(PATTERN, Q, 0.05)) == {(0, 0), (2, 1), (4, 2)}


@pytest.mark.parametrize("matcher", MATCHERS)
@pytest.mark.parametrize("seed", range(3))
def test_clutter_missed_points_and_noise(matcher, seed: int) -> None:
    Q, truth = _cluttered(seed, 0.02, keep=(0, 1, 3, 4))
    assert _pairs(matcher(PATTERN, Q, 0.02, scale_range=(1.3, 1.5))) == truth
    Q, truth = _cluttered(seed, 0.2, n_clutter=6)
    match = matcher(PATTERN, Q, 0.2)
    assert _pairs(match) == truth
    assert match is not None and match.registration.s == pytest.approx(1.4, abs=0.05)


@pytest.mark.parametrize("matcher", MATCHERS)
def test_pure_clutter_and_scale_range(matcher) -> None:
    rng = np.random.default_rng(7)
    no_match = [
        matcher(rng.normal(size=(1, 2)) + PATTERN, rng.uniform(-60.0, 60.0, (15, 2)), 0.01),
        matcher(PATTERN, G.apply(PATTERN), 0.01, scale_range=(0.9, 1.1)),
    ]
    for match in no_match:
        if matcher is match_ransac:
            assert match is None or match.support - 1 < 2
        else:  # the vote has no residual test (the weakness paper 000 points at): what it
            assert match is None or match.mse > 100 * 0.01**2  # returns fits badly


def test_ransac_is_deterministic_given_a_seed() -> None:
    Q, _ = _cluttered(5, 0.2)
    a = match_ransac(PATTERN, Q, 0.2, rng=3)
    b = match_ransac(PATTERN, Q, 0.2, rng=np.random.default_rng(3))
    c = match_ransac(PATTERN, Q, 0.2)
    d = match_ransac(PATTERN, Q, 0.2)
    assert a is not None and b is not None and c is not None and d is not None
    np.testing.assert_array_equal(a.pairs, b.pairs)
    np.testing.assert_array_equal(c.pairs, d.pairs)


def test_ransac_iterations() -> None:
    assert ransac_iterations(20) == pytest.approx(2155, abs=5)
    assert ransac_iterations(2) == 100
    assert ransac_iterations(1000) == 20000
    with pytest.raises(ValueError):
        match_ransac(PATTERN, G.apply(PATTERN), 0.1, iterations=0)


def test_vote_bins_argument() -> None:
    Q = G.apply(PATTERN)
    assert _pairs(match_vote(PATTERN, Q, 0.05, bins=36)) == {(i, i) for i in range(5)}
    with pytest.raises(ValueError):
        match_vote(PATTERN, Q, 0.05, bins=2)
