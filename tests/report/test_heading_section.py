"""The report's section "Initial heading error" on a small store of hand-made runs: one row per filter and heading
error, with the time and the number of updates to converge."""

from __future__ import annotations

import dataclasses
from pathlib import Path

import numpy as np
from test_report import _fake_run, _fake_truth

from locbench.report.collect import collect
from locbench.report.context import Report
from locbench.report.doc import Table
from locbench.report.sections.heading import heading_section
from locbench.run.store import Store

VARIANT = "room[initial_heading_error_deg=45]"


def _store(root: Path) -> Store:
    """``room`` as it is, and its 45 deg variant whose runs hold the heading 0.8 rad off until the first landmark
    update (at 5 s) brings it back."""
    st = Store(root)
    for seed in range(2):
        for name in ("room", VARIANT):
            truth = dataclasses.replace(_fake_truth(seed), dataset=name)
            st.write_truth(truth)
            run = _fake_run(truth, "ekf_landmarks", drift=0.0004, sigma=0.006)
            run.meta.update(dataset=name)
            if name == VARIANT:
                first = int(np.flatnonzero(run.kind != run.kind[1])[1])  # the first landmark update's row
                run.mean[:first, 2] += 0.8
            st.write_run(run)
        # a configuration of the main comparison, run on the plain world only: not a row of the heading table
        other = _fake_run(dataclasses.replace(_fake_truth(seed), dataset="room"), "odometry", drift=0.01, sigma=0.05)
        other.meta.update(dataset="room")
        st.write_run(other)
    return st


def test_the_section_counts_the_updates_that_the_time_hides(tmp_path: Path) -> None:
    sec = heading_section(Report(collect(_store(tmp_path / "results"))))
    (table,) = (b for b in sec.blocks if isinstance(b, Table))
    head = list(table.header)
    assert {r[0] for r in table.rows} == {"`ekf_landmarks`"}
    rows = {r[head.index("heading error (deg)")]: r for r in table.rows}
    assert set(rows) == {"0", "45"}
    conv = head.index("time to converge (s, median)")
    upd = head.index("updates to converge (median, max)")
    assert (rows["0"][conv], rows["0"][upd]) == ("0", "0 (0)")
    assert (rows["45"][conv], rows["45"][upd]) == ("5", "1 (1)")
