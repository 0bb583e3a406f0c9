"""One filter's pass over a dataset: the belief scored at the ground-truth times by the zero-order hold."""

from __future__ import annotations

from typing import Any

import numpy as np
from harness_support import LineBuilder, LineParams

from locbench.core.events import LandmarkObservations, Odometry
from locbench.datasets.dataset import Gaussian2, SensorSpec, WorldMap
from locbench.evaluate.hold import hold_indices
from locbench.evaluate.scores import SAMPLE_SCORE_KEYS
from locbench.filters.base import SCORE_SAMPLE_SIZE, Estimate, Filter, FilterConfig
from locbench.run.filter_pass import FilterPass, run_filter


class CountingFilter(Filter):
    """Stands still; its belief sample is one point at x = the number of calls so far (m), so a score says which
    row's belief it was."""

    consumes = frozenset({Odometry, LandmarkObservations})
    Config = FilterConfig

    def reset(self, initial: Gaussian2, world: WorldMap, sensors: SensorSpec, rng: np.random.Generator) -> None:
        self.calls = 0
        self.samples = 0

    def predict(self, u: Odometry) -> None:
        self.calls += 1

    def update(self, z: Any) -> None:
        self.calls += 1

    def estimate(self) -> Estimate:
        return Estimate(0.0, np.zeros(3), np.eye(3))

    def belief_sample(self, rng: np.random.Generator, size: int) -> tuple[np.ndarray, np.ndarray]:
        self.samples += 1
        return np.array([[float(self.calls), 0.0, 0.0]]), np.ones(1)


def _line() -> Any:
    return LineBuilder().build(LineParams(steps=20), np.random.default_rng(0))


def test_each_ground_truth_time_scores_the_belief_the_hold_puts_in_force() -> None:
    ds = _line()
    flt = CountingFilter()
    trace = run_filter(flt, ds, np.random.default_rng(0), np.random.default_rng(1))
    gt = ds.ground_truth
    # row r is the belief after r calls; the stored rows' times give, by the hold, the row at each truth time
    rows = hold_indices(trace.t, gt.t)
    crps_x = trace.extra[SAMPLE_SCORE_KEYS[0]]
    np.testing.assert_allclose(crps_x, np.abs(rows - gt.xy[:, 0]), rtol=0.0, atol=1e-12)
    # at truth time k (0.1 s steps): k odometry calls and, every 5th, a sighting at the same time, which the truth
    # sees too (at equal times the later row holds)
    assert rows.tolist() == [k + k // 5 for k in range(gt.t.size)]
    # one sample for each row that holds at least one truth time, no more
    assert flt.samples == np.unique(rows).size


def test_the_sample_asked_for_has_the_runs_score_sample_size() -> None:
    class Sized(CountingFilter):
        def belief_sample(self, rng: np.random.Generator, size: int) -> tuple[np.ndarray, np.ndarray]:
            self.sizes = getattr(self, "sizes", set()) | {size}
            return super().belief_sample(rng, size)

    for asked, expected in ((7, 7), (None, SCORE_SAMPLE_SIZE)):
        flt = Sized()
        rngs = (np.random.default_rng(0), np.random.default_rng(1))
        run_filter(flt, _line(), *rngs) if asked is None else run_filter(flt, _line(), *rngs, score_sample=asked)
        assert flt.sizes == {expected}


def test_a_filter_without_belief_samples_is_not_scored() -> None:
    class Plain(CountingFilter):
        belief_sample = Filter.belief_sample  # type: ignore[assignment]

    trace = run_filter(Plain(), _line(), np.random.default_rng(0), np.random.default_rng(1))
    assert trace.status == "ok" and not trace.extra


def test_a_pass_in_stretches_scores_as_one_pass() -> None:
    ds = _line()
    whole = run_filter(CountingFilter(), ds, np.random.default_rng(0), np.random.default_rng(1))
    run = FilterPass(CountingFilter(), ds, np.random.default_rng(0), np.random.default_rng(1))
    for stop in (3, 4, 17, len(ds.events)):
        run.advance(stop)
    pieces = run.finish()
    for key in SAMPLE_SCORE_KEYS:
        np.testing.assert_array_equal(pieces.extra[key], whole.extra[key])


def test_a_weights_array_handed_again_is_read_as_it_is_now() -> None:
    # weights that alternate between the sample's two members: a fresh array each call, the same writable array
    # changed in place, or (constant weights) one read-only array, which the runner normalises once
    class Fresh(CountingFilter):
        def weights(self) -> np.ndarray:
            return np.array([1.0, 0.0]) if self.samples % 2 else np.array([0.0, 3.0])

        def belief_sample(self, rng: np.random.Generator, size: int) -> tuple[np.ndarray, np.ndarray]:
            self.samples += 1
            return np.array([[float(self.calls), 0.0, 0.0], [self.calls + 10.0, 0.0, 0.0]]), self.weights()

    class Reused(Fresh):
        buffer = np.zeros(2)

        def weights(self) -> np.ndarray:
            self.buffer[:] = super().weights()
            return self.buffer

    class ReadOnly(Fresh):
        def weights(self) -> np.ndarray:
            if not hasattr(self, "fixed"):
                self.fixed = np.array([1.0, 3.0])
                self.fixed.flags.writeable = False
            return self.fixed

    class Constant(Fresh):
        def weights(self) -> np.ndarray:
            return np.array([1.0, 3.0])

    ds = _line()

    def scores(flt: CountingFilter) -> dict[str, np.ndarray]:
        return run_filter(flt, ds, np.random.default_rng(0), np.random.default_rng(1)).extra

    fresh, reused = scores(Fresh()), scores(Reused())
    assert not np.array_equal(fresh[SAMPLE_SCORE_KEYS[0]], scores(Constant())[SAMPLE_SCORE_KEYS[0]])
    for key in SAMPLE_SCORE_KEYS:
        np.testing.assert_array_equal(reused[key], fresh[key])
        np.testing.assert_array_equal(scores(ReadOnly())[key], scores(Constant())[key])
