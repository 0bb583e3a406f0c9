"""The plan of a sweep: each spec parsed once into the value every later stage passes on, run keys, cached runs,
the traits each run records, and the declared costs that order the tasks."""

from __future__ import annotations

from pathlib import Path

import pytest

from locbench.core.errors import ConfigError
from locbench.filters.base import MAX_SCORE_SAMPLE, SCORE_SAMPLE_SIZE
from locbench.registry import DATASETS, FILTERS, resolve_filter
from locbench.run import plan as plan_mod
from locbench.run.plan import _BOUND_COST_S, FilterTraits, parse_filter, plan_sweep
from locbench.run.store import Store
from locbench.run.sweep import run_many


def test_a_spec_is_parsed_once_and_passed_down_as_one_value(tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> None:
    seen: list[str] = []
    real = plan_mod.parse_filter
    monkeypatch.setattr(plan_mod, "parse_filter", lambda s: seen.append(s) or real(s))
    blocks = [(["odometry", "ekf_landmarks"], ["room", "room[kidnap_m=1]"], [0, 1]), (["odometry"], ["office"], [0])]
    plan = plan_sweep(blocks, Store(tmp_path))
    assert sorted(seen) == ["ekf_landmarks", "odometry"]
    values = {id(j.filter) for t in plan.tasks for j in t.jobs if j.filter.name == "odometry"}
    assert len(values) == 1 and plan.total == 9
    # a parsed value is taken as it is, and a text naming the same configuration plans the same run once
    again = plan_sweep([([parse_filter("odometry"), "odometry"], ["room"], [0])], tmp_path)
    assert [j.filter.name for t in again.tasks for j in t.jobs] == ["odometry"]


def test_a_plan_keeps_the_store_it_was_given(tmp_path: Path) -> None:
    store = Store(tmp_path)
    assert plan_sweep([(["odometry"], ["room"], [0])], store).store is store
    assert plan_sweep([(["odometry"], ["room"], [0])], str(tmp_path)).store.root == tmp_path


def test_traits_are_the_classes_answers() -> None:
    assert parse_filter("odometry").traits == FilterTraits(True, False, None, ("Odometry",), ())
    pf = parse_filter("pf[adaptive=kld]").traits
    assert pf is not None and not pf.baseline and not pf.global_start
    assert pf.kidnap_name == resolve_filter("pf[adaptive=kld,augmented=true,inject=sensor,inject_pairs=true]").name
    assert parse_filter("pf[init=uniform]").traits.global_start  # type: ignore[union-attr]
    assert parse_filter("ekf_icp").traits.maps == ("occupancy",)  # type: ignore[union-attr]


def test_traits_read_back_from_a_record_and_a_malformed_record_is_none() -> None:
    traits = parse_filter("pf").traits
    assert traits is not None and FilterTraits.from_record(traits.record()) == traits
    good = traits.record()
    for bad in (None, "pf", [], good | {"baseline": "no"}, good | {"sensors": "Odometry"}, good | {"maps": [1]}):
        assert FilterTraits.from_record(bad) is None


@pytest.mark.usefixtures("harness_registry")
def test_every_run_records_its_filter_traits_failed_ones_too(tmp_path: Path) -> None:
    run_many(["odometry", "bad[fail_at_s=100]"], ["line", "line[steps=0]"], [0], str(tmp_path))
    store = Store(tmp_path)
    for dataset, status in (("line", "ok"), ("line[steps=0]", "error")):  # the second does not build
        for name in ("odometry", "bad[fail_at_s=100]"):
            meta = store.existing_meta(dataset, name, 0)
            assert meta is not None and meta["status"] == status
            assert FilterTraits.from_record(meta["filter_traits"]) == parse_filter(name).traits


@pytest.mark.usefixtures("harness_registry")
def test_finished_runs_are_not_rerun_unless_forced(tmp_path: Path) -> None:
    run_many(["bad[fail_at_s=100]"], ["line"], [0], str(tmp_path))
    assert [o.status for o in run_many(["bad[fail_at_s=100]"], ["line"], [0], str(tmp_path))] == ["cached"]
    assert [o.status for o in run_many(["bad[fail_at_s=100]"], ["line"], [0], str(tmp_path), force=True)] == ["ok"]
    # a changed config is a different run key: it runs again
    assert [o.status for o in run_many(["bad[fail_at_s=99]"], ["line"], [0], str(tmp_path))] == ["ok"]


# --- declared costs --------------------------------------------------------------------------------------


@pytest.mark.parametrize("fid", FILTERS.ids())
def test_every_filter_declares_its_cost(fid: str) -> None:
    if FILTERS.missing_dependency(fid):
        pytest.skip(FILTERS.missing_dependency(fid))
    cls = FILTERS.load(fid)
    assert cls.cost_per_data_s > 0 and cls.cost_scale(resolve_filter(fid).params) == 1.0


@pytest.mark.parametrize("did", DATASETS.ids())
def test_every_dataset_declares_its_duration(did: str) -> None:
    assert DATASETS.load(did).nominal_duration_s > 0


def test_the_cost_estimate_reads_the_declared_attributes(tmp_path: Path) -> None:
    # the two the former id table missed: ukf_landmarks (its own cost) and Lost in the Woods (recorded: long)
    assert FILTERS.load("ukf_landmarks").cost_per_data_s != FILTERS.load("ekf_landmarks").cost_per_data_s
    assert DATASETS.load("lost_in_the_woods").nominal_duration_s == DATASETS.load("mrclam").nominal_duration_s
    pf = FILTERS.load("pf")
    assert pf.cost_scale(resolve_filter("pf[particles=300]").params) == pytest.approx(0.3)
    plan = plan_sweep([(["odometry", "pf[particles=300]"], ["room"], [0])], str(tmp_path))
    (task,) = plan.tasks
    expected = 60.0 * (0.002 + 0.1 * 0.3) + _BOUND_COST_S
    assert task.cost_s == pytest.approx(expected)


def test_the_score_sample_size_is_in_the_run_key_of_a_sampling_filter_only(tmp_path: Path) -> None:
    pf, ekf = parse_filter("pf[particles=300]"), parse_filter("ekf_landmarks")
    room = plan_mod.parse_dataset("room")
    assert plan_mod.run_key(pf, room, 0, 32) != plan_mod.run_key(pf, room, 0, SCORE_SAMPLE_SIZE)
    assert plan_mod.run_key(pf, room, 0) == plan_mod.run_key(pf, room, 0, SCORE_SAMPLE_SIZE)
    assert plan_mod.run_key(ekf, room, 0, 32) == plan_mod.run_key(ekf, room, 0, SCORE_SAMPLE_SIZE)
    plan = plan_sweep([([pf, ekf], [room], [0])], tmp_path, score_sample=32)
    assert [t.score_sample for t in plan.tasks] == [32]
    assert {j.key for j in plan.tasks[0].jobs} == {plan_mod.run_key(pf, room, 0, 32), plan_mod.run_key(ekf, room, 0)}
    for bad in (1, MAX_SCORE_SAMPLE + 1):
        with pytest.raises(ConfigError, match="score sample"):
            plan_sweep([([pf], [room], [0])], tmp_path, score_sample=bad)
