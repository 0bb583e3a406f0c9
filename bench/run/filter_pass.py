"""One filter's pass over one dataset's events: the step loop every run goes through.

:func:`run_filter` resets a filter and sends it the dataset's events: ``predict`` for odometry, ``update`` for
each observation type the filter routes (:meth:`~locbench.filters.base.Filter.routed_events`), taking
``estimate()`` and the filter's health after every call, and the time of each call. A filter's own failure
(an exception, a non-finite estimate, an estimate outside the world, a broken estimate contract) ends the pass
with its status and message; it never raises. :class:`FilterPass` is the same pass advanced in stretches of
events, so that several filters of one task can take turns over slices of the data (interleaved timing,
:mod:`locbench.run.execute`). A filter that exposes belief samples has them scored at the ground-truth times while
it runs (:class:`_BeliefScorer`).
"""

from __future__ import annotations

import math
import time
import traceback
from collections.abc import Sequence
from dataclasses import dataclass, field

import numpy as np

from locbench.core.errors import FilterDiverged
from locbench.core.events import EVENT_TYPES, Event, Odometry
from locbench.datasets.dataset import Dataset
from locbench.evaluate.divergence import left_world, world_box
from locbench.evaluate.hold import hold_ends
from locbench.evaluate.records import KIND_NAMES
from locbench.filters.base import GAUSSIAN_HEALTH_NAMES, SCORE_SAMPLE_SIZE, Filter, gaussian_health_rows
from locbench.run.contract import EstimateContractError, check_shapes, first_violation

_RESET = KIND_NAMES.index("reset")
_KIND_OF = {t: KIND_NAMES.index(t.__name__) for t in EVENT_TYPES}


@dataclass
class FilterTrace:
    """What one pass of a filter over a dataset produced (arrays as in :class:`RunRecord`)."""

    t: np.ndarray
    mean: np.ndarray
    cov: np.ndarray
    kind: np.ndarray
    step_ns: np.ndarray
    diagnostics: dict[str, np.ndarray]
    status: str = "ok"
    message: str = ""
    diverged_t: float | None = None
    extra: dict[str, np.ndarray] = field(default_factory=dict)
    health: dict[str, np.ndarray] = field(default_factory=dict)


#: Belief samples the runner keeps before scoring them together (:func:`locbench.evaluate.scores.sample_scores_batch`):
#: one compiled call per batch instead of one per ground-truth interval; at 64 members, 0.8 MB of samples.
SCORE_BATCH = 512


class _BeliefScorer:
    """Scores a filter's own belief samples at the ground-truth times while it runs (:mod:`locbench.evaluate.scores`).

    Each row of the run is in force at the ground-truth times the zero-order hold gives it
    (:func:`locbench.evaluate.hold.hold_ends`, on the row times known before the run: the reset and one row per
    event the filter is sent); before the next event changes the belief, those times get one sample of it. The
    samples wait in a batch of :data:`SCORE_BATCH` and are scored together (the same values as one by one); only
    the per-time scores are kept. Inactive (no cost) for a filter without :meth:`Filter.belief_sample`, or whose
    belief sample is None.
    """

    def __init__(
        self, flt: Filter, ds: Dataset, rng: np.random.Generator | None, row_t: list[float], size: int
    ) -> None:
        self._flt, self._rng, self._size = flt, rng, size
        self._poses = ds.ground_truth.poses
        self._next = 0
        self._scores = np.full((4, ds.ground_truth.t.shape[0]), np.nan)
        # the base class's belief_sample is None, drawing nothing: such a filter is not scored
        self.active = rng is not None and type(flt).belief_sample is not Filter.belief_sample
        #: ends[r]: the ground-truth times row r holds end there (a list: read once per event)
        self._ends: list[int] = hold_ends(row_t, ds.ground_truth.t).tolist() if self.active else []
        #: the batch: each sample's points and normalised weights, and the truth index its times end at
        self._points: list[np.ndarray] = []
        self._weights: list[np.ndarray] = []
        self._stops: list[int] = []
        self._first = 0  # the first truth index of the batch
        #: the last read-only weights array the filter handed and its normalised copy (it cannot change in place)
        self._weights_in: np.ndarray | None = None
        self._weights_normalised = np.empty(0)

    def score_row(self, row: int) -> None:
        """Score the ground-truth times row ``row`` holds with the filter's current belief (that row's)."""
        if self.active:
            self._score_until(self._ends[row])

    def _score_until(self, stop: int) -> None:
        """Sample the current belief for the ground-truth times not yet scored before index ``stop``."""
        if stop <= self._next:
            return
        assert self._rng is not None
        sample = self._flt.belief_sample(self._rng, self._size)
        if sample is None:
            self.active = False
            return
        points, weights = sample
        p = np.ascontiguousarray(points, dtype=np.float64)
        if weights is self._weights_in:  # a read-only array handed again (a particle filter's 1/m): normalised once
            w = self._weights_normalised
        else:
            w = np.asarray(weights, dtype=np.float64)
            w = w / w.sum()  # as sample_scores normalises: the batch's scores are its values
            if isinstance(weights, np.ndarray) and not weights.flags.writeable:
                self._weights_in, self._weights_normalised = weights, w
        if self._points and p.shape != self._points[0].shape:
            self._flush()  # a sample of another size starts a batch of its own
        self._points.append(p)
        self._weights.append(w)
        self._stops.append(stop)
        self._next = stop
        if len(self._stops) >= SCORE_BATCH:
            self._flush()

    def _flush(self) -> None:
        """Score the batch's samples at their ground-truth times."""
        if not self._stops:
            return
        # imported here: scipy and numba stay out of the runner's import (a sweep's start, before its signal handler)
        from locbench.evaluate.scores import sample_scores_batch

        first, stop = self._first, self._stops[-1]
        self._scores[:, first:stop] = sample_scores_batch(
            np.stack(self._points), np.stack(self._weights), np.asarray(self._stops) - first, self._poses[first:stop]
        )
        self._points, self._weights, self._stops = [], [], []
        self._first = stop

    def result(self) -> dict[str, np.ndarray]:
        """The per-time scores, the times left scored with the last belief, or nothing for a Gaussian filter."""
        if self.active:
            self._score_until(self._scores.shape[1])
        if not self.active:
            return {}
        self._flush()
        from locbench.evaluate.scores import SAMPLE_SCORE_KEYS

        return dict(zip(SAMPLE_SCORE_KEYS, self._scores, strict=True))


def incompatibility(flt: Filter, ds: Dataset) -> str | None:
    """Why ``flt`` cannot run on ``ds`` (a recorded skip), or None."""
    missing = sorted(k.value for k in flt.requires - ds.world.kinds)
    if missing:
        return f"{type(flt).__name__} requires map kinds {missing} which {ds.name or ds.id} does not provide"
    bound = flt.unsupported(ds.world)
    if bound is not None:
        return f"{type(flt).__name__} on {ds.name or ds.id}: {bound}"
    wanted = flt.routed_events() - {Odometry}
    present = {type(e) for e in ds.events}
    if wanted and not wanted & present:
        # A filter that would see no observation at all would only dead-reckon under another name.
        names = ", ".join(sorted(t.__name__ for t in wanted))
        return f"{type(flt).__name__} uses {names}, none of which {ds.name or ds.id} provides"
    return None


def run_filter(
    flt: Filter,
    ds: Dataset,
    rng: np.random.Generator,
    sample_rng: np.random.Generator | None = None,
    score_sample: int = SCORE_SAMPLE_SIZE,
) -> FilterTrace:
    """Reset ``flt`` and run it over ``ds``; never raises for a filter's own failure.

    The first row is the belief right after ``reset`` (kind "reset"); then one row per routed event, with the
    filter's :meth:`Filter.health` beside its estimate. With ``sample_rng`` (a generator of the runner's, not
    the filter's), a filter that exposes belief samples has them scored at every ground-truth time
    (:class:`_BeliefScorer`; the scores go into ``extra``) from samples of ``score_sample`` members.
    """
    run = FilterPass(flt, ds, rng, sample_rng, score_sample)
    run.advance(len(ds.events))
    return run.finish()


#: Routed events the warm-up pass sends at least (:func:`warm_up`), and of each routed type present at least.
WARM_EVENTS = 60
WARM_PER_TYPE = 3
#: The (filter class, config, event types) this process has warmed up: a kernel compiles once per process.
_WARMED: set[tuple[type, str, frozenset[type]]] = set()


def _warm_events(routed: frozenset[type], events: Sequence[Event]) -> list[Event]:
    """The dataset's first events the warm-up sends: at least :data:`WARM_EVENTS` routed ones and
    :data:`WARM_PER_TYPE` of every routed type the dataset has (fewer where it has fewer)."""
    present = {type(e) for e in events} & (routed | {Odometry})
    seen: dict[type, int] = {}
    out: list[Event] = []
    for ev in events:
        typ = type(ev)
        if typ is not Odometry and typ not in routed:
            continue
        out.append(ev)
        seen[typ] = seen.get(typ, 0) + 1
        if len(out) >= WARM_EVENTS and all(seen.get(t, 0) >= WARM_PER_TYPE for t in present):
            break
    return out


def warm_key(flt: Filter, ds: Dataset) -> tuple[type, str, frozenset[type]]:
    """What one warm-up serves: the filter's class and config and the dataset's event types."""
    return (type(flt), repr(flt.config), frozenset(type(e) for e in ds.events))


def warm_up(flt: Filter, ds: Dataset) -> bool:
    """Compile and warm ``flt``'s kernels before its timed pass: a throwaway instance of the same class and
    config, reset with its own generator, is sent the first events of ``ds`` (:func:`_warm_events`) and asked
    for every output the pass asks for.

    Numba compiles a kernel at its first call (or loads it from the on-disk cache), and libraries warm their
    own caches; without this, that time lands in the first timed steps of the first run in a process. The
    throwaway instance shares nothing with ``flt`` (its own config copy, generator and state), so the timed
    pass's estimates are the same bit for bit. A failure here is ignored: the timed pass meets it and records it.
    Once per process for each (filter class, config, event types of the dataset), :func:`warm_key`; a child forked
    after it inherits the warmed kernels (:func:`locbench.run.execute.execute_contained`).

    Returns
    -------
    bool
        Whether a warm-up pass ran (False: this process had warmed up the same already).
    """
    key = warm_key(flt, ds)
    if key in _WARMED:
        return False
    _WARMED.add(key)
    try:
        twin = type(flt)(flt.config)
        rng = np.random.default_rng(0)
        twin.reset(ds.initial, ds.world, ds.sensors, rng)
        for ev in _warm_events(flt.routed_events(), ds.events):
            if type(ev) is Odometry:
                twin.predict(ev)
            else:
                twin.update(ev)  # type: ignore[arg-type]
            twin.estimate()
            twin.health()
            twin.event_health()
        twin.belief_sample(rng, SCORE_SAMPLE_SIZE)
    except Exception:  # the timed pass meets the same failure and records it
        pass
    return True


class FilterPass:
    """One filter's pass over a dataset (:func:`run_filter`), advanced in stretches of events.

    :func:`locbench.run.execute.execute_task` advances several passes in turn over slices of a dataset (interleaved
    timing), so a busy moment of the machine falls on every configuration of the task alike; each pass keeps its own
    filter, generators and arrays, so its estimates are those of a pass alone, bit for bit.
    """

    def __init__(
        self,
        flt: Filter,
        ds: Dataset,
        rng: np.random.Generator,
        sample_rng: np.random.Generator | None = None,
        score_sample: int = SCORE_SAMPLE_SIZE,
    ) -> None:
        self._flt, self._ds = flt, ds
        self._routed = routed = flt.routed_events()
        self._t0 = ds.events[0].t if ds.events else 0.0
        t_reset = float(min(self._t0, ds.ground_truth.t[0]))
        # the rows' times, known before the run: the reset, then each event the filter is sent (the loop's rule)
        row_t = [t_reset] + [e.t for e in ds.events if type(e) is Odometry or type(e) in routed]
        n_max = len(row_t)
        self.t = np.full(n_max, np.nan)
        self.mean = np.full((n_max, 3), np.nan)
        self.cov = np.full((n_max, 3, 3), np.nan)
        self.kind = np.zeros(n_max, dtype=np.int8)
        self.step_ns = np.zeros(n_max, dtype=np.int64)
        self._n_max = n_max
        self.diags: dict[str, np.ndarray] = {}
        self.health: dict[str, np.ndarray] = {}
        # The first row of every diagnostic and health signal, and of both counts at once: the Gaussian health of
        # a filter keeping Filter.health is computed after the run from the stored rows (_gaussian_health_after),
        # in the order the per-event calls would have reported it.
        self._first: dict[str, int] = {}
        self._deferred = type(flt).health is Filter.health
        self._per_event_health = flt.event_health if self._deferred else flt.health
        self._scorer = _BeliefScorer(flt, ds, sample_rng, row_t, score_sample)
        self.status, self.message = "ok", ""
        self.diverged_t: float | None = None
        self.row = 0
        #: The next event to process; the wall time spent in :meth:`advance`, s.
        self.next = 0
        self.wall_s = 0.0
        self._box = world_box(ds)
        warm_up(flt, ds)  # before the clock: compilation and first-call costs are not the filter's steps
        start = time.perf_counter()
        try:
            flt.reset(ds.initial, ds.world, ds.sensors, rng)
            self._record(t_reset, _RESET, 0)
        except Exception as exc:
            self._fail(exc)
        self.wall_s += time.perf_counter() - start

    @property
    def done(self) -> bool:
        """Stopped early (diverged, failed) or every event processed."""
        return self.status != "ok" or self.next >= len(self._ds.events)

    def _record(self, tt: float, k: int, ns: int) -> None:
        flt, row, n_max = self._flt, self.row, self._n_max
        est = flt.estimate()
        check_shapes(est.mean, est.cov, tt)  # a wrong shape would be broadcast into the rows, or fail as numpy's
        self.t[row], self.kind[row], self.step_ns[row] = tt, k, ns
        self.mean[row] = est.mean
        self.cov[row] = est.cov
        first = self._first
        d = est.diagnostics
        for name, value in d.items():
            arr = self.diags.get(name)
            if arr is None:
                arr = self.diags[name] = np.full(n_max, np.nan)
                first[name] = row
            arr[row] = value
        if _BOTH_COUNTS not in first and "accepted" in d and "rejected" in d:
            first[_BOTH_COUNTS] = row
        for name, value in self._per_event_health().items():
            arr = self.health.get(name)
            if arr is None:
                arr = self.health[name] = np.full(n_max, np.nan)
                first[" " + name] = row
            arr[row] = value
        self.row += 1

    def _fail(self, exc: Exception) -> None:
        if isinstance(exc, EstimateContractError):
            self.status, self.message = "error", str(exc)
            return
        if isinstance(exc, FilterDiverged):
            self.status, self.message = "diverged", str(exc)
            self.diverged_t = float(self.t[self.row - 1]) if self.row else float(self._t0)
            return
        self.status = "error"
        tb = traceback.extract_tb(exc.__traceback__)
        where = f" ({tb[-1].filename.rsplit('/', 1)[-1]}:{tb[-1].lineno})" if tb else ""
        self.message = f"{type(exc).__name__}: {exc}{where}"

    def advance(self, stop: int) -> None:
        """Process the events before index ``stop`` not yet processed (none once :attr:`done`)."""
        if self.done:
            return
        flt, routed, scorer, box = self._flt, self._routed, self._scorer, self._box
        mean, cov = self.mean, self.cov
        events = self._ds.events
        clock = time.perf_counter_ns
        start_s = time.perf_counter()
        try:
            while self.next < stop:
                ev = events[self.next]
                self.next += 1
                typ = type(ev)
                if typ is not Odometry and typ not in routed:
                    continue
                scorer.score_row(self.row - 1)  # the belief in force until this event
                if typ is Odometry:
                    start = clock()
                    flt.predict(ev)  # type: ignore[arg-type]
                    ns = clock() - start
                else:
                    start = clock()
                    flt.update(ev)  # type: ignore[arg-type]
                    ns = clock() - start
                self._record(ev.t, _KIND_OF[typ], ns)
                # scalar tests on the row's 12 floats: np.all(np.isfinite(.)) twice cost 8 us per event, these 1 us
                m, c = mean[self.row - 1].tolist(), cov[self.row - 1].ravel().tolist()
                if not (all(map(math.isfinite, m)) and all(map(math.isfinite, c))):
                    raise FilterDiverged(f"non-finite estimate at t={ev.t:.3f} s")
                if not box.contains(m[0], m[1]):
                    raise FilterDiverged(f"{left_world(mean[self.row - 1], box)} at t={ev.t:.3f} s")
        except Exception as exc:
            self._fail(exc)
        self.wall_s += time.perf_counter() - start_s

    def finish(self) -> FilterTrace:
        """The pass's trace (after its filter's extra results and the belief scores, when it ended ok)."""
        self._check_contract()
        row = self.row
        if self._deferred:
            self.health = _gaussian_health_after(
                self._flt, self.cov[:row], {k: v[:row] for k, v in self.diags.items()}, self.health, self._first
            )
        extra: dict[str, np.ndarray] = {}
        if self.status == "ok":
            try:
                extra = {k: np.asarray(v) for k, v in self._flt.extra_results().items()}
                extra |= self._scorer.result()
            except Exception as exc:
                self.status, self.message = "error", f"extra_results failed: {type(exc).__name__}: {exc}"
        return FilterTrace(
            self.t[:row],
            self.mean[:row],
            self.cov[:row],
            self.kind[:row],
            self.step_ns[:row],
            {k: v[:row] for k, v in self.diags.items()},
            self.status,
            self.message,
            self.diverged_t,
            extra,
            {k: v[:row] for k, v in self.health.items()},
        )

    def _check_contract(self) -> None:
        """The estimate contract's values over the rows recorded (:func:`locbench.run.contract.first_violation`): the
        first violation, when it comes before the pass's own end, fails the run there (its rows end with it)."""
        found = first_violation(self.t[: self.row], self.mean[: self.row], self.cov[: self.row])
        if found is None:
            return
        i, message = found
        self.row = i + 1
        self.status, self.message, self.diverged_t = "error", message, None


_BOTH_COUNTS = " accepted+rejected"  # run_filter's key of the first row with both counts (no name has a space)


def _gaussian_health_after(
    flt: Filter,
    cov: np.ndarray,
    diags: dict[str, np.ndarray],
    event: dict[str, np.ndarray],
    first: dict[str, int],
) -> dict[str, np.ndarray]:
    """The health of a filter keeping :meth:`Filter.health`: its Gaussian signals from the run's rows
    (:func:`gaussian_health_rows`, equal bit for bit to the per-event values) with the per-event
    :meth:`Filter.event_health` arrays ``event`` (n_max rows, ``first`` the row each appeared in), every name in
    the order of its first report: by row, the Gaussian ones first as :meth:`Filter.health` merges them."""
    n = cov.shape[0]
    gauss = gaussian_health_rows(cov, diags, flt.health_nis_dof) if n else {}
    starts = {"cov_trace_xy_m2": 0, "heading_var_rad2": 0}
    if "nis" in first:
        starts |= {"nis": first["nis"], "nis_p": first["nis"]}
    if _BOTH_COUNTS in first:
        starts["accepted_fraction"] = first[_BOTH_COUNTS]
    order = [(starts[k], 0, i, k) for i, k in enumerate(GAUSSIAN_HEALTH_NAMES) if k in gauss and k in starts]
    order += [(first[" " + k], 1, i, k) for i, k in enumerate(event)]
    arrays = gauss | {k: v[:n] for k, v in event.items()}
    return {k: arrays[k] for *_, k in sorted(order)}
