"""``locbench verify``: a fresh store passes, one altered array fails, and the sample is drawn as documented."""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import pytest

from locbench.cli import main
from locbench.run.store import Store, _sealed, npz_digest
from locbench.run.sweep import run_many
from locbench.run.verify import RunId, compare, read_record, record_text, sample, verify

FILTERS = ["bad[fail_at_s=100]", "odometry"]
DATASET = "line[noise_m=0.01]"


def _store(tmp_path: Path) -> Store:
    run_many(FILTERS, [DATASET], [0, 1, 2], str(tmp_path))
    return Store(tmp_path)


def _alter(store: Store, dataset: str, filt: str, seed: int, array: str, reseal: bool = True) -> None:
    """Change one value of one stored array by the smallest step (as a corrupted or non-deterministic run would)."""
    path = store.run_dir(dataset, filt, seed) / "estimates.npz"
    with np.load(path) as z:
        arrays = {k: z[k] for k in z.files}
    a = arrays[array].copy()
    a.flat[a.size // 2] = np.nextafter(a.flat[a.size // 2], np.inf)
    arrays[array] = a
    np.savez_compressed(path, **arrays)
    if reseal:  # a consistent record of other numbers (a non-deterministic run), not a corrupted file
        meta_path = path.parent / "meta.json"
        meta = json.loads(meta_path.read_text())
        meta["files"] = {path.name: npz_digest(path)}
        meta_path.write_text(json.dumps(_sealed(meta)))


@pytest.mark.usefixtures("harness_registry")
def test_a_run_altered_behind_its_checksum_is_stale(tmp_path: Path) -> None:
    store = _store(tmp_path)
    _alter(store, DATASET, "odometry", 1, "mean", reseal=False)
    res = verify(store, fraction=1.0, seed=0)
    assert [(r.filter, r.seed) for r, _ in res.differ] == [("odometry", 1)]
    assert res.differ[0][1].startswith("stale: ") and "sha256" in res.differ[0][1]


@pytest.mark.usefixtures("harness_registry")
def test_a_fresh_store_passes_and_the_record_says_so(tmp_path: Path) -> None:
    store = _store(tmp_path)
    res = verify(store, fraction=1.0, seed=0)
    assert res.passed and len(res.checked) == 6 and not res.differ
    assert main(["verify", "--results", str(tmp_path), "--fraction", "1"]) == 0
    record = read_record(tmp_path)
    assert record is not None and record["passed"] and record["checked"] == 6
    assert record_text(record, record["store_digest"]).startswith("verify: passed")
    assert "changed since" in record_text(record, "another digest")


@pytest.mark.usefixtures("harness_registry")
def test_one_altered_array_fails_and_is_named(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    store = _store(tmp_path)
    _alter(store, DATASET, "odometry", 1, "mean")
    res = verify(store, fraction=1.0, seed=0)
    assert not res.passed
    assert [(r.filter, r.seed, why) for r, why in res.differ] == [("odometry", 1, "mean")]
    assert main(["verify", "--results", str(tmp_path), "--fraction", "1"]) == 1
    out = capsys.readouterr().out
    assert "differs: odometry on line[noise_m=0.01] seed 1: mean" in out
    assert json.loads((tmp_path / "verify.json").read_text())["passed"] is False


@pytest.mark.usefixtures("harness_registry")
def test_call_times_may_differ_but_nothing_else(tmp_path: Path) -> None:
    store = _store(tmp_path)
    rec = store.read_run(store.run_dir(DATASET, "odometry", 0))
    other = store.read_run(store.run_dir(DATASET, "odometry", 0))
    other.step_ns = other.step_ns + 1
    assert compare(rec, other) == []
    other.cov = other.cov.copy()
    other.cov[-1, 0, 0] = -0.0 if other.cov[-1, 0, 0] == 0.0 else other.cov[-1, 0, 0] * (1 + 1e-15)
    assert compare(rec, other) == ["cov"]


def test_the_sample_takes_the_fraction_and_one_run_of_every_filter() -> None:
    runs = [RunId("d", "a", s, f"a{s}") for s in range(200)] + [RunId("d", "b", 0, "b0")]
    picked = sample(runs, 0.02, seed=3)
    assert len(picked) in (5, 6)  # ceil(0.02 x 201) = 5, plus b's run when the draw missed it
    assert {r.filter for r in picked} == {"a", "b"}
    assert picked == sample(runs, 0.02, seed=3)
    with pytest.raises(ValueError, match="fraction"):
        sample(runs, 0.0, seed=0)


def test_the_folds_of_a_study_count_as_one_configuration_for_the_minimum() -> None:
    # five folds' tuned configurations, each run once on its own test robot, beside a large suite
    folds = [RunId(f"robot{k}", f"a[x={k}]", 0, f"f{k}") for k in range(5)]
    runs = [RunId("d", "a", s, f"a{s}") for s in range(400)] + folds
    groups = {r.filter: "a tuned, every fold" for r in folds}
    alone = sample(runs, 0.01, seed=1)
    assert set(folds) <= set(alone)  # each fold its own configuration: every fold's run is re-run
    grouped = sample(runs, 0.01, seed=1, groups=groups)
    # ceil(0.01 x 405) = 5 drawn, plus one fold run when the draw took none
    assert 0 < len(set(folds) & set(grouped)) < len(folds) and len(grouped) <= 6
    assert grouped == sample(runs, 0.01, seed=1, groups=groups)


@pytest.mark.usefixtures("harness_registry")
def test_worker_processes_re_run_the_sample_as_this_process_does(
    tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    store = _store(tmp_path)
    _alter(store, DATASET, "odometry", 1, "mean")
    assert main(["verify", "--results", str(tmp_path), "--fraction", "1", "--jobs", "2"]) == 1
    out = capsys.readouterr().out
    assert "differs: odometry on line[noise_m=0.01] seed 1: mean" in out
    record = json.loads((tmp_path / "verify.json").read_text())
    assert record["checked"] == 6 and len(record["differ"]) == 1


@pytest.mark.usefixtures("harness_registry")
def test_a_stored_derived_value_the_re_run_does_not_give_fails_and_is_named(tmp_path: Path) -> None:
    from locbench.run.store import DERIVED_FILE

    store = _store(tmp_path)
    path = store.run_dir(DATASET, "odometry", 2) / DERIVED_FILE
    with np.load(path) as z:
        arrays = {k: z[k] for k in z.files}
    ids = arrays["metric_ids"].tolist()
    values = arrays["metric_values"].copy()
    values[ids.index("ate_m")] = np.nextafter(values[ids.index("ate_m")], np.inf)
    np.savez(path, **(arrays | {"metric_values": values}))
    assert store.read_derived(path.parent) is not None  # its keys still hold: the report would take it
    res = verify(store, fraction=1.0, seed=0)
    assert [(r.filter, r.seed, why) for r, why in res.differ] == [("odometry", 2, "derived ate_m")]
