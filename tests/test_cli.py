"""The command line: one-line errors that say what is valid, and a run -> report round trip."""

from __future__ import annotations

from pathlib import Path

import pandas as pd
import pytest

from locbench.cli import main


@pytest.mark.parametrize(
    ("argv", "expected"),
    [
        (["run", "--filter", "nope", "--dataset", "room"], "unknown filter 'nope'; valid: "),
        (["run", "--filter", "odometry", "--dataset", "nowhere"], "unknown dataset 'nowhere'; valid: "),
        (["run", "--filter", "ekf_landmarks[gate_probability=high]", "--dataset", "room"], "expected a number"),
        (["run", "--filter", "ekf_landmarks[no_such_key=1]", "--dataset", "room"], "valid: "),
        (["run", "--filter", "odometry[", "--dataset", "room"], "malformed spec"),
        (["run", "--suite", "nosuch"], "unknown suite 'nosuch'; valid: all, consistency, default"),
        (["run", "--filter", "odometry"], "--filter and --dataset go together"),
        (["check", "nope"], "unknown filter or dataset 'nope'; valid: "),
    ],
)
def test_bad_input_is_one_line_error(
    argv: list[str], expected: str, capsys: pytest.CaptureFixture[str], tmp_path: Path
) -> None:
    code = main([*argv, "--results", str(tmp_path)] if argv[0] == "run" else argv)
    err = capsys.readouterr().err
    assert code == 2
    assert expected in err
    assert err.count("\n") == 1, err


@pytest.mark.parametrize(
    ("text", "expected"),
    [
        ("filters = [\n", "not valid TOML"),
        ('filters = ["odometry"]\ndatasets = []\n', "field 'datasets' must be a non-empty list"),
        ('filters = ["odometry"]\ndatasets = ["room"]\nseeds = "ten"\n', "field 'seeds' must be a positive integer"),
        ('filters = ["odometry"]\ndatasets = ["room"]\ncolour = 1\n', "unknown field(s) colour"),
    ],
)
def test_malformed_suite_file_names_file_and_field(
    text: str, expected: str, tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    f = tmp_path / "bad.toml"
    f.write_text(text)
    assert main(["run", "--suite", str(f), "--results", str(tmp_path / "r")]) == 2
    err = capsys.readouterr().err
    assert str(f) in err and expected in err


def test_report_without_runs_is_an_error(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    assert main(["report", "--results", str(tmp_path)]) == 2
    assert "no stored runs" in capsys.readouterr().err


def test_list_shows_filters_datasets_suites(capsys: pytest.CaptureFixture[str]) -> None:
    assert main(["list"]) == 0
    out = capsys.readouterr().out
    for word in ("odometry", "ekf_landmarks", "room", "office", "default"):
        assert word in out


def test_run_then_report(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    res = str(tmp_path / "res")
    assert main(["run", "--suite", "smoke", "--seeds", "1", "--results", res, "--no-progress"]) == 0
    assert "6 ok" in capsys.readouterr().out
    assert main(["report", "--results", res]) == 0
    summary = Path(res) / "summary"
    assert (summary / "metrics.parquet").is_file() and (summary / "REPORT.md").is_file()
    assert list(pd.read_parquet(summary / "metrics.parquet").columns) == [
        "dataset",
        "filter",
        "seed",
        "metric",
        "value",
    ]
    # every stored run and its truth as TUM trajectories, for evo
    out = tmp_path / "tum"
    assert main(["export", "--results", res, "--out", str(out), "--filter", "odometry"]) == 0
    assert "TUM trajectory files written" in capsys.readouterr().out
    files = sorted(p.relative_to(out).as_posix() for p in out.rglob("*.tum"))
    assert any(f.startswith("tiny_line/odometry/") for f in files)
    assert any("/_truth/" in f for f in files)
    assert not any("ekf_landmarks" in f for f in files)


@pytest.mark.usefixtures("harness_registry")
def test_run_plans_claims_and_writes_through_one_store(tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> None:
    from locbench.run import store as store_mod

    made: list[Path] = []
    real = store_mod.Store.__init__

    def counted(self: store_mod.Store, root: str) -> None:
        made.append(Path(root))
        real(self, root)

    monkeypatch.setattr(store_mod.Store, "__init__", counted)
    argv = ["run", "--filter", "bad[fail_at_s=100]", "--dataset", "line", "--results", str(tmp_path), "--no-progress"]
    assert main(argv) == 0
    assert made == [tmp_path]
    assert main(argv) == 0  # the second time every run is cached: still one store
    assert made == [tmp_path, tmp_path]


def test_fetch_synthetic_has_nothing_to_fetch(capsys: pytest.CaptureFixture[str]) -> None:
    assert main(["fetch", "room"]) == 0
    assert "nothing to fetch" in capsys.readouterr().out


def test_fetch_without_an_official_download_is_a_one_line_error(
    tmp_path: Path, monkeypatch: pytest.MonkeyPatch, capsys: pytest.CaptureFixture[str]
) -> None:
    monkeypatch.setenv("LOCBENCH_DATA", str(tmp_path / "nodata"))
    monkeypatch.setenv("LOCBENCH_CACHE", str(tmp_path / "cache"))
    assert main(["fetch", "lost_in_the_woods"]) == 2
    err = capsys.readouterr().err
    assert "no official download" in err and err.count("\n") == 1


def test_list_filter_prints_every_parameter_with_type_default_unit_and_meaning(
    capsys: pytest.CaptureFixture[str],
) -> None:
    from locbench.core.spec import param_fields
    from locbench.filters.pf import ParticleFilterConfig

    assert main(["list", "pf"]) == 0
    lines = capsys.readouterr().out.splitlines()
    rows = {ln.split()[0]: ln for ln in lines[3:]}
    assert set(rows) == set(param_fields(ParticleFilterConfig))
    assert rows["particles"].split()[1:3] == ["int", "1000"] and "Number of particles" in rows["particles"]
    assert rows["sigma_hit_m"].split()[1:4] == ["float", "0.2", "m"] and "hit Gaussian" in rows["sigma_hit_m"]
    assert rows["init"].split()[1:4] == ["{belief,", "uniform}", "belief"]
    assert "(undocumented)" not in "\n".join(lines)


def test_list_dataset_and_unknown_id(capsys: pytest.CaptureFixture[str]) -> None:
    assert main(["list", "room", "office"]) == 0
    out = capsys.readouterr().out
    assert "kidnap_m" in out and "Kidnap distance" in out and "dataset office:" in out
    assert main(["list", "nope"]) == 2
    assert "unknown filter or dataset 'nope'; valid: " in capsys.readouterr().err
