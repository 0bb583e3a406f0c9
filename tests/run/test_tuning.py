"""Tuning: declared search spaces, the optuna study (seeded, resumable, shared), the protocol's splits and budget."""

from __future__ import annotations

import dataclasses
import math
from pathlib import Path
from typing import Any

import pandas as pd
import pytest

from locbench.cli import main
from locbench.core.tunable import TunableRange, tunable_fields
from locbench.registry import FILTERS, resolve_dataset, resolve_filter
from locbench.run import sweep
from locbench.run.store import Store
from locbench.suites import SUITES

optuna = pytest.importorskip("optuna", reason="tuning needs optuna (pip install 'locbench[tune]')")

from locbench.run import tuning  # noqa: E402 - after the skip: the module needs optuna to tune

#: Fields that are a user's compute budget, never tuned for accuracy.
COMPUTE_KNOBS = {
    "particles",
    "lag_s",
    "laser_beams",
    "grid_step_m",
    "heading_step_deg",
    "min_particles",
    "max_particles",
}


@pytest.mark.parametrize("ident", FILTERS.ids())
def test_declared_ranges_are_valid_and_hold_the_default(ident: str) -> None:
    if FILTERS.missing_dependency(ident):
        pytest.skip(FILTERS.missing_dependency(ident) or "")
    cls = FILTERS.load(ident).Config
    fields = tunable_fields(cls)
    assert not set(fields) & COMPUTE_KNOBS, "a compute knob is the user's budget, not a tuning parameter"
    defaults = {f.name: f.default for f in dataclasses.fields(cls)}
    for name, rng in fields.items():
        assert isinstance(rng, TunableRange)
        if defaults[name] is not None:  # None: the dataset's nominal value
            assert rng.contains(defaults[name]), f"{ident}.{name}: default {defaults[name]} outside {rng.describe()}"
        # the range's ends build a valid config (the tuner may ask for them)
        for end in (rng.low, rng.high) if rng.kind != "choice" else rng.choices:
            resolve_filter(f"{ident}[{name}={int(end) if rng.kind == 'int' else end}]")


def test_every_comparison_filter_but_the_baseline_is_tunable() -> None:
    assert "odometry" not in tuning.tuned_filters()
    assert set(tuning.tuned_filters()) == {
        "ekf_landmarks",
        "ukf_landmarks",
        "iekf_landmarks",
        "ekf_lines",
        "ekf_icp",
        "kf_linear",
        "pf",
        "gtsam_fls",
    } - {f for f in FILTERS.ids() if FILTERS.missing_dependency(f)}


def test_tunable_metadata_leaves_the_run_key_alone() -> None:
    from locbench.core.runkey import key_params

    cfg = resolve_filter("ekf_landmarks").params
    assert "motion_noise_scale" not in key_params(cfg)  # added after runs were stored: omitted at its default
    assert key_params(resolve_filter("ekf_landmarks[motion_noise_scale=2]").params)["motion_noise_scale"] == 2.0


def test_list_shows_the_tunable_fields_and_ranges(capsys: pytest.CaptureFixture[str]) -> None:
    assert main(["list", "ekf_icp"]) == 0
    out = capsys.readouterr().out
    assert "tunable ('locbench tune ekf_icp'): r_x_m2, " in out
    line = next(ln for ln in out.splitlines() if ln.strip().startswith("max_iterations "))
    assert "[5, 700] int log" in line
    assert main(["list", "pf"]) == 0
    particles = next(ln for ln in capsys.readouterr().out.splitlines() if ln.strip().startswith("particles "))
    assert "  -  " in particles  # not tunable


def test_a_misset_noise_parameter_is_found(tmp_path: Path) -> None:
    # ekf_landmarks with everything else at its value, the range noise free: tiny_line's simulator draws ranges
    # with 0.02 m; a filter told 0.5 m (25 times too much) ignores its landmarks. The tuner, on train seeds only,
    # must bring it back to the right value within a factor of 2 (log-scale search over [0.001, 1] m).
    spec = "ekf_landmarks[motion_noise_scale=1,sigma_bearing_rad=0.01745]"
    # The default (trial 0, the dataset's nominal value) is the right one; the searched trials must find it too.
    res = tuning.tune(spec, ["tiny_line"], 14, 3, tmp_path, objective="nll")
    searched = [t for t in res.trials if t.number > 0 and math.isfinite(t.value)]
    best = min(searched, key=lambda t: t.value, default=None)
    assert best is not None
    found = resolve_filter(best.spec).params.sigma_range_m
    assert 0.01 <= found <= 0.04, f"tuned sigma_range_m {found} m, the simulator's is 0.02 m"
    misset = tuning.trial_spec("ekf_landmarks", {"sigma_bearing_rad": "0.01745"}, {"sigma_range_m": 0.5})
    store = Store(tmp_path / "misset")
    sweep.run_many([misset], ["tiny_line"], tuning.train_seeds(3), str(store.root))
    worse, _ = tuning.score_trial(store, misset, ["tiny_line"], tuning.train_seeds(3), "nll")
    assert best.value < worse


def test_same_command_same_trials(tmp_path: Path) -> None:
    a = tuning.tune("ekf_landmarks", ["tiny_line"], 4, 1, tmp_path / "a")
    b = tuning.tune("ekf_landmarks", ["tiny_line"], 4, 1, tmp_path / "b")
    assert [t.spec for t in a.trials] == [t.spec for t in b.trials]
    assert [t.value for t in a.trials] == [t.value for t in b.trials]


def test_the_default_is_trial_0_and_counts_in_the_budget(tmp_path: Path) -> None:
    spec = "ekf_landmarks[motion_noise_scale=1]"
    res = tuning.tune(spec, ["tiny_line"], 3, 2, tmp_path)
    assert [t.number for t in res.trials] == [0, 1, 2] and res.budget_runs == 3 * 2
    assert res.trials[0].spec == resolve_filter(spec).name  # the plain spec: sigma_* stay the dataset's nominal
    assert all(t.spec != res.trials[0].spec for t in res.trials[1:])
    # its runs are ordinary stored runs of the plain spec, read back by a rerun without the journal
    store = Store(tmp_path / "tuning")
    assert all(store.existing_meta("tiny_line", res.trials[0].spec, s) for s in tuning.train_seeds(2))
    for p in (tmp_path / "tuning" / "studies").iterdir():
        p.unlink()
    again = tuning.tune(spec, ["tiny_line"], 3, 2, tmp_path)
    assert again.trials == res.trials and again.reused == 3


def test_the_default_is_kept_when_every_searched_trial_is_worse(
    tmp_path: Path, monkeypatch: pytest.MonkeyPatch, capsys: pytest.CaptureFixture[str]
) -> None:
    # tiny_line's simulator draws ranges with 0.02 m, the default's nominal value; the search may only ask
    # 0.3-1 m, which ignores the landmarks: no searched trial can beat the default on the train data's NLL.
    real = tuning.tunable_fields

    def narrowed(cls: Any) -> dict[str, TunableRange]:
        out = real(cls)
        return {**out, "sigma_range_m": dataclasses.replace(out["sigma_range_m"], low=0.3, high=1.0)}

    monkeypatch.setattr(tuning, "tunable_fields", narrowed)
    spec = "ekf_landmarks[motion_noise_scale=1,sigma_bearing_rad=0.01745]"
    args = ["--dataset", "tiny_line", "--trials", "4", "--seeds", "2", "--results", str(tmp_path)]
    assert main(["tune", spec, "--objective", "nll", *args]) == 0
    last = capsys.readouterr().out.strip().splitlines()[-1]
    assert last == resolve_filter(spec).name and "sigma_range_m" not in last
    res = tuning.tune(spec, ["tiny_line"], 4, 2, tmp_path, objective="nll")
    assert res.default_kept and res.best is not None and res.best.number == 0
    assert all(t.value > res.best.value for t in res.trials[1:])
    assert all(0.3 <= resolve_filter(t.spec).params.sigma_range_m <= 1.0 for t in res.trials[1:])


def test_two_filters_get_the_same_budget(tmp_path: Path) -> None:
    a = tuning.tune("ekf_landmarks", ["tiny_line", "tiny_circle"], 3, 2, tmp_path)
    b = tuning.tune("ukf_landmarks", ["tiny_line", "tiny_circle"], 3, 2, tmp_path)
    assert a.budget_runs == b.budget_runs == 3 * 2 * 2
    # and every study of the tuned suite: the same trials x train runs
    budgets = {(tuning.SUITE_TRIALS, len(s.train) * s.seeds) for s in tuning.suite_studies()}
    assert len(budgets) == 1, budgets


def test_train_and_test_data_are_disjoint() -> None:
    train = tuning.train_seeds(tuning.SUITE_TRAIN_RUNS)
    # no suite stores a run at a train seed: every stored comparison run is test data for a tuned filter
    assert min(train) > max(b.seeds for s in SUITES.values() for b in s.blocks)
    held_out: dict[str, list[str]] = {}
    for s in tuning.suite_studies():
        if set(s.train) & set(s.test):  # a synthetic world: split by seed
            assert not set(tuning.train_seeds(s.seeds)) & set(s.test_seeds), s
        else:  # recordings: leave one robot out, the others tune
            assert len(s.test) == 1 and s.fold, s
            (held,) = (resolve_dataset(d).params.robot for d in s.test)
            train = [resolve_dataset(d).params for d in s.train]
            # the other four robots, each with the held-out robot's fold of noise (derived without it)
            assert sorted(p.robot for p in train) == [r for r in range(1, 6) if r != held]
            assert {p.noise_fold for p in train} == {held}
            held_out.setdefault(s.filter, []).extend(s.test)
    # every robot is held out exactly once per filter
    robots = sorted(test for _, test in tuning.mrclam_folds())
    assert held_out and all(sorted(v) == robots for v in held_out.values()), held_out


def test_a_diverging_trial_scores_as_the_worst(tmp_path: Path, harness_registry: None) -> None:
    FILTERS.register("bad_tunable", "harness_support:TunableBadFilter")
    res = tuning.tune("bad_tunable", ["line"], 6, 1, tmp_path)
    fail_at = {t.number: resolve_filter(t.spec).params.fail_at_s for t in res.trials}
    diverged = [t for t in res.trials if fail_at[t.number] < 5.0]  # line lasts 5 s
    fine = [t for t in res.trials if fail_at[t.number] >= 5.0]
    assert diverged and fine, fail_at
    assert all(t.value == math.inf and "diverged" in t.message for t in diverged)
    assert all(math.isfinite(t.value) for t in fine)
    assert res.best is not None and res.best in fine


def test_a_resumed_study_does_not_repeat_finished_trials(tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> None:
    straight = tuning.tune("ekf_landmarks", ["tiny_line"], 5, 1, tmp_path / "straight")

    # The same study stopped by Ctrl-C during its fourth trial, then run again.
    calls = {"n": 0}
    real = sweep.run_sweep

    def interrupted_once(plan: Any, *a: Any, **k: Any) -> Any:
        calls["n"] += 1
        if calls["n"] == 4:
            return sweep.SweepResult([], plan.total, interrupted=True)
        return real(plan, *a, **k)

    monkeypatch.setattr(sweep, "run_sweep", interrupted_once)
    first = tuning.tune("ekf_landmarks", ["tiny_line"], 5, 1, tmp_path / "resumed")
    assert first.interrupted and len(first.trials) == 3
    monkeypatch.setattr(sweep, "run_sweep", real)
    planned: list[int] = []

    def counting(plan: Any, *a: Any, **k: Any) -> Any:
        planned.append(sum(len(t.jobs) for t in plan.tasks))
        return real(plan, *a, **k)

    monkeypatch.setattr(sweep, "run_sweep", counting)
    again = tuning.tune("ekf_landmarks", ["tiny_line"], 5, 1, tmp_path / "resumed")
    assert planned == [1, 1], "only the two unfinished trials run, one run each"
    assert [t.spec for t in again.trials] == [t.spec for t in straight.trials]
    assert again.best == straight.best
    # a finished study asks nothing more, and a rerun without its journal reads every trial's runs back
    planned.clear()
    assert tuning.tune("ekf_landmarks", ["tiny_line"], 5, 1, tmp_path / "resumed").trials == again.trials
    assert planned == []
    for p in (tmp_path / "resumed" / "tuning" / "studies").iterdir():
        p.unlink()
    fresh = tuning.tune("ekf_landmarks", ["tiny_line"], 5, 1, tmp_path / "resumed")
    assert fresh.reused == 5 and planned == [0] * 5


def test_cli_prints_the_best_spec_last_runnable_as_is(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    rc = main(
        ["tune", "gtsam_fls", "--dataset", "tiny_line", "--trials", "2", "--seeds", "1", "--results", str(tmp_path)]
    )
    if FILTERS.missing_dependency("gtsam_fls"):
        assert rc == 2
        return
    assert rc == 0
    lines = capsys.readouterr().out.strip().splitlines()
    assert lines[0].startswith("trial 0: ")
    last = lines[-1]
    assert resolve_filter(last).name == last and last.startswith("gtsam_fls")
    assert main(["run", "--filter", last, "--dataset", "tiny_line", "--results", str(tmp_path), "--no-progress"]) == 0


def test_cli_errors_are_one_line(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    base = ["--dataset", "tiny_line", "--trials", "2", "--seeds", "1", "--results", str(tmp_path)]
    assert main(["tune", "odometry", *base]) == 2
    assert "no tunable parameter" in capsys.readouterr().err
    room = ["--dataset", "room", *base[2:]]
    assert main(["tune", "ekf_lines", *room]) == 2  # room has no laser: a wrong command, not a bad trial
    err = capsys.readouterr().err
    assert "does not run on room" in err and len(err.strip().splitlines()) == 1
    assert main(["tune", "ekf_landmarks", "--dataset", "tiny_line", "--trials", "0", "--seeds", "1"]) == 2


def test_every_study_of_the_suite_has_the_same_budget_and_a_multivariate_sampler(tmp_path: Path) -> None:
    assert {len(s.train) * s.seeds for s in tuning.suite_studies()} == {tuning.SUITE_TRAIN_RUNS}
    studies = [tuning.SuiteStudy("ekf_landmarks", ("tiny_line",), 1, ("tiny_line",), (0,))]
    res = tuning.tune_suite(str(tmp_path), trials=2, studies=studies)
    doc = tuning.read_tuning(tmp_path)
    assert doc["budget"] == {"trials": 2, "train_runs": tuning.SUITE_TRAIN_RUNS}
    assert doc["sampler"]["multivariate"] is True and doc["sampler"]["seed"] == tuning.SUITE_SAMPLER_SEED
    assert "numpy" in doc["versions"] and "commit" in doc
    (entry,) = doc["studies"]
    assert [t["spec"] for t in entry["trials"]] == [t.spec for t in res.studies[0][1].trials]
    assert (tmp_path / entry["journal"]).is_file()


def test_the_tuned_suite_runs_only_what_was_tuned(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    studies = [tuning.SuiteStudy("ekf_landmarks", ("tiny_line",), 1, ("tiny_line",), (0,))]
    with pytest.raises(tuning.ConfigError, match=r"tuned\.json: no tuned configurations; tune first"):
        tuning.run_tuned_suite(str(tmp_path), studies=studies)
    tuning.tune_suite(str(tmp_path), trials=2, studies=studies)
    # a study declared for another split is not run with this one's configuration
    other = tuning.SuiteStudy("ekf_landmarks", ("tiny_circle",), 1, ("tiny_circle",), (0,))
    res = tuning.run_tuned_suite(str(tmp_path), studies=[*studies, other])
    assert [(s, why) for s, why in res.skipped] == [(other, "not tuned for this split (tune with 'nox -s tune')")]
    assert {str(o.filter) for o in res.outcomes} <= {tuning.read_summary(tmp_path)[0]["best_spec"], "ekf_landmarks"}
    # a summary of another format is refused, naming the file
    path = tmp_path / "tuning" / "tuned.json"
    path.write_text("[]\n", encoding="utf-8")
    with pytest.raises(tuning.ConfigError, match=r"tuned\.json: expected a tuning summary of format 2"):
        tuning.read_tuning(tmp_path)


def test_verify_re_runs_a_sampled_trial_and_catches_a_changed_journal(tmp_path: Path) -> None:
    studies = [tuning.SuiteStudy("ekf_landmarks", ("tiny_line",), 1, ("tiny_line",), (0,))]
    tuning.tune_suite(str(tmp_path), trials=3, studies=studies)
    (check,) = tuning.verify_trials(tmp_path, seed=0)
    assert check.number != 0 and check.fresh == check.stored and check.passed
    # the train runs are re-run in a store of their own, not read back from results/tuning/runs
    path = tmp_path / "tuning" / "tuned.json"
    doc = tuning.read_tuning(tmp_path)
    for t in doc["studies"][0]["trials"]:
        t["value"] *= 1.001
    path.write_text(__import__("json").dumps(doc), encoding="utf-8")
    (check,) = tuning.verify_trials(tmp_path, seed=0)
    assert not check.passed and 9e-4 < check.rel_diff < 1.1e-3


def test_cli_verify_records_the_re_run_trials(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    studies = [tuning.SuiteStudy("ekf_landmarks", ("tiny_line",), 1, ("tiny_line",), (0,))]
    tuning.tune_suite(str(tmp_path), trials=2, studies=studies)
    tuning.run_tuned_suite(str(tmp_path), studies=studies)
    assert main(["verify", "--results", str(tmp_path), "--fraction", "1"]) == 0
    assert "1 tuning trial(s) re-run on their train data" in capsys.readouterr().out
    record = __import__("json").loads((tmp_path / "verify.json").read_text(encoding="utf-8"))
    (trial,) = record["trials"]
    assert trial["filter"] == "ekf_landmarks" and trial["rel_diff"] == 0.0 and record["passed"]


def test_cli_tune_suite_arguments(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    assert main(["tune", "--suite", "ekf_landmarks", "--results", str(tmp_path)]) == 2
    assert "--suite tunes every study" in capsys.readouterr().err
    assert main(["tune", "ekf_landmarks", "--dataset", "tiny_line", "--results", str(tmp_path)]) == 2
    assert "tune needs FILTER, --dataset, --trials and --seeds" in capsys.readouterr().err


@pytest.mark.slow
def test_tuned_suite_reports_test_data_only(tmp_path: Path) -> None:
    studies = [tuning.SuiteStudy("ekf_landmarks", ("tiny_line",), 2, ("tiny_line",), (0, 1))]
    tuned = tuning.tune_suite(str(tmp_path), trials=3, studies=studies)
    assert not tuned.interrupted and tuned.studies
    best = tuned.studies[0][1].best
    assert best is not None
    res = tuning.run_tuned_suite(str(tmp_path), studies=studies)
    assert not res.interrupted and res.outcomes and not res.skipped
    from locbench.report import suite_filter, write_report
    from locbench.report.site import site_markdown

    paths = write_report(Store(tmp_path), keep=suite_filter("tuned", results=tmp_path))
    text = site_markdown(paths.markdown.parent)
    assert "Tuned against default (test data only)" in text and "3 trials x 2 train runs = 6 runs" in text
    assert "change per test unit (%)" in text and "no test possible (n = 2)" in text
    metrics = pd.read_parquet(paths.markdown.parent / "metrics.parquet")
    # the train seeds' runs are in results/tuning, never in the report
    assert not set(tuning.train_seeds(2)) & set(metrics["seed"])
    assert best.spec in set(metrics.loc[metrics["dataset"] == "tiny_line", "filter"])


@pytest.mark.slow
@pytest.mark.parametrize("ident", tuning.tuned_filters())
def test_every_tunable_filter_tunes(ident: str, tmp_path: Path) -> None:
    res = tuning.tune(ident, ["tiny_line"], 1, 1, tmp_path)
    assert len(res.trials) == 1 and res.best is not None and math.isfinite(res.best.value)
    assert resolve_filter(res.best.spec).spec.ident == ident


def test_a_study_builds_each_train_dataset_once(tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> None:
    from locbench.run import execute

    built: list[tuple[str, int]] = []
    real = execute.build_dataset

    def counting(cls: Any, params: Any, seed: int) -> Any:
        built.append((cls.__name__, seed))
        return real(cls, params, seed)

    monkeypatch.setattr(execute, "build_dataset", counting)
    res = tuning.tune("ekf_landmarks", ["tiny_line", "tiny_circle"], 3, 2, tmp_path)
    assert len(res.trials) == 3
    # 2 datasets x 2 seeds, each built once for the study's 3 trials, and none kept after it
    assert len(built) == len(set(built)) == 4
    assert not execute._REALISATION


def test_verify_re_runs_every_sampled_trial_in_one_sweep(tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> None:
    from locbench.run import sweep

    studies = [
        tuning.SuiteStudy(f, ("tiny_line",), 1, ("tiny_line",), (0,)) for f in ("ekf_landmarks", "ukf_landmarks")
    ]
    tuning.tune_suite(str(tmp_path), trials=3, studies=studies)
    sweeps: list[int] = []
    real = sweep.run_sweep
    monkeypatch.setattr(sweep, "run_sweep", lambda plan, *a, **k: sweeps.append(len(plan.tasks)) or real(plan, *a, **k))
    checks = tuning.verify_trials(tmp_path, seed=0)
    assert sorted(c.filter for c in checks) == ["ekf_landmarks", "ukf_landmarks"]
    assert all(c.passed and c.fresh == c.stored for c in checks)
    assert len(sweeps) == 1  # the workers start once for every trial


def test_run_plans_the_tuned_suite_with_the_others_in_one_sweep(
    tmp_path: Path, monkeypatch: pytest.MonkeyPatch, capsys: pytest.CaptureFixture[str]
) -> None:
    from locbench.run import execute

    studies = [tuning.SuiteStudy("ekf_landmarks", ("tiny_line",), 1, ("tiny_line",), (0,))]
    tuning.tune_suite(str(tmp_path), trials=2, studies=studies)
    # a tuned configuration other than the default, whatever two trials found
    doc = tuning.read_tuning(tmp_path)
    best = doc["studies"][0]["best_spec"] = "ekf_landmarks[motion_noise_scale=2]"
    (tmp_path / "tuning" / "tuned.json").write_text(__import__("json").dumps(doc), encoding="utf-8")
    monkeypatch.setattr(tuning, "suite_studies", lambda: studies)
    suite = tmp_path / "comparison.toml"
    suite.write_text('filters = ["odometry", "ekf_landmarks"]\ndatasets = ["tiny_line"]\nseeds = 1\n')
    sweeps: list[list[tuple[str, int, list[str]]]] = []
    real_sweep = sweep.run_sweep
    monkeypatch.setattr(
        sweep,
        "run_sweep",
        lambda plan, *a, **k: (
            sweeps.append([(t.dataset.name, t.seed, [j.filter.name for j in t.jobs]) for t in plan.tasks])
            or real_sweep(plan, *a, **k)
        ),
    )
    built: list[int] = []
    real_build = execute.build_dataset
    monkeypatch.setattr(execute, "build_dataset", lambda cls, r, seed: built.append(seed) or real_build(cls, r, seed))
    args = ["run", "--suite", str(suite), "tuned", "--results", str(tmp_path), "--no-progress"]
    assert main(args) == 0
    # one sweep, one task for the test realisation: the comparison's runs and the tuned one, built once
    assert sweeps == [[("tiny_line", 0, ["odometry", "ekf_landmarks", best])]]
    assert built == [0]
    assert Store(tmp_path).existing_meta("tiny_line", best, 0) is not None
    # nothing tuned: the other suites run alone, and the output says why
    (tmp_path / "tuning" / "tuned.json").unlink()
    assert main([*args, "--force"]) == 0
    assert "suite tuned skipped: no tuned configurations" in capsys.readouterr().out


def test_verify_counts_the_folds_of_a_study_as_one_configuration(tmp_path: Path) -> None:
    studies = [tuning.SuiteStudy("ekf_landmarks", ("tiny_line",), 1, ("tiny_line",), (0,))]
    tuning.tune_suite(str(tmp_path), trials=2, studies=studies)
    doc = tuning.read_tuning(tmp_path)
    entry = doc["studies"][0]
    bests = ["ekf_landmarks[motion_noise_scale=2]", "ekf_landmarks[motion_noise_scale=3]", "ekf_landmarks"]
    doc["studies"] = [entry | {"best_spec": "ekf_landmarks[motion_noise_scale=4]"}] + [
        entry | {"fold": f"robot {k}", "best_spec": b} for k, b in enumerate(bests)
    ]
    (tmp_path / "tuning" / "tuned.json").write_text(__import__("json").dumps(doc), encoding="utf-8")
    # the folds' tuned configurations share one group; a fold that kept the default and a study without folds
    # keep their own
    group = f"ekf_landmarks tuned on {entry['world']}, every fold"
    assert tuning.study_groups(tmp_path) == {bests[0]: group, bests[1]: group}
