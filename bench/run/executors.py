"""Where a sweep's tasks run: this process, a local process pool, or dask.distributed workers.

Every executor goes through one loop (:class:`_Schedule`) over ``concurrent.futures`` executors: this
process's, a ``ProcessPoolExecutor``, or the dask client's (``Client.get_executor``). It splits the plan's
tasks (longest first) into one part per filter (:func:`parts`), runs :func:`locbench.run.execute.execute_contained` on
each somewhere, and hands each result back to the caller, which writes the store in this process as each
filter finishes; so a dask worker on another machine needs locbench installed but no shared folder. Wherever
a part runs, its filter runs in a child process of that worker under the run time limit
(:mod:`locbench.run.containment`): a filter that exits, crashes or hangs is an error run, never a dead sweep. A part
whose worker died is retried, one that raised or kept killing its worker is handed to ``lost`` with the
reason, which records an error run for its filter, and the sweep goes on. SIGINT (Ctrl-C) and SIGTERM stop
the loop: parts not started are not submitted, running ones abandoned (their workers killed), and it returns
within a few seconds saying it was interrupted.
"""

from __future__ import annotations

import asyncio
import collections
import concurrent.futures as cf
import contextlib
import dataclasses
import importlib.util
import ipaddress
import logging
import multiprocessing
import os
import re
import signal
import threading
import time
import types
from collections.abc import Callable, Iterator, Sequence
from dataclasses import dataclass
from typing import Any

from locbench.core.errors import ConfigError, DependencyNotInstalled, one_line
from locbench.run.containment import die_with_parent
from locbench.run.execute import TaskResult, execute_contained, forget_realisations
from locbench.run.plan import Task

log = logging.getLogger(__name__)

Handle = Callable[[Task, TaskResult], None]
Lost = Callable[[Task, str], None]

#: A LocalCluster's settings: no retry of its own (``allowed-failures`` 0: a worker's death is a
#: ``KilledWorker`` error at once, which the loop retries as it does the local pool's, :data:`RETRIES`); one
#: task per worker thread at a time, so that a worker's death is charged to the part it was running only and
#: the part submitted when a worker frees up goes to that worker; no profiler.
_DASK_LOCAL_CONFIG = {
    "distributed.scheduler.allowed-failures": 0,
    "distributed.scheduler.worker-saturation": 1.0,
    # the statistical profiler samples every worker thread's stack every 10 ms: CPU a sweep does not need
    "distributed.worker.profile.enabled": False,
    # dask starts workers with MALLOC_TRIM_THRESHOLD_=65536, which makes glibc return memory after nearly every
    # numpy temporary (measured: 5 s of system time on `default --seeds 1`); run them as the local pool's are
    "distributed.nanny.pre-spawn-environ": {},
    # housekeeping that a sweep of second-long tasks on a few workers does not need at dask's default rates
    # (an event-loop tick every 20 ms and a memory poll every 100 ms in every process, and work stealing)
    "distributed.admin.tick.interval": "1s",
    "distributed.worker.memory.monitor-interval": "1s",
    "distributed.scheduler.work-stealing": False,
    # results are gathered as they finish: no replicas for the active memory manager to balance
    "distributed.scheduler.active-memory-manager.start": False,
}
#: How often a waiting executor looks at the stop flag, s.
_POLL_S = 0.2


#: Seconds a dask client waits for the scheduler at ``--scheduler`` to answer (``--connect-timeout``).
CONNECT_TIMEOUT_S = 30.0
#: Longest ``--scheduler`` address accepted, characters.
MAX_ADDRESS_CHARS = 300
#: Schemes of a dask scheduler address (``tcp`` when none is written); ``ucx`` needs its package.
SCHEDULER_SCHEMES = ("tcp", "tls", "ws", "wss", "ucx")
#: A DNS host name: dot-separated labels of letters, digits and inner hyphens (RFC 1123), 253 characters at most.
_HOSTNAME = re.compile(
    r"^(?=.{1,253}$)[A-Za-z0-9](?:[A-Za-z0-9-]{0,61}[A-Za-z0-9])?(?:\.[A-Za-z0-9](?:[A-Za-z0-9-]{0,61}[A-Za-z0-9])?)*\.?$"
)


def check_scheduler_address(address: str) -> str:
    """The ``--scheduler`` address checked and written ``scheme://host:port``; a :class:`ConfigError` otherwise.

    Accepts ``[scheme://]host:port`` with a scheme of :data:`SCHEDULER_SCHEMES` (``tcp`` by default), a host
    name, an IPv4 address or an IPv6 address in brackets (``tcp://[::1]:8786``), and a port 1-65535. Refused:
    an empty, over-long (:data:`MAX_ADDRESS_CHARS`) or non-printable address, ``http(s)://`` (the dashboard,
    not the scheduler), ``inproc://`` (one process only), ``ucx://`` without its package, anything else.
    """
    expected = "expected [tcp://]HOST:PORT, e.g. tcp://10.0.0.5:8786 or tcp://[::1]:8786"
    if len(address) > MAX_ADDRESS_CHARS:
        raise ConfigError(
            f"--scheduler: an address of {len(address)} characters (at most {MAX_ADDRESS_CHARS}); {expected}"
        )
    shown = repr(address)
    if not address.strip():
        raise ConfigError(f"--scheduler: empty address; {expected}")
    if any(c.isspace() or not c.isprintable() for c in address):
        raise ConfigError(f"--scheduler {shown}: spaces or control characters in the address; {expected}")
    scheme, sep, rest = address.partition("://")
    scheme = scheme.lower() if sep else "tcp"
    rest = rest if sep else address
    if scheme in ("http", "https"):
        raise ConfigError(
            f"--scheduler {shown}: {scheme}:// is the dashboard's web address; the scheduler listens on "
            "tcp://HOST:PORT (port 8786 by default)"
        )
    if scheme == "inproc":
        raise ConfigError(f"--scheduler {shown}: an inproc:// scheduler lives inside one process only; {expected}")
    if scheme not in SCHEDULER_SCHEMES:
        raise ConfigError(f"--scheduler {shown}: unknown scheme {scheme!r}; valid: {', '.join(SCHEDULER_SCHEMES)}")
    if scheme == "ucx" and not any(importlib.util.find_spec(m) for m in ("ucp", "distributed_ucxx")):
        raise DependencyNotInstalled(
            f"--scheduler {shown}: ucx:// needs UCX-Py; install it with: pip install distributed-ucxx"
        )
    if rest.startswith("["):
        end = rest.find("]")
        host, tail = (rest[1:end], rest[end + 1 :]) if end > 0 else ("", "")
        try:
            ipaddress.IPv6Address(host)
        except ValueError:
            raise ConfigError(f"--scheduler {shown}: malformed IPv6 address in brackets; {expected}") from None
        if not tail.startswith(":"):
            raise ConfigError(f"--scheduler {shown}: no port after the IPv6 address; {expected}")
        netloc, port = f"[{host}]", tail[1:]
    else:
        if rest.count(":") != 1:
            why = "an IPv6 address goes in brackets" if rest.count(":") > 1 else "no port"
            raise ConfigError(f"--scheduler {shown}: {why}; {expected}")
        host, port = rest.split(":")
        if not _HOSTNAME.match(host):
            raise ConfigError(f"--scheduler {shown}: {host!r} is not a host name or IP address; {expected}")
        netloc = host
    if not (port.isascii() and port.isdigit() and 1 <= int(port) <= 65535):
        raise ConfigError(f"--scheduler {shown}: port {port!r} is not a number 1-65535; {expected}")
    return f"{scheme}://{netloc}:{int(port)}"


@dataclass
class ExecStatus:
    """What an executor reports beyond the results: whether it was stopped early, and retries."""

    interrupted: bool = False
    retried: int = 0


class StopRequest:
    """SIGINT and SIGTERM, caught for the duration of a ``with`` block.

    A signal sets :attr:`requested`; with ``raise_now`` (work done in this process) it also raises
    ``KeyboardInterrupt`` to abandon the running task, except inside :meth:`shield` (a store write), which
    finishes first. Outside the main thread signals cannot be caught, and the default behaviour stays.
    """

    def __init__(self, raise_now: bool) -> None:
        self.raise_now = raise_now
        self.requested = False
        self._shielded = 0
        self._old: dict[int, Any] = {}

    def __enter__(self) -> StopRequest:
        if threading.current_thread() is threading.main_thread():
            for sig in (signal.SIGINT, signal.SIGTERM):
                self._old[sig] = signal.signal(sig, self._handle)
        return self

    def __exit__(self, *exc: object) -> None:
        for sig, old in self._old.items():
            signal.signal(sig, old)
        self._old.clear()

    def _handle(self, signum: int, frame: types.FrameType | None) -> None:
        self.requested = True
        if self.raise_now and not self._shielded:
            raise KeyboardInterrupt

    @contextlib.contextmanager
    def shield(self) -> Iterator[None]:
        """A block a signal does not interrupt (it only sets :attr:`requested`)."""
        self._shielded += 1
        try:
            yield
        finally:
            self._shielded -= 1


def scheduler_from_file(path: str, timeout_s: float) -> str:
    """The address in a dask scheduler file (``dask scheduler --scheduler-file PATH``), waiting for it to appear.

    A scheduler started with ``--port 0`` picks a free port and writes it, as ``{"address": ...}``, to its file once
    it listens; this waits up to ``timeout_s`` seconds for a complete file (the scheduler writes it while this may
    read), then checks the address as :func:`check_scheduler_address` does. A :class:`ConfigError` naming the file
    when it does not appear in time, is not JSON or has no address.
    """
    import json

    deadline = time.monotonic() + timeout_s
    why = "it does not exist"
    while True:
        try:
            with open(path, encoding="utf-8") as fh:
                info = json.load(fh)
            break
        except FileNotFoundError:
            why = "it does not exist"
        except (json.JSONDecodeError, UnicodeDecodeError) as exc:
            why = f"it is not JSON ({one_line(str(exc))})"
        except OSError as exc:
            raise ConfigError(f"--scheduler {path}: cannot read the scheduler file: {one_line(str(exc))}") from None
        if time.monotonic() >= deadline:
            raise ConfigError(
                f"--scheduler {path}: no scheduler file after {timeout_s:g} s ({why}); expected the file that "
                "'dask scheduler --scheduler-file PATH' writes"
            )
        time.sleep(0.05)  # the scheduler is another process: poll its file until the deadline
    address = info.get("address") if isinstance(info, dict) else None
    if not isinstance(address, str):
        raise ConfigError(f"--scheduler {path}: field 'address' missing or not a string in the scheduler file")
    return check_scheduler_address(address)


def scheduler_address(value: str, timeout_s: float = CONNECT_TIMEOUT_S) -> str:
    """``--scheduler``'s value as a checked address: a scheduler file when it ends in ``.json``, else an address."""
    if value.endswith(".json"):
        return scheduler_from_file(value, timeout_s)
    return check_scheduler_address(value)


def probe_scheduler(address: str, timeout_s: float) -> None:
    """Ask the dask scheduler at ``address`` for its identity; a :class:`TimeoutError` or :class:`OSError` when it
    does not answer within ``timeout_s`` seconds.

    ``distributed.Client(address, timeout=...)`` bounds the TCP connect only: a peer that accepts the connection
    but never answers (a wrong service, a stopped process whose socket is still listening) holds the client's
    handshake forever. This round trip on a fresh event loop is bounded as a whole.
    """
    from distributed.comm import connect

    async def identity() -> None:
        comm = await connect(address, timeout=timeout_s)
        try:
            await comm.write({"op": "identity", "reply": True})
            await comm.read()
        finally:
            comm.abort()

    async def bounded() -> None:
        await asyncio.wait_for(identity(), timeout_s)

    asyncio.run(bounded())


def get(name: str) -> Callable[..., ExecStatus]:
    """The executor called ``name``: ``local`` or ``dask``."""
    try:
        return {"local": run_local, "dask": run_dask}[name]
    except KeyError:
        raise ConfigError(f"unknown executor {name!r}; valid: dask, local") from None


def run_local(
    tasks: Sequence[Task],
    handle: Handle,
    lost: Lost,
    jobs: int = 1,
    scheduler: str | None = None,
    timeout_s: float = 0.0,
) -> ExecStatus:
    """Run the tasks in this process (``jobs`` = 1) or in a pool of ``jobs`` worker processes."""
    if scheduler is not None:
        raise ConfigError("--scheduler needs --executor dask")
    backend: _Backend = _Inline() if jobs <= 1 else _Pool(jobs)
    with StopRequest(raise_now=backend.raise_now) as stop:
        return _Schedule(tasks, backend, handle, lost).run(stop)


# --- the one scheduling loop ---------------------------------------------------------------------------


class _Backend:
    """Where the loop's futures run: opens ``concurrent.futures`` executors and says what a failure means.

    ``slots`` is how many parts run at once; ``raise_now`` whether the work runs in this process (a signal
    then abandons it by ``KeyboardInterrupt``).
    """

    slots = 1
    raise_now = False

    def open(self, workers: int) -> cf.Executor:
        """An executor of at most ``workers`` workers (a fresh one after :meth:`close`)."""
        raise NotImplementedError

    def broken(self, exc: BaseException) -> bool:
        """Whether ``exc`` says the whole executor broke (it fails every part it holds, naming no culprit)."""
        return isinstance(exc, cf.BrokenExecutor)

    def died(self, exc: BaseException) -> bool:
        """Whether ``exc`` says the worker running the part died (charged to that part alone)."""
        return False

    def death(self, times: int) -> str:
        """The message of a part whose worker died ``times`` times."""
        return f"its worker process died {times} times (killed, or out of memory)"

    def close(self, executor: cf.Executor, abandon: bool) -> None:
        """Shut ``executor`` down; with ``abandon`` (an interrupt), kill its workers rather than wait for them."""
        executor.shutdown(wait=not abandon, cancel_futures=True)


class _InlineExecutor(cf.Executor):
    """Runs each call at submission, in this process: the loop's futures without a worker."""

    def submit(self, fn: Callable[..., Any], /, *args: Any, **kwargs: Any) -> cf.Future[Any]:
        fut: cf.Future[Any] = cf.Future()
        fut.set_running_or_notify_cancel()
        try:
            fut.set_result(fn(*args, **kwargs))
        except Exception as exc:  # KeyboardInterrupt (a stop) is not caught: it abandons the part
            fut.set_exception(exc)
        return fut


class _Inline(_Backend):
    raise_now = True

    def open(self, workers: int) -> cf.Executor:
        return _InlineExecutor()

    def close(self, executor: cf.Executor, abandon: bool) -> None:
        forget_realisations()  # the last dataset built here is not kept after the sweep


class _Pool(_Backend):
    """A local ``ProcessPoolExecutor``; its workers end with this process (:func:`_pool_worker_init`)."""

    def __init__(self, jobs: int) -> None:
        self.slots = jobs
        self._before: set[Any] = set()

    def open(self, workers: int) -> cf.Executor:
        # the pool's worker processes are this process's multiprocessing children started from now on
        self._before = set(multiprocessing.active_children())
        return cf.ProcessPoolExecutor(max_workers=workers, initializer=_pool_worker_init)

    def close(self, executor: cf.Executor, abandon: bool) -> None:
        if abandon:
            kill = getattr(executor, "kill_workers", None)  # Python >= 3.14
            if callable(kill):
                kill()
            for proc in set(multiprocessing.active_children()) - self._before:
                with contextlib.suppress(Exception):
                    proc.kill()
        executor.shutdown(wait=not abandon, cancel_futures=True)


#: Times a part whose worker died is submitted again before it is an error run (the local pool and dask alike).
RETRIES = 1


def parts(task: Task) -> list[Task]:
    """One task per filter of ``task`` (the bound goes with the first), or the task itself when it has none.

    A part's result holds one run, so each run is stored as soon as its filter finishes, and a worker that
    dies takes only its own filter with it. The parts of a task run one after another on one worker, which
    builds the dataset once for all of them (:func:`locbench.run.execute.execute_task` keeps it).
    """
    if not task.jobs or task.slice_s > 0:
        # interleaved timing (Task.slice_s) runs the task's filters in turns: one part, stored together
        return [task]
    return [
        dataclasses.replace(task, jobs=(job,), bound_key=task.bound_key if i == 0 else None)
        for i, job in enumerate(task.jobs)
    ]


class _Schedule:
    """The loop every executor runs: parts submitted as workers free up, results handed on, deaths retried.

    At most ``backend.slots`` parts are in flight, never two of one task: a worker that finishes a part is
    the one free, so the next part of its task goes to it (its dataset is built), else the first task not
    started (longest first). A part whose worker died (``backend.died``) is charged that death and submitted
    again up to :data:`RETRIES` times, then it is an error run. An executor that broke (a local pool whose
    worker died) fails every part it held without saying whose worker died: if it held one, that one is
    charged; otherwise each runs again alone in a one-worker executor, where a death is its own, so a part is
    never blamed for a sibling's. A stop (SIGINT, SIGTERM) abandons the parts in flight.
    """

    def __init__(self, tasks: Sequence[Task], backend: _Backend, handle: Handle, lost: Lost) -> None:
        self.backend, self.handle, self.lost = backend, handle, lost
        self.todo = [collections.deque(parts(t)) for t in tasks]
        self.fresh = collections.deque(range(len(tasks)))  # tasks none of whose parts has started
        self.started = [False] * len(tasks)
        self.busy = [0] * len(tasks)  # parts of each task in flight (0 or 1)
        self.deaths: dict[tuple[int, str], int] = {}  # (task, filter) -> deaths charged to that part
        self.suspects: collections.deque[tuple[int, Task]] = collections.deque()  # to run alone
        self.casualties: list[tuple[int, Task]] = []  # failed with the executor that broke
        self.flight: dict[cf.Future[TaskResult], tuple[int, Task]] = {}
        self.ready: collections.deque[tuple[Task, TaskResult]] = collections.deque()  # results to hand on
        self.status = ExecStatus()
        self.abandoned = False

    def run(self, stop: StopRequest) -> ExecStatus:
        """Run every part, or until ``stop`` is requested (then the parts in flight are abandoned)."""
        self.stop = stop
        executor: cf.Executor | None = None
        broken = alone = False
        try:
            while not stop.requested and (self.flight or self._left()):
                if executor is None:
                    alone = bool(self.suspects)
                    executor = self.backend.open(1 if alone else self.backend.slots)
                    broken = False
                if not broken:
                    broken = self._fill(executor, alone)
                done, _ = cf.wait(self.flight, timeout=_POLL_S, return_when=cf.FIRST_COMPLETED)
                for fut in done:
                    broken = self._finished(fut) or broken
                if done and not (broken or alone or self.backend.raise_now):
                    # the freed workers get their next parts before this process stores the results (work done
                    # here waits: a part run now would run before the finished ones are stored)
                    broken = self._fill(executor, alone)
                self._hand_on()
                if (broken or alone) and not self.flight:
                    self._blame(alone)
                    self.backend.close(executor, abandon=False)
                    executor = None
        except KeyboardInterrupt:  # raised by the stop request while a part ran in this process
            self.abandoned = True
        finally:
            if executor is not None:
                self.backend.close(executor, abandon=stop.requested)
        self.status.interrupted = stop.requested and (self.abandoned or bool(self.flight) or self._left())
        return self.status

    def _left(self) -> bool:
        return bool(self.suspects or self.casualties or any(self.todo))

    def _fill(self, executor: cf.Executor, alone: bool) -> bool:
        """Submit parts while a slot is free: a suspect when alone, else the next part (see the class); whether
        the executor refused one because it broke (its failed parts are then still to be seen)."""
        while len(self.flight) < (1 if alone else self.backend.slots):
            if alone:
                if not self.suspects:
                    return False
                i, part = self.suspects.popleft()
            else:
                nxt = self._next()
                if nxt is None:
                    return False
                i, part = nxt, self.todo[nxt].popleft()
            try:
                fut = executor.submit(execute_contained, part)
            except cf.BrokenExecutor:
                if alone:
                    self.suspects.appendleft((i, part))
                else:
                    self.todo[i].appendleft(part)
                return True
            self.busy[i] += 1
            self.flight[fut] = (i, part)
        return False

    def _next(self) -> int | None:
        """The task whose next part to submit: one started and idle (its worker freed), else a fresh one."""
        idle = (i for i, q in enumerate(self.todo) if q and not self.busy[i] and self.started[i])
        i = next(idle, None)
        if i is None and self.fresh:
            i = self.fresh.popleft()
            self.started[i] = True
        return i

    def _finished(self, fut: cf.Future[TaskResult]) -> bool:
        """Take a finished part's result (to hand on), its death or its failure; whether its executor broke."""
        i, part = self.flight.pop(fut)
        self.busy[i] -= 1
        if fut.cancelled():  # not by this loop (it cancels only when stopping): a dask result lost with its worker
            self._charge(i, part)
            return False
        exc = fut.exception()
        if exc is None:
            self.ready.append((part, fut.result()))
        elif self.backend.broken(exc):
            self.casualties.append((i, part))
            return True
        elif self.backend.died(exc):
            self._charge(i, part)
        else:
            with self.stop.shield():
                self.lost(part, f"worker failed: {type(exc).__name__}: {exc}")
        return False

    def _hand_on(self) -> None:
        """Hand the finished parts' results to the caller (which stores them), a signal waiting meanwhile."""
        with self.stop.shield():
            while self.ready:
                self.handle(*self.ready.popleft())

    def _blame(self, alone: bool) -> None:
        """After an executor broke: its one part is charged; several each run again alone, uncharged."""
        if len(self.casualties) == 1 or alone:
            for i, part in self.casualties:
                self._charge(i, part)
        else:
            self.suspects.extend(self.casualties)
        self.casualties.clear()

    def _charge(self, i: int, part: Task) -> None:
        who = (i, part.jobs[0].filter.name if part.jobs else "")
        times = self.deaths[who] = self.deaths.get(who, 0) + 1
        if times <= RETRIES:
            self.status.retried += 1
            self.todo[i].appendleft(part)
            return
        with self.stop.shield():
            self.lost(part, self.backend.death(times))


#: How often a pool worker's watchdog looks whether its parent is still alive, s.
_PARENT_POLL_S = 1.0


def _end_with_parent() -> None:
    """End this worker process when the process that started it dies, however it dies (kill -9 included).

    On Linux the kernel sends SIGKILL at the parent's death (``PR_SET_PDEATHSIG``); everywhere a daemon thread
    also polls the parent's pid (a dead parent's children are re-parented) and exits, as a fallback.
    """
    parent = os.getppid()
    if not die_with_parent(parent):  # the parent died before the request took effect
        os._exit(1)

    def watch() -> None:
        while True:
            time.sleep(_PARENT_POLL_S)
            if os.getppid() != parent:
                os._exit(1)

    threading.Thread(target=watch, name="locbench-parent-watchdog", daemon=True).start()


def _pool_worker_init() -> None:
    # Ctrl-C reaches the whole process group: only the parent decides what stops, and it kills the workers.
    signal.signal(signal.SIGINT, signal.SIG_IGN)
    signal.signal(signal.SIGTERM, signal.SIG_DFL)
    _end_with_parent()


@contextlib.contextmanager
def _sigint_deferred() -> Iterator[None]:
    """Block SIGINT in this thread while a LocalCluster starts, then unblock it: a Ctrl-C meanwhile is deferred.

    The cluster's threads are created here and its worker processes started from them, so they inherit the
    blocked signal (the group's Ctrl-C does not kill a worker: the parent decides, and kills them). A SIGINT
    that arrives meanwhile stays pending and reaches the :class:`StopRequest` handler at the unblock, so the
    sweep stops as soon as the cluster is up (an ignored signal would be dropped).
    """
    if threading.current_thread() is not threading.main_thread() or not hasattr(signal, "pthread_sigmask"):
        yield
        return
    old = signal.pthread_sigmask(signal.SIG_BLOCK, {signal.SIGINT})
    try:
        yield
    finally:
        signal.pthread_sigmask(signal.SIG_SETMASK, old)


#: Seconds to wait for a dask worker process to exit after its cluster closed, before it is killed.
_REAP_S = 10.0


def _worker_processes(cluster: Any) -> list[Any]:
    """``psutil.Process`` handles of a LocalCluster's worker processes (pid and start time: no pid reuse)."""
    import psutil

    procs = []
    for nanny in list(getattr(cluster, "workers", {}).values()):
        pid = getattr(nanny, "pid", None)
        if pid:
            with contextlib.suppress(psutil.Error):
                procs.append(psutil.Process(pid))
    return procs


def _reap(procs: list[Any]) -> None:
    """Wait until a closed cluster's worker processes have exited (a worker outlives its client by seconds),
    killing any still alive after :data:`_REAP_S`: nothing a sweep started outlives it."""
    if not procs:
        return
    import psutil

    _, alive = psutil.wait_procs(procs, timeout=_REAP_S)
    for proc in alive:
        with contextlib.suppress(psutil.Error):
            proc.kill()
    psutil.wait_procs(alive, timeout=_REAP_S)


def _kill_local_workers(cluster: Any) -> None:
    """Kill a LocalCluster's worker processes: closing waits for a running task to finish, killing does not."""
    for nanny in list(getattr(cluster, "workers", {}).values()):
        pid = getattr(nanny, "pid", None)
        if pid:
            with contextlib.suppress(OSError):
                os.kill(pid, signal.SIGKILL)


class _Dask(_Backend):
    """dask.distributed workers through the client's ``concurrent.futures`` executor (one for the sweep)."""

    def __init__(self, client: Any, slots: int) -> None:
        import distributed

        self.client, self.slots = client, slots
        self._killed = distributed.KilledWorker
        self._executor = client.get_executor(pure=False)

    def open(self, workers: int) -> cf.Executor:
        return self._executor  # a dask worker that dies is replaced: the executor never breaks

    def died(self, exc: BaseException) -> bool:
        return isinstance(exc, self._killed)

    def death(self, times: int) -> str:
        return f"its dask worker died each time it ran, {times} times (KilledWorker)"

    def close(self, executor: cf.Executor, abandon: bool) -> None:
        executor.shutdown(wait=not abandon)  # without wait it cancels the parts in flight
        if not abandon:
            with contextlib.suppress(Exception):
                self.client.run(forget_realisations)  # a remote worker keeps no dataset after the sweep


def run_dask(
    tasks: Sequence[Task],
    handle: Handle,
    lost: Lost,
    jobs: int = 1,
    scheduler: str | None = None,
    timeout_s: float = CONNECT_TIMEOUT_S,
) -> ExecStatus:
    """Run the tasks on dask.distributed workers: the scheduler at ``scheduler``, else a LocalCluster of ``jobs``.

    The parts go through :class:`_Schedule` as the local pool's do, one per worker thread at a time; the
    records come back to this process, which writes them. A worker that dies is replaced by dask, and its part
    is a ``KilledWorker`` error that the loop retries (a LocalCluster does not retry it itself:
    ``allowed-failures`` 0; a remote scheduler keeps its own setting); a part that raises is an error run. A
    scheduler that does not answer within ``timeout_s`` seconds is a :class:`ConfigError`.
    """
    try:
        import dask
        import distributed
    except ImportError:
        raise DependencyNotInstalled(
            "--executor dask needs dask.distributed; install it with: pip install 'locbench[dask]'"
        ) from None
    status = ExecStatus()
    if not tasks:
        return status
    cluster: Any = None
    workers: list[Any] = []
    if not log.isEnabledFor(logging.INFO):
        # distributed logs every connection at INFO; a sweep prints its own summary
        logging.getLogger("distributed").setLevel(logging.ERROR)
    with StopRequest(raise_now=False) as stop:
        with _sigint_deferred(), dask.config.set(_DASK_LOCAL_CONFIG):
            try:
                if scheduler is None:
                    cluster = distributed.LocalCluster(
                        n_workers=jobs,
                        threads_per_worker=1,
                        processes=True,
                        host="127.0.0.1",
                        # no fixed port: the scheduler's HTTP server (dashboard off) on a port the system picks
                        dashboard_address=":0",
                        scheduler_kwargs={"dashboard": False},
                        silence_logs=logging.CRITICAL,
                    )
                    workers = _worker_processes(cluster)
                    client = distributed.Client(cluster)
                else:
                    address = check_scheduler_address(scheduler)
                    probe_scheduler(address, timeout_s)
                    client = distributed.Client(address, timeout=f"{timeout_s}s")
            except (OSError, TimeoutError, ValueError) as exc:
                if cluster is not None:
                    with contextlib.suppress(Exception):
                        cluster.close()
                    _reap(workers)
                where = one_line(scheduler, 200) if scheduler else "a LocalCluster on 127.0.0.1"
                why = str(exc) or "no answer"
                raise ConfigError(
                    one_line(f"cannot reach the dask scheduler at {where} within {timeout_s:g} s: {why}")
                ) from None
        # a Ctrl-C deferred during the start arrived at the unblock above: the loop then submits nothing
        try:
            slots = jobs if cluster is not None else max(1, sum(client.nthreads().values()))
            status = _Schedule(tasks, _Dask(client, slots), handle, lost).run(stop)
        finally:
            with contextlib.suppress(Exception):
                client.close(timeout=2)
            if cluster is not None:
                if stop.requested:
                    _kill_local_workers(cluster)
                with contextlib.suppress(Exception):
                    cluster.close(timeout=3)
                _reap(workers)
    return status
