"""Proper scores and health signals on recorded data: finite rows for every filter that runs there.

MRCLAM robot 4 is a recording no other test runs a filter on; Lost in the Woods is the other landmark
recording with ground truth. Slow (whole recordings), and skipped with the reason when $LOCBENCH_DATA lacks them.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

from locbench.evaluate.scores import SCORE_IDS, ci_ids
from locbench.registry import DATASETS, resolve_dataset
from locbench.report import collect_metrics
from locbench.run.store import Store
from locbench.run.sweep import run_many

# every filter that runs on landmark recordings; the particle filter with fewer particles to keep the test short
FILTERS = ("odometry", "ekf_landmarks", "ukf_landmarks", "gtsam_fls", "pf[particles=300]")


@pytest.mark.recorded
@pytest.mark.slow
@pytest.mark.parametrize("dataset", ["mrclam[robot=4]", "lost_in_the_woods"])
def test_scores_are_finite_and_health_is_stored_on_recorded_data(dataset: str, tmp_path: Path) -> None:
    reason = DATASETS.load(resolve_dataset(dataset).id).data_unavailable()
    if reason is not None:
        pytest.skip(str(reason))
    results = tmp_path / "results"
    outcomes = run_many(FILTERS, [dataset], [0], str(results))
    ran = {str(o.filter) for o in outcomes if o.status == "ok"}
    assert ran, [(str(o.filter), o.status, o.message) for o in outcomes]
    df = collect_metrics(Store(results))
    for f in ran:
        sub = df[df["filter"] == f].set_index("metric")["value"]
        for sid in SCORE_IDS:
            lo_id, hi_id = ci_ids(sid)
            assert np.isfinite(sub[sid]) and sub[sid] > 0, (f, sid)
            assert sub[lo_id] <= sub[sid] <= sub[hi_id], (f, sid)
    store = Store(results)
    for run_dir in store.iter_runs():
        run = store.read_run(run_dir)
        if run.status == "ok":
            assert run.health and all(v.shape == run.t.shape for v in run.health.values()), run_dir
