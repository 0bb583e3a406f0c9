"""Conformance checks parametrised over every registered filter and dataset.

A filter or dataset is tested the moment it is registered; one whose optional dependency is missing
is skipped with the install hint; a check that does not apply to a filter's declared capabilities is skipped
with the reason; a check a filter declares it fails runs as strict xfail.
"""

from __future__ import annotations

import pytest

from locbench.checks import DATASET_CHECKS, FILTER_CHECKS, check_specs, marking
from locbench.core.spec import Spec
from locbench.registry import DATASETS, FILTERS, make_filter


def _filter_cases() -> list[object]:
    # every configuration a filter declares for the checks (check_specs), each filter once even when its
    # optional dependency is missing (the test then skips with the install hint)
    cases = []
    for fid in FILTERS.ids():
        specs = [fid] if FILTERS.unavailable_reason(fid) is not None else check_specs(fid)
        cases += [pytest.param(spec, name, id=f"{spec}-{name}") for spec in specs for name in FILTER_CHECKS]
    return cases


def _dataset_cases() -> list[object]:
    return [pytest.param(did, name, id=f"{did}-{name}") for did in DATASETS.ids() for name in DATASET_CHECKS]


@pytest.mark.parametrize(("spec", "check"), _filter_cases())
def test_filter_conformance(spec: str, check: str, request: pytest.FixtureRequest) -> None:
    reason = FILTERS.unavailable_reason(Spec.parse(spec).ident)
    if reason is not None:
        pytest.skip(f"{spec} {reason}")
    flt = make_filter(spec)
    mark = marking(flt, FILTER_CHECKS[check])  # the policy `locbench check` applies too
    if mark is not None and mark[0] == "skip":
        pytest.skip(mark[1])
    if mark is not None:
        # declared failure: the check still runs, and passing it anyway fails the test (strict)
        request.applymarker(pytest.mark.xfail(reason=mark[1], strict=True))
    FILTER_CHECKS[check](flt)


def test_declared_check_configurations() -> None:
    assert check_specs("pf") == [
        "pf",
        "pf[adaptive=kld]",
        "pf[init=uniform]",
        "pf[augmented=true,inject=sensor,inject_pairs=true]",
    ]
    assert check_specs("ekf_landmarks") == ["ekf_landmarks", "ekf_landmarks[association=nearest]"]


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
