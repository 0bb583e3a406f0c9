"""``locbench export --format rosbag2|rosbag1``: the bag opens with rosbags and holds the dataset's messages."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

pytest.importorskip("rosbags")

from locbench.cli import main
from locbench.core.events import LandmarkObservations, LaserScan, Odometry, PoseFix
from locbench.datasets.recorded.ros_map import load_map_server_map
from locbench.datasets.recorded.tum import read_tum
from locbench.registry import make_dataset
from locbench.run.ros_messages import SIM_EPOCH_S, typestore
from locbench.run.rosbag_export import TOPICS, export_ros


def _read(bag: Path) -> dict[str, tuple[str, int]]:
    from rosbags.highlevel import AnyReader

    with AnyReader([bag], default_typestore=typestore()) as reader:
        return {n: (i.msgtype or "", int(i.msgcount)) for n, i in reader.topics.items()}


def test_office_rosbag2_has_every_topic_with_its_type_and_count(tmp_path: Path) -> None:
    assert main(["export", "--format", "rosbag2", "--dataset", "office", "--seed", "0", "--out", str(tmp_path)]) == 0
    ds = make_dataset("office", 0)
    topics = _read(tmp_path / "bag")
    n_odo = sum(isinstance(e, Odometry) for e in ds.events)
    want = {
        "/odom": n_odo + 1,  # the odometry origin, then one pose per increment
        "/tf": n_odo + 1,
        "/tf_static": 1,
        "/scan": sum(isinstance(e, LaserScan) for e in ds.events),
        "/landmarks": sum(isinstance(e, LandmarkObservations) for e in ds.events),
        "/fix": sum(isinstance(e, PoseFix) for e in ds.events),
        "/map": 1,
    }
    for topic, count in want.items():
        assert topics[topic] == (TOPICS[topic], count), topic
    assert topics["/clock"][1] == len({e.t for e in ds.events} | {ds.events[0].t})
    assert min(want.values()) > 0
    # the map reads back as the dataset's grid, the truth on the bag's clock
    grid = load_map_server_map(tmp_path / "map.yaml")
    assert grid.shape == ds.world.occupancy.shape
    np.testing.assert_array_equal(grid.occupied(), ds.world.occupancy.occupied())
    truth = read_tum(tmp_path / "truth.tum")
    np.testing.assert_allclose(truth.t - SIM_EPOCH_S, ds.ground_truth.t, rtol=0, atol=1e-9)
    # the example beside the launch file is what the export writes for office seed 0
    example = Path(__file__).parents[2] / "examples" / "nav2_amcl" / "amcl_office_params.yaml"
    assert (tmp_path / "nav2_amcl_params.yaml").read_text() == example.read_text()


def test_rosbag1_odometry_integrates_the_increments(tmp_path: Path) -> None:
    from rosbags.highlevel import AnyReader

    res = export_ros("room", 1, tmp_path, "rosbag1")
    ds = make_dataset("room", 1)
    odo = [e for e in ds.events if isinstance(e, Odometry)]
    with AnyReader([res.bag], default_typestore=typestore()) as reader:
        conns = [c for c in reader.connections if c.topic == "/odom"]
        poses = []
        for conn, _, raw in reader.messages(connections=conns):
            m = reader.deserialize(raw, conn.msgtype)
            q = m.pose.pose.orientation
            poses.append((m.pose.pose.position.x, m.pose.pose.position.y, 2 * np.arctan2(q.z, q.w)))
    p = np.array(poses)
    assert p.shape == (len(odo) + 1, 3)
    # the increment between consecutive poses, in the earlier robot frame, is the event's
    d = p[1:, :2] - p[:-1, :2]
    c, s = np.cos(p[:-1, 2]), np.sin(p[:-1, 2])
    dx, dy = c * d[:, 0] + s * d[:, 1], -s * d[:, 0] + c * d[:, 1]
    np.testing.assert_allclose(dx, [e.dx for e in odo], rtol=0, atol=1e-9)
    np.testing.assert_allclose(dy, [e.dy for e in odo], rtol=0, atol=1e-9)
    assert res.counts["/odom"] == len(odo) + 1


def test_an_existing_bag_is_never_overwritten(tmp_path: Path) -> None:
    (tmp_path / "dataset.bag").write_bytes(b"someone's bag")
    with pytest.raises(Exception, match="already exists"):
        export_ros("room", 0, tmp_path, "rosbag1")
    assert (tmp_path / "dataset.bag").read_bytes() == b"someone's bag"
