"""Wall time of ``locbench run`` under each executor, and the time Ctrl-C takes to return.

Each configuration runs the same sweep into a fresh results folder (nothing cached), ``--repeat`` times
in turn (A B C A B C ...) so that a drift of the machine's speed touches every configuration alike;
the script prints the median wall time of each and its ratio to the first. With ``--interrupt-after S``
it instead starts the sweep, sends SIGINT after S seconds and prints how long the command took to exit
and its status (130 expected).

    python tools/measure/sweep_timing.py --suite default --seeds 2 --repeat 3
    python tools/measure/sweep_timing.py --suite default --interrupt-after 20 --repeat 3 --config local:2 dask:2

A configuration is ``EXECUTOR:JOBS`` (``local:1``, ``local:2``, ``dask:2``). The machine must be otherwise
idle for the ratios to mean anything; the script prints the load average before and after.
"""

from __future__ import annotations

import argparse
import os
import shutil
import signal
import statistics
import subprocess
import sys
import tempfile
import time


def _command(config: str, suite: str, seeds: int | None, results: str) -> list[str]:
    executor, jobs = config.split(":")
    cmd = [sys.executable, "-m", "locbench.cli", "run", "--suite", suite, "--results", results, "--no-progress"]
    cmd += ["--executor", executor, "--jobs", jobs]
    return cmd + (["--seeds", str(seeds)] if seeds else [])


def _wall(cmd: list[str]) -> float:
    start = time.perf_counter()
    subprocess.run(cmd, check=True, stdout=subprocess.DEVNULL)
    return time.perf_counter() - start


def _interrupt(cmd: list[str], after_s: float) -> tuple[float, int]:
    proc = subprocess.Popen(cmd, stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL)
    time.sleep(after_s)
    sent = time.perf_counter()
    proc.send_signal(signal.SIGINT)
    code = proc.wait(timeout=600)
    return time.perf_counter() - sent, code


def main() -> int:
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("--suite", default="default")
    p.add_argument("--seeds", type=int, default=None)
    p.add_argument("--repeat", type=int, default=3)
    p.add_argument("--config", nargs="+", default=["local:1", "local:2", "dask:2"])
    p.add_argument("--interrupt-after", type=float, default=None, metavar="S")
    args = p.parse_args()
    print(f"load average before: {os.getloadavg()}")
    times: dict[str, list[float]] = {c: [] for c in args.config}
    for _ in range(args.repeat):
        for config in args.config:
            results = tempfile.mkdtemp(prefix="locbench-timing-")
            try:
                cmd = _command(config, args.suite, args.seeds, results)
                if args.interrupt_after is None:
                    times[config].append(_wall(cmd))
                else:
                    seconds, code = _interrupt(cmd, args.interrupt_after)
                    print(f"{config}: Ctrl-C to exit {seconds:.2f} s, status {code}")
                    times[config].append(seconds)
            finally:
                shutil.rmtree(results, ignore_errors=True)
    first = statistics.median(times[args.config[0]])
    what = "Ctrl-C to exit" if args.interrupt_after is not None else "wall"
    for config, ts in times.items():
        med = statistics.median(ts)
        runs = ", ".join(f"{t:.1f}" for t in ts)
        print(f"{config}: median {what} {med:.2f} s ({runs}); ratio to {args.config[0]}: {med / first:.3f}")
    print(f"load average after: {os.getloadavg()}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
