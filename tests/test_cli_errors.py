"""Operating-system and network errors the command line meets: one line each, never a traceback.

The tests run as any user (root ignores permission bits), so "permission denied" and "read-only" are
injected where the operating system would raise them: the first write into the folder concerned.
"""

from __future__ import annotations

import errno
import os
import pathlib
import tempfile
from pathlib import Path

import pytest

from locbench.cli import main

SMOKE = ["run", "--filter", "odometry", "--dataset", "tiny_line", "--no-progress"]


def _one_line(capsys: pytest.CaptureFixture[str], *expected: str) -> str:
    err = capsys.readouterr().err
    assert err.count("\n") == 1 and "Traceback" not in err, err
    for text in expected:
        assert text in err, err
    return err


def _refuse_writes_under(monkeypatch: pytest.MonkeyPatch, folder: Path, code: int) -> None:
    """Make creating a folder or a temporary file under ``folder`` fail with ``code``, as the OS would."""
    real_mkdir, real_mkstemp = pathlib.Path.mkdir, tempfile.mkstemp

    def refuse(path: str) -> None:
        raise OSError(code, os.strerror(code), path)

    def mkdir(self: Path, *args: object, **kwargs: object) -> None:
        if str(self).startswith(str(folder)):
            refuse(str(self))
        real_mkdir(self, *args, **kwargs)  # type: ignore[arg-type]

    def mkstemp(*args: object, dir: str | None = None, **kwargs: object) -> tuple[int, str]:
        if dir is not None and str(dir).startswith(str(folder)):
            refuse(str(dir))
        return real_mkstemp(*args, dir=dir, **kwargs)  # type: ignore[call-overload,no-any-return]

    monkeypatch.setattr(pathlib.Path, "mkdir", mkdir)
    monkeypatch.setattr(tempfile, "mkstemp", mkstemp)


@pytest.mark.parametrize(
    ("code", "text"),
    [
        (errno.EACCES, "Permission denied (choose a folder you may write"),
        (errno.EROFS, "Read-only file system (the file system is read-only"),
        (errno.ENOSPC, "No space left on device (the disk is full"),
    ],
)
def test_run_into_an_unwritable_results_folder(
    tmp_path: Path, monkeypatch: pytest.MonkeyPatch, capsys: pytest.CaptureFixture[str], code: int, text: str
) -> None:
    res = tmp_path / "res"
    res.mkdir()
    _refuse_writes_under(monkeypatch, res, code)
    assert main([*SMOKE, "--results", str(res)]) == 2
    _one_line(capsys, str(res / "runs"), text)
    assert list(res.iterdir()) == []


def test_run_with_results_naming_a_file(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    f = tmp_path / "results.txt"
    f.write_text("not a folder")
    assert main([*SMOKE, "--results", str(f)]) == 2
    _one_line(capsys, str(f), "Not a directory", "give a folder")


def _stored_results(tmp_path: Path) -> Path:
    res = tmp_path / "res"
    assert main([*SMOKE, "--results", str(res)]) == 0
    return res


def test_report_into_a_read_only_folder(
    tmp_path: Path, monkeypatch: pytest.MonkeyPatch, capsys: pytest.CaptureFixture[str]
) -> None:
    res = _stored_results(tmp_path)
    # the summary is written in a new folder beside it, then swapped in: the results folder is written into
    _refuse_writes_under(monkeypatch, res, errno.EROFS)
    capsys.readouterr()
    assert main(["report", "--results", str(res)]) == 2
    _one_line(capsys, "summary", "Read-only file system")


def test_export_into_a_read_only_folder_and_export_of_nothing(
    tmp_path: Path, monkeypatch: pytest.MonkeyPatch, capsys: pytest.CaptureFixture[str]
) -> None:
    res = _stored_results(tmp_path)
    capsys.readouterr()
    assert main(["export", "--results", str(res), "--out", str(tmp_path / "tum"), "--filter", "pf"]) == 1
    _one_line(capsys, "no stored run with estimates matching", "nothing written")
    _refuse_writes_under(monkeypatch, tmp_path / "ro", errno.EACCES)
    assert main(["export", "--results", str(res), "--out", str(tmp_path / "ro")]) == 2
    _one_line(capsys, str(tmp_path / "ro"), "Permission denied")


def test_export_to_a_file(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    res = _stored_results(tmp_path)
    (tmp_path / "out").write_text("")
    capsys.readouterr()
    assert main(["export", "--results", str(res), "--out", str(tmp_path / "out")]) == 2
    _one_line(capsys, str(tmp_path / "out"))


@pytest.mark.parametrize(
    ("make", "expected"),
    [
        (lambda p: p.mkdir(), "is a folder; expected the suite file as a regular file of at most 1048576 bytes"),
        (lambda p: p.write_bytes(b'filters = ["odometry"]\ndatasets = ["r\xf6om"]\n'), "not UTF-8 text (byte 37)"),
    ],
    ids=["is-a-directory", "undecodable"],
)
def test_suite_argument_that_is_not_a_suite_file(
    tmp_path: Path, capsys: pytest.CaptureFixture[str], make: object, expected: str
) -> None:
    suite = tmp_path / "suite.toml"
    make(suite)  # type: ignore[operator]
    assert main(["run", "--suite", str(suite), "--results", str(tmp_path / "r"), "--no-progress"]) == 2
    _one_line(capsys, str(suite), expected)


def test_fetch_without_network(
    tmp_path: Path, monkeypatch: pytest.MonkeyPatch, capsys: pytest.CaptureFixture[str]
) -> None:
    import pooch
    import requests

    def offline(*args: object, **kwargs: object) -> str:
        raise requests.exceptions.ConnectionError(
            "HTTPSConnectionPool(host='example.org', port=443): Max retries exceeded (Caused by NameResolutionError(\n"
            "'Failed to resolve'))"
        )

    monkeypatch.setenv("LOCBENCH_DATA", str(tmp_path / "nodata"))
    monkeypatch.setenv("LOCBENCH_CACHE", str(tmp_path / "cache"))
    monkeypatch.setattr(pooch, "retrieve", offline)
    assert main(["fetch", "plaza[run=1]"]) == 2
    _one_line(capsys, "plaza: download failed (is the network reachable?)", "Max retries exceeded")


def test_fetch_rosbag_without_a_path_names_the_parameter(capsys: pytest.CaptureFixture[str]) -> None:
    pytest.importorskip("rosbags", reason="the rosbag loader needs the 'ros' extra")
    assert main(["fetch", "rosbag"]) == 2
    _one_line(capsys, "parameter 'path' is required")


def test_missing_data_names_the_path_once(tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> None:
    from locbench.run.sweep import run_many

    monkeypatch.setenv("LOCBENCH_DATA", str(tmp_path / "nodata"))
    monkeypatch.setenv("LOCBENCH_CACHE", str(tmp_path / "cache"))
    (out,) = run_many(["odometry"], ["plaza"], [0], str(tmp_path / "res"))
    first = str(tmp_path / "nodata")
    assert out.status == "skipped" and out.message.count(first) == 1 and "locbench fetch" in out.message
    assert "download=true" not in out.message


def test_check_does_not_say_all_passed_when_checks_were_skipped(
    monkeypatch: pytest.MonkeyPatch, capsys: pytest.CaptureFixture[str]
) -> None:
    from types import SimpleNamespace

    import locbench.checks

    results = [
        SimpleNamespace(target="pf", check="determinism", outcome="passed", message=""),
        SimpleNamespace(target="kf_linear", check="contract", outcome="skipped", message="filterpy is not installed"),
    ]
    monkeypatch.setattr(locbench.checks, "run_checks", lambda ids: iter(results))
    assert main(["check"]) == 0
    last = capsys.readouterr().out.splitlines()[-1]
    assert "all" not in last and "1 were skipped" in last and "1 passed, 1 skipped" in last
