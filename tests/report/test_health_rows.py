"""The runner's Gaussian health after the run equals the per-event :meth:`Filter.health` bit for bit."""

from __future__ import annotations

import numpy as np
import pytest

from locbench.filters.base import Estimate, gaussian_health, gaussian_health_rows
from locbench.registry import FILTERS, make_dataset, resolve_filter
from locbench.run.filter_pass import run_filter


def _rows(rng: np.random.Generator, n: int) -> tuple[np.ndarray, dict[str, np.ndarray]]:
    """Random covariances and diagnostics with NaN (absent), inf, zero counts and a missing count."""
    a = rng.normal(size=(n, 3, 3))
    cov = a @ a.transpose(0, 2, 1) * rng.uniform(1e-6, 1e3, size=(n, 1, 1))
    nis = rng.chisquare(3, size=n)
    nis[::7] = np.nan
    nis[3::11] = np.inf
    dof = rng.integers(0, 5, size=n).astype(float)
    dof[::5] = np.nan
    acc = rng.integers(0, 4, size=n).astype(float)
    rej = rng.integers(0, 3, size=n).astype(float)
    acc[::9] = np.nan
    return cov, {"nis": nis, "nis_dof": dof, "accepted": acc, "rejected": rej}


@pytest.mark.parametrize("nis_dof", [None, 3])
def test_rows_equal_per_row_calls(nis_dof: float | None) -> None:
    cov, diags = _rows(np.random.default_rng(4), 300)
    got = gaussian_health_rows(cov, diags, nis_dof)
    for i in range(cov.shape[0]):
        d = {k: float(v[i]) for k, v in diags.items() if not np.isnan(v[i]) or k == "nis"}
        want = gaussian_health(Estimate(t=0.0, mean=np.zeros(3), cov=cov[i], diagnostics=d), nis_dof)
        for name in got:
            value = want.get(name, np.nan)
            assert np.array_equal(got[name][i], value, equal_nan=True), (name, i, got[name][i], value)


@pytest.mark.parametrize("spec", ["ekf_landmarks", "ekf_landmarks[association=nearest]", "odometry", "pf"])
def test_run_filter_deferred_health_equals_per_event(spec: str) -> None:
    """A subclass overriding ``health`` (with the same method) is called per event; the default is deferred."""
    ds = make_dataset("tiny_line", 0)
    r = resolve_filter(spec)
    cls = FILTERS.load(r.id)
    flt, other = cls(r.params), type("PerEvent", (cls,), {"health": lambda self: cls.health(self)})(r.params)
    a = run_filter(flt, ds, np.random.default_rng(1))
    b = run_filter(other, ds, np.random.default_rng(1))
    assert a.status == b.status == "ok"
    assert list(a.health) == list(b.health)
    for name in a.health:
        assert np.array_equal(a.health[name], b.health[name], equal_nan=True), name
