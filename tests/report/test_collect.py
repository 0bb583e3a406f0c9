"""Collecting stored runs: a filter configuration is labelled by the traits its runs recorded."""

from __future__ import annotations

import importlib
from pathlib import Path

import pytest

from locbench.report.collect import collect, realisation_groups
from locbench.run.plan import parse_filter
from locbench.run.store import Store
from locbench.run.sweep import run_many

NAMES = ("odometry", "bad[fail_at_s=100]")
#: The module (the package's ``collect`` is its function of that name).
collect_mod = importlib.import_module("locbench.report.collect")


@pytest.mark.usefixtures("harness_registry")
def test_runs_are_labelled_by_their_recorded_traits_and_older_ones_as_before(
    tmp_path: Path, monkeypatch: pytest.MonkeyPatch
) -> None:
    run_many(list(NAMES), ["line"], [0], str(tmp_path))
    store = Store(tmp_path)
    derived = {n: collect_mod.describe_filter(n, parse_filter(n).traits) for n in NAMES}
    assert derived["odometry"].baseline and derived["odometry"].sensors == ("Odometry",)
    assert not derived["bad[fail_at_s=100]"].baseline

    def refuse(name: str) -> None:
        raise AssertionError(f"the report re-derived what {name} was from its name")

    with monkeypatch.context() as m:
        m.setattr(collect_mod, "parse_filter", refuse)
        col = collect(store)
    assert {n: col.filters[n] for n in NAMES} == derived

    # a run stored before runs recorded their traits: derived from the registry, the same labels
    for run_dir in store.iter_runs():
        rec = store.read_run(run_dir)
        del rec.meta["filter_traits"]
        store.write_run(rec)
    assert all("filter_traits" not in store.read_run(d).meta for d in store.iter_runs())
    assert {n: collect(store).filters[n] for n in NAMES} == derived


def test_runs_are_grouped_by_the_realisation_their_folders_name() -> None:
    """One task per truth: every run of a dataset and seed in one group, whatever its filter, in the list's order."""
    runs = Path("runs")
    dirs = [
        runs / "room" / "ekf" / "seed-0000",
        runs / "room" / "pf" / "seed-0001",
        runs / "office" / "ekf" / "seed-0000",
        runs / "room" / "pf" / "seed-0000",
        runs / "room" / "ekf" / "seed-0001",
    ]
    assert realisation_groups(dirs) == [[0, 3], [1, 4], [2]]
    assert realisation_groups([]) == []
