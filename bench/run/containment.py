"""Running a filter's code in a child process with a time limit, so that nothing it does ends the sweep.

:func:`call_in_child` forks this process (the dataset already built here is shared, not copied or rebuilt),
runs a function in the child and returns its pickled result through a pipe. Whatever the filter does there,
the caller gets a :class:`ChildOutcome`: the result; an exception that escaped (``SystemExit`` included); an
exit (``os._exit(3)``: "exit code 3") or a death by a signal (a segfault: "signal SIGSEGV"); or the time
limit passed, after which the child is killed. Every executor runs its parts through it (in this process at
``--jobs 1``, in a pool worker, in a dask worker), so the containment and the limit are the same everywhere.

The time limit of a run (:func:`run_time_limit`): ``--run-timeout S`` when given (``0``/``none``: no limit),
else ``max(RUN_TIMEOUT_FLOOR_S, RUN_TIMEOUT_PER_DATA_S x the dataset's duration)``.

Signals: the child ignores SIGINT (Ctrl-C reaches the whole process group; the parent decides what stops)
and dies with its parent (``PR_SET_PDEATHSIG`` on Linux). A ``KeyboardInterrupt`` in the parent while it
waits (a stop request) kills the child and propagates.
"""

from __future__ import annotations

import contextlib
import ctypes
import math
import os
import pickle
import select
import signal
import sys
import time
import traceback
from collections.abc import Callable, Iterator
from dataclasses import dataclass
from typing import Any

# numba's GNU OpenMP threading layer is not fork-safe: a child forked from a process that ran a parallel kernel
# (the ray casting of a dataset's build) is killed by numba as soon as it runs one. "forksafe" picks TBB when
# installed, else numba's workqueue (same kernels, same results); an explicit NUMBA_THREADING_LAYER is kept.
if "numba" in sys.modules:
    _numba_config = sys.modules["numba"].config
    if os.environ.get("NUMBA_THREADING_LAYER") is None and _numba_config.THREADING_LAYER == "default":
        _numba_config.THREADING_LAYER = "forksafe"
os.environ.setdefault("NUMBA_THREADING_LAYER", "forksafe")

#: The default time limit of a run is ``max(RUN_TIMEOUT_FLOOR_S, RUN_TIMEOUT_PER_DATA_S x duration)``, s. The
#: slowest run of the committed benchmark computes at 1/44 of real time (ekf_icp on lap[kidnap_m=2]), so a
#: limit of 10x real time leaves it a margin of 400.
RUN_TIMEOUT_FLOOR_S = 60.0
RUN_TIMEOUT_PER_DATA_S = 10.0
#: The rule, as recorded in a run's provenance and printed in messages.
DEFAULT_RULE = f"max({RUN_TIMEOUT_FLOOR_S:g} s, {RUN_TIMEOUT_PER_DATA_S:g} x dataset duration)"

#: The ``--run-timeout`` of the command being run: None for the default rule, ``math.inf`` for no limit, else
#: seconds. Set by :func:`run_timeout` around a command; read when a task is planned.
_RUN_TIMEOUT: float | None = None


def current_run_timeout() -> float | None:
    """The run time limit set by :func:`run_timeout` (None: the default rule; ``inf``: none)."""
    return _RUN_TIMEOUT


@contextlib.contextmanager
def run_timeout(seconds: float | None) -> Iterator[None]:
    """Within the block, tasks are planned with this run time limit (None: the default rule; 0 or inf: none)."""
    global _RUN_TIMEOUT
    old = _RUN_TIMEOUT
    _RUN_TIMEOUT = None if seconds is None else (math.inf if seconds == 0 else float(seconds))
    try:
        yield
    finally:
        _RUN_TIMEOUT = old


def parse_run_timeout(text: str) -> float:
    """``--run-timeout``'s value: seconds > 0, or ``0``/``none`` for no limit (``inf``); a ValueError otherwise."""
    if text.strip().lower() in ("none", "inf"):
        return math.inf
    value = float(text)
    if value == 0:
        return math.inf
    if not (math.isfinite(value) and value > 0):
        raise ValueError(f"expected seconds > 0, or 0/none for no limit, got {text!r}")
    return value


def run_time_limit(duration_s: float, override: float | None) -> float:
    """The time limit of one run, s (``inf``: none): ``override`` when set, else the default rule on the dataset's
    duration ``duration_s`` (s)."""
    if override is not None:
        return override
    return max(RUN_TIMEOUT_FLOOR_S, RUN_TIMEOUT_PER_DATA_S * max(duration_s, 0.0))


@dataclass(frozen=True)
class ChildOutcome:
    """What a child process gave back: ``value`` when ``ok``, else ``message`` (one line) and ``kind``.

    ``kind``: ``raised`` (an exception escaped the function), ``died`` (exit or signal), ``timeout``.
    """

    ok: bool
    value: Any = None
    message: str = ""
    kind: str = ""
    wall_s: float = 0.0


#: How long the parent waits in one ``select`` call, s (a stop request interrupts it sooner).
_WAIT_S = 1.0
#: ``prctl`` option: the signal this process receives when its parent dies (linux/prctl.h).
_PR_SET_PDEATHSIG = 1


def die_with_parent(parent: int) -> bool:
    """Ask the kernel to SIGKILL this process when its parent dies (Linux); False when the parent already died."""
    if sys.platform.startswith("linux"):
        with contextlib.suppress(OSError, AttributeError):
            libc = ctypes.CDLL(None, use_errno=True)
            libc.prctl(_PR_SET_PDEATHSIG, int(signal.SIGKILL), 0, 0, 0)
    return os.getppid() == parent and parent != 1


def describe_exception(exc: BaseException) -> str:
    """``Type: message (file.py:line)`` of an exception, the line being the innermost frame."""
    tb = traceback.extract_tb(exc.__traceback__)
    where = f" ({tb[-1].filename.rsplit('/', 1)[-1]}:{tb[-1].lineno})" if tb else ""
    text = " ".join(str(exc).split())
    return f"{type(exc).__name__}: {text}{where}" if text else f"{type(exc).__name__}{where}"


def _child(fn: Callable[[], Any], write_fd: int, parent: int, mask: set[int | signal.Signals]) -> None:
    """The child's whole life: run ``fn``, write its pickled outcome, exit without returning to the caller.

    ``mask``: the signal mask to restore once the child's own handlers are in place (the fork blocked SIGINT).
    """
    code = 0
    try:
        with contextlib.suppress(ValueError, OSError):  # not the main thread of a platform without it: keep going
            signal.signal(signal.SIGINT, signal.SIG_IGN)
            signal.signal(signal.SIGTERM, signal.SIG_DFL)
        signal.pthread_sigmask(signal.SIG_SETMASK, mask)
        if not die_with_parent(parent):
            os._exit(1)
        try:
            payload = pickle.dumps((True, fn()), protocol=pickle.HIGHEST_PROTOCOL)
        except BaseException as exc:  # SystemExit and KeyboardInterrupt too: the child reports, the parent decides
            payload = pickle.dumps((False, describe_exception(exc)), protocol=pickle.HIGHEST_PROTOCOL)
        view = memoryview(payload)
        while view:
            view = view[os.write(write_fd, view) :]
        with contextlib.suppress(Exception):
            sys.stdout.flush()
            sys.stderr.flush()
    except BaseException:
        code = 70  # the outcome could not be written (a closed pipe): the parent reports the exit code
    finally:
        os._exit(code)


def call_in_child(fn: Callable[[], Any], timeout_s: float) -> ChildOutcome:
    """Run ``fn()`` in a forked child process and return its outcome; never raises for what ``fn`` does.

    Parameters
    ----------
    fn : callable
        Called without arguments in the child; its return value must pickle.
    timeout_s : float
        Wall-time limit, s (``inf``: none); the child is killed (SIGKILL) when it passes.

    A ``KeyboardInterrupt`` while waiting kills the child and propagates.
    """
    # what this process has buffered would otherwise be written twice, by the child too
    for stream in (sys.stdout, sys.stderr):
        with contextlib.suppress(Exception):
            stream.flush()
    read_fd, write_fd = os.pipe()
    start = time.perf_counter()
    parent = os.getpid()
    # A Ctrl-C during the fork would raise inside an at-fork hook, where Python prints it and drops it: it is held
    # until the fork is done, then delivered in the parent (the child ignores it).
    mask = signal.pthread_sigmask(signal.SIG_BLOCK, {signal.SIGINT, signal.SIGTERM})
    try:
        pid = os.fork()
        if pid == 0:  # the child
            os.close(read_fd)
            _child(fn, write_fd, parent, mask)
    finally:
        signal.pthread_sigmask(signal.SIG_SETMASK, mask)
    os.close(write_fd)
    reaped = False
    try:
        chunks: list[bytes] = []
        deadline = time.monotonic() + timeout_s
        timed_out = False
        while True:
            left = deadline - time.monotonic()
            if left <= 0:
                timed_out = True
                break
            ready, _, _ = select.select([read_fd], [], [], min(left, _WAIT_S))
            if ready:
                data = os.read(read_fd, 1 << 20)
                if not data:
                    break  # the child closed the pipe: it finished, or died
                chunks.append(data)
        if timed_out:
            _kill(pid)
        _, status = os.waitpid(pid, 0)
        reaped = True
        wall = time.perf_counter() - start
        if timed_out:
            return ChildOutcome(False, message=f"timed out after {timeout_s:g} s", kind="timeout", wall_s=wall)
        if chunks and os.WIFEXITED(status) and os.WEXITSTATUS(status) == 0:
            ok, value = pickle.loads(b"".join(chunks))
            if ok:
                return ChildOutcome(True, value, wall_s=wall)
            return ChildOutcome(False, message=value, kind="raised", wall_s=wall)
        return ChildOutcome(False, message=_death(status), kind="died", wall_s=wall)
    finally:
        os.close(read_fd)
        if not reaped:  # interrupted while waiting: the child goes with the stop
            _kill(pid)
            with contextlib.suppress(ChildProcessError):
                os.waitpid(pid, 0)


def _kill(pid: int) -> None:
    with contextlib.suppress(ProcessLookupError):
        os.kill(pid, signal.SIGKILL)


def _death(status: int) -> str:
    """'worker process died with signal SIGSEGV' / '... with exit code 3 ...'."""
    if os.WIFSIGNALED(status):
        sig = os.WTERMSIG(status)
        try:
            name = signal.Signals(sig).name
        except ValueError:
            name = f"signal {sig}"
        return f"worker process died with signal {name}"
    return f"worker process died with exit code {os.WEXITSTATUS(status)} before returning its result"
