"""ROS 1 and ROS 2 bags: the tests write small bags from a synthetic run and load them back through the builder.

The run is ``tiny_circle`` seed 0 (340 odometry poses, 85 scans, 340 truth poses; the heading crosses +-pi):
odometry messages integrate its increments in an odometry frame of their own, scans and truth are copied, the
map is its world's grid saved as a map_server map. Stamps are offset to Unix-like times, as in real bags.
"""

from __future__ import annotations

import dataclasses
import json
import math
from collections.abc import Callable
from pathlib import Path
from typing import Any

import numpy as np
import pytest

from locbench.core.errors import ConfigError, DataNotFound
from locbench.core.events import LandmarkObservations, LaserScan, Odometry, PoseFix
from locbench.core.geometry import quaternion_to_yaw, wrap_angle
from locbench.datasets.dataset import Dataset, WorldMap
from locbench.datasets.recorded.files import RecordedDataError
from locbench.datasets.recorded.ros_map import save_map_server_map
from locbench.evaluate.metrics import align, ate
from locbench.registry import DATASETS, make_dataset, make_filter
from locbench.run.filter_pass import run_filter

rosbags = pytest.importorskip("rosbags", reason="rosbags is not installed: pip install 'locbench[ros]'")

from locbench.datasets.recorded.rosbag import (  # noqa: E402  (after the importorskip)
    RosbagDataset,
    clean_ranges,
    load_rosbag,
    odometry_increments,
)

OFFSET_S = 1_700_000_000.0
ODOM_START = (1.0, -2.0, 2.5)  # the odometry frame's own origin: it must drop out of the increments
# The synthetic run's nominal noise, so that the bag's dataset hands filters the same values.
NOISE = {
    "laser_sigma_m": 0.01,
    "odometry_sigma_xy_per_m": 0.0070710678118654745,
    "odometry_sigma_theta_per_m": 0.035355339059327376,
    "odometry_sigma_theta_per_rad": 0.015811388300841896,
    "initial_sigma_xy_m": 0.01,
    "initial_sigma_theta_rad": math.radians(1.0),
}

Msg = tuple[str, str, Any, int]  # topic, type, message, record time ns


class _Bag:
    """Builds the messages of a dataset with one typestore (ROS 1 or ROS 2)."""

    def __init__(self, ros1: bool) -> None:
        from rosbags.typesys import Stores, get_typestore

        self.ros1 = ros1
        self.ts = get_typestore(Stores.ROS1_NOETIC if ros1 else Stores.ROS2_HUMBLE)
        self.T = self.ts.types

    def header(self, t: float, frame: str) -> tuple[Any, int]:
        ns = round((t + OFFSET_S) * 1e9)
        stamp = self.T["builtin_interfaces/msg/Time"](sec=ns // 10**9, nanosec=ns % 10**9)
        hdr = self.T["std_msgs/msg/Header"]
        return (hdr(seq=0, stamp=stamp, frame_id=frame) if self.ros1 else hdr(stamp=stamp, frame_id=frame)), ns

    def pose(self, x: float, y: float, th: float) -> Any:
        T = self.T
        return T["geometry_msgs/msg/Pose"](
            position=T["geometry_msgs/msg/Point"](x=x, y=y, z=0.0),
            orientation=T["geometry_msgs/msg/Quaternion"](x=0.0, y=0.0, z=math.sin(th / 2), w=math.cos(th / 2)),
        )

    def odometry(self, t: float, pose: tuple[float, float, float], v: float, omega: float) -> tuple[Any, int]:
        T = self.T
        hdr, ns = self.header(t, "odom")
        vec = T["geometry_msgs/msg/Vector3"]
        twist = T["geometry_msgs/msg/Twist"](linear=vec(x=v, y=0.0, z=0.0), angular=vec(x=0.0, y=0.0, z=omega))
        msg = T["nav_msgs/msg/Odometry"](
            header=hdr,
            child_frame_id="base_link",
            pose=T["geometry_msgs/msg/PoseWithCovariance"](pose=self.pose(*pose), covariance=np.zeros(36)),
            twist=T["geometry_msgs/msg/TwistWithCovariance"](twist=twist, covariance=np.zeros(36)),
        )
        return msg, ns

    def scan(self, e: LaserScan) -> tuple[Any, int]:
        hdr, ns = self.header(e.t, "laser")
        n = e.ranges.shape[0]
        msg = self.T["sensor_msgs/msg/LaserScan"](
            header=hdr,
            angle_min=e.angle_min,
            angle_max=e.angle_min + (n - 1) * e.angle_increment,
            angle_increment=e.angle_increment,
            time_increment=0.0,
            scan_time=0.0,
            range_min=e.range_min,
            range_max=e.range_max,
            ranges=e.ranges.astype(np.float32),
            intensities=np.zeros(0, np.float32),
        )
        return msg, ns

    def truth(self, t: float, pose: tuple[float, float, float], msgtype: str) -> tuple[Any, int]:
        T = self.T
        if msgtype == "nav_msgs/msg/Odometry":
            return self.odometry(t, pose, 0.0, 0.0)
        hdr, ns = self.header(t, "map")
        if msgtype == "geometry_msgs/msg/PoseStamped":
            return T["geometry_msgs/msg/PoseStamped"](header=hdr, pose=self.pose(*pose)), ns
        pwc = T["geometry_msgs/msg/PoseWithCovariance"](pose=self.pose(*pose), covariance=np.zeros(36))
        return T["geometry_msgs/msg/PoseWithCovarianceStamped"](header=hdr, pose=pwc), ns

    def messages(self, ds: Dataset, truth_type: str) -> list[Msg]:
        out: list[Msg] = []
        x, y, th = ODOM_START
        out.append(("/odom", "nav_msgs/msg/Odometry", *self.odometry(float(ds.ground_truth.t[0]), (x, y, th), 0, 0)))
        for e in ds.events:
            if isinstance(e, Odometry):
                c, s = math.cos(th), math.sin(th)
                x, y, th = x + c * e.dx - s * e.dy, y + s * e.dx + c * e.dy, th + e.dtheta
                assert e.v is not None and e.omega is not None
                out.append(("/odom", "nav_msgs/msg/Odometry", *self.odometry(e.t, (x, y, th), e.v, e.omega)))
            elif isinstance(e, LaserScan):
                out.append(("/scan", "sensor_msgs/msg/LaserScan", *self.scan(e)))
        gt = ds.ground_truth
        for t, (px, py), pth in zip(gt.t, gt.xy, gt.theta, strict=True):
            out.append(("/ground_truth", truth_type, *self.truth(float(t), (px, py, pth), truth_type)))
        out.sort(key=lambda m: m[3])
        return out

    def write(self, path: Path, msgs: list[Msg], storage: str = "sqlite3") -> Path:
        if self.ros1:
            from rosbags.rosbag1 import Writer as Writer1

            writer: Any = Writer1(path)
        else:
            from rosbags.rosbag2 import StoragePlugin
            from rosbags.rosbag2 import Writer as Writer2

            plugin = StoragePlugin.MCAP if storage == "mcap" else StoragePlugin.SQLITE3
            writer = Writer2(path, version=9, storage_plugin=plugin)
        with writer:
            conns: dict[str, Any] = {}
            for topic, typ, msg, ns in msgs:
                if topic not in conns:
                    conns[topic] = writer.add_connection(topic, typ, typestore=self.ts)
                raw = self.ts.serialize_ros1(msg, typ) if self.ros1 else self.ts.serialize_cdr(msg, typ)
                writer.write(conns[topic], ns, raw)
        return path


# kind -> (ROS 1?, storage, truth message type): every truth type and every storage once
KINDS = {
    "ros1": (True, "", "nav_msgs/msg/Odometry"),
    "ros2-sqlite3": (False, "sqlite3", "geometry_msgs/msg/PoseStamped"),
    "ros2-mcap": (False, "mcap", "geometry_msgs/msg/PoseWithCovarianceStamped"),
}


@pytest.fixture(scope="module")
def synthetic() -> Dataset:
    return make_dataset("tiny_circle", 0)


@pytest.fixture(scope="module")
def folder(tmp_path_factory: pytest.TempPathFactory, synthetic: Dataset) -> Path:
    d = tmp_path_factory.mktemp("bags")
    assert synthetic.world.occupancy is not None
    save_map_server_map(synthetic.world.occupancy, d / "map.yaml")
    return d


@pytest.fixture(scope="module")
def bags(folder: Path, synthetic: Dataset) -> Callable[[str], Path]:
    made: dict[str, Path] = {}

    def get(kind: str) -> Path:
        if kind not in made:
            ros1, storage, truth_type = KINDS[kind]
            b = _Bag(ros1)
            path = folder / (f"{kind}.bag" if ros1 else kind)
            made[kind] = b.write(path, b.messages(synthetic, truth_type), storage)
        return made[kind]

    return get


def _odometry(ds: Dataset) -> list[Odometry]:
    return [e for e in ds.events if isinstance(e, Odometry)]


def _scans(ds: Dataset) -> list[LaserScan]:
    return [e for e in ds.events if isinstance(e, LaserScan)]


@pytest.mark.parametrize("kind", list(KINDS))
def test_bag_round_trips_events_truth_and_map(
    kind: str, bags: Callable[[str], Path], folder: Path, synthetic: Dataset
) -> None:
    ds = load_rosbag(bags(kind), folder / "map.yaml", **NOISE)
    ds.check()
    assert ds.metadata["warnings"] == []  # the commanded twist agrees with the increments: no warning
    assert ds.metadata["truth_type"] == KINDS[kind][2]
    assert ds.metadata["format"] == ("ROS 1 bag" if kind == "ros1" else "ROS 2 bag")
    # odometry: the increments come back whatever the odometry frame's origin
    got, want = _odometry(ds), _odometry(synthetic)
    assert len(got) == len(want) == 339
    np.testing.assert_allclose([e.t - OFFSET_S for e in got], [e.t for e in want], atol=1e-6)
    np.testing.assert_allclose([e.delta for e in got], [e.delta for e in want], atol=1e-9)
    np.testing.assert_allclose([(e.v, e.omega) for e in got], [(e.v, e.omega) for e in want], atol=1e-12)
    assert all(e.d_left is None and e.dt is not None and 0.04 < e.dt < 0.06 for e in got)
    # scans: float32 ranges; no return stays inf
    gs, ws = _scans(ds), _scans(synthetic)
    assert len(gs) == len(ws) == 85
    for a, b in zip(gs, ws, strict=True):
        assert a.t - OFFSET_S == pytest.approx(b.t, abs=1e-6)
        assert a.angle_min == pytest.approx(b.angle_min, abs=1e-6)
        assert a.angle_increment == pytest.approx(b.angle_increment, abs=1e-7)
        assert (a.range_min, a.range_max) == pytest.approx((b.range_min, b.range_max), abs=1e-6)
        np.testing.assert_array_equal(np.isinf(a.ranges), np.isinf(b.ranges))
        fin = np.isfinite(b.ranges)
        np.testing.assert_allclose(a.ranges[fin], b.ranges[fin], rtol=1e-6)
        assert a.sensor_pose == (0.0, 0.0, 0.0)
    assert any(np.isinf(s.ranges).any() for s in gs)  # the run has dropouts: the case is exercised
    # truth and initial belief
    gt, wt = ds.ground_truth, synthetic.ground_truth
    np.testing.assert_allclose(gt.t - OFFSET_S, wt.t, atol=1e-6)
    np.testing.assert_allclose(gt.xy, wt.xy, atol=1e-12)
    np.testing.assert_allclose(wrap_angle(gt.theta - wt.theta), 0.0, atol=1e-12)
    np.testing.assert_allclose(ds.initial.mean, wt.poses[0], atol=1e-12)
    np.testing.assert_allclose(np.sqrt(np.diag(ds.initial.cov)), [0.01, 0.01, math.radians(1.0)])
    # the map and the nominal noise
    assert ds.world.occupancy is not None and synthetic.world.occupancy is not None
    np.testing.assert_array_equal(ds.world.occupancy.occupancy, synthetic.world.occupancy.occupancy)
    assert ds.sensors.laser_sigma_m == 0.01 and ds.sensors.wheelbase_m is None
    # map lines extracted from the grid lie on the world's walls (the 6 m x 6 m box)
    assert ds.world.lines is not None and len(ds.world.lines) == 4
    ends = ds.world.lines.segments.reshape(-1, 2)
    np.testing.assert_array_less(np.minimum(np.abs(ends), np.abs(ends - 6.0)).min(axis=1), 0.05)


def _odometry_and_laser_only(ds: Dataset, like: Dataset) -> Dataset:
    """The synthetic run as the bag holds it: no wheel travel, no landmarks or fixes, the bag's nominal noise."""
    events = tuple(
        dataclasses.replace(e, d_left=None, d_right=None) if isinstance(e, Odometry) else e
        for e in ds.events
        if isinstance(e, (Odometry, LaserScan))
    )
    return dataclasses.replace(ds, events=events, world=WorldMap(occupancy=ds.world.occupancy), sensors=like.sensors)


def _ate(flt: str, ds: Dataset) -> float:
    trace = run_filter(make_filter(flt), ds, np.random.default_rng(0))
    assert trace.status == "ok", trace.message
    return ate(align(trace.t, trace.mean, ds.ground_truth.t, ds.ground_truth.poses))


def test_filters_on_the_bag_match_the_synthetic_run(
    bags: Callable[[str], Path], folder: Path, synthetic: Dataset
) -> None:
    ds = load_rosbag(bags("ros1"), folder / "map.yaml", **NOISE)
    same = _odometry_and_laser_only(synthetic, ds)
    odo = _ate("odometry", ds)
    assert odo == pytest.approx(_ate("odometry", synthetic), rel=1e-6)
    # ekf_icp is deterministic: the bag's data (float32 ranges, offset stamps) give the same estimate
    icp_bag = _ate("ekf_icp", ds)
    assert icp_bag == pytest.approx(_ate("ekf_icp", same), rel=1e-3)
    assert icp_bag == pytest.approx(_ate("ekf_icp", synthetic), rel=0.1)
    assert icp_bag < 0.5 * odo
    # the particle filter on the laser alone: close to its run on the full synthetic data (landmarks too)
    pf_bag = _ate("pf[use_laser=true]", ds)
    assert pf_bag == pytest.approx(_ate("pf[use_laser=true]", synthetic), rel=0.5)
    assert pf_bag < 0.2 * odo


def test_builder_through_the_registry(bags: Callable[[str], Path], folder: Path, isolated_registries: None) -> None:
    DATASETS.register("rosbag", "locbench.datasets.recorded.rosbag:RosbagDataset", requires_modules=("rosbags",))
    assert DATASETS.unavailable_reason("rosbag") is not None  # no default recording: conformance checks skip
    spec = f"rosbag[path={bags('ros2-sqlite3')},map={folder / 'map.yaml'},truth_topic=/ground_truth,laser_x_m=0.1]"
    ds = make_dataset(spec, 3)
    assert ds.id == "rosbag" and ds.name.startswith("rosbag[laser_x_m=0.1,map=")
    assert _scans(ds)[0].sensor_pose == (0.1, 0.0, 0.0)
    assert [e.delta.tolist() for e in _odometry(make_dataset(spec, 4))] == [e.delta.tolist() for e in _odometry(ds)]
    assert RosbagDataset().fetch(RosbagDataset.Params(path=str(bags("ros2-sqlite3")))) == [str(bags("ros2-sqlite3"))]


def test_truth_span_trims_the_events(bags: Callable[[str], Path], folder: Path, synthetic: Dataset) -> None:
    b = _Bag(True)
    msgs = [
        m
        for m in b.messages(synthetic, "nav_msgs/msg/Odometry")
        if m[0] != "/ground_truth" or 2.0 <= m[3] * 1e-9 - OFFSET_S <= 12.0
    ]
    ds = load_rosbag(b.write(folder / "trim.bag", msgs), folder / "map.yaml")
    t0, t1 = ds.ground_truth.t[0], ds.ground_truth.t[-1]
    assert t0 - OFFSET_S == pytest.approx(2.0, abs=1e-6) and t1 - OFFSET_S == pytest.approx(12.0, abs=1e-6)
    assert all(t0 < e.t <= t1 for e in ds.events if isinstance(e, Odometry))
    assert all(t0 <= e.t <= t1 for e in ds.events)
    # the first increment starts at the odometry pose stamped at the first truth time
    want = [e for e in _odometry(synthetic) if 2.0 < e.t <= 12.0 + 1e-9]
    got = _odometry(ds)
    assert len(got) == len(want)
    np.testing.assert_allclose([e.delta for e in got], [e.delta for e in want], atol=1e-9)


def test_scan_topic_can_be_ignored_and_then_no_map_is_needed(bags: Callable[[str], Path], folder: Path) -> None:
    ds = load_rosbag(bags("ros1"), scan_topic="")
    assert not _scans(ds) and ds.world.occupancy is None and ds.world.lines is None
    assert load_rosbag(bags("ros1"), folder / "map.yaml", map_lines=False).world.lines is None
    with pytest.raises(ConfigError, match=r"85 scans on '/scan' need a map: give map="):
        load_rosbag(bags("ros1"))


# --- malformed input -----------------------------------------------------------------------------


def test_missing_topic_lists_the_bags_topics(bags: Callable[[str], Path]) -> None:
    with pytest.raises(RecordedDataError, match=r"ros1\.bag: no topic '/gt' \(truth_topic\); the bag has: "
                       r"/ground_truth \(nav_msgs/msg/Odometry, 340 messages\), /odom .*, /scan "):  # fmt: skip
        load_rosbag(bags("ros1"), truth_topic="/gt")


def test_wrong_topic_type(bags: Callable[[str], Path]) -> None:
    with pytest.raises(RecordedDataError, match=r"topic '/ground_truth' \(scan_topic\) has type nav_msgs/msg/Odometry, "
                       r"expected sensor_msgs/msg/LaserScan"):  # fmt: skip
        load_rosbag(bags("ros1"), scan_topic="/ground_truth")
    with pytest.raises(RecordedDataError, match=r"topic '/scan' \(odom_topic\) has type sensor_msgs/msg/LaserScan"):
        load_rosbag(bags("ros2-mcap"), odom_topic="/scan")


def test_stamps_going_backwards(folder: Path, synthetic: Dataset) -> None:
    b = _Bag(False)
    msgs = [m for m in b.messages(synthetic, "geometry_msgs/msg/PoseStamped") if m[3] < (OFFSET_S + 6.01) * 1e9]
    odo = [k for k, m in enumerate(msgs) if m[0] == "/odom"]
    assert len(odo) == 121
    k = odo[100]
    topic, typ, msg, ns = msgs[k]
    back = ns - 10**9  # header one second in the past; the bag's record time stays in order
    stamp = b.T["builtin_interfaces/msg/Time"](sec=back // 10**9, nanosec=back % 10**9)
    msg = dataclasses.replace(msg, header=dataclasses.replace(msg.header, stamp=stamp))
    msgs[k] = (topic, typ, msg, ns)
    path = b.write(folder / "backwards", msgs)
    msg = (
        r"backwards: topic '/odom' message 101 of 121: header stamp 1700000004\.0 s goes backwards from "
        r"1700000004\.95 s \(expected non-decreasing stamps; stamps=bag uses the recording time instead\)"
    )
    with pytest.raises(RecordedDataError, match=msg):
        load_rosbag(path, folder / "map.yaml")
    # the recording times are in order: they can be used instead
    assert len(_odometry(load_rosbag(path, folder / "map.yaml", stamps="bag"))) == 120


def test_missing_and_unreadable_bags(tmp_path: Path, folder: Path, bags: Callable[[str], Path]) -> None:
    # a path the user typed is an error, never a "data not found" skip
    with pytest.raises(RecordedDataError, match=r"nothing\.bag: missing bag .*expected a ROS 1 \.bag file") as info:
        load_rosbag(tmp_path / "nothing.bag")
    assert not isinstance(info.value, DataNotFound)
    with pytest.raises(RecordedDataError, match=r"gone\.yaml: missing map") as info:
        load_rosbag(bags("ros1"), tmp_path / "gone.yaml")
    assert not isinstance(info.value, DataNotFound)
    cut = tmp_path / "cut.bag"
    cut.write_bytes(bags("ros1").read_bytes()[:5000])
    with pytest.raises(RecordedDataError, match=r"cut\.bag: unreadable bag"):
        load_rosbag(cut, folder / "map.yaml")
    (tmp_path / "ros2").mkdir()
    with pytest.raises(RecordedDataError, match=r"ros2: unreadable bag"):
        load_rosbag(tmp_path / "ros2")
    with pytest.raises(ConfigError, match="parameter 'path' is required"):
        RosbagDataset().build(RosbagDataset.Params(), np.random.default_rng(0))
    with pytest.raises(ConfigError, match="'laser_sigma_m' must be a finite number >= 0"):
        load_rosbag(bags("ros1"), laser_sigma_m=-1.0)


def test_a_relative_path_is_found_under_the_data_folder(
    bags: Callable[[str], Path], folder: Path, monkeypatch: pytest.MonkeyPatch
) -> None:
    monkeypatch.setenv("LOCBENCH_DATA", str(folder))
    ds = load_rosbag("ros1.bag", "map.yaml")
    assert ds.metadata["source"] == str(bags("ros1"))


# --- conversions ---------------------------------------------------------------------------------


def test_clean_ranges_marks_every_invalid_reading_as_no_return() -> None:
    r = clean_ranges(np.array([0.5, np.nan, np.inf, -np.inf, 0.01, 7.0, 6.0, 0.1]), 0.1, 6.0)
    np.testing.assert_array_equal(r, [0.5, np.inf, np.inf, np.inf, np.inf, np.inf, 6.0, 0.1])


def test_quaternion_yaw_and_increments() -> None:
    for yaw in (-3.1, -1.0, 0.0, 0.7, math.pi):
        q = np.array([0.0, 0.0, math.sin(yaw / 2), math.cos(yaw / 2)])
        assert quaternion_to_yaw(q) == pytest.approx(yaw)
        assert quaternion_to_yaw(-q) == pytest.approx(yaw)  # q and -q are the same rotation
    pose = np.array([[1.0, 1.0, math.pi / 2], [1.0, 2.0, math.pi - 0.1], [0.0, 2.0, -math.pi + 0.1]])
    inc = odometry_increments(pose)
    np.testing.assert_allclose(inc, [[1.0, 0.0, math.pi / 2 - 0.1], [math.cos(0.1), math.sin(0.1), 0.2]], atol=1e-12)


# --- twist check, fixes and sidecar files ---------------------------------------------------------------------


def test_a_zero_twist_while_the_pose_moves_is_a_warning(folder: Path, synthetic: Dataset) -> None:
    b = _Bag(True)
    msgs = []
    for topic, typ, msg, ns in b.messages(synthetic, "nav_msgs/msg/Odometry"):
        if topic == "/odom":
            vec = b.T["geometry_msgs/msg/Vector3"](x=0.0, y=0.0, z=0.0)
            zero = b.T["geometry_msgs/msg/Twist"](linear=vec, angular=vec)
            msg = dataclasses.replace(msg, twist=dataclasses.replace(msg.twist, twist=zero))
        msgs.append((topic, typ, msg, ns))
    ds = load_rosbag(b.write(folder / "zero-twist.bag", msgs), folder / "map.yaml")
    (w,) = ds.metadata["warnings"]
    assert w.startswith("topic '/odom': odometry twist contradicts its pose: the twist is zero in ")
    assert "kf_linear" in w


def _latlon(east: np.ndarray, north: np.ndarray, lat0: float, lon0: float) -> tuple[np.ndarray, np.ndarray]:
    """The inverse of geodetic_to_enu by fixed-point steps (converges to well below a micrometre here)."""
    from locbench.datasets.recorded.rosbag import geodetic_to_enu

    m_per_deg_lat, m_per_deg_lon = 111_000.0, 111_000.0 * math.cos(math.radians(lat0))
    lat, lon = lat0 + north / m_per_deg_lat, lon0 + east / m_per_deg_lon
    for _ in range(8):
        e, n = geodetic_to_enu(lat, lon, lat0, lon0)
        lat, lon = lat + (north - n) / m_per_deg_lat, lon + (east - e) / m_per_deg_lon
    return lat, lon


def test_navsatfix_becomes_map_frame_position_fixes(folder: Path, synthetic: Dataset) -> None:
    lat0, lon0, yaw = 50.8, 12.9, 0.3
    b = _Bag(False)
    msgs = b.messages(synthetic, "geometry_msgs/msg/PoseStamped")
    gt = synthetic.ground_truth
    pick = np.arange(0, len(gt), 20)
    c, sn = math.cos(yaw), math.sin(yaw)
    xy = gt.xy[pick]
    east, north = c * xy[:, 0] - sn * xy[:, 1], sn * xy[:, 0] + c * xy[:, 1]
    lat, lon = _latlon(east, north, lat0, lon0)
    T = b.T
    for j, k in enumerate(pick):
        hdr, ns = b.header(float(gt.t[k]), "gps")
        status = T["sensor_msgs/msg/NavSatStatus"](status=-1 if j == 3 else 0, service=1)
        cov = np.array([1.0, 0, 0, 0, 4.0, 0, 0, 0, 9.0])
        fix = T["sensor_msgs/msg/NavSatFix"](
            header=hdr, status=status, latitude=float(lat[j]), longitude=float(lon[j]), altitude=300.0,
            position_covariance=cov, position_covariance_type=2 if j % 2 else 0,
        )  # fmt: skip
        msgs.append(("/gps", "sensor_msgs/msg/NavSatFix", fix, ns))
    msgs.sort(key=lambda m: m[3])
    path = b.write(folder / "gps", msgs)
    with pytest.raises(ConfigError, match="'fix_topic' needs the map origin's fix_lat0_deg"):
        load_rosbag(path, folder / "map.yaml", fix_topic="/gps")
    ds = load_rosbag(
        path, folder / "map.yaml", fix_topic="/gps", fix_lat0_deg=lat0, fix_lon0_deg=lon0, fix_yaw_rad=yaw,
        fix_sigma_xy_m=1.5,
    )  # fmt: skip
    fixes = [e for e in ds.events if isinstance(e, PoseFix)]
    assert len(fixes) == len(pick) - 1 and ds.metadata["fixes_without_fix"] == 1
    keep = [j for j in range(len(pick)) if j != 3]
    np.testing.assert_allclose([f.z for f in fixes], xy[keep], atol=1e-6)
    rot = np.array([[c, sn], [-sn, c]])
    for f, j in zip(fixes, keep, strict=True):
        want = rot @ np.diag([1.0, 4.0]) @ rot.T if j % 2 else np.diag([1.5**2, 1.5**2])
        np.testing.assert_allclose(f.cov, want, atol=1e-12)
    assert PoseFix in ds.declared and ds.sensors.pose_fix_sigma_xy_m == 1.5


def test_landmark_waypoint_and_event_sidecars(
    bags: Callable[[str], Path], folder: Path, synthetic: Dataset, tmp_path: Path
) -> None:
    from locbench.datasets.recorded.jsonl_events import event_object

    lm = synthetic.world.landmarks
    assert lm is not None and synthetic.waypoints is not None
    (tmp_path / "lm.txt").write_text(
        "".join(f"{i} {x!r} {y!r}\n" for i, (x, y) in zip(lm.ids.tolist(), lm.xy.tolist(), strict=True))
    )
    wp = synthetic.waypoints
    (tmp_path / "wp.txt").write_text(
        "".join(f"{t + OFFSET_S!r} {x!r} {y!r}\n" for t, (x, y) in zip(wp.t.tolist(), wp.xy.tolist(), strict=True))
    )
    sightings = [e for e in synthetic.events if isinstance(e, LandmarkObservations)]
    lines = [json.dumps(event_object(dataclasses.replace(e, t=e.t + OFFSET_S))) for e in sightings]
    (tmp_path / "ev.jsonl").write_text("\n".join(lines) + "\n")
    bags_path = bags("ros1")
    side = {"landmarks": str(tmp_path / "lm.txt"), "waypoints": str(tmp_path / "wp.txt")}
    ds = load_rosbag(bags_path, folder / "map.yaml", events=str(tmp_path / "ev.jsonl"), **side, **NOISE)
    got = [e for e in ds.events if isinstance(e, LandmarkObservations)]
    assert len(got) == len(sightings) > 0 and LandmarkObservations in ds.declared
    for a, e in zip(got, sightings, strict=True):
        assert np.array_equal(a.ids, e.ids) and np.array_equal(a.ranges, e.ranges)
    assert ds.world.landmarks is not None and np.array_equal(ds.world.landmarks.xy, lm.xy)
    assert ds.waypoints is not None and len(ds.waypoints) == len(wp)
    assert str(tmp_path / "ev.jsonl") in ds.sources
    assert _ate("ekf_landmarks", ds) < 0.5 * _ate("odometry", ds)
    # odometry in the sidecar would be counted twice: refused
    (tmp_path / "odo.jsonl").write_text('{"t": 1700000001.0, "type": "odometry", "dx": 0, "dy": 0, "dtheta": 0}\n')
    with pytest.raises(RecordedDataError, match=r"odo\.jsonl: has Odometry events, expected only landmarks, ranges"):
        load_rosbag(bags_path, folder / "map.yaml", events=str(tmp_path / "odo.jsonl"))
    with pytest.raises(RecordedDataError, match=r"nope\.txt: missing landmarks"):
        load_rosbag(bags_path, folder / "map.yaml", landmarks=str(tmp_path / "nope.txt"))
