"""``python -m benchmarks.formation --plots DIR``: paper 003's figures 4-6 and Table II as
PNGs, and the whole comparison end to end with one seed."""

from __future__ import annotations

from pathlib import Path

import pytest

from benchmarks import formation

NAMES = ("formation_tracks.png", "formation_rmse.png", "formation_rates.png")


@pytest.mark.timeout(300)
def test_write_plots_writes_the_three_figures(tmp_path: Path) -> None:
    paths = formation.write_plots(tmp_path, seeds=1)
    assert [p.name for p in paths] == list(NAMES)
    for path in paths:
        assert path.parent == tmp_path
        data = path.read_bytes()
        assert data[:4] == b"\x89PNG"
        assert len(data) > 10_000


@pytest.mark.timeout(300)
def test_main_with_one_seed_prints_the_tables_and_writes_the_plots(
    tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    assert formation.main(["--seeds", "1", "--plots", str(tmp_path)]) == 0
    out = capsys.readouterr().out
    assert "Environment 1" in out and "Environment 2" in out and "Environment 3" in out
    assert "plots: " in out
    for name in NAMES:
        assert str(tmp_path / name) in out
        assert (tmp_path / name).read_bytes()[:4] == b"\x89PNG"
