"""tools/measure/timing_transfer.py, run as a script: the accuracy-runtime figure's places of two regenerations,
compared."""

from __future__ import annotations

from pathlib import Path

import pandas as pd
from tool_support import run_tool


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


def _transfer(*args: str) -> tuple[int, list[str]]:
    done = run_tool("measure/timing_transfer.py", *args)
    assert not done.stderr, done.stderr
    return done.returncode, done.stdout.splitlines()


def test_ratios_are_b_over_a_per_configuration(tmp_path: Path) -> None:
    a = _metrics(tmp_path / "a.csv", {"pf": 10.0, "odometry": 100.0}, {"pf": 1.0, "odometry": 8.0})
    b = _metrics(tmp_path / "b.csv", {"pf": 4.0, "odometry": 30.0}, {"pf": 1.1, "odometry": 8.0})
    code, lines = _transfer(a, b)
    assert code == 0
    # raw: pf 6 / 15 = 0.4, odometry 45 / 150 = 0.3; reference units: pf 1.65 / 1.5 = 1.1, odometry 12 / 12 = 1
    assert "ratio_raw: median 0.350 (0.300-0.400) over 2 configurations" in lines
    assert "ratio_ref: median 1.050 (1.000-1.100) over 2 configurations" in lines
    assert lines[-1] == "x order (reference units), Spearman A vs B: 1.000; ATE identical: True"


def test_tolerance_and_moved_accuracy_fail(tmp_path: Path) -> None:
    a = _metrics(tmp_path / "a.csv", {"pf": 10.0}, {"pf": 1.0})
    b = _metrics(tmp_path / "b.csv", {"pf": 4.0}, {"pf": 1.5})
    code, lines = _transfer(a, b, "--tolerance", "0.8", "1.25")
    assert code == 1 and "outside [0.8, 1.25]: office pf" in lines
    assert _transfer(a, b, "--tolerance", "0.8", "1.6")[0] == 0
    moved = _metrics(tmp_path / "c.csv", {"pf": 10.0}, {"pf": 1.0}, ate_shift=1e-12)
    code, lines = _transfer(a, moved)
    assert code == 1 and lines[-1].endswith("ATE identical: False")
