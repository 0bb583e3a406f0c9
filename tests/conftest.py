"""Shared fixtures: registry isolation and the test-only entries of ``harness_support``."""

from __future__ import annotations

import signal
from collections.abc import Iterator

import pytest
from hypothesis import HealthCheck, settings

from locbench.registry import DATASETS, FILTERS

# Hypothesis profiles of the loader fuzzing (tests/fuzz/test_fuzz_loaders.py): "ci" (the default) keeps the module near
# a minute on 2 cores (100 examples a test, about 15 s measured); "fuzz" (nox -s fuzz, or pytest
# --hypothesis-profile=fuzz) runs 10 000 a test, random each time (11 min measured on the shared 2 cores).
_FUZZ_SETTINGS = {
    "deadline": None,  # the first load of a format compiles numba kernels
    "suppress_health_check": [HealthCheck.too_slow, HealthCheck.data_too_large],
    "derandomize": True,  # CI runs the same examples every time; the fuzz profile explores
    "database": None,  # no .hypothesis folder in the checkout; a failure prints its reproducing example
}
settings.register_profile("ci", max_examples=100, **_FUZZ_SETTINGS)
settings.register_profile("fuzz", max_examples=10_000, **{**_FUZZ_SETTINGS, "derandomize": False})
settings.load_profile("ci")


def pytest_configure(config: pytest.Config) -> None:
    """Put back the interpreter's Ctrl-C handler where the run inherited SIGINT ignored.

    A shell without job control starts a command in the background with SIGINT ignored, and Python then leaves it
    so: the tests that send a Ctrl-C on purpose (to this process, or to a child it starts, which inherits the
    disposition) would wait for an interrupt that never comes.
    """
    if signal.getsignal(signal.SIGINT) is signal.SIG_IGN:
        signal.signal(signal.SIGINT, signal.default_int_handler)


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
