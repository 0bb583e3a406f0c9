"""A run's derived values, stored by the sweep's worker, are the ones the report computes from the run, bit for bit,
and are used only while their keys (estimates, truth, code) hold."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pandas as pd
import pytest

from locbench.evaluate import derived as derived_module
from locbench.report.collect import Collected, collect
from locbench.run.store import DERIVED_FILE, Store, truth_key
from locbench.run.sweep import run_many

FILTERS = ["odometry", "ekf_landmarks", "pf[particles=100]"]
DATASET = "room[kidnap_m=1]"


@pytest.fixture(scope="module")
def store(tmp_path_factory: pytest.TempPathFactory) -> Store:
    root = tmp_path_factory.mktemp("derived")
    run_many(FILTERS, [DATASET], [0, 1], str(root))
    return Store(root)


def _same(a: Collected, b: Collected) -> None:
    pd.testing.assert_frame_equal(a.metrics, b.metrics, check_exact=True)
    assert a.nees.keys() == b.nees.keys()
    for k in a.nees:
        for (ta, na), (tb, nb) in zip(a.nees[k], b.nees[k], strict=True):
            assert np.array_equal(ta, tb) and np.array_equal(na, nb, equal_nan=True)
    assert a.health.keys() == b.health.keys() and a.health
    for k in a.health:
        for ha, hb in zip(a.health[k], b.health[k], strict=True):
            assert np.array_equal(ha.t, hb.t) and np.array_equal(ha.error_m, hb.error_m)
            assert ha.signals.keys() == hb.signals.keys()
            assert all(np.array_equal(ha.signals[s], hb.signals[s], equal_nan=True) for s in ha.signals)
            assert ha.kidnap_t == hb.kidnap_t


def test_the_sweep_stores_them_for_every_ok_run_against_the_truth_read_back(store: Store) -> None:
    for f in FILTERS:
        for seed in (0, 1):
            d = store.run_dir(DATASET, f, seed)
            assert (d / DERIVED_FILE).is_file()
            stored = store.read_derived(d)
            assert stored is not None
            # computed in the worker against the truth in memory; the key of the truth as read back matches it
            assert stored[2] == truth_key(store.read_truth(DATASET, seed))


def test_stored_and_recomputed_values_are_the_same_bit_for_bit(store: Store, tmp_path: Path) -> None:
    with_stored = collect(store)
    copy = Store(tmp_path / "copy")
    import shutil

    shutil.copytree(store.root, copy.root, dirs_exist_ok=True)
    for path in copy.runs.rglob(DERIVED_FILE):
        path.unlink()
    recomputed = collect(copy)
    assert not with_stored.broken and not recomputed.broken
    _same(with_stored, recomputed)
    assert with_stored.metrics["metric"].eq("ate_m").sum() == len(FILTERS) * 2


def test_values_of_other_code_are_not_used(store: Store, monkeypatch: pytest.MonkeyPatch) -> None:
    d = store.run_dir(DATASET, "ekf_landmarks", 0)
    assert store.read_derived(d) is not None
    monkeypatch.setattr(derived_module, "code_digest", lambda: "0" * 64)
    assert store.read_derived(d) is None


def test_values_of_another_truth_are_computed_again(store: Store, tmp_path: Path) -> None:
    import shutil

    copy = Store(tmp_path / "copy")
    shutil.copytree(store.root, copy.root, dirs_exist_ok=True)
    # the derived values of seed 1 put beside the run of seed 0: keys of another run and truth, so not used
    for f in FILTERS:
        shutil.copy(copy.run_dir(DATASET, f, 1) / DERIVED_FILE, copy.run_dir(DATASET, f, 0) / DERIVED_FILE)
        assert copy.read_derived(copy.run_dir(DATASET, f, 0)) is None
    _same(collect(store), collect(copy))


def _rewrite(path: Path, **changes: np.ndarray) -> None:
    with np.load(path) as z:
        arrays = {k: z[k] for k in z.files}
    np.savez(path, **(arrays | changes))


@pytest.mark.parametrize("truth_matches", [True, False])
def test_stored_values_are_used_only_for_the_truth_they_name(store: Store, tmp_path: Path, truth_matches: bool) -> None:
    import shutil

    copy = Store(tmp_path / "copy")
    shutil.copytree(store.root, copy.root, dirs_exist_ok=True)
    path = copy.run_dir(DATASET, "ekf_landmarks", 0) / DERIVED_FILE
    with np.load(path) as z:
        doubled, key = 2 * z["metric_values"], str(z["key_truth"])
    _rewrite(path, metric_values=doubled, key_truth=np.array(key if truth_matches else "f" * 64))
    ate = collect(copy).metrics.query("filter == 'ekf_landmarks' and seed == 0 and metric == 'ate_m'")["value"]
    truth = collect(store).metrics.query("filter == 'ekf_landmarks' and seed == 0 and metric == 'ate_m'")["value"]
    # the stored values are taken as they are while the keys hold (so the doubled ones show), else computed again
    assert float(ate.iloc[0]) == pytest.approx(float(truth.iloc[0]) * (2 if truth_matches else 1), rel=1e-12)


def test_tuning_train_runs_store_none(tmp_path: Path) -> None:
    """No report reads tuning's train runs: their workers compute no derived values and their folders hold none,
    while a sweep of the same run into a results folder stores them."""
    from locbench.run import tuning

    tuning.tune("ekf_landmarks", ["tiny_line"], 2, 1, tmp_path)
    train = Store(tmp_path / tuning.TUNING_DIR)
    folders = list(train.iter_runs())
    assert folders and not any((d / DERIVED_FILE).exists() for d in folders)
    run_many(["ekf_landmarks"], ["tiny_line"], [0], str(tmp_path / "sweep"))
    assert (Store(tmp_path / "sweep").run_dir("tiny_line", "ekf_landmarks", 0) / DERIVED_FILE).is_file()
