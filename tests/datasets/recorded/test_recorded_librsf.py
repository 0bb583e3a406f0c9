"""libRSF ranging sets: the format on small written files, the generated Gaussian reference, every
file error, and the shared files (all nine sets, the UWB odometry convention)."""

from __future__ import annotations

import math
import os
from pathlib import Path

import numpy as np
import pytest
from numpy.testing import assert_allclose

from locbench.core.errors import ConfigError
from locbench.core.events import Odometry, RangeObservations
from locbench.datasets.recorded import librsf
from locbench.datasets.recorded.files import MissingDataFile, RecordedDataError
from locbench.datasets.recorded.librsf import LibrsfParams, load_librsf, read_set
from locbench.registry import make_dataset

ANCHORS = {1: (-10.0, -10.0), 2: (10.0, -10.0), 3: (10.0, 10.0), 4: (-10.0, 10.0)}


def _truth(n: int) -> np.ndarray:
    """(t, x, y, theta): a robot driving backwards (body vx < 0) along +x, then turning, at 1 s steps."""
    out = [(0.0, 0.0, 0.0, math.pi)]
    for k in range(1, n):
        _, x, y, th = out[-1]
        turn = 0.3 if k % 5 == 0 else 0.0
        # body-frame motion (-1, 0) then the turn, as the M3500 files move
        x, y = x - math.cos(th), y - math.sin(th)
        out.append((float(k), x, y, th + turn))
    return np.array(out)


def write_sim(folder: Path, n: int = 12, name: str = "M3500", noise: str = "skewed", edit: str = "") -> Path:
    """A small Ranging_Simulation folder whose odometry is the truth's exact increments."""
    sim = folder / "librsf" / "Ranging_Simulation"
    sim.mkdir(parents=True, exist_ok=True)
    tr = _truth(n)
    # the heading as the M3500 files write it, within one turn (the odometry turns by the unwrapped differences)
    gt = "".join(
        f"point2 {t:g} {x:.9f} {y:.9f} 0 0 0 0 \nangle {t:g} {math.remainder(th, 2 * math.pi):.9f} 0 \n"
        for t, x, y, th in tr
    )
    (sim / f"{name}_GT.txt").write_text(gt, encoding="ascii")
    lines = []
    for k in range(n):
        t, x, y, _ = tr[k]
        if k > 0:
            w = tr[k, 3] - tr[k - 1, 3]
            lines.append(f"odom2 {t:g} -1.0 0.0 {w:.9f} 0.0005 0.001 0.0005 \n")
        for i, (ax, ay) in ANCHORS.items():
            r = math.hypot(ax - x, ay - y) + (0.7 if (k + i) % 3 == 0 else 0.0)
            lines.append(f"range2 {t:g} {r:.9f} 0.25 {ax:g} {ay:g} {i} 0 \n")
    path = sim / f"{name}_{noise}_Input.txt"
    path.write_text("".join(lines) + edit, encoding="ascii")
    return path


def write_uwb(folder: Path, n: int = 20, edit: str = "") -> Path:
    uwb = folder / "librsf" / "Indoor_UWB"
    uwb.mkdir(parents=True, exist_ok=True)
    gt, inp = [], []
    for k in range(n):
        t = 0.1 * k
        x = 1.0 + 0.03 * k
        gt.append(f"point2 {t:.3f} {x:.6f} 1.0 0 0 0 0 \n")
        inp.append(f"odom2diff {t:.3f} 0.3 0.3 0 0.0785 0.0001 0.0001 0.0001 \n")
        i = 105 + k % 4
        ax, ay = [(0.0, 0.0), (0.0, 2.4), (2.4, 2.4), (2.4, 0.0)][k % 4]
        inp.append(f"range2 {t:.3f} {math.hypot(ax - x, ay - 1.0):.6f} 0.01 {ax} {ay} {i} 0 \n")
    (uwb / "Indoor_UWB_GT.txt").write_text("".join(gt), encoding="ascii")
    path = uwb / "Indoor_UWB_Input.txt"
    path.write_text("".join(inp) + edit, encoding="ascii")
    return path


# --- the format -------------------------------------------------------------------------------------------


def test_simulated_set(tmp_path: Path) -> None:
    write_sim(tmp_path)
    ds = load_librsf("m3500", "skewed", tmp_path, verify=False)
    ds.check()
    odo = [e for e in ds.events if isinstance(e, Odometry)]
    rng = [e for e in ds.events if isinstance(e, RangeObservations)]
    assert len(odo) == 11 and len(rng) == 12 and all(len(r.ids) == 4 for r in rng)
    assert (odo[0].dx, odo[0].dy) == (-1.0, 0.0)
    assert ds.world.landmarks is not None and ds.world.landmarks.ids.tolist() == [1, 2, 3, 4]
    assert abs(ds.initial.mean[2]) == pytest.approx(math.pi)
    assert ds.sensors.range_sigma_m == pytest.approx(0.5)
    # dead reckoning of the exact increments reproduces the truth
    pose = ds.initial.mean.copy()
    for e in odo:
        c, s = math.cos(pose[2]), math.sin(pose[2])
        pose = pose + np.array([c * e.dx - s * e.dy, s * e.dx + c * e.dy, e.dtheta])
    assert_allclose(pose[:2], ds.ground_truth.xy[-1], atol=1e-6)
    assert ds.metadata["range_error"]["mean_m"] > 0.0  # the skew is in the file's ranges


def test_gaussian_reference_is_seeded_and_of_the_declared_variance(tmp_path: Path) -> None:
    write_sim(tmp_path, n=400, noise="heavy-tailed")

    def values(seed: int) -> np.ndarray:
        ds = load_librsf("m3500", "gaussian", tmp_path, np.random.default_rng(seed), verify=False)
        return np.concatenate([e.ranges for e in ds.events if isinstance(e, RangeObservations)])

    a, b, c = values(1), values(1), values(2)
    assert np.array_equal(a, b) and not np.array_equal(a, c)
    ds = load_librsf("m3500", "gaussian", tmp_path, np.random.default_rng(1), verify=False)
    xy = np.interp  # truth at the range times equals the truth rows here (same times)
    del xy
    true = []
    for e in ds.events:
        if isinstance(e, RangeObservations):
            k = int(np.searchsorted(ds.ground_truth.t, e.t))
            p = ds.ground_truth.xy[k]
            true.extend(math.hypot(ANCHORS[int(i)][0] - p[0], ANCHORS[int(i)][1] - p[1]) for i in e.ids)
    err = a - np.array(true)
    assert abs(err.mean()) < 0.05 and err.var() == pytest.approx(0.25, rel=0.1)
    assert ds.metadata["range_error"] == {"generated_variance_m2": 0.25}


def test_moment_matched_gaussian(tmp_path: Path) -> None:
    write_sim(tmp_path, n=60, noise="heavy-tailed")
    write_sim(tmp_path, n=60, noise="skewed")
    ds = load_librsf("m3500", "gaussian", tmp_path, like="skewed", verify=False)
    skew = librsf.range_error_moments(
        read_set(
            tmp_path / "librsf/Ranging_Simulation/M3500_skewed_Input.txt",
            tmp_path / "librsf/Ranging_Simulation/M3500_GT.txt",
            False,
        )
    )
    assert ds.metadata["range_error"]["generated_variance_m2"] == pytest.approx(skew["variance_m2"])


def test_uwb_set(tmp_path: Path) -> None:
    write_uwb(tmp_path)
    ds = load_librsf("indoor_uwb", "", tmp_path, verify=False)
    ds.check()
    odo = [e for e in ds.events if isinstance(e, Odometry)]
    assert len(odo) == 19
    assert odo[0].v == pytest.approx(0.3) and odo[0].omega == 0.0 and odo[0].dt == pytest.approx(0.1)
    assert ds.sensors.twist_sigma_v_mps == pytest.approx(math.sqrt(0.0002 / 4))
    assert ds.ground_truth.theta[0] == pytest.approx(0.0)  # the direction of travel (+x)


def test_window(tmp_path: Path) -> None:
    write_sim(tmp_path, n=12)
    ds = load_librsf("m3500", "skewed", tmp_path, max_steps=4, verify=False)
    assert sum(isinstance(e, Odometry) for e in ds.events) == 4
    assert ds.ground_truth.t[-1] == 4.0


# --- bad input -------------------------------------------------------------------------------------------------


def _err(tmp_path: Path, edit: str, *words: str, uwb: bool = False) -> None:
    path = write_uwb(tmp_path, edit=edit) if uwb else write_sim(tmp_path, edit=edit)
    with pytest.raises(RecordedDataError) as info:
        if uwb:
            load_librsf("indoor_uwb", "", tmp_path, verify=False)
        else:
            load_librsf("m3500", "skewed", tmp_path, verify=False)
    msg = str(info.value)
    assert "\n" not in msg and str(path) in msg, msg
    for w in words:
        assert w in msg, msg


@pytest.mark.parametrize(
    ("edit", "words"),
    [
        ("pose2 12 1 2 3\n", ("measurement type 'pose2'", ":60:")),
        ("range2 12 1.0 0.25 1 1 1\n", ("wrong field count", "7 fields, expected 8")),
        ("range2 12 1.0 0.25 -10 -10 1 0", ("truncated line", "no line end")),
        ("range2 12 nan 0.25 -10 -10 1 0\n", ("field 3 (range m)", "finite number")),
        ("range2 12 1.0 0 -10 -10 1 0\n", ("range variance", "(0.0,")),
        ("range2 12 1.0 0.25 -10 -10 1.5 0\n", ("anchor id", "integer")),
        ("range2 12 1.0 0.25 -9 -10 1 0\n", ("anchor id 1", "fixed")),
        ("range2 12 1.0 0.25 1e7 -10 1 0\n", ("anchor x m",)),
        ("range2 3 1.0 0.25 -10 -10 1 0\n", ("time goes backwards",)),
        ("odom2 12 -1 0 0 -0.1 0.001 0.001\n", ("var vx",)),
        ("odom2 100 -1 0 0 0.1 0.001 0.001\n", ("time step", "at most 60.0 s")),
        ("range2 12 1.0 0.25 -10 -10 1 0 \u00e9\n", ("non-ASCII byte",)),
    ],
)
def test_malformed_simulated_input(tmp_path: Path, edit: str, words: tuple[str, ...]) -> None:
    if "\u00e9" in edit:
        path = write_sim(tmp_path)
        path.write_bytes(path.read_bytes() + edit.encode("utf-8"))
        with pytest.raises(RecordedDataError, match="non-ASCII byte"):
            load_librsf("m3500", "skewed", tmp_path, verify=False)
        return
    _err(tmp_path, edit, *words)


@pytest.mark.parametrize(
    ("edit", "words"),
    [
        ("odom2diff 9 0.3 0.3 0 0 0.0001 0.0001 0.0001\n", ("wheel distance",)),
        # flagged (outside [0, 300] m), and one flag of 21 ranges is beyond the policy's 1 %
        ("range2 9 -1.0 0.01 0 0 105 0\n", ("1 of 21 range2 (UWB) samples", "value, m -1, expected in [0, 300]")),
        ("odom2 9 1 0 0 1 1 1\n", ("measurement type 'odom2'",)),
    ],
)
def test_malformed_uwb_input(tmp_path: Path, edit: str, words: tuple[str, ...]) -> None:
    _err(tmp_path, edit, *words, uwb=True)


def test_gt_errors(tmp_path: Path) -> None:
    write_sim(tmp_path)
    gt = tmp_path / "librsf/Ranging_Simulation/M3500_GT.txt"
    gt.write_text(gt.read_text(encoding="ascii") + "point2 20 1 1 0 0 0 0\n", encoding="ascii")
    with pytest.raises(RecordedDataError, match="angle rows, expected one at each"):
        load_librsf("m3500", "skewed", tmp_path, verify=False)
    gt.write_text("point2 0 0 0 0 0 0 0\nangle 0 3.14 0\n", encoding="ascii")
    with pytest.raises(RecordedDataError, match="1 point2 row"):
        load_librsf("m3500", "skewed", tmp_path, verify=False)


def test_file_size_is_bounded(tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> None:
    path = write_sim(tmp_path)
    monkeypatch.setattr(librsf, "MAX_FILE_BYTES", 100)
    with pytest.raises(RecordedDataError, match="expected a libRSF file of at most 100 bytes") as info:
        load_librsf("m3500", "skewed", tmp_path, verify=False)
    assert str(path.parent) in str(info.value)


def test_missing_file(tmp_path: Path) -> None:
    with pytest.raises(MissingDataFile, match=r"librsf/Indoor_UWB/Indoor_UWB_Input\.txt"):
        load_librsf("indoor_uwb", "", tmp_path)


@pytest.mark.parametrize(
    "kw",
    [
        {"set": "m3500"},
        {"set": "m3500", "noise": "cauchy"},
        {"set": "indoor_uwb", "noise": "skewed"},
        {"set": "x"},
        {"set": "w3500", "noise": "skewed", "like": "skewed"},
        {"set": "w3500", "noise": "gaussian", "like": "gaussian"},
        {"set": "m3500", "noise": "skewed", "max_steps": -1},
    ],
)
def test_bad_params(kw: dict[str, object]) -> None:
    with pytest.raises(ConfigError, match="librsf"):
        LibrsfParams(**kw)  # type: ignore[arg-type]


# --- the shared files -----------------------------------------------------------------------------------------


def _data_root() -> Path:
    env = os.environ.get("LOCBENCH_DATA", "")
    if not env or not (Path(env) / "librsf").is_dir():
        pytest.skip("LOCBENCH_DATA with librsf/ is not set: the shared files are not here")
    return Path(env)


SETS = [
    "librsf[set=indoor_uwb]",
    *(f"librsf[set={w},noise={n}]" for w in ("m3500", "w3500") for n in ("heavy-tailed", "multimodal", "skewed")),
    "librsf[set=m3500,noise=gaussian]",
    "librsf[set=w3500,noise=gaussian]",
]


@pytest.mark.recorded
@pytest.mark.parametrize("spec", SETS)
def test_every_shared_set_builds(spec: str) -> None:
    _data_root()
    ds = make_dataset(spec)
    n_ranges = sum(len(e.ranges) for e in ds.events if isinstance(e, RangeObservations))
    if "indoor" in spec:
        assert n_ranges == 233 and ds.world.landmarks is not None and len(ds.world.landmarks) == 4
    else:
        assert n_ranges >= 27990 and len(ds.world.landmarks or []) == 8


@pytest.mark.recorded
def test_the_uwb_yaw_convention_follows_the_truth() -> None:
    """The convention omega = (v_l - v_r) / (2 b) is measured, not assumed: it must follow the truth where the
    readme's (v_r - v_l) / b does not (the test fails if the data or the reading changes)."""
    _data_root()
    ds = make_dataset("librsf[set=indoor_uwb]")
    odo = [e for e in ds.events if isinstance(e, Odometry)]

    def dead_reckon(flip: float, scale: float) -> float:
        x, y, th = ds.initial.mean
        err = []
        for e in odo:
            if e.t > ds.ground_truth.t[0] + 10.0:
                break
            assert e.v is not None and e.omega is not None and e.dt is not None
            w = flip * e.omega * scale
            x += e.v * e.dt * math.cos(th + 0.5 * w * e.dt)
            y += e.v * e.dt * math.sin(th + 0.5 * w * e.dt)
            th += w * e.dt
            k = int(np.searchsorted(ds.ground_truth.t, e.t))
            err.append(math.hypot(x - ds.ground_truth.xy[k, 0], y - ds.ground_truth.xy[k, 1]))
        return float(np.sqrt(np.mean(np.square(err))))

    assert dead_reckon(1.0, 1.0) < 0.15
    assert dead_reckon(-1.0, 2.0) > 0.5  # the readme's reading: (v_r - v_l) / b
