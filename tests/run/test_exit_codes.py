"""Exit codes a script can rely on, and the modes of the files the commands write."""

from __future__ import annotations

import os
import stat
from collections.abc import Iterator
from pathlib import Path

import pytest

from locbench.cli import main
from locbench.run import store as store_mod


@pytest.fixture
def no_data(tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> Path:
    """An empty data folder: every recorded dataset is skipped for missing files."""
    empty = tmp_path / "data"
    empty.mkdir()
    monkeypatch.setenv("LOCBENCH_DATA", str(empty))
    monkeypatch.setenv("XDG_CACHE_HOME", str(tmp_path / "cache"))
    monkeypatch.setenv("HOME", str(tmp_path / "home"))
    return empty


def test_a_run_of_named_datasets_that_ran_none_exits_nonzero_with_the_reason(
    no_data: Path, tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    res = tmp_path / "res"
    argv = ["run", "--filter", "odometry", "--dataset", "mrclam", "--results", str(res), "--no-progress"]
    assert main(argv) == 1
    cap = capsys.readouterr()
    assert "1 skipped" in cap.out
    assert "no run was made: every run was skipped" in cap.err and "data not found" in cap.err
    # the report of a store of skipped runs is written, and says that nothing ran
    assert main(["report", "--results", str(res), "--out", str(tmp_path / "out")]) == 1
    err = capsys.readouterr().err
    assert "holds only skipped runs" in err and "data not found" in err
    assert (tmp_path / "out" / "REPORT.md").is_file()


def test_a_run_with_one_made_run_exits_zero(no_data: Path, tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    res = tmp_path / "res"
    argv = ["run", "--filter", "odometry", "--dataset", "mrclam", "tiny_line", "--results", str(res), "--no-progress"]
    assert main(argv) == 0
    assert "1 ok, 1 skipped" in capsys.readouterr().out
    assert main(["report", "--results", str(res), "--out", str(tmp_path / "out")]) == 0
    assert "only skipped" not in capsys.readouterr().err


@pytest.fixture
def umask_027() -> Iterator[None]:
    """The process's umask set to 027 (and the store's cached reading of it cleared) for one test."""
    old = os.umask(0o027)
    store_mod._umask.cache_clear()
    try:
        yield
    finally:
        os.umask(old)
        store_mod._umask.cache_clear()


@pytest.mark.usefixtures("umask_027")
def test_exported_files_follow_the_umask(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    res = tmp_path / "res"
    assert main(["run", "--filter", "odometry", "--dataset", "tiny_line", "--results", str(res), "--no-progress"]) == 0
    tum = tmp_path / "tum"
    assert main(["export", "--results", str(res), "--out", str(tum)]) == 0
    log = tmp_path / "log"
    assert main(["export", "--format", "textlog", "--dataset", "tiny_line", "--out", str(log)]) == 0
    files = [p for p in [*tum.rglob("*"), *log.rglob("*")] if p.is_file()]
    assert len(files) >= 4
    modes = {p.name: stat.S_IMODE(p.stat().st_mode) for p in files}
    assert set(modes.values()) == {0o640}, modes
