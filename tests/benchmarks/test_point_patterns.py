"""``python -m benchmarks.point_patterns --quick``: the point-pattern benchmark runs end to end
and prints its table and targets."""

from __future__ import annotations

import re

import numpy as np
import pytest

from benchmarks import point_patterns
from trackers.pattern.fppm import pattern_match

ROW = re.compile(
    r"^\s+(?P<m>\d+)\s+(?P<n>\d+)\s+(?P<sigma>[\d.]+)\s+(?P<pct>\d+) \|"
    r"(?P<cells>(?:\s+[\d.]+%\s+[\d.]+\s+[\d.]+ \|){3})"
    r"\s+[\d.]+\s+[\d.]+\s+[+-][\d.]+%$",
    re.MULTILINE,
)


def test_scenes_hold_their_truth() -> None:
    rng = np.random.default_rng(0)
    for free in (False, True):
        scene = point_patterns.draw_scene(6, 25, 0.2, rng, free)
        assert scene.pattern.shape == (6, 2) and scene.detections.shape == (25, 2)
        assert 3 <= len(scene.truth) <= 6
        match = pattern_match(scene.pattern, scene.detections, np.array(sorted(scene.truth)))
        assert match.mse < 9 * 0.2**2
        if not free:
            assert match.registration.s == pytest.approx(1.0, abs=0.05)
        assert point_patterns.correct(match, scene.truth)
        assert not point_patterns.correct(None, scene.truth)


@pytest.mark.timeout(120)
def test_quick_run_prints_the_table(capsys: pytest.CaptureFixture[str]) -> None:
    assert point_patterns.main(["--quick", "--trials", "5"]) == 0
    out = capsys.readouterr().out
    rows = list(ROW.finditer(out))
    assert len(rows) == 2, out
    for row in rows:
        assert (int(row["m"]), int(row["n"])) == (5, 20)
    assert out.count("target: ") == 2
    assert re.search(r"target: FPPM median under 2 ms .*: (met|NOT met)", out)
