"""Conformance checks parametrised over every registered filter and dataset.

A filter or dataset is tested the moment it is registered; one whose optional dependency is missing
is skipped with the install hint; a check that does not apply to a filter's declared capabilities is skipped
with the reason; a check a filter declares it fails runs as strict xfail.
"""

from __future__ import annotations

import pytest

from locbench.checks import DATASET_CHECKS, FILTER_CHECKS, expected_failures
from locbench.registry import DATASETS, FILTERS, make_filter


def _filter_cases() -> list[object]:
    return [pytest.param(fid, name, id=f"{fid}-{name}") for fid in FILTERS.ids() for name in FILTER_CHECKS]


def _dataset_cases() -> list[object]:
    return [pytest.param(did, name, id=f"{did}-{name}") for did in DATASETS.ids() for name in DATASET_CHECKS]


@pytest.mark.parametrize(("filter_id", "check"), _filter_cases())
def test_filter_conformance(filter_id: str, check: str, request: pytest.FixtureRequest) -> None:
    reason = FILTERS.unavailable_reason(filter_id)
    if reason is not None:
        pytest.skip(f"{filter_id} {reason}")
    flt = make_filter(filter_id)
    not_applicable = FILTER_CHECKS[check].applies(flt)
    if not_applicable is not None:
        pytest.skip(not_applicable)
    xfail = expected_failures(filter_id)
    if check in xfail:
        # declared failure: the check still runs, and passing it anyway fails the test (strict)
        request.applymarker(pytest.mark.xfail(reason=xfail[check], strict=True))
    FILTER_CHECKS[check](flt)


@pytest.mark.parametrize(("dataset_id", "check"), _dataset_cases())
def test_dataset_conformance(dataset_id: str, check: str) -> None:
    reason = DATASETS.unavailable_reason(dataset_id)
    if reason is not None:
        pytest.skip(f"{dataset_id} {reason}")
    DATASET_CHECKS[check](dataset_id)


def test_check_cli_reports_every_registered_target(capsys: pytest.CaptureFixture[str]) -> None:
    from locbench.cli import main

    code = main(["check", "odometry"])
    out = capsys.readouterr().out
    assert code == 0, out
    assert all(name in out for name in FILTER_CHECKS)
