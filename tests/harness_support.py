"""Hand-made datasets and filters for the harness tests (importable as ``harness_support``)."""

from __future__ import annotations

import dataclasses
import os
import signal
import time
import uuid
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np

from locbench.core.errors import FilterDiverged
from locbench.core.events import LandmarkObservations, Odometry
from locbench.core.tunable import tunable
from locbench.datasets.dataset import (
    Dataset,
    DatasetBuilder,
    FlaggedSample,
    Gaussian2,
    Landmarks,
    SensorSpec,
    Trajectory2D,
    Waypoints,
    WorldMap,
    sort_events,
)
from locbench.filters.base import Estimate, Filter, FilterConfig

# --- a hand-made dataset: straight line at 1 m/s, one landmark, 10 Hz ------------------------------


@dataclass(frozen=True, kw_only=True)
class LineParams:
    steps: int = 50
    noise_m: float = 0.0
    label: str = ""  # free text, only in the name (long and non-ASCII names for the store and export tests)


class LineBuilder(DatasetBuilder):
    Params = LineParams
    description = "test-only straight line"

    def build(self, params: Any, rng: np.random.Generator) -> Dataset:
        dt = 0.1
        t = np.arange(params.steps + 1) * dt
        xy = np.column_stack([t * 1.0, np.zeros_like(t)])
        events: list[Any] = []
        for k in range(1, params.steps + 1):
            events.append(
                Odometry(float(t[k]), 0.1 + float(rng.normal(0.0, params.noise_m)) if params.noise_m else 0.1, 0.0, 0.0)
            )
            if k % 5 == 0:
                d = np.hypot(10.0 - xy[k, 0], 2.0)
                b = np.arctan2(2.0, 10.0 - xy[k, 0])
                events.append(LandmarkObservations(float(t[k]), np.array([0]), np.array([d]), np.array([b])))
        return Dataset(
            id="line",
            params={},
            events=sort_events(events),
            ground_truth=Trajectory2D(t, xy, np.zeros_like(t)),
            initial=Gaussian2(np.zeros(3), np.diag([1e-4, 1e-4, 1e-4])),
            world=WorldMap(landmarks=Landmarks(np.array([0]), np.array([[10.0, 2.0]]))),
            sensors=SensorSpec(odometry_sigma_xy_per_m=0.01, odometry_sigma_theta_per_m=0.01),
            waypoints=Waypoints(np.array([2.0, 4.0]), np.array([[2.0, 0.0], [4.0, 0.0]])),
        )


# --- hand-made filters that misbehave on purpose -----------------------------------------------------


@dataclass(frozen=True, kw_only=True)
class BadConfig(FilterConfig):
    fail_at_s: float = 1.0
    #: raise, nan, diverge, far (a finite but absurd 1e300 m), exit (the process dies), slow, or signal (SIGINT
    #: to the process ``LOCBENCH_TEST_SIGNAL_PID`` at reset, once: while the marker ``LOCBENCH_TEST_SIGNAL`` is
    #: absent, which it creates; then dead reckoning)
    mode: str = "raise"


class BadFilter(Filter):
    """Dead reckoning that breaks at ``fail_at_s`` in the configured way."""

    consumes = frozenset({Odometry})
    Config = BadConfig

    def reset(self, initial: Gaussian2, world: WorldMap, sensors: SensorSpec, rng: np.random.Generator) -> None:
        self._x = initial.mean.copy()
        self._t = 0.0
        started = os.environ.get("LOCBENCH_TEST_STARTED")
        if started and self.config.mode == "slow":  # type: ignore[attr-defined]
            # tells a test that a run is in progress (it then interrupts it), in whichever process runs it
            (Path(started) / f"run-{os.getpid()}-{uuid.uuid4().hex}").touch()
        marker = os.environ.get("LOCBENCH_TEST_SIGNAL")
        if marker and self.config.mode == "signal" and not Path(marker).exists():  # type: ignore[attr-defined]
            # a Ctrl-C at a known moment: this run has started, so every run before it on its task has finished
            Path(marker).touch()
            os.kill(int(os.environ["LOCBENCH_TEST_SIGNAL_PID"]), signal.SIGINT)
            time.sleep(60)  # the sweep abandons this run (in this process the signal interrupts the sleep)

    def predict(self, u: Odometry) -> None:
        self._t = u.t
        self._x = self._x + u.delta
        mode = self.config.mode  # type: ignore[attr-defined]
        if mode == "slow":
            time.sleep(0.05)
            return
        if u.t >= self.config.fail_at_s:  # type: ignore[attr-defined]
            if mode == "exit":
                os._exit(3)  # a worker that dies (a crash, the OOM killer), not an exception
            if mode == "raise":
                raise RuntimeError("boom")
            if mode == "diverge":
                raise FilterDiverged("covariance exploded")
            if mode == "far":
                self._x[:2] = -1.0e300
                return
            self._x[:] = np.nan

    def update(self, z: Any) -> None:
        self.check_consumes(z)

    def estimate(self) -> Estimate:
        return Estimate(self._t, self._x.copy(), np.eye(3) * 0.01)


# --- a filter with a tunable parameter that makes it diverge (the tuner's worst score) --------------------


@dataclass(frozen=True, kw_only=True)
class TunableBadConfig(FilterConfig):
    #: below the dataset's duration (5 s on ``line``) the filter diverges at that time
    fail_at_s: float = field(default=1.0, metadata=tunable(0.5, 20.0))
    mode: str = "diverge"


class TunableBadFilter(BadFilter):
    """:class:`BadFilter` whose failure time is tunable: a tuner must score its diverging trials as the worst."""

    Config = TunableBadConfig


class GlitchyLineBuilder(LineBuilder):
    """The straight line with one truth sample a loader flagged (as a recorded loader reports a Vicon glitch)."""

    description = "test-only straight line with one flagged sample"

    def build(self, params: Any, rng: np.random.Generator) -> Dataset:
        ds = super().build(params, rng)
        glitch = FlaggedSample("line.dat", 7, 2.5, "ground-truth", "apparent speed, m/s", 4.4, "at most 1 m/s")
        return dataclasses.replace(ds, id="glitchy", flagged=(glitch,))
