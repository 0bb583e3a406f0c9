"""tools/timing_transfer.py: the accuracy-runtime figure's places of two regenerations, compared."""

from __future__ import annotations

from pathlib import Path

import pandas as pd
import pytest
from tool_support import load_tool

tt = load_tool("timing_transfer")


def _metrics(path: Path, rtf: dict[str, float], ref: dict[str, float], ate_shift: float = 0.0) -> str:
    rows = []
    for flt in rtf:
        for seed in (0, 1):
            rows += [
                ("office", flt, seed, "realtime_factor", rtf[flt] * (1 + seed)),
                ("office", flt, seed, "realtime_factor_ref", ref[flt] * (1 + seed)),
                ("office", flt, seed, "ate_m", 0.1 + seed + ate_shift),
                ("office", flt, seed, "rpe_m_per_m", 9.0),
            ]
    pd.DataFrame(rows, columns=["dataset", "filter", "seed", "metric", "value"]).to_csv(path, index=False)
    return str(path)


def test_ratios_are_b_over_a_per_configuration(tmp_path: Path) -> None:
    a = _metrics(tmp_path / "a.csv", {"pf": 10.0, "odometry": 100.0}, {"pf": 1.0, "odometry": 8.0})
    b = _metrics(tmp_path / "b.csv", {"pf": 4.0, "odometry": 30.0}, {"pf": 1.1, "odometry": 8.0})
    table = tt.compare(tt.places(a), tt.places(b))
    assert table.loc[("office", "pf"), "ratio_raw"] == pytest.approx(0.4)
    assert table.loc[("office", "pf"), "ratio_ref"] == pytest.approx(1.1)
    assert table.loc[("office", "odometry"), "ratio_ref"] == pytest.approx(1.0)
    assert table["same_ate"].all()


def test_tolerance_and_moved_accuracy_fail(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    a = _metrics(tmp_path / "a.csv", {"pf": 10.0}, {"pf": 1.0})
    b = _metrics(tmp_path / "b.csv", {"pf": 4.0}, {"pf": 1.5})
    assert tt.main([a, b, "--tolerance", "0.8", "1.25"]) == 1
    assert "outside [0.8, 1.25]: office pf" in capsys.readouterr().out
    assert tt.main([a, b, "--tolerance", "0.8", "1.6"]) == 0
    moved = _metrics(tmp_path / "c.csv", {"pf": 10.0}, {"pf": 1.0}, ate_shift=1e-12)
    assert tt.main([a, moved]) == 1
