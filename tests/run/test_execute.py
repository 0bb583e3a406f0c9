"""Executing a task: its runs stored with their provenance, the same on every worker, failures recorded as results."""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import pytest

from locbench.run.store import Store
from locbench.run.sweep import run_many


@pytest.mark.usefixtures("harness_registry")
def test_runs_are_stored_with_provenance(tmp_path: Path) -> None:
    out = run_many(["bad[fail_at_s=100]"], ["line"], [0, 1], str(tmp_path))
    assert [o.status for o in out] == ["ok", "ok"]
    store = Store(tmp_path)
    runs = list(store.iter_runs())
    assert len(runs) == 2
    rec = store.read_run(runs[0])
    for key in ("run_key", "seed", "versions", "git_commit", "filter_config", "dataset_params", "status"):
        assert key in rec.meta
    assert rec.meta["versions"]["numpy"] == np.__version__
    assert rec.t.shape[0] == rec.mean.shape[0] == rec.cov.shape[0] == 51  # reset row + 50 odometry
    assert np.allclose(rec.mean[-1], [5.0, 0.0, 0.0])
    truth = store.read_truth(rec.meta["dataset"], rec.meta["seed"])
    assert len(truth.waypoints) == 2  # type: ignore[arg-type]
    assert np.array_equal(truth.map_landmarks, [[10.0, 2.0]])  # the map travels with the truth, for figures


@pytest.mark.usefixtures("harness_registry")
@pytest.mark.parametrize(
    ("mode", "status", "text"),
    [("raise", "error", "RuntimeError: boom"), ("nan", "diverged", "non-finite"), ("diverge", "diverged", "exploded")],
)
def test_failures_are_results_and_the_sweep_goes_on(tmp_path: Path, mode: str, status: str, text: str) -> None:
    out = run_many([f"bad[mode={mode}]", "bad[fail_at_s=100]"], ["line"], [0], str(tmp_path))
    assert [o.status for o in out] == [status, "ok"]
    meta = json.loads((Store(tmp_path).run_dir("line", out[0].filter, 0) / "meta.json").read_text())
    assert meta["status"] == status and text in meta["message"]


@pytest.mark.usefixtures("harness_registry")
def test_incompatible_filter_is_a_recorded_skip(tmp_path: Path) -> None:
    out = run_many(["ekf_landmarks"], ["line"], [0], str(tmp_path))
    assert out[0].status in ("ok", "skipped")  # line has landmarks, so ekf_landmarks runs


@pytest.mark.usefixtures("harness_registry")
def test_parallel_jobs_give_the_same_results(tmp_path: Path) -> None:
    run_many(["bad[fail_at_s=100]"], ["line[noise_m=0.01]"], [0, 1, 2], str(tmp_path / "a"), jobs=1)
    run_many(["bad[fail_at_s=100]"], ["line[noise_m=0.01]"], [0, 1, 2], str(tmp_path / "b"), jobs=2)
    for seed in (0, 1, 2):
        a = Store(tmp_path / "a").read_run(
            Store(tmp_path / "a").run_dir("line[noise_m=0.01]", "bad[fail_at_s=100]", seed)
        )
        b = Store(tmp_path / "b").read_run(
            Store(tmp_path / "b").run_dir("line[noise_m=0.01]", "bad[fail_at_s=100]", seed)
        )
        assert np.array_equal(a.mean, b.mean)
    seeds_differ = Store(tmp_path / "a").read_run(
        Store(tmp_path / "a").run_dir("line[noise_m=0.01]", "bad[fail_at_s=100]", 1)
    )
    assert not np.array_equal(a.mean, seeds_differ.mean)


@pytest.mark.usefixtures("harness_registry")
def test_no_half_written_runs(tmp_path: Path) -> None:
    run_many(["bad[fail_at_s=100]"], ["line"], [0], str(tmp_path))
    leftovers = [p for p in tmp_path.rglob(".tmp-*")]
    assert leftovers == []


def test_missing_recorded_data_is_a_recorded_skip(tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> None:
    monkeypatch.setenv("LOCBENCH_DATA", str(tmp_path / "nodata"))
    monkeypatch.setenv("LOCBENCH_CACHE", str(tmp_path / "cache"))
    out = run_many(["odometry", "ekf_landmarks"], ["lost_in_the_woods"], [0], str(tmp_path / "res"))
    assert [o.status for o in out] == ["skipped", "skipped"]
    assert all("data not found" in o.message and "dataset2.mat" in o.message for o in out)
    store = Store(tmp_path / "res")
    assert not store.has_truth("lost_in_the_woods", 0)  # nothing half-made: no truth without data


def test_filter_that_sees_no_observation_is_a_recorded_skip(tmp_path: Path) -> None:
    # pf with its laser model off consumes landmarks only; a laser-only world gives it nothing to fuse
    out = run_many(["pf", "pf[use_laser=true]"], ["lap[people=0]"], [0], str(tmp_path))
    assert out[0].status == "skipped" and "none of which" in out[0].message
    assert out[1].status == "ok"


def test_a_tasks_provenance_is_computed_before_its_child_is_forked(tmp_path: Path) -> None:
    # a forked child's caches die with it: what every record of the task takes is computed in the worker, once
    from locbench.run import provenance
    from locbench.run.execute import execute_contained
    from locbench.run.plan import plan_sweep

    plan = plan_sweep([(["odometry", "ekf_landmarks"], ("tiny_line",), [0])], Store(tmp_path))
    provenance.distribution.cache_clear()
    out = execute_contained(plan.tasks[0])
    assert [r.meta["status"] for r in out.runs] == ["ok", "ok"]
    assert provenance.distribution.cache_info().currsize == 3  # the dataset's class and the two filters'
    assert out.runs[0].meta["filter_distribution"] == provenance.distribution(plan.tasks[0].jobs[0].filter.cls)


def _parent_warm_ups(monkeypatch: pytest.MonkeyPatch) -> list[str]:
    """The filters the worker itself warms up before forking (a child's own warm-ups are not counted)."""
    from locbench.run import execute

    calls: list[str] = []
    real = execute.warm_up
    monkeypatch.setattr(execute, "_RAN_OK", set())
    monkeypatch.setattr(execute, "warm_up", lambda flt, ds: calls.append(type(flt).__name__) or real(flt, ds))
    return calls


def test_a_filter_a_child_ran_ok_is_warmed_in_the_worker_and_keeps_its_estimates(
    tmp_path: Path, monkeypatch: pytest.MonkeyPatch
) -> None:
    # the children inherit its loaded kernels instead of loading them again, each one
    from locbench.run.execute import execute_contained, execute_task
    from locbench.run.plan import plan_sweep

    calls = _parent_warm_ups(monkeypatch)
    plan = plan_sweep([(["ekf_landmarks", "pf[particles=50]"], ("tiny_line",), [0, 1])], Store(tmp_path))
    first = execute_contained(plan.tasks[0])
    assert [r.meta["status"] for r in first.runs] == ["ok", "ok"]
    assert calls == []  # not yet proven in this process: its warm-up ran in the child
    second = execute_contained(plan.tasks[1])
    assert sorted(calls) == ["LandmarkEKF", "ParticleFilter"]
    direct = execute_task(plan.tasks[1])
    for a, b in zip(second.runs, direct.runs, strict=True):
        np.testing.assert_array_equal(a.mean, b.mean)  # our code against itself on one machine
        np.testing.assert_array_equal(a.cov, b.cov)


@pytest.mark.usefixtures("harness_registry")
@pytest.mark.parametrize("mode", ["exit", "raise"])
def test_a_filter_whose_child_did_not_end_ok_is_never_warmed_in_the_worker(
    mode: str, tmp_path: Path, monkeypatch: pytest.MonkeyPatch
) -> None:
    # its first events could crash or hang this process, outside the child's containment
    from locbench.run.execute import execute_contained
    from locbench.run.plan import plan_sweep

    calls = _parent_warm_ups(monkeypatch)
    plan = plan_sweep([([f"bad[mode={mode}]", "odometry"], ("line",), [0, 1])], Store(tmp_path))
    for task in plan.tasks:
        out = execute_contained(task)
        assert out.runs[0].meta["status"] == "error"
    assert "BadFilter" not in calls
    if mode == "raise":  # the child returned: its dead-reckoning run proved odometry
        assert calls == ["OdometryFilter"]
