"""Calls run in forked worker processes: the report's closures (section builders, draw functions) do not pickle, so
the workers inherit them by forking, and only the results come back."""

from __future__ import annotations

import gc
from collections.abc import Callable, Sequence
from typing import Any, TypeVar

T = TypeVar("T")

#: The calls a forked worker of :func:`forked_map` makes (set before the pool forks).
_CALLS: list[Callable[[], Any]] = []


def _call(i: int) -> Any:
    return _CALLS[i]()


def forked_map(calls: Sequence[Callable[[], T]], jobs: int, order: Sequence[int] | None = None) -> list[T]:
    """Each of ``calls`` made in one of ``jobs`` forked processes (in this one for ``jobs`` <= 1 or a single call),
    started in ``order`` (indices; default as given: the largest first keeps a worker from being left with it at the
    end); the results in the order of ``calls``. Each result must pickle."""
    if jobs <= 1 or len(calls) < 2:
        return [c() for c in calls]
    import multiprocessing
    from concurrent.futures import ProcessPoolExecutor

    idx = list(order) if order is not None else list(range(len(calls)))
    if sorted(idx) != list(range(len(calls))):
        raise ValueError("order must name every call once")
    _CALLS[:] = calls
    out: list[Any] = [None] * len(calls)
    # the workers' collections then leave the inherited objects alone: a collection that walked them would
    # write to each one's page and make the worker copy the whole report's memory
    gc.freeze()
    try:
        with ProcessPoolExecutor(jobs, mp_context=multiprocessing.get_context("fork")) as pool:
            for i, value in zip(idx, pool.map(_call, idx), strict=True):
                out[i] = value
    finally:
        gc.unfreeze()
        _CALLS.clear()
    return out
