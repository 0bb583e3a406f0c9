"""Property-based fuzzing of every recorded-data parser and loader.

The property, for any mutation of a small valid file: the loader either raises a clean locbench error (a
:class:`~locbench.core.errors.LocbenchError` whose message is one line of bounded length naming the file) or returns
a dataset that passes the contract check. Any other exception, a multi-line or unbounded message, or running out
of the memory limit fails the test.

Mutations: truncation at every byte of a small file (exhaustive where the file is small, drawn otherwise), column
drops and swaps, values replaced by NaN, infinities, huge or negative numbers or text, reordered and duplicated
lines (times), and for MAT files dtype changes (integers, logicals, complex, text), shapes and missing variables.

The whole module runs under an address-space limit (``RLIMIT_AS``) of the process's size when it starts plus
:data:`MEMORY_HEADROOM`, so a resource bomb fails with ``MemoryError`` instead of taking the machine. The
``ci`` hypothesis profile (the default, registered in ``conftest.py``) keeps the module near a minute on 2 cores;
``nox -s fuzz`` runs the ``fuzz`` profile with many more examples.
"""

from __future__ import annotations

import copy
import itertools
import resource
import tempfile
from collections.abc import Callable, Iterator
from pathlib import Path
from typing import Any

import numpy as np
import pytest
import scipy.io
from hypothesis import example, given, settings
from hypothesis import strategies as st
from test_recorded_intel import write_small_intel
from test_recorded_lost_in_the_woods import _small_mat
from test_recorded_plaza import _tiny

from locbench.core.errors import MAX_MESSAGE_CHARS, LocbenchError
from locbench.datasets.dataset import OccupancyGrid
from locbench.datasets.recorded.intel import load_intel
from locbench.datasets.recorded.lost_in_the_woods import load_lost_in_the_woods
from locbench.datasets.recorded.mrclam import load_mrclam
from locbench.datasets.recorded.plaza import load_plaza
from locbench.datasets.recorded.ros_map import load_map_server_map, save_map_server_map

#: Address space the loaders may add to the test process, bytes (no small input may take 1 GB).
MEMORY_HEADROOM = 1 << 30


def _vm_size() -> int:
    with open("/proc/self/status", encoding="ascii") as fh:
        for line in fh:
            if line.startswith("VmSize:"):
                return int(line.split()[1]) * 1024
    raise RuntimeError("no VmSize in /proc/self/status")


@pytest.fixture(scope="module", autouse=True)
def memory_limit() -> Iterator[None]:
    """Cap the address space at the current size + MEMORY_HEADROOM for the module, then restore it."""
    soft, hard = resource.getrlimit(resource.RLIMIT_AS)
    try:
        cap = _vm_size() + MEMORY_HEADROOM
    except (OSError, RuntimeError):
        pytest.skip("no /proc/self/status: the memory limit cannot be set here")
    if hard != resource.RLIM_INFINITY:
        cap = min(cap, hard)
    resource.setrlimit(resource.RLIMIT_AS, (cap, hard))
    try:
        yield
    finally:
        resource.setrlimit(resource.RLIMIT_AS, (soft, hard))


_COUNTER = itertools.count()


def _fresh_dir(base: Path) -> Path:
    """A new folder per example: the loaders cache per (path, size, mtime), so paths are never reused."""
    return Path(tempfile.mkdtemp(prefix=f"ex{next(_COUNTER)}-", dir=base))


@pytest.fixture(scope="module")
def base(tmp_path_factory: pytest.TempPathFactory) -> Path:
    return tmp_path_factory.mktemp("fuzz")


def outcome_is_clean(load: Callable[[], Any], names: list[str]) -> None:
    """The property: a clean one-line error naming one of ``names``, or a dataset that passes the contract."""
    try:
        load().check()  # as registry.make_dataset does: a dataset that breaks the contract is an error too
    except LocbenchError as exc:
        msg = str(exc)
        assert "\n" not in msg, msg[:500]
        assert len(msg) <= MAX_MESSAGE_CHARS, msg[:500]
        assert any(n in msg for n in names), msg


# --- mutations of text tables and logs -----------------------------------------------------------------------

#: Replacement fields: non-finite, huge, negative, tiny, text, empty-ish and integer-overflow values.
BAD_FIELDS = [b"nan", b"inf", b"-inf", b"1e308", b"-1e308", b"1e20", b"-1", b"0", b"1e-320", b"abc", b"0x10", b"1e400"]


@st.composite
def text_mutation(draw: st.DrawFn, raw: bytes) -> bytes:
    """One mutation of a line-oriented text file."""
    lines = raw.split(b"\n")
    data = [k for k, ln in enumerate(lines) if ln.strip() and not ln.lstrip().startswith(b"#")]
    kind = draw(st.sampled_from(["truncate", "drop", "swap", "value", "reorder", "duplicate", "insert"]))
    if kind == "truncate" or not data:
        return raw[: draw(st.integers(0, len(raw)))]
    k = draw(st.sampled_from(data))
    fields = lines[k].split()
    if kind == "drop" and len(fields) > 1:
        fields.pop(draw(st.integers(0, len(fields) - 1)))
    elif kind == "swap" and len(fields) > 1:
        i, j = draw(st.integers(0, len(fields) - 1)), draw(st.integers(0, len(fields) - 1))
        fields[i], fields[j] = fields[j], fields[i]
    elif kind == "value":
        fields[draw(st.integers(0, len(fields) - 1))] = draw(st.sampled_from(BAD_FIELDS))
    elif kind == "reorder" and len(data) > 1:
        j = draw(st.sampled_from(data))
        lines[k], lines[j] = lines[j], lines[k]
        return b"\n".join(lines)
    elif kind == "duplicate":
        lines.insert(k, lines[k])
        return b"\n".join(lines)
    elif kind == "insert":
        lines.insert(k, b" ".join(draw(st.lists(st.sampled_from([*BAD_FIELDS, b"1.5", b"2"]), max_size=6))))
        return b"\n".join(lines)
    lines[k] = b" ".join(fields) + (b"\r" if lines[k].endswith(b"\r") else b"")
    return b"\n".join(lines)


# --- MRCLAM --------------------------------------------------------------------------------------------------


def _mini_mrclam(folder: Path) -> Path:
    """A tiny but valid MRCLAM folder: 1 s of truth at 10 Hz, 6 odometry samples, 3 sightings."""
    folder.mkdir(parents=True, exist_ok=True)

    def w(name: str, rows: list[str]) -> None:
        (folder / name).write_bytes(("# header\r\n" + "".join(r + " \r\n" for r in rows)).encode("ascii"))

    w("Barcodes.dat", ["1 \t 5", "6 \t 63", "7 \t 81"])
    w("Landmark_Groundtruth.dat", ["6 \t 2.0 \t 0.0 \t 0.001 \t 0.002", "7 \t 0.0 \t 2.0 \t 0.003 \t 0.004"])
    w("Robot1_Groundtruth.dat", [f"{100 + 0.1 * k:.3f} \t {0.05 * k:.4f} \t -1.0 \t 0.0" for k in range(11)])
    w("Robot1_Odometry.dat", [f"{100 + 0.2 * k:.3f} \t 0.500 \t 0.000" for k in range(6)])
    w(
        "Robot1_Measurement.dat",
        ["100.300 \t 63 \t 3.100 \t 0.200", "100.300 \t 5 \t 1.5 \t 0.1", "100.700 \t 81 \t 2.5 \t 1.0"],
    )
    return folder


MRCLAM_FILES = [
    "Barcodes.dat",
    "Landmark_Groundtruth.dat",
    "Robot1_Groundtruth.dat",
    "Robot1_Odometry.dat",
    "Robot1_Measurement.dat",
]


def test_mini_mrclam_is_valid(base: Path) -> None:
    load_mrclam(_mini_mrclam(_fresh_dir(base) / "MRCLAM_Dataset9"), 1, verify=False).check()


@pytest.mark.parametrize("name", MRCLAM_FILES)
def test_mrclam_truncated_at_every_byte(base: Path, name: str) -> None:
    template = _mini_mrclam(_fresh_dir(base) / "MRCLAM_Dataset9")
    raw = (template / name).read_bytes()
    for cut in range(len(raw)):
        folder = _mini_mrclam(_fresh_dir(base) / "MRCLAM_Dataset9")
        (folder / name).write_bytes(raw[:cut])
        # a cut file can surface in another (a barcode no longer on the map): a file of the run is named
        outcome_is_clean(lambda f=folder: load_mrclam(f, 1, verify=False), [str(folder)])


@given(name=st.sampled_from(MRCLAM_FILES), data=st.data())
def test_mrclam_mutations(base: Path, name: str, data: st.DataObject) -> None:
    folder = _mini_mrclam(_fresh_dir(base) / "MRCLAM_Dataset9")
    path = folder / name
    path.write_bytes(data.draw(text_mutation(path.read_bytes())))
    # a bad value in one file can surface as a mismatch against another (a barcode not on the map): any file
    outcome_is_clean(lambda: load_mrclam(folder, 1, verify=False), [str(folder)])


# --- CARMEN (Intel) ------------------------------------------------------------------------------------------


@pytest.fixture(scope="module")
def intel_template(base: Path) -> dict[str, bytes]:
    root = _fresh_dir(base)
    write_small_intel(root)
    folder = root / "freiburg_slam_benchmark"
    return {p.name: p.read_bytes() for p in folder.iterdir()}


def _intel_copy(base: Path, template: dict[str, bytes]) -> Path:
    root = _fresh_dir(base)
    (root / "freiburg_slam_benchmark").mkdir()
    for name, raw in template.items():
        (root / "freiburg_slam_benchmark" / name).write_bytes(raw)
    return root


@given(name=st.sampled_from(["intel.clf", "intel.gfs.log", "intel.relations"]), data=st.data())
def test_carmen_mutations(base: Path, intel_template: dict[str, bytes], name: str, data: st.DataObject) -> None:
    root = _intel_copy(base, intel_template)
    path = root / "freiburg_slam_benchmark" / name
    path.write_bytes(data.draw(text_mutation(path.read_bytes())))
    outcome_is_clean(lambda: load_intel(root, verify=False), [str(root / "freiburg_slam_benchmark")])


def test_carmen_relations_truncated_at_every_byte(base: Path, intel_template: dict[str, bytes]) -> None:
    raw = intel_template["intel.relations"]
    for cut in range(len(raw)):
        root = _intel_copy(base, intel_template)
        (root / "freiburg_slam_benchmark" / "intel.relations").write_bytes(raw[:cut])
        outcome_is_clean(lambda r=root: load_intel(r, verify=False), [str(root / "freiburg_slam_benchmark")])


# --- MAT files (Lost in the Woods, Plaza) --------------------------------------------------------------------

VALUES = [np.nan, np.inf, -np.inf, 1e300, -1e300, 1e20, -1.0, 0.0, 1e-320]


@st.composite
def mat_mutation(draw: st.DrawFn, mat: dict[str, Any]) -> dict[str, Any]:
    """One mutation of a MAT file's variables: dtype, value, shape, order or presence."""
    out = copy.deepcopy(mat)
    name = draw(st.sampled_from(sorted(out)))
    a = np.asarray(out[name])
    kind = draw(st.sampled_from(["dtype", "value", "rows", "drop_col", "swap_cols", "reorder", "dup", "T", "del"]))
    if kind == "dtype":
        dtype = draw(st.sampled_from(["int16", "int32", "uint8", "bool", "complex128", "float32", "str"]))
        out[name] = np.array(a.astype(str).tolist()) if dtype == "str" else a.astype(dtype)
    elif kind == "value" and a.size:
        b = a.astype(np.float64)
        b.flat[draw(st.integers(0, a.size - 1))] = draw(st.sampled_from(VALUES))
        out[name] = b
    elif kind == "rows" and a.ndim == 2:
        out[name] = a[: draw(st.integers(0, a.shape[0]))]
    elif kind == "drop_col" and a.ndim == 2 and a.shape[1] > 1:
        out[name] = np.delete(a, draw(st.integers(0, a.shape[1] - 1)), axis=1)
    elif kind == "swap_cols" and a.ndim == 2 and a.shape[1] > 1:
        i, j = draw(st.integers(0, a.shape[1] - 1)), draw(st.integers(0, a.shape[1] - 1))
        b = a.copy()
        b[:, [i, j]] = b[:, [j, i]]
        out[name] = b
    elif kind == "reorder" and a.ndim == 2 and a.shape[0] > 1:
        i, j = draw(st.integers(0, a.shape[0] - 1)), draw(st.integers(0, a.shape[0] - 1))
        b = a.copy()
        b[[i, j]] = b[[j, i]]
        out[name] = b
    elif kind == "dup" and a.ndim == 2 and a.shape[0] > 0:
        k = draw(st.integers(0, a.shape[0] - 1))
        out[name] = np.insert(a, k, a[k], axis=0)
    elif kind == "T":
        out[name] = a.T
    elif kind == "del":
        del out[name]
    return out


def _savemat(path: Path, mat: dict[str, Any]) -> Path:
    scipy.io.savemat(path, mat)
    return path


@given(data=st.data())
def test_lost_in_the_woods_mutations(base: Path, data: st.DataObject) -> None:
    path = _savemat(_fresh_dir(base) / "dataset2.mat", data.draw(mat_mutation(_small_mat())))
    outcome_is_clean(lambda: load_lost_in_the_woods(path), [str(path)])


@given(data=st.data())
def test_plaza_mutations(base: Path, data: st.DataObject) -> None:
    path = _savemat(_fresh_dir(base) / "tiny.mat", data.draw(mat_mutation(_tiny())))
    outcome_is_clean(lambda: load_plaza(path), [str(path)])


def test_plaza_truncated_at_every_byte(base: Path) -> None:
    raw = _savemat(_fresh_dir(base) / "tiny.mat", _tiny()).read_bytes()
    for cut in range(len(raw)):
        path = _fresh_dir(base) / "tiny.mat"
        path.write_bytes(raw[:cut])
        outcome_is_clean(lambda p=path: load_plaza(p), [str(path)])


@given(data=st.data())
def test_lost_in_the_woods_truncated(base: Path, data: st.DataObject) -> None:
    raw = _savemat(_fresh_dir(base) / "dataset2.mat", _small_mat()).read_bytes()
    path = _fresh_dir(base) / "dataset2.mat"
    path.write_bytes(raw[: data.draw(st.integers(0, len(raw) - 1))])
    outcome_is_clean(lambda: load_lost_in_the_woods(path), [str(path)])


# --- ROS map_server maps -------------------------------------------------------------------------------------


def _map_folder(base: Path) -> Path:
    folder = _fresh_dir(base)
    occ = np.zeros((4, 5))
    occ[0, :] = 1.0
    occ[2, 2] = -1.0
    save_map_server_map(OccupancyGrid(occ, 0.05, (-1.0, -2.0, 0.0)), folder / "m.yaml")
    return folder


YAML_VALUES = ["1.0e+6", "1.0e-300", "-1", ".nan", ".inf", "[1, 2]", "{a: 1}", "abc", "", "*x", "&x 1",
               "!!python/tuple [1]", "[0, 0, 1e300]", "999999999999999999999999", "m.pgm", "/nowhere.pgm",
               "'../m.yaml'", "true"]  # fmt: skip


@given(data=st.data())
def test_map_yaml_mutations(base: Path, data: st.DataObject) -> None:
    folder = _map_folder(base)
    y = folder / "m.yaml"
    lines = y.read_text().splitlines()
    k = data.draw(st.integers(0, len(lines) - 1))
    key = lines[k].split(":", 1)[0]
    kind = data.draw(st.sampled_from(["value", "drop", "truncate", "alias"]))
    if kind == "value":
        lines[k] = f"{key}: {data.draw(st.sampled_from(YAML_VALUES))}"
        text = "\n".join(lines) + "\n"
    elif kind == "drop":
        text = "\n".join(lines[:k] + lines[k + 1 :]) + "\n"
    elif kind == "alias":
        text = "\n".join(lines) + "\nx: &a [1, 2]\ny: [*a, *a]\n"
    else:
        raw = "\n".join(lines) + "\n"
        text = raw[: data.draw(st.integers(0, len(raw)))]
    y.write_text(text)
    outcome_is_map(lambda: load_map_server_map(y), [str(folder)])


def outcome_is_map(load: Callable[[], OccupancyGrid], names: list[str]) -> None:
    """The map property: a clean error naming the folder, or a grid of probabilities in [0, 1] or -1."""
    try:
        grid = load()
    except LocbenchError as exc:
        msg = str(exc)
        assert "\n" not in msg and len(msg) <= MAX_MESSAGE_CHARS, msg[:500]
        assert any(n in msg for n in names), msg
        return
    occ = grid.occupancy
    assert occ.ndim == 2 and occ.size > 0
    assert np.all(((occ >= 0.0) & (occ <= 1.0)) | (occ == -1.0))
    assert np.isfinite(grid.resolution) and grid.resolution > 0


def test_pgm_truncated_at_every_byte(base: Path) -> None:
    raw = (_map_folder(base) / "m.pgm").read_bytes()
    for cut in range(len(raw)):
        folder = _map_folder(base)
        (folder / "m.pgm").write_bytes(raw[:cut])
        outcome_is_map(lambda f=folder: load_map_server_map(f / "m.yaml"), [str(folder)])


@given(data=st.data())
def test_pgm_header_mutations(base: Path, data: st.DataObject) -> None:
    folder = _map_folder(base)
    pgm = folder / "m.pgm"
    raw = pgm.read_bytes()
    header_end = raw.index(b"\n", raw.index(b"\n", raw.index(b"\n") + 1) + 1)
    head = raw[:header_end].split(b"\n")
    k = data.draw(st.integers(1, len(head) - 1))
    head[k] = data.draw(
        st.sampled_from([b"99999 99999", b"5 4", b"0 0", b"-5 4", b"65536", b"255", b"1", b"# c", b"x y"])
    )
    pgm.write_bytes(b"\n".join(head) + raw[header_end:])
    outcome_is_map(lambda: load_map_server_map(folder / "m.yaml"), [str(folder)])


# --- ROS 1 and ROS 2 bags ------------------------------------------------------------------------------------


@pytest.fixture(scope="module")
def bag_template(base: Path) -> dict[str, Any]:
    pytest.importorskip("rosbags")
    from test_rosbag import _Bag

    from locbench.datasets.dataset import sort_events
    from locbench.registry import make_dataset

    ds = make_dataset("tiny_line", 0)
    # a short stretch keeps each example fast: 2 s of the run
    t0 = float(ds.ground_truth.t[0])
    keep = ds.ground_truth.t <= t0 + 2.0
    from dataclasses import replace

    from locbench.datasets.dataset import Trajectory2D

    gt = ds.ground_truth
    ds = replace(
        ds,
        events=sort_events([e for e in ds.events if e.t <= t0 + 2.0]),
        ground_truth=Trajectory2D(gt.t[keep], gt.xy[keep], gt.theta[keep]),
    )
    folder = _fresh_dir(base)
    assert ds.world.occupancy is not None
    save_map_server_map(ds.world.occupancy, folder / "map.yaml")
    out: dict[str, Any] = {"map": folder / "map.yaml"}
    for ros1 in (True, False):
        b = _Bag(ros1)
        path = folder / ("t.bag" if ros1 else "t2")
        b.write(path, b.messages(ds, "nav_msgs/msg/Odometry"), "sqlite3")
        out["ros1" if ros1 else "ros2"] = path
    return out


@given(data=st.data())
def test_ros1_bag_truncated_or_flipped(base: Path, bag_template: dict[str, Any], data: st.DataObject) -> None:
    from locbench.datasets.recorded.rosbag import load_rosbag

    raw = bag_template["ros1"].read_bytes()
    if data.draw(st.booleans()):
        raw = raw[: data.draw(st.integers(0, len(raw) - 1))]
    else:
        k = data.draw(st.integers(0, len(raw) - 1))
        raw = raw[:k] + bytes([raw[k] ^ data.draw(st.integers(1, 255))]) + raw[k + 1 :]
    path = _fresh_dir(base) / "t.bag"
    path.write_bytes(raw)
    outcome_is_clean(lambda: load_rosbag(path, bag_template["map"]), [str(path)])


@given(data=st.data())
def test_ros2_bag_storage_truncated(base: Path, bag_template: dict[str, Any], data: st.DataObject) -> None:
    from locbench.datasets.recorded.rosbag import load_rosbag

    src: Path = bag_template["ros2"]
    folder = _fresh_dir(base) / "t2"
    folder.mkdir()
    name = data.draw(st.sampled_from(sorted(p.name for p in src.iterdir())))
    for p in src.iterdir():
        raw = p.read_bytes()
        if p.name == name:
            raw = raw[: data.draw(st.integers(0, len(raw) - 1))]
        (folder / p.name).write_bytes(raw)
    outcome_is_clean(lambda: load_rosbag(folder, bag_template["map"]), [str(folder)])


@pytest.mark.slow
def test_a_map_at_the_pixel_limit_loads_within_the_memory_limit(base: Path) -> None:
    """A 4096 x 4096 PNG (the default limit, a few KB on disk) is read inside the module's 1 GB headroom."""
    pytest.importorskip("PIL")
    from input_support import grey_png

    folder = _fresh_dir(base)
    grey_png(folder / "m.png", 4096, 4096)
    (folder / "m.yaml").write_text("image: m.png\nresolution: 0.05\norigin: [0, 0, 0]\n")
    assert load_map_server_map(folder / "m.yaml").shape == (4096, 4096)


# --- filters on grids of any size: refused by their estimate, or run within the memory limit -----------------


@settings(max_examples=6)  # an accepted example builds the tables of a grid of up to 1.6 M cells
@example(rows=4096, cols=4096, spec="ekf_icp")  # the map: refused
@example(rows=1200, cols=1200, spec="ekf_icp")  # just under the limit: its tables fit the headroom
@example(rows=4096, cols=4096, spec="pf[use_laser=true,particles=50]")
@example(rows=2000, cols=2000, spec="pf[use_laser=true,particles=50]")
@given(
    rows=st.integers(1, 4096),
    cols=st.integers(1, 4096),
    spec=st.sampled_from(["ekf_icp", "pf[use_laser=true,particles=50]"]),
)
def test_grid_filters_refuse_or_run_within_the_memory_limit(rows: int, cols: int, spec: str) -> None:
    import dataclasses

    from locbench.core.limits import LIKELIHOOD_FIELD_BYTES_PER_CELL, MAX_TABLE_BYTES, RAYCAST_BYTES_PER_CELL
    from locbench.registry import make_dataset, make_filter
    from locbench.run.filter_pass import run_filter

    occ = np.zeros((rows, cols))
    occ[::37, ::41] = 1.0
    ds = make_dataset("tiny_line", 0)
    ds = dataclasses.replace(ds, world=dataclasses.replace(ds.world, occupancy=OccupancyGrid(occ, 0.05)))
    trace = run_filter(make_filter(spec), ds, np.random.default_rng(0))
    per_cell = RAYCAST_BYTES_PER_CELL if spec == "ekf_icp" else LIKELIHOOD_FIELD_BYTES_PER_CELL
    if rows * cols * per_cell > MAX_TABLE_BYTES:
        assert trace.status == "error" and trace.message.startswith("ResourceLimit:"), trace.message
        assert "\n" not in trace.message and len(trace.message) <= MAX_MESSAGE_CHARS
    else:  # accepted: it ran (a MemoryError under the module's address-space limit would be an error here)
        assert "MemoryError" not in trace.message and "ResourceLimit" not in trace.message, trace.message
