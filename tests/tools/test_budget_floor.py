"""tools/measure/budget_floor.py, run as a script: a store's runs counted once each, by the first suite that has
them, and the floor from their recorded seconds."""

from __future__ import annotations

import json
from pathlib import Path

from tool_support import run_tool


def _write(path: Path, record: dict) -> None:
    path.parent.mkdir(parents=True, exist_ok=True)
    path.write_text(json.dumps(record))


def _run(root: Path, dataset: str, flt: str, seed: int, wall: float, steps: float) -> None:
    meta = {"filter": flt, "filter_id": flt.split("[")[0], "dataset": dataset, "wall_s": wall, "compute_s": steps}
    _write(root / "runs" / dataset / flt / f"seed-{seed:04d}" / "meta.json", meta)


def test_floor_counts_each_run_once_by_its_first_suite(tmp_path: Path) -> None:
    # pf on room is in 'default' (and in no earlier suite); pf on room[matched=true] only in 'consistency'
    _run(tmp_path, "room", "pf", 0, 10.0, 6.0)
    _run(tmp_path, "room", "pf", 1, 14.0, 8.0)
    _run(tmp_path, "room[matched=true]", "pf", 0, 30.0, 20.0)
    _run(tmp_path, "tiny_line", "odometry", 0, 2.0, 1.0)  # in none of them: 'tuned (test runs)'
    _run(tmp_path / "tuning", "room", "pf[sigma_range_m=0.2]", 1000, 40.0, 30.0)
    _write(tmp_path / "runs" / "room" / "_truth" / "seed-0000.json", {"build_s": 3.0})
    _write(tmp_path / "runs" / "room" / "_truth" / "seed-0000.bound.json", {"compute_s": 5.0})
    done = run_tool("measure/budget_floor.py", str(tmp_path))
    assert done.returncode == 0, done.stderr
    lines = done.stdout.splitlines()
    rows = {line[:22].strip(): line[22:].split() for line in lines[: lines.index("")]}
    assert rows["default"] == ["2", "24", "14", "10"]
    assert rows["consistency"] == ["1", "30", "20", "10"]
    assert rows["tuned (test runs)"] == ["1", "2", "1", "1"]
    assert rows["tuned (trials)"] == ["1", "40", "30", "10"]
    assert rows["all"] == ["5", "96", "65", "31"]
    assert "dataset builds 3 s, bounds 5 s (each realisation once)" in lines
    # (96 run-s + 3 s + 5 s) / 2 cores = 52 s; (65 + 3 + 5) / 2 = 36.5 s
    assert lines[-2:] == [
        "floor on 2 cores, the runs as measured: 0.9 min",
        "floor on 2 cores, no time around the filters' steps: 0.6 min",
    ]
