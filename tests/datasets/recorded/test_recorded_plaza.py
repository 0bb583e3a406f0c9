"""The CMU Plaza loader: the shared files (skipped without LOCBENCH_DATA) and malformed copies in tmp_path."""

from __future__ import annotations

import math
import shutil
from collections.abc import Iterator
from pathlib import Path

import numpy as np
import pytest
from numpy.testing import assert_allclose
from scipy.io import savemat

from locbench.core.errors import ConfigError
from locbench.core.events import Odometry, RangeObservations
from locbench.core.geometry import wrap_angle
from locbench.datasets.recorded import plaza
from locbench.datasets.recorded.files import MissingDataFile, RecordedDataError
from locbench.datasets.recorded.plaza import PlazaDataset, PlazaParams, load_plaza, read_plaza_mat
from locbench.datasets.recorded.reference import heading_from_track
from locbench.registry import DATASETS, make_dataset

_SKIP = PlazaDataset.data_unavailable()
_skip_without_data = pytest.mark.skipif(_SKIP is not None, reason=_SKIP or "")


def needs_data(fn):  # type: ignore[no-untyped-def]
    """The shared files: marked ``recorded`` and skipped with the reason when they are absent."""
    return pytest.mark.recorded(_skip_without_data(fn))


def _shared(run: int) -> Path:
    (path,) = PlazaDataset().paths(PlazaParams(run=run)).values()
    return path


@pytest.fixture
def registered() -> Iterator[None]:
    snap = DATASETS.snapshot()
    DATASETS.register("plaza", "locbench.datasets.recorded.plaza:PlazaDataset")
    try:
        yield
    finally:
        DATASETS.restore(snap)


# --- the shared files ------------------------------------------------------------------------------


@needs_data
@pytest.mark.parametrize(("run", "n_ranges", "out_of_order"), [(1, 3529, 2), (2, 1816, 0)])
def test_runs_build_and_keep_every_range(run: int, n_ranges: int, out_of_order: int, registered: None) -> None:
    ds = make_dataset(f"plaza[run={run}]", 0)
    ds.check()
    ranges = [e for e in ds.events if isinstance(e, RangeObservations)]
    odo = [e for e in ds.events if isinstance(e, Odometry)]
    assert sum(len(e) for e in ranges) == n_ranges
    assert len(odo) == read_plaza_mat(_shared(run)).DR.shape[0]
    assert ds.metadata["td_rows_out_of_order"] == out_of_order
    times = [e.t for e in ds.events]
    assert times == sorted(times)
    assert ds.ground_truth.t[0] <= times[0] and times[-1] <= ds.ground_truth.t[-1]
    assert ds.world.landmarks is not None and sorted(ds.world.landmarks.ids.tolist()) == [0, 1, 5, 6]
    assert_allclose(ds.initial.mean[:2], ds.ground_truth.xy[0])
    assert ds.initial.mean[2] == ds.ground_truth.theta[0]
    assert ds.sensors.range_sigma_m == plaza.NOMINAL_NOISE[run].range_sigma_m
    # The seed changes nothing in recorded data.
    other = make_dataset(f"plaza[run={run}]", 5)
    assert len(other.events) == len(ds.events) and np.array_equal(other.ground_truth.xy, ds.ground_truth.xy)


@needs_data
@pytest.mark.parametrize("run", [1, 2])
def test_frozen_nominal_noise_is_what_the_procedure_gives(run: int) -> None:
    noise, median = plaza.estimate_nominal_noise(read_plaza_mat(_shared(run), plaza.SHA256[run]))
    frozen = plaza.NOMINAL_NOISE[run]
    assert noise.range_sigma_m == pytest.approx(frozen.range_sigma_m, rel=1e-9)
    assert noise.odometry_sigma_xy_per_m == pytest.approx(frozen.odometry_sigma_xy_per_m, rel=1e-9)
    assert noise.odometry_sigma_theta_per_m == pytest.approx(frozen.odometry_sigma_theta_per_m, rel=1e-9)
    assert median == pytest.approx(plaza.RANGE_RESIDUAL_MEDIAN_M[run], rel=1e-9)


@needs_data
def test_odometry_model_reproduces_plaza2_dead_reckoning() -> None:
    a2 = read_plaza_mat(_shared(2))
    check = plaza.dead_reckoning_check(a2)
    assert check["drp_max_position_diff_m"] < 0.1  # over 1354 m of travel
    assert check["drp_max_heading_diff_rad"] < 1e-9
    # Moving before turning (GTSAM's Pose2(d, 0, dh) composition) fits DRp worse than the mid-rotation model.
    dr = a2.DR
    before = np.stack([dr[:, 1], np.zeros(len(dr)), dr[:, 2]], axis=-1)
    assert a2.DRp is not None
    poses = plaza.integrate(a2.DRp[0, 1:4], before)
    assert np.hypot(*(poses[:, :2] - a2.DRp[:, 1:3]).T).max() > 3 * check["drp_max_position_diff_m"]
    # Plaza1's DRp headings are the integrated d_heading, its positions are not (module docstring).
    check1 = plaza.dead_reckoning_check(read_plaza_mat(_shared(1)))
    assert check1["drp_max_heading_diff_rad"] < 1e-9 and check1["drp_max_position_diff_m"] > 10.0


@needs_data
def test_truth_heading_is_the_direction_of_travel() -> None:
    a1, a2 = read_plaza_mat(_shared(1)), read_plaza_mat(_shared(2))
    # Plaza1's GT heading column is its odometry heading (good locally); Plaza2's points backwards.
    d1 = wrap_angle(heading_from_track(a1.GT[:, 1:3], plaza.HEADING_CHORD_M) - a1.GT[:, 3])
    d2 = wrap_angle(heading_from_track(a2.GT[:, 1:3], plaza.HEADING_CHORD_M) - a2.GT[:, 3] - math.pi)
    assert abs(float(np.median(d1))) < 0.05 and abs(float(np.median(d2))) < 0.05
    assert a1.DRp is not None and np.array_equal(a1.GT[:, 3], a1.DRp[:, 3])


@needs_data
def test_checksum_mismatch_of_a_modified_copy(tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> None:
    target = tmp_path / plaza.FOLDER / "Plaza2_.mat"
    target.parent.mkdir()
    shutil.copyfile(_shared(2), target)
    with target.open("ab") as f:
        f.write(b"\0")
    monkeypatch.setenv("LOCBENCH_DATA", str(tmp_path))
    with pytest.raises(RecordedDataError, match=r"Plaza2_\.mat: checksum mismatch"):
        PlazaDataset().build(PlazaParams(run=2), np.random.default_rng(0))


def test_missing_file_is_a_recorded_skip(tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> None:
    monkeypatch.setenv("LOCBENCH_DATA", str(tmp_path))
    monkeypatch.setenv("LOCBENCH_CACHE", str(tmp_path / "cache"))
    with pytest.raises(MissingDataFile, match=r"Plaza1_\.mat"):
        PlazaDataset().build(PlazaParams(run=1), np.random.default_rng(0))
    assert "Plaza1_.mat" in (PlazaDataset.data_unavailable() or "")
    with pytest.raises(MissingDataFile, match=r"nothing\.mat"):
        load_plaza(tmp_path / "nothing.mat")


def test_params_are_checked() -> None:
    with pytest.raises(ConfigError, match="run must be 1 or 2"):
        PlazaParams(run=3)


# --- small files written here ------------------------------------------------------------------------------


def _tiny() -> dict[str, np.ndarray]:
    """A consistent tiny run: 3 m straight east then a left turn, two beacons, ranges at shared and lone times."""
    gt_t = np.arange(0.0, 2.01, 0.5)
    gt = np.stack([gt_t, gt_t, np.zeros_like(gt_t), np.zeros_like(gt_t)], axis=-1)
    dr = np.array([[0.5, 0.5, 0.0], [1.0, 0.5, 0.2], [1.5, 0.5, 0.0], [2.0, 0.5, -0.1]])
    tl = np.array([[4.0, 0.0, 5.0], [7.0, 3.0, -2.0]])
    td = np.array(
        [
            [0.6, 2.0, 4.0, 5.1],
            [0.6, 2.0, 7.0, 3.2],
            [1.2, 2.0, 7.0, 3.9],
            [2.5, 2.0, 4.0, 6.0],  # after the truth ends: trimmed
        ]
    )
    drp = np.vstack([[0.0, 0.0, 0.0, 0.0], np.column_stack([dr[:, 0], np.zeros((4, 3))])])
    return {"GT": gt, "DR": dr, "TL": tl, "TD": td, "DRp": drp}


def _write(tmp_path: Path, data: dict[str, np.ndarray], name: str = "tiny.mat") -> Path:
    path = tmp_path / name
    savemat(path, data)
    return path


def test_tiny_file_events_truth_and_odometry_model(tmp_path: Path) -> None:
    ds = load_plaza(_write(tmp_path, _tiny()))
    ds.check()
    odo = [e for e in ds.events if isinstance(e, Odometry)]
    rng = [e for e in ds.events if isinstance(e, RangeObservations)]
    assert [e.t for e in odo] == [0.5, 1.0, 1.5, 2.0]
    # mid-rotation: d along dh / 2 in the previous robot frame
    assert odo[1].dx == pytest.approx(0.5 * math.cos(0.1)) and odo[1].dy == pytest.approx(0.5 * math.sin(0.1))
    assert odo[1].dtheta == 0.2
    assert [(e.t, e.ids.tolist(), e.ranges.tolist()) for e in rng] == [(0.6, [4, 7], [5.1, 3.2]), (1.2, [7], [3.9])]
    assert ds.world.landmarks is not None and ds.world.landmarks.ids.tolist() == [4, 7]
    assert_allclose(ds.ground_truth.theta, 0.0, atol=1e-12)  # travelling east
    shifted = load_plaza(_write(tmp_path, _tiny(), "b.mat"), range_offset_m=0.5)
    first = next(e for e in shifted.events if isinstance(e, RangeObservations))
    assert_allclose(first.ranges, [4.6, 2.7])


@pytest.mark.parametrize(
    ("edit", "message"),
    [
        (lambda d: d.pop("TD"), r"variable 'TD': missing variable, expected a real \(n, 4\) matrix \[t s sender_id"),
        (lambda d: d.__setitem__("DR", d["DR"][:, :2]), r"variable 'DR' has shape \(4, 2\).*expected a real \(n, 3\)"),
        (lambda d: d["GT"].__setitem__((2, 1), np.nan), r"variable 'GT': non-finite value nan at \(3, 2\) \(1-based\)"),
        (lambda d: d["DR"].__setitem__((2, 0), 0.2), r"variable 'DR' column 1 \(t s\): time goes backwards at row 3"),
        (lambda d: d["GT"].__setitem__((1, 0), 1.7), r"variable 'GT' column 1 \(t s\): time goes backwards at row 3"),
        (lambda d: d["TD"].__setitem__((1, 2), 9.0), r"variable 'TD' row 2: beacon_id 9.0 is not in TL"),
        (lambda d: d["TD"].__setitem__((0, 3), -1.0), r"range \(variable 'TD'\) range, m -1, expected in \[0, 1000\]"),
        (lambda d: d.__setitem__("TL", np.array([[4.0, 0.0, 5.0], [4.0, 3.0, -2.0]])), r"'TL' column 1 \(id\)"),
    ],
)
def test_malformed_variables_name_file_variable_and_expectation(tmp_path: Path, edit, message: str) -> None:  # type: ignore[no-untyped-def]
    data = _tiny()
    edit(data)
    path = _write(tmp_path, data)
    with pytest.raises(RecordedDataError, match=message) as info:
        load_plaza(path)
    assert str(info.value).startswith(str(path))


def test_not_a_mat_file_and_checksum(tmp_path: Path) -> None:
    bad = tmp_path / "bad.mat"
    bad.write_bytes(b"MATLAB? no: a text file\n1 2 3\n")
    with pytest.raises(RecordedDataError, match=r"bad\.mat: not a readable MATLAB v5 file"):
        load_plaza(bad)
    good = _write(tmp_path, _tiny())
    with pytest.raises(RecordedDataError, match=r"tiny\.mat: checksum mismatch"):
        load_plaza(good, sha256="0" * 64)


def test_nominal_noise_of_an_unknown_file_is_estimated(tmp_path: Path) -> None:
    data = _tiny()
    ds = load_plaza(_write(tmp_path, data))
    noise, _ = plaza.estimate_nominal_noise(read_plaza_mat(tmp_path / "tiny.mat"))
    assert ds.sensors.range_sigma_m == noise.range_sigma_m and math.isfinite(noise.range_sigma_m)
