"""nox sessions for locbench.

nox                 the tests (the default session)
nox -s tests_busy   the sweep, executor and signal tests (with the slow ones); .ci/run runs it with both cores busy
nox -s tests_dispatch  the numeric tests on other numpy, OpenBLAS and numba kernels than the machine's default
nox -s lint         ruff, mypy and the import contracts (lint-imports)
nox -s docs         the documentation site, warnings as errors, into docs/_build/html
nox -s bench        run every experiment, verify a sample, write results/summary (posargs go to 'locbench run')
nox -s report       regenerate results/summary from the stored runs, no re-run
nox -s html         open the site in results/summary in headless Chromium (renders, links, sorts; screenshot)
nox -s perf         pytest-benchmark micro-benchmarks of each filter's predict and update
nox -s fuzz         the loader, store-reader and CLI fuzzing with the long hypothesis profile (posargs go to pytest)
"""

from __future__ import annotations

import json
import os
import shutil

import nox

nox.needs_version = ">=2024.3.2"
# uv makes each session's environment in seconds where pip takes minutes (the same pinned versions, from the same
# constraints); without uv on the machine, the standard library's venv and pip
nox.options.default_venv_backend = "uv|venv"
nox.options.sessions = ["tests"]
nox.options.reuse_existing_virtualenvs = True

PYTHON = "3.11"
CONSTRAINTS = ("-c", "constraints.txt")


#: Where the recorded datasets lie when LOCBENCH_DATA is not set: ../shared/datasets beside the checkout, if present.
_SHARED_DATA = os.path.join(os.path.dirname(os.path.abspath(__file__)), os.pardir, "shared", "datasets")


def _data_env() -> dict[str, str]:
    """LOCBENCH_DATA for the session: the caller's, else ../shared/datasets when it exists, else empty (skips)."""
    data = os.environ.get("LOCBENCH_DATA") or (os.path.normpath(_SHARED_DATA) if os.path.isdir(_SHARED_DATA) else "")
    return {"LOCBENCH_DATA": data}


_HERE = os.path.dirname(os.path.abspath(__file__))
#: numba's on-disk cache of compiled kernels for the sessions that run filters (bench, tune), outside their
#: environments: a reinstall deletes the package's folders, and with them numba's default cache beside the modules.
KERNEL_CACHE = os.path.join(_HERE, ".nox", "numba-cache")
#: The source folder of each installed subpackage (pyproject's package-dir); the rest of the package is bench/.
_PACKAGE_DIRS = ("filters", "datasets")


def _install(session: nox.Session, extras: str) -> None:
    # A regular (non-editable) install: the tests import the installed package, as users do. setuptools builds
    # in ./build and never deletes a module that left the source tree, so a stale copy (a moved or renamed module)
    # would be installed beside its successor: build from nothing.
    shutil.rmtree(os.path.join(_HERE, "build"), ignore_errors=True)
    session.install(*CONSTRAINTS, f".[{extras}]")
    _keep_source_times(session)


def _keep_source_times(session: nox.Session) -> None:
    """Give each installed module its source file's modification time where their bytes are the same.

    numba keeps a compiled kernel (``cache=True``) while its module's time and size are unchanged; an install
    stamps every file with the install's time, so every bench compiled every kernel again, 2-3 minutes of its
    start on two cores. With the source's time (and :data:`KERNEL_CACHE`), only a changed module's kernels are.
    """
    out = session.run("python", "-c", "import locbench, os; print(os.path.dirname(locbench.__file__))", silent=True)
    if not isinstance(out, str):  # nox --install-only and dry runs run nothing
        return
    root = out.strip().splitlines()[-1]
    for folder, _, names in os.walk(root):
        for name in names:
            if not name.endswith(".py"):
                continue
            installed = os.path.join(folder, name)
            rel = os.path.relpath(installed, root)
            top = rel.split(os.sep, 1)[0]
            source = os.path.join(_HERE, rel) if top in _PACKAGE_DIRS else os.path.join(_HERE, "bench", rel)
            try:
                with open(installed, "rb") as a, open(source, "rb") as b:
                    same = a.read() == b.read()
                if same:
                    st = os.stat(source)
                    os.utime(installed, ns=(st.st_atime_ns, st.st_mtime_ns))
            except OSError:  # a generated module without a source file keeps the install's time
                continue


def _kernel_env() -> dict[str, str]:
    """The environment of a session that runs filters: the data, and numba's cache outside the environment."""
    return {**_data_env(), "NUMBA_CACHE_DIR": KERNEL_CACHE}


#: The example filter plugin (README "Writing a filter plugin"), installed into the test session.
EXAMPLE_PLUGIN = "./examples/locbench-iterated-ekf-plugin"


@nox.session(python=PYTHON)
def tests(session: nox.Session) -> None:
    """Run the test suite (recorded-data tests read $LOCBENCH_DATA and skip without it); with Stone Soup, so
    that the bound's recursion is compared with its PCRB metric, and with the example plugin package."""
    _install(session, "all,test,stonesoup")
    # the tutorials install with pip, as their readers do; an environment made by uv has none of its own
    session.install(*CONSTRAINTS, "pip")
    # the example plugin package, so that tests/run/test_plugin_example.py checks the entry-point path (without it
    # that file skips); --no-deps: locbench is the checkout's, never an index's
    session.install("--no-deps", EXAMPLE_PLUGIN)
    session.run("pytest", "--benchmark-disable", *session.posargs, env=_data_env())


#: The tests that race the machine (executors, Ctrl-C, child processes, dask's ports): run again under load by CI.
BUSY_TESTS = (
    "tests/run/test_sweep.py",
    "tests/run/test_execute.py",
    "tests/run/test_store.py",
    "tests/malformed/test_untrusted_inputs.py",
)
#: The dask signal tests among the slow ones (a LocalCluster's start is where a Ctrl-C used to be dropped).
BUSY_DASK = "dask and (ctrl_c or sigint or no_process)"


@nox.session(python=PYTHON, default=False)
def tests_busy(session: nox.Session) -> None:
    """The sweep, executor and signal tests, and the dask signal tests (.ci/run keeps both cores busy meanwhile)."""
    _install(session, "all,test")
    common = ("pytest", "--benchmark-disable", "-p", "no:cacheprovider")
    session.run(*common, "-m", "not slow", *(session.posargs or BUSY_TESTS), env=_data_env())
    session.run(*common, "-m", "slow", "-k", BUSY_DASK, "tests/run/test_sweep.py", env=_data_env())


#: The numeric tests: every comparison with numpy, OpenBLAS, LAPACK, scipy, filterpy, gtsam or Stone Soup (filters,
#: kernels, metrics, scores, bound, ray casting, datasets), led by the check that the dispatch below took effect.
DISPATCH_TESTS = (
    "tests/test_cpu_dispatch.py",
    "tests/filters/test_ukf_kernels.py",
    "tests/filters/test_ukf_landmarks.py",
    "tests/filters/test_kf_linear.py",
    "tests/filters/test_kalman.py",
    "tests/filters/test_ekf_landmarks.py",
    "tests/filters/test_ekf_lines.py",
    "tests/filters/test_ekf_icp.py",
    "tests/filters/test_pf.py",
    "tests/filters/test_gtsam_fls.py",
    "tests/filters/test_odometry_filter.py",
    "tests/filters/test_motion.py",
    "tests/filters/test_line_extraction.py",
    "tests/filters/test_scan_database.py",
    "tests/filters/test_landmark_index.py",
    "tests/raycast/test_raycast.py",
    "tests/datasets/synthetic/test_scan_grid.py",
    "tests/evaluate/test_metrics.py",
    "tests/evaluate/test_scores.py",
    "tests/report/test_kidnap_metrics.py",
    "tests/evaluate/test_lost.py",
    "tests/evaluate/test_pcrb.py",
    "tests/evaluate/test_pcrb_stonesoup.py",
    "tests/report/test_bound_rows.py",
    "tests/report/test_health_rows.py",
    "tests/evaluate/test_aggregate.py",
    "tests/evaluate/test_significance.py",
    "tests/datasets/synthetic/test_synthetic.py",
    "tests/datasets/synthetic/test_line_room.py",
    "tests/datasets/synthetic/test_landmark_geometry.py",
    "tests/datasets/synthetic/test_matched.py",
    "tests/datasets/recorded/test_textlog.py",
    "tests/report/test_recorded_scores.py",
    "tests/datasets/recorded/test_recorded_lost_in_the_woods.py",
    "tests/datasets/recorded/test_recorded_mrclam.py",
    "tests/datasets/recorded/test_recorded_plaza.py",
    "tests/datasets/recorded/test_recorded_librsf.py",
)
#: Kernels other than a current x86-64 CPU's default: numpy without its X86_V3/X86_V4 loops (AVX2, FMA3, AVX-512:
#: the SSE4.2 baseline), OpenBLAS's Katmai kernels (plain C, they run on every x86-64 CPU; their sums round unlike
#: Haswell's and SkylakeX's), numba compiling for a generic x86-64. tests/test_cpu_dispatch.py fails when numpy or
#: OpenBLAS did not take the setting, so the session cannot pass on the default dispatch unnoticed.
DISPATCH_ENV = {
    "NPY_DISABLE_CPU_FEATURES": "X86_V3 X86_V4 AVX512_ICL AVX512_SPR",
    "OPENBLAS_CORETYPE": "Katmai",
    "NUMBA_CPU_NAME": "generic",
}


@nox.session(python=PYTHON, default=False)
def tests_dispatch(session: nox.Session) -> None:
    """The numeric tests with numpy's, OpenBLAS's and numba's CPU dispatch changed (:data:`DISPATCH_ENV`): what
    compares with another library must hold on any CPU, not only this one (docs/design.md, "Reproducibility")."""
    _install(session, "all,test,stonesoup")
    session.run(
        "pytest", "--benchmark-disable", "-p", "no:cacheprovider", "-m", "not slow", "-rs",
        *(session.posargs or DISPATCH_TESTS), env={**_data_env(), **DISPATCH_ENV},
    )  # fmt: skip


@nox.session(python=PYTHON, default=False)
def tests_lowest(session: nox.Session) -> None:
    """The tests against the lower bounds of every dependency (gtsam-free: its extra has one release)."""
    session.install("-c", "constraints-lowest.txt", ".[filterpy,test]", "pip")  # pip: as in tests
    session.run("pytest", "--benchmark-disable", *session.posargs, env=_data_env())


@nox.session(python=PYTHON, default=False)
def lint(session: nox.Session) -> None:
    """ruff (lint and format check), mypy over the package and the import contracts of pyproject.toml."""
    _install(session, "all,lint")
    session.run("ruff", "check", ".")
    session.run("ruff", "format", "--check", ".")
    session.run("mypy", "-p", "locbench")
    session.run("lint-imports")


@nox.session(python=PYTHON, default=False)
def bench(session: nox.Session) -> None:
    """Run suites 'all', 'consistency' and 'tuned' (the committed tuned configurations of results/tuning, written
    by 'nox -s tune', run on their test data), verify a sample of the stored runs and of the tuning trials
    (``locbench verify``) and write results/summary; with 'locbench run' arguments after --, a sub-suite into
    results/custom (never over the committed results/summary)."""
    _install(session, "all")
    # interleaved timing (docs/protocols.md, Runtime): a busy moment slows every configuration of a task alike
    args = list(session.posargs) or ["--suite", "all", "consistency", "tuned", "--jobs", "2", "--interleave"]
    results = "results" if not session.posargs else "results/custom"
    if "--results" in args:
        results = args[args.index("--results") + 1]
        args = [a for i, a in enumerate(args) if a != "--results" and (i == 0 or args[i - 1] != "--results")]
    if session.posargs and os.path.abspath(results) == os.path.abspath("results"):
        session.error("a sub-suite must not overwrite results/summary (suite 'all'): pass another --results DIR")
    session.run("locbench", "run", "--results", results, *args, env=_kernel_env())
    suites: list[str] = []
    if "--suite" in args:
        for a in args[args.index("--suite") + 1 :]:
            if a.startswith("-"):
                break
            suites.append(a)
    jobs = args[args.index("--jobs") + 1] if "--jobs" in args else "1"
    # re-run 2 % of the stored runs (at least one per filter) with the sweep's processes and check them bit for
    # bit; the report shows it (a failure still writes the report, whose provenance says so, then fails the session)
    session.run("locbench", "verify", "--results", results, "--jobs", jobs, env=_kernel_env(), success_codes=[0, 1])
    # the report reads the runs and draws the figures with the sweep's processes
    session.run(
        "locbench",
        "report",
        "--results",
        results,
        "--jobs",
        jobs,
        *(["--suite", *suites] if suites else []),
        env=_kernel_env(),
    )
    record = os.path.join(results, "verify.json")
    with open(record, encoding="utf-8") as fh:
        if not json.load(fh).get("passed"):
            session.error(f"locbench verify failed: re-run runs differ from the stored ones (see {record})")


@nox.session(python=PYTHON, default=False)
def tune(session: nox.Session) -> None:
    """Tune every study of suite 'tuned' on its train data (each tunable filter on each world and MRCLAM fold, the
    same budget) and write the journals and results/tuning/tuned.json, which are committed and which 'nox -s bench'
    runs on test data. Arguments after -- go to 'locbench tune --suite' (e.g. --executor dask --scheduler FILE)."""
    _install(session, "all")
    args = list(session.posargs) or ["--jobs", "2"]
    session.run("locbench", "tune", "--suite", "--results", "results", *args, env=_kernel_env())


@nox.session(python=PYTHON, default=False)
def report(session: nox.Session) -> None:
    """Regenerate results/summary (the site, its figures, metrics.parquet) from the stored runs of suites 'all',
    'consistency' and 'tuned'."""
    _install(session, "all")
    session.run("locbench", "report", "--results", "results", "--jobs", "2", "--suite", "all", "consistency", "tuned")


@nox.session(python=PYTHON, default=False)
def html(session: nox.Session) -> None:
    """Open every page of the site in results/summary in headless Chromium: each renders with no console error and
    every link resolves; the landing page's decision table sorts; screenshot of it to results/summary/index.png."""
    _install(session, "all,test")
    env = {
        "LOCBENCH_REPORT_PAGE": os.path.abspath("results/summary/index.html"),
        "LOCBENCH_SCREENSHOTS": os.path.abspath("results/summary"),
    }
    session.run(
        "pytest", "--benchmark-disable", "tests/report/test_report.py", "-k", "html", "-p", "no:cacheprovider", env=env
    )


@nox.session(python=PYTHON, default=False)
def perf(session: nox.Session) -> None:
    """pytest-benchmark micro-benchmarks: predict/update per filter, ray casting, particle throughput."""
    _install(session, "all,test")
    session.run(
        "pytest",
        "tests/perf",
        "--benchmark-only",
        "--benchmark-columns=min,median,mean,iqr,ops,rounds",
        "--benchmark-sort=name",
        *session.posargs,
    )


@nox.session(python=PYTHON, default=False)
def fuzz(session: nox.Session) -> None:
    """Fuzz every recorded-data loader, the store's readers and the CLI's arguments with the long hypothesis profile
    (the tests session runs the short one)."""
    _install(session, "all,test")
    args = session.posargs or ["--hypothesis-profile=fuzz", "--hypothesis-show-statistics"]
    fuzzed = ("tests/fuzz/",)
    session.run("pytest", "--benchmark-disable", "-p", "no:cacheprovider", *fuzzed, *args)


@nox.session(python=PYTHON, default=False)
def docs(session: nox.Session) -> None:
    """Build the documentation site from docs/ with every warning an error (docs/_build/html/index.html)."""
    _install(session, "all,docs")
    session.run("sphinx-build", "-W", "--keep-going", "-b", "html", "docs", "docs/_build/html", *session.posargs)
