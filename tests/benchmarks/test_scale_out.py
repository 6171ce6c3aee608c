"""``python -m benchmarks.scale_out --quick``: the scale-out benchmark runs end to end (a
router, one then two service instances, the publisher process) and loses nothing."""

from __future__ import annotations

import re
from pathlib import Path

import orjson
import pytest

from benchmarks import scale_out

ROW = re.compile(
    r"^\s+(?P<name>\d instances?)\s+(?P<instances>\d+)\s+(?P<published>\d+)\s+"
    r"(?P<processed>\d+)\s+(?P<lost>-?\d+)\s+(?P<seconds>[\d.]+)\s+(?P<rate>[\d.]+)\s+"
    r"(?P<detections>\d+)\s+(?P<ratio>[\d.]+)$",
    re.MULTILINE,
)


def test_batches_are_in_time_order_and_survive_the_file(tmp_path: Path) -> None:
    batches = scale_out.generate_batches(targets=20, scans=6, clutter=5.0, seed=3)
    assert len(batches) == 12
    docs = [orjson.loads(payload) for _, payload in batches]
    times = [d["time"] for d in docs]
    assert times == sorted(times) and len(set(times)) == len(times)
    for (key, _), doc in zip(batches, docs, strict=True):
        assert key == f"tracking/detections/{doc['sensor_id']}"
        assert 10 <= len(doc["detections"]) <= 40
    path = tmp_path / "batches.bin"
    scale_out.write_batches(path, batches)
    assert scale_out.read_batches(path) == batches
    assert scale_out.generate_batches(20, 6, 5.0, 3) == batches  # reproducible


@pytest.mark.timeout(180)
def test_quick_run_scales_out_and_loses_nothing(capsys: pytest.CaptureFixture[str]) -> None:
    code = scale_out.main(["--quick"])
    out = capsys.readouterr().out
    assert code == 0, out
    rows = {m["name"]: m for m in ROW.finditer(out)}
    assert set(rows) == {"1 instance", "2 instances"}, out
    for name, row in rows.items():
        assert int(row["instances"]) == (1 if name == "1 instance" else 2)
        assert int(row["published"]) > 0
        assert int(row["processed"]) == int(row["published"]), out
        assert int(row["lost"]) == 0, out
        assert float(row["rate"]) > 0 and int(row["detections"]) > 0, out
    assert "rejected 0, dropped 0" in out
    assert "nothing lost (met)" in out
    # every target of the quick run (50 per sector) is held by the instance(s) of its sector
    confirmed = [int(n) for n in re.findall(r"(\d+) confirmed", out)]
    assert len(confirmed) == 3, out
    assert confirmed[0] >= 90 and all(n >= 45 for n in confirmed[1:]), out
