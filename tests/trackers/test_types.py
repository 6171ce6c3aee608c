"""The scan type: its id groups and its subsets."""

import numpy as np

from trackers.types import Scan


def _scan(ids=()) -> Scan:
    n = 3
    return Scan("radar", 1.0, np.arange(2.0 * n).reshape(n, 2), np.tile(np.eye(2), (n, 1, 1)), ids)


def test_detection_id_groups_are_one_tuple_a_detection() -> None:
    groups = _scan(("a", None, "c")).detection_id_groups
    assert groups.shape == (3,) and groups.dtype == object
    assert groups.tolist() == [("a",), (), ("c",)]
    # every detection with an id: still tuples, not a (3, 1) array of strings
    assert _scan(("a", "b", "c")).detection_id_groups.tolist() == [("a",), ("b",), ("c",)]


def test_detection_id_groups_without_ids_are_empty_tuples() -> None:
    assert _scan().detection_id_groups.tolist() == [(), (), ()]
    empty = Scan("radar", 1.0, np.zeros((0, 2)), np.zeros((0, 2, 2)))
    assert empty.detection_id_groups.shape == (0,)


def test_a_subset_has_the_groups_of_its_detections() -> None:
    sub = _scan(("a", None, "c")).subset(np.array([False, True, True]))
    assert sub.detection_id_groups.tolist() == [(), ("c",)]
