"""Paper 003's template matching (section III.B) on hand-made point sets."""

from __future__ import annotations

import numpy as np
import pytest

from trackers.formation.template import (
    cell_sizes,
    cells_of,
    match_counts,
    match_template,
    shape_matrix,
)


def test_cell_sizes_follow_eq_7_with_their_floor() -> None:
    square = np.array([[0.0, 0.0], [300.0, 0.0], [0.0, 300.0], [300.0, 300.0]])
    # 4σ = 160 m is below the 300 m member spacing: μ = 4σ on both axes.
    assert np.allclose(cell_sizes(square, np.array([40.0, 40.0])), [160.0, 160.0])
    # 4σ = 400 m is above it: μ = the smallest difference, 300 m.
    assert np.allclose(cell_sizes(square, np.array([100.0, 100.0])), [300.0, 300.0])
    # Members in a line along x: no y-difference of 2σ or more; μ_y = 4σ.
    line = np.array([[0.0, 0.0], [250.0, 5.0], [500.0, -5.0]])
    assert np.allclose(cell_sizes(line, np.array([30.0, 30.0])), [120.0, 120.0])
    close = np.array([[0.0, 0.0], [70.0, 0.0]])
    assert np.allclose(cell_sizes(close, np.array([30.0, 30.0])), [70.0, 120.0])
    with pytest.raises(ValueError, match="sigma"):
        cell_sizes(square, np.array([0.0, 1.0]))


def test_shape_matrix_marks_occupied_cells_eqs_8_to_10() -> None:
    pts = np.array([[5.0, 5.0], [25.0, 5.0], [25.0, 35.0], [-1.0, 0.0], [100.0, 100.0]])
    E = shape_matrix(pts, np.array([0.0, 0.0]), np.array([10.0, 10.0]), (3, 4))
    expected = np.zeros((3, 4), dtype=bool)
    expected[0, 0] = expected[2, 0] = expected[2, 3] = True  # the last two points are outside
    assert (expected == E).all()
    assert cells_of(pts[:3], [0.0, 0.0], [10.0, 10.0]).tolist() == [[0, 0], [2, 0], [2, 3]]


def test_matching_search_counts_each_placement_eqs_12_to_15() -> None:
    E_m = np.array([[1, 0], [0, 1]], dtype=bool)
    E_p = np.zeros((4, 5), dtype=bool)
    E_p[1, 2] = E_p[2, 3] = True  # the template's diagonal at placement (1, 2)
    E_p[3, 0] = True  # a lone detection
    counts = match_counts(E_m, E_p, tolerance=0)
    assert counts.shape == (3, 4)  # eq. 13: l_p − l_m + 1 per axis
    assert counts[1, 2] == 2 and counts.max() == 2
    assert (counts == 2).sum() == 1
    assert counts[0, 1] == 1 and counts[0, 0] == 0  # (1, 2) seen by the lower-right cell
    # With a one-cell tolerance a detection also matches its neighbours' cells.
    assert match_counts(E_m, E_p, tolerance=1)[0, 1] == 2  # both, each off by one cell
    # A template larger than B has no placement.
    assert match_counts(np.ones((5, 1), dtype=bool), E_p).size == 0


def test_least_cost_placement_among_equal_matches_eqs_16_to_18() -> None:
    template = np.array([[0.0, 0.0], [300.0, 0.0], [600.0, 0.0]])
    # The same pattern twice: once 20 m from the prediction, once 1.5 km away.
    near = template + np.array([20.0, 10.0])
    far = template + np.array([1500.0, 0.0])
    Z = np.vstack([far, near])
    m = match_template(template, Z, np.array([100.0, 100.0]))
    assert m is not None and m.count == 3
    assert m.assignment.tolist() == [3, 4, 5]
    assert m.cost == pytest.approx(3 * np.hypot(20.0, 10.0))
    assert np.allclose(m.shift, [20.0, 10.0], atol=100.0)
    # max_shift keeps the search near the prediction; far alone is then no match.
    assert (
        match_template(template, far, np.array([100.0, 100.0]), max_shift=np.array([200.0, 200.0]))
        is None
    )


def test_a_false_alarm_completing_a_shifted_pattern_loses_with_a_miss_cost() -> None:
    # A formation in line; its first member missed; a false alarm one spacing beyond the last.
    template = np.array([[0.0, 0.0], [250.0, 0.0], [500.0, 0.0], [750.0, 0.0]])
    Z = np.array([[252.0, 8.0], [505.0, -6.0], [748.0, 4.0], [1000.0, 3.0]])
    mu = np.array([160.0, 160.0])
    counted = match_template(template, Z, mu)
    assert counted is not None and counted.count == 4  # count first: the shifted placement
    assert counted.assignment.tolist() == [0, 1, 2, 3]
    weighed = match_template(template, Z, mu, miss_cost=200.0)
    assert weighed is not None and weighed.count == 3
    assert weighed.assignment.tolist() == [-1, 0, 1, 2]


def test_one_detection_serves_one_member_in_the_placement_cost() -> None:
    # A turning formation in its own frame (environment 3, seed 8, batch 131): the members'
    # predictions lag, the first member (top) is missed, and cells of 150 m let the first
    # two members both see the second member's detection B0. Counted for both, B0 made a
    # placement that gives it to the first member (255 m off) as cheap as the true one; one
    # to one, the second member (79 m off) takes it.
    template = np.array([[-92.5, 455.0], [-33.6, 207.4], [112.8, -462.0], [13.3, -200.4]])
    Z = np.array([[38.0, 235.1], [56.8, -395.3], [2.7, -93.9], [705.4, 313.4], [-437.8, 452.1]])
    m = match_template(
        template,
        Z,
        np.array([146.4, 168.9]),
        max_shift=np.array([256.0, 239.9]),
        miss_cost=263.9,
    )
    assert m is not None and m.assignment.tolist() == [-1, 0, 1, 2]
    dist = np.hypot(*(Z[[0, 1, 2]] - template[[1, 2, 3]]).T)
    assert m.cost == pytest.approx(263.9 + dist.sum())  # the miss, and each detection once


def test_no_detection_or_no_template_is_no_match() -> None:
    assert match_template(np.zeros((0, 2)), np.ones((3, 2)), np.array([10.0, 10.0])) is None
    assert match_template(np.ones((3, 2)), np.zeros((0, 2)), np.array([10.0, 10.0])) is None
