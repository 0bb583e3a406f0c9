"""The report scores each configuration's lost-detection signals once per dataset, as scoring them afresh does."""

from __future__ import annotations

import numpy as np

from locbench.evaluate.lost import HealthSeries, score_signals
from locbench.filters.base import HEALTH_SIGNALS
from locbench.report.collect import Collected, frame
from locbench.report.context import Report
from locbench.report.sections.health import best_auroc, best_signal


def _series(rng: np.random.Generator, k: int = 400) -> HealthSeries:
    err = np.abs(rng.normal(size=k)) * 0.6
    names = list(HEALTH_SIGNALS)[:2]
    signals = {names[0]: err + rng.normal(scale=0.1, size=k), names[1]: rng.normal(size=k)}
    return HealthSeries(np.arange(k, dtype=float), err, signals)


def test_scores_are_computed_once_and_equal_fresh_ones() -> None:
    rng = np.random.default_rng(7)
    runs = [_series(rng) for _ in range(3)]
    rep = Report(Collected(metrics=frame([]), health={("room", "pf"): runs}))
    first = rep.signal_scores("room", "pf")
    assert rep.signal_scores("room", "pf") is first
    assert list(first) == score_signals(runs)
    best = best_signal(rep, "room", "pf")
    assert best is not None and best == first[0]
    assert best_auroc(rep, "room", "pf") == first[0].auroc[0]


def test_a_configuration_without_series_has_no_scores() -> None:
    rep = Report(Collected(metrics=frame([])))
    assert rep.signal_scores("room", "pf") == ()
    assert best_signal(rep, "room", "pf") is None
    assert np.isnan(best_auroc(rep, "room", "pf"))
