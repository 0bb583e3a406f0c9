"""Where a sweep's tasks run: this process, a local process pool, or dask.distributed workers.

Every executor takes the plan's tasks (longest first), runs :func:`locbench.runner.execute_task` on each
somewhere, and hands each result back to the caller, which writes the store in this process; so a dask
worker on another machine needs locbench installed but no shared folder. A task whose worker died or raised
is handed to ``lost`` with the reason, which records an error run for each of its filters, and the sweep goes
on. SIGINT (Ctrl-C) and SIGTERM stop an executor: tasks not started are cancelled, running ones abandoned
(their workers killed), and the executor returns within a few seconds saying it was interrupted.
"""

from __future__ import annotations

import asyncio
import concurrent.futures as cf
import contextlib
import ctypes
import dataclasses
import importlib.util
import ipaddress
import logging
import os
import re
import signal
import sys
import threading
import time
import types
import uuid
from collections.abc import Callable, Iterator, Sequence
from concurrent.futures.process import BrokenProcessPool
from dataclasses import dataclass
from typing import Any

from locbench.errors import ConfigError, DependencyNotInstalled, one_line
from locbench.runner import Task, TaskResult, execute_task

log = logging.getLogger(__name__)

Handle = Callable[[Task, TaskResult], None]
Lost = Callable[[Task, str], None]

#: Times a task is handed to a fresh local pool after the worker running it died (a crash, the OOM killer).
LOCAL_RETRIES = 1
#: dask's ``distributed.scheduler.allowed-failures`` for a LocalCluster: a task whose worker dies is retried
#: on another worker this many times, then it is a ``KilledWorker`` error (a remote scheduler keeps its own).
DASK_ALLOWED_FAILURES = 1
#: A LocalCluster's settings: the retries above; one task per worker thread at a time, so that a worker's death
#: is charged to the task it was running only (not to tasks queued behind it on that worker); no profiler.
_DASK_LOCAL_CONFIG = {
    "distributed.scheduler.allowed-failures": DASK_ALLOWED_FAILURES,
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
#: Times a one-filter task that dask gave up on (``KilledWorker``) is submitted again before it is an error run.
DASK_RESUBMITS = 2
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
    if jobs <= 1:
        return _run_inline(tasks, handle, lost)
    return _run_pool(tasks, handle, lost, jobs)


def _run_inline(tasks: Sequence[Task], handle: Handle, lost: Lost) -> ExecStatus:
    with StopRequest(raise_now=True) as stop:
        for n, task in enumerate(tasks):
            if stop.requested:
                return ExecStatus(interrupted=True)
            try:
                result = execute_task(task)
            except KeyboardInterrupt:
                return ExecStatus(interrupted=True)
            except Exception as exc:  # execute_task records a filter's or a dataset's failure itself: a bug
                with stop.shield():
                    lost(task, f"task failed: {type(exc).__name__}: {exc}")
                continue
            with stop.shield():
                handle(task, result)
            if stop.requested and n + 1 < len(tasks):
                return ExecStatus(interrupted=True)
    return ExecStatus()


#: How often a pool worker's watchdog looks whether its parent is still alive, s.
_PARENT_POLL_S = 1.0


def _end_with_parent() -> None:
    """End this worker process when the process that started it dies, however it dies (kill -9 included).

    On Linux the kernel sends SIGKILL at the parent's death (``PR_SET_PDEATHSIG``); everywhere a daemon thread
    also polls the parent's pid (a dead parent's children are re-parented) and exits, as a fallback.
    """
    parent = os.getppid()
    if sys.platform.startswith("linux"):
        with contextlib.suppress(OSError, AttributeError):
            libc = ctypes.CDLL(None, use_errno=True)
            libc.prctl(_PR_SET_PDEATHSIG, int(signal.SIGKILL), 0, 0, 0)
    if os.getppid() != parent or parent == 1:  # the parent died before the request above took effect
        os._exit(1)

    def watch() -> None:
        while True:
            time.sleep(_PARENT_POLL_S)
            if os.getppid() != parent:
                os._exit(1)

    threading.Thread(target=watch, name="locbench-parent-watchdog", daemon=True).start()


#: ``prctl`` option: the signal this process receives when its parent dies (linux/prctl.h).
_PR_SET_PDEATHSIG = 1


def _pool_worker_init() -> None:
    # Ctrl-C reaches the whole process group: only the parent decides what stops, and it kills the workers.
    signal.signal(signal.SIGINT, signal.SIG_IGN)
    signal.signal(signal.SIGTERM, signal.SIG_DFL)
    _end_with_parent()


def _kill_pool(pool: cf.ProcessPoolExecutor) -> None:
    """Kill the pool's worker processes (their tasks are abandoned; nothing of theirs is stored)."""
    kill = getattr(pool, "kill_workers", None)  # Python >= 3.14
    if callable(kill):
        kill()
        return
    for proc in list(getattr(pool, "_processes", {}).values()):
        with contextlib.suppress(Exception):
            proc.kill()


def split(task: Task) -> list[Task]:
    """One task per filter of ``task``: after its worker died, so that only the filter that kills it fails."""
    # the realisation's bound goes with the first part only
    return [
        dataclasses.replace(task, jobs=(job,), bound_key=task.bound_key if i == 0 else None)
        for i, job in enumerate(task.jobs)
    ]


def _run_pool(tasks: Sequence[Task], handle: Handle, lost: Lost, jobs: int) -> ExecStatus:
    status = ExecStatus()
    todo = list(tasks)
    deaths = [0] * len(todo)
    # A broken pool fails every task it holds and does not say whose worker died: a task that was running
    # beside others then runs again alone, where a death is its own, so a task is never blamed for a sibling's.
    alone = [False] * len(todo)
    queue = list(range(len(todo)))
    finished = 0
    with StopRequest(raise_now=False) as stop:
        while queue and not stop.requested:
            first_alone = next((i for i in queue if alone[i]), None)
            if first_alone is not None:
                batch = [first_alone]
                queue = [i for i in queue if i != first_alone]
            else:
                batch, queue = queue, []
            pool = cf.ProcessPoolExecutor(max_workers=min(jobs, len(batch)), initializer=_pool_worker_init)
            futures = {pool.submit(execute_task, todo[i]): i for i in batch}
            pending = set(futures)
            try:
                while pending and not stop.requested:
                    running = {f for f in pending if f.running()}
                    done, pending = cf.wait(pending, timeout=_POLL_S, return_when=cf.FIRST_COMPLETED)
                    for fut in done:
                        i = futures[fut]
                        try:
                            result = fut.result()
                        except BrokenProcessPool:
                            # Its own death only when it was alone in the pool or the only one running.
                            own = len(batch) == 1 or (fut in running and len(running) == 1)
                            if not own:
                                alone[i] = alone[i] or fut in running
                                queue.append(i)
                                continue
                            deaths[i] += 1
                            if deaths[i] <= LOCAL_RETRIES:
                                status.retried += 1
                                queue.append(i)
                            elif len(todo[i].jobs) > 1:
                                finished += 1
                                for part in split(todo[i]):
                                    queue.append(len(todo))
                                    todo.append(part)
                                    deaths.append(0)
                                    alone.append(False)
                            else:
                                why = f"its worker process died {deaths[i]} times (killed, or out of memory)"
                                with stop.shield():
                                    lost(todo[i], why)
                                finished += 1
                            continue
                        except Exception as exc:
                            with stop.shield():
                                lost(todo[i], f"worker failed: {type(exc).__name__}: {exc}")
                        else:
                            with stop.shield():
                                handle(todo[i], result)
                        finished += 1
            finally:
                if stop.requested:
                    _kill_pool(pool)
                pool.shutdown(wait=not stop.requested, cancel_futures=True)
            queue.sort()
    status.interrupted = stop.requested and finished < len(todo)
    return status


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


def run_dask(
    tasks: Sequence[Task],
    handle: Handle,
    lost: Lost,
    jobs: int = 1,
    scheduler: str | None = None,
    timeout_s: float = CONNECT_TIMEOUT_S,
) -> ExecStatus:
    """Run the tasks on dask.distributed workers: the scheduler at ``scheduler``, else a LocalCluster of ``jobs``.

    Each task is one dask task (longest first by priority); the records come back to this process, which
    writes them. A worker that dies is replaced and its task retried by dask (``allowed-failures`` times),
    then the task is a ``KilledWorker`` error run; a task that raises is an error run. A scheduler that does
    not answer within ``timeout_s`` seconds is a :class:`ConfigError`.
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
        run_id = uuid.uuid4().hex[:8]
        todo = list(tasks)
        futures: dict[Any, int] = {}

        def submit(i: int) -> Any:
            key = f"locbench-{run_id}-{i}"
            fut = client.submit(execute_task, todo[i], pure=False, priority=len(todo) - i, key=key)
            futures[fut] = i
            return fut

        resubmitted = [0] * len(todo)
        pending = {submit(i) for i in range(len(todo))}
        try:
            while pending and not stop.requested:
                with contextlib.suppress(TimeoutError, distributed.TimeoutError):
                    distributed.wait(list(pending), timeout=_POLL_S, return_when="FIRST_COMPLETED")
                for fut in [f for f in pending if f.done()]:
                    pending.discard(fut)
                    i = futures[fut]
                    error: BaseException | None = None
                    # retryable: the worker died (KilledWorker) or the result was lost with it, not the task failed
                    retryable = fut.status != "error"
                    if fut.status == "finished":
                        try:
                            # a result held by a worker that died since is recomputed: wait for it in the next round
                            result = fut.result(timeout=_POLL_S)
                        except (TimeoutError, distributed.TimeoutError):
                            pending.add(fut)
                            continue
                        except Exception as exc:
                            error = exc
                        else:
                            with stop.shield():
                                handle(todo[i], result)
                            continue
                    else:
                        error = fut.exception() if fut.status == "error" else None
                    killed = isinstance(error, distributed.KilledWorker)
                    if (killed or retryable) and (len(todo[i].jobs) > 1 or resubmitted[i] < DASK_RESUBMITS):
                        # A task with several filters is split, one per filter, to find the one that kills its
                        # worker; a single one is submitted again, since a task whose worker was killed by
                        # another task's crash (holding its result) can be charged that death too.
                        status.retried += 1
                        parts = split(todo[i]) if len(todo[i].jobs) > 1 else [todo[i]]
                        for part in parts:
                            todo.append(part)
                            resubmitted.append(resubmitted[i] + (len(parts) == 1))
                            pending.add(submit(len(todo) - 1))
                        continue
                    if killed:
                        reason = "its dask worker died each time it ran (KilledWorker)"
                    elif error is not None:
                        reason = f"worker failed: {type(error).__name__}: {error}"
                    else:
                        reason = f"dask task {fut.status}"
                    with stop.shield():
                        lost(todo[i], reason)
        finally:
            status.interrupted = bool(pending) and stop.requested
            with contextlib.suppress(Exception):
                client.cancel(list(pending), force=True)
            with contextlib.suppress(Exception):
                client.close(timeout=2)
            if cluster is not None:
                if status.interrupted:
                    _kill_local_workers(cluster)
                with contextlib.suppress(Exception):
                    cluster.close(timeout=3)
                _reap(workers)
    return status
