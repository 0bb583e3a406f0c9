"""Shared fixtures: registry isolation and the test-only entries of ``harness_support``."""

from __future__ import annotations

from collections.abc import Iterator

import pytest

from locbench.registry import DATASETS, FILTERS


@pytest.fixture
def isolated_registries() -> Iterator[None]:
    """Register test-only entries inside a test without leaking them into others."""
    f, d = FILTERS.snapshot(), DATASETS.snapshot()
    try:
        yield
    finally:
        FILTERS.restore(f)
        DATASETS.restore(d)


@pytest.fixture
def harness_registry(isolated_registries: None) -> None:
    """Registers the test-only dataset ``line`` and filter ``bad``."""
    DATASETS.register("line", "harness_support:LineBuilder")
    FILTERS.register("bad", "harness_support:BadFilter")
