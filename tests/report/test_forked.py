"""Calls made in forked workers come back in the order of the calls, whatever order they were started in."""

from __future__ import annotations

import os
from functools import partial

import pytest

from locbench.report.forked import forked_map


def _square_and_pid(x: int) -> tuple[int, int]:
    return x * x, os.getpid()


def test_results_come_back_in_the_calls_order_from_other_processes() -> None:
    calls = [partial(_square_and_pid, i) for i in range(6)]
    out = forked_map(calls, 2, order=[5, 3, 1, 0, 2, 4])
    assert [v for v, _ in out] == [i * i for i in range(6)]
    assert os.getpid() not in {pid for _, pid in out}


def test_one_job_calls_here_and_an_order_must_name_every_call_once() -> None:
    calls = [partial(_square_and_pid, i) for i in range(3)]
    assert {pid for _, pid in forked_map(calls, 1)} == {os.getpid()}
    with pytest.raises(ValueError, match="every call once"):
        forked_map(calls, 2, order=[0, 0, 1])
