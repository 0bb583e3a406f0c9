"""Property-based fuzzing of the store's readers and of the CLI's arguments.

Store readers: for any mutation of a stored run (``estimates.npz`` bytes, ``meta.json`` text, or arrays and record
fields rewritten with valid checksums, so that the shape contracts are what is tested), truth or bound, reading
either succeeds with a record that satisfies its contract or raises :class:`~locbench.run.store.StaleRecord` /
:class:`~locbench.core.errors.ConfigError` with a one-line message of bounded length. Any other exception fails.

CLI: random argument lists for ``locbench run/report/verify/tune/list`` built from the real option names (read from
the parser) and random values end with exit code 0, 1 or 2, no traceback and at most one error line on stderr.
Nothing real runs: ``run`` and ``tune`` always get a non-empty folder without the ``.locbench`` mark as
``--results`` (refused before anything runs or is written), ``report`` and ``verify`` a missing, empty or foreign
one (no stored runs), and ``--help`` / ``--version`` are never drawn.

The ``ci`` hypothesis profile (conftest.py) keeps the module short; ``nox -s fuzz`` runs the ``fuzz`` profile.
"""

from __future__ import annotations

import argparse
import itertools
import json
import os
import shutil
import tempfile
from pathlib import Path
from typing import Any

import numpy as np
import pytest
from hypothesis import HealthCheck, example, given, settings
from hypothesis import strategies as st

from locbench.cli import build_parser, main
from locbench.core.errors import MAX_MESSAGE_CHARS, ConfigError
from locbench.datasets.dataset import Trajectory2D
from locbench.evaluate.records import BoundRecord, RunRecord, TruthRecord
from locbench.run import store as store_mod
from locbench.run.store import StaleRecord, Store

_COUNTER = itertools.count()
N = 4


@pytest.fixture(scope="module")
def base(tmp_path_factory: pytest.TempPathFactory) -> Path:
    return tmp_path_factory.mktemp("fuzz-store-cli")


def _fresh_store(base: Path) -> Store:
    """A new store per example holding one run, one truth and one bound (the readers cache nothing, but a fresh
    folder keeps the examples independent)."""
    st_ = Store(Path(tempfile.mkdtemp(prefix=f"ex{next(_COUNTER)}-", dir=base)))
    meta = {"dataset": "room", "filter": "odometry", "seed": 0, "run_key": "k", "status": "ok", "n_rows": N}
    st_.write_run(
        RunRecord(
            meta,
            np.arange(N, dtype=float),
            np.ones((N, 3)),
            np.tile(np.eye(3), (N, 1, 1)),
            np.zeros(N, np.int8),
            np.zeros(N, np.int64),
            {"nis": np.ones(N)},
        )
    )
    t = np.arange(3.0)
    st_.write_truth(TruthRecord("room", 0, Trajectory2D(t, np.zeros((3, 2)), np.zeros(3)), None, (), 2.0))
    st_.write_bound(BoundRecord("room", 0, t, {"pcrb": np.tile(np.eye(3), (3, 1, 1))}, {"bound_key": "b"}))
    return st_


def _clean_error(exc: BaseException) -> None:
    assert isinstance(exc, (StaleRecord, ConfigError)), f"{type(exc).__name__}: {exc}"
    message = str(exc)
    assert message and "\n" not in message and len(message) <= MAX_MESSAGE_CHARS, message


def _read_all(st_: Store) -> None:
    """Read the run, truth and bound; each either passes its contract or is a clean error."""
    try:
        rec = st_.read_run(st_.run_dir("room", "odometry", 0))
    except Exception as exc:
        _clean_error(exc)
    else:
        arrays = {"t": rec.t, "mean": rec.mean, "cov": rec.cov, "kind": rec.kind, "step_ns": rec.step_ns}
        arrays |= {f"diag_{k}": v for k, v in rec.diagnostics.items()}
        assert store_mod.run_problem(rec.meta, arrays) is None
        assert st_.unreadable("room", "odometry", 0) is None
    try:
        truth = st_.read_truth("room", 0)
    except Exception as exc:
        _clean_error(exc)
    else:
        gt = truth.ground_truth
        assert gt.t.shape == gt.theta.shape == gt.xy.shape[:1] and np.all(np.isfinite(gt.xy))
        assert np.all(np.diff(gt.t) >= 0) and np.isfinite(truth.duration_s)
        assert st_.truth_problem("room", 0) is None
    try:
        bound = st_.read_bound("room", 0)
    except Exception as exc:
        _clean_error(exc)
    else:
        assert bound is not None
        assert all(c.shape == (bound.t.shape[0], 3, 3) for c in bound.covs.values())
        assert len(bound.covs) == len(bound.meta["rows"])
    st_.bound_key("room", 0)  # never raises


def _files(st_: Store) -> list[Path]:
    run = st_.run_dir("room", "odometry", 0)
    truth, bound = st_.truth_path("room", 0), st_.bound_path("room", 0)
    return [
        run / "estimates.npz",
        run / "meta.json",
        truth,
        truth.with_suffix(".json"),
        bound,
        bound.with_suffix(".json"),
    ]


# --- store: raw bytes ----------------------------------------------------------------------------------------

#: Signatures of a zip's local file header, central directory entry and end of central directory.
_ZIP_SIGNATURES = (b"PK\x03\x04", b"PK\x01\x02", b"PK\x05\x06")


@given(
    which=st.integers(0, 5),
    edits=st.lists(st.tuples(st.floats(0, 1, exclude_max=True), st.binary(min_size=0, max_size=8)), max_size=4),
    cut=st.one_of(st.none(), st.floats(0, 1)),
    header=st.lists(st.tuples(st.sampled_from(_ZIP_SIGNATURES), st.integers(0, 45), st.integers(0, 255)), max_size=3),
)
@example(which=0, edits=[], cut=None, header=[(b"PK\x01\x02", 10, 99)])  # unknown compression method
@example(which=0, edits=[], cut=None, header=[(b"PK\x01\x02", 8, 1)])  # "encrypted" member
@example(which=4, edits=[], cut=None, header=[(b"PK\x05\x06", 10, 255)])  # member count of the directory
def test_mutated_bytes_never_crash_a_reader(
    base: Path, which: int, edits: list[tuple[float, bytes]], cut: Any, header: list[tuple[bytes, int, int]]
) -> None:
    """Overwrite, insert or truncate bytes of one stored file (npz or JSON record), or one byte of a zip header
    field (local, central directory, end of directory: compression method, flags, sizes, offsets)."""
    st_ = _fresh_store(base)
    path = _files(st_)[which]
    data = bytearray(path.read_bytes())
    for signature, offset, byte in header:
        i = data.find(signature)
        if i >= 0 and i + offset < len(data):
            data[i + offset] = byte
    for where, chunk in edits:
        i = int(where * len(data))
        data[i : i + len(chunk) // 2] = chunk  # replaces half as many bytes as it writes: a mix of both
    if cut is not None:
        data = data[: int(cut * len(data))]
    path.write_bytes(bytes(data))
    _read_all(st_)
    shutil.rmtree(st_.root, ignore_errors=True)


# --- store: resealed records (valid checksums, contracts under test) ------------------------------------------

_NUMBERS = st.one_of(
    st.floats(allow_nan=True, allow_infinity=True), st.integers(-(2**63), 2**63 - 1), st.sampled_from([0, -1, 1e300])
)
_JSON = st.recursive(
    st.one_of(
        st.none(),
        st.booleans(),
        _NUMBERS.filter(lambda v: not isinstance(v, float) or np.isfinite(v)),
        st.text(max_size=20),
    ),
    lambda kids: st.one_of(st.lists(kids, max_size=3), st.dictionaries(st.text(max_size=8), kids, max_size=3)),
    max_leaves=8,
)
_DTYPES = st.sampled_from(["f8", "f4", "i8", "i1", "u1", "b1", "c16", "U3", "M8[s]"])


@st.composite
def _array(draw: st.DrawFn) -> np.ndarray:
    shape = tuple(draw(st.lists(st.integers(0, 5), max_size=3)))
    dtype = np.dtype(draw(_DTYPES))
    size = int(np.prod(shape))
    if dtype.kind in "fc":
        values = draw(st.lists(st.floats(allow_nan=True, allow_infinity=True), min_size=size, max_size=size))
    elif dtype.kind in "iub":
        values = draw(st.lists(st.integers(-128, 127), min_size=size, max_size=size))
    else:
        values = [0] * size
    with np.errstate(all="ignore"):
        if dtype.kind in "UM":
            return np.zeros(shape, dtype)
        return np.array(values, dtype=np.float64 if dtype.kind in "fc" else np.int64).astype(dtype).reshape(shape)


def _reseal(npz: Path, record: Path, arrays: dict[str, np.ndarray], meta: dict[str, Any]) -> None:
    """Write ``arrays`` and ``meta`` with the checksums the store would write (its own writer's functions)."""
    np.savez_compressed(npz, **arrays)  # type: ignore[arg-type]
    sealed = store_mod._sealed(meta | {"files": {npz.name: store_mod.npz_digest(npz)}})
    record.write_text(json.dumps(sealed))


@given(
    which=st.integers(0, 2),
    drop=st.lists(st.integers(0, 20), max_size=2),
    replace=st.lists(st.tuples(st.integers(0, 20), _array()), max_size=3),
    fields=st.dictionaries(
        st.sampled_from(["dataset", "filter", "seed", "run_key", "status", "n_rows", "rows", "bound_key", "files"]),
        st.one_of(_JSON, st.sampled_from(["ok", "error", "room", "odometry", 0, 4, ["pcrb"]])),
        max_size=3,
    ),
    drop_fields=st.lists(st.sampled_from(["dataset", "filter", "seed", "run_key", "status", "rows"]), max_size=2),
)
def test_resealed_records_are_checked_by_their_contract(
    base: Path,
    which: int,
    drop: list[int],
    replace: list[tuple[int, np.ndarray]],
    fields: dict[str, Any],
    drop_fields: list[str],
) -> None:
    """Arrays dropped or replaced (any dtype and shape, NaN, inf) and record fields changed, checksums rewritten."""
    st_ = _fresh_store(base)
    npz, record = _files(st_)[2 * which : 2 * which + 2]
    meta = json.loads(record.read_text())
    with np.load(npz) as z:
        arrays = {k: z[k] for k in z.files}
    names = sorted(arrays)
    for i in drop:
        arrays.pop(names[i % len(names)], None)
    for i, a in replace:
        arrays[names[i % len(names)]] = a
    meta = {k: v for k, v in meta.items() if k not in drop_fields and k != "meta_sha256"} | fields
    files = meta.pop("files", None)
    _reseal(npz, record, arrays, meta)
    if "files" in fields:  # a record whose own files entry is what is fuzzed
        sealed = store_mod._sealed(meta | {"files": files})
        record.write_text(json.dumps(sealed))
    _read_all(st_)
    shutil.rmtree(st_.root, ignore_errors=True)


# --- CLI ------------------------------------------------------------------------------------------------------

COMMANDS = ("run", "report", "verify", "tune", "list")


def _options(command: str) -> dict[str, argparse.Action]:
    """The real options of a subcommand, by name, from the parser (help and version excluded)."""
    parser = build_parser()
    sub = next(a for a in parser._actions if isinstance(a, argparse._SubParsersAction))
    return {
        s: a
        for a in sub.choices[command]._actions
        for s in a.option_strings
        if s.startswith("--") and not isinstance(a, (argparse._HelpAction, argparse._VersionAction))
    }


OPTIONS = {c: sorted(_options(c)) for c in COMMANDS}


@pytest.fixture(scope="module")
def paths(base: Path) -> dict[str, str]:
    """Inputs the values are drawn from: folders of each kind, a FIFO, a small suite file."""
    foreign = base / "foreign"
    foreign.mkdir()
    (foreign / "notes.txt").write_text("another tool's file\n")
    (base / "empty").mkdir()
    fifo = base / "fifo.toml"
    os.mkfifo(fifo)
    suite = base / "s.toml"
    suite.write_text('filters = ["odometry"]\ndatasets = ["room"]\nseeds = 2\n')
    return {
        "foreign": str(foreign),
        "empty": str(base / "empty"),
        "missing": str(base / "missing"),
        "fifo": str(fifo),
        "suite": str(suite),
    }


_WORDS = st.sampled_from(
    [
        "odometry", "pf", "ekf", "room", "lap", "smoke", "tuned", "default", "pf[particles=10]", "room[seeds=1]",
        "dask", "local", "ate", "nll", "tcp://", "tcp://[::1", "inproc://", "ucx://h:1", "http://x:1", "", "-", "--",
        "0", "1", "2", "-1", "10001", "1e9", str(2**64), "0.5", "nan", "inf", "-inf", "/dev/zero",
    ]
)  # fmt: skip


@st.composite
def _argv(draw: st.DrawFn, paths: dict[str, str]) -> list[str]:
    command = draw(st.sampled_from(COMMANDS))
    names = OPTIONS[command]
    path_values = st.sampled_from([paths["fifo"], paths["suite"], paths["missing"], paths["empty"]])
    value = st.one_of(_WORDS, path_values, st.text(max_size=30), st.integers(-5, 20_000).map(str))
    argv = [command]
    for _ in range(draw(st.integers(0, 6))):
        kind = draw(st.integers(0, 3))
        if kind == 0 and names:
            argv.append(draw(st.sampled_from(names)))
        elif kind == 1 and names:
            argv += [draw(st.sampled_from(names)), draw(value)]
        else:
            argv.append(draw(value))
    # the last --results wins: run and tune always meet a folder they must refuse, so nothing ever runs
    if command in ("run", "tune"):
        argv += ["--results", paths["foreign"]]
    elif command in ("report", "verify"):
        argv += ["--results", paths[draw(st.sampled_from(["foreign", "empty", "missing"]))]]
    return argv


@pytest.fixture(scope="module")
def argv_strategy(paths: dict[str, str]) -> st.SearchStrategy[list[str]]:
    return _argv(paths)


def _check_cli(argv: list[str], capsys: pytest.CaptureFixture[str]) -> None:
    capsys.readouterr()
    try:
        code = main(argv)
    except SystemExit as exc:  # argparse: usage, then one error line, exit 2
        code = exc.code if isinstance(exc.code, int) else 2
    out = capsys.readouterr()
    assert code in (0, 1, 2), (argv, code, out.err)
    assert "Traceback" not in out.err, (argv, out.err)
    errors = [line for line in out.err.splitlines() if "error:" in line]
    assert len(errors) <= 1 and all(len(e) <= MAX_MESSAGE_CHARS + 100 for e in errors), (argv, out.err)
    if code == 2:
        assert len(errors) == 1, (argv, out.err)


@settings(  # capsys is read at the start of each example, so sharing it across examples is safe
    suppress_health_check=[HealthCheck.function_scoped_fixture, HealthCheck.too_slow, HealthCheck.data_too_large]
)
@given(data=st.data())
def test_random_arguments_end_in_one_line(
    data: st.DataObject, argv_strategy: st.SearchStrategy[list[str]], paths: dict[str, str], capsys: Any
) -> None:
    argv = data.draw(argv_strategy)
    _check_cli(argv, capsys)
    assert sorted(os.listdir(paths["foreign"])) == ["notes.txt"], argv  # nothing written in another tool's folder
    assert not os.path.exists(paths["missing"]) or not os.listdir(paths["missing"]), argv


def test_the_option_names_are_read_from_the_parser() -> None:
    """The fuzzing draws every real option (a renamed or new option is fuzzed too)."""
    assert {"--seeds", "--max-seeds", "--max-configs", "--jobs", "--scheduler", "--connect-timeout"} <= set(
        OPTIONS["run"]
    )
    assert "--trials" in OPTIONS["tune"] and "--fraction" in OPTIONS["verify"] and "--help" not in OPTIONS["run"]
