"""``locbench import`` refuses bad output with one line naming the file, the line or message, and what was expected;
nothing is stored."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

pytest.importorskip("rosbags")

from external_support import write_bag, write_tumcov

from locbench.cli import main
from locbench.core.errors import ConfigError
from locbench.run.import_runs import import_system

T = np.array([0.0, 1.0, 2.0])
MEAN = np.array([[1.0, 1.0, 0.0], [1.1, 1.0, 0.1], [1.2, 1.0, 0.2]])
COV = np.repeat(np.diag([0.01, 0.02, 0.003])[None], 3, axis=0)


def _refused(tmp_path: Path, files: list[Path], match: str, seeds: tuple[int, ...] = (0,), **options: object) -> str:
    res = tmp_path / "res"
    with pytest.raises(ConfigError, match=match) as info:
        import_system(res, "bad", "room", list(seeds), [str(f) for f in files], **options)
    assert not (res / "runs").exists()  # nothing stored
    message = str(info.value)
    assert "\n" not in message
    return message


def test_times_outside_the_dataset_are_refused_with_both_spans(tmp_path: Path) -> None:
    f = write_tumcov(tmp_path / "late.txt", T + 5.0e6, MEAN, COV)
    msg = _refused(tmp_path, [f], "do not overlap the dataset's")
    assert str(f) in msg and "5000000.0" in msg


def test_a_nan_pose_names_its_line(tmp_path: Path) -> None:
    mean = MEAN.copy()
    mean[1, 0] = np.nan
    f = write_tumcov(tmp_path / "nan.txt", T, mean, COV)
    _refused(tmp_path, [f], r"nan\.txt:3: field 2 \(x \[m\]\) is 'nan', a non-finite value")


def test_a_covariance_that_is_not_positive_definite_is_refused(tmp_path: Path) -> None:
    cov = COV.copy()
    cov[2, 0, 0] = -0.01
    f = write_tumcov(tmp_path / "npd.txt", T, MEAN, cov)
    _refused(tmp_path, [f], "line 4: covariance is not positive definite")


def test_an_asymmetric_covariance_in_a_bag_is_refused(tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> None:
    import external_support

    cov = COV.copy()
    cov[1, 0, 1] = 0.005  # only the upper term: the 6x6 message is asymmetric
    monkeypatch.setattr(external_support, "_cov36", _asymmetric_cov36)
    bag = write_bag(tmp_path / "asym", "rosbag2", (T, MEAN, cov))
    _refused(tmp_path, [bag], "message 2 of '/amcl_pose': covariance is not symmetric")


def _asymmetric_cov36(c: np.ndarray) -> np.ndarray:
    out = np.zeros((6, 6))
    idx = [0, 1, 5]
    for i in range(3):
        for j in range(i, 3):
            out[idx[i], idx[j]] = c[i, j]
            out[idx[j], idx[i]] = c[i, j] if i == j else c[j, i]
    return out.ravel()


def test_poses_in_another_frame_name_the_transform_expected(tmp_path: Path) -> None:
    bag = write_bag(tmp_path / "odomframe.bag", "rosbag1", (T, MEAN, COV), frame="odom")
    _refused(tmp_path, [bag], r"frame 'odom', expected 'map'.*transform map -> odom")


def test_a_bag_without_the_topic_lists_the_topics_it_has(tmp_path: Path) -> None:
    bag = write_bag(tmp_path / "other", "rosbag2", (T, MEAN, COV))
    msg = _refused(tmp_path, [bag], "no topic '/pose'", topics=("/pose",))
    assert "/amcl_pose (geometry_msgs/msg/PoseWithCovarianceStamped, 3 messages)" in msg


@pytest.mark.parametrize(
    ("weights", "match"),
    [
        ([0.5, -0.1, 0.6], "particle 2: weight -0.1, expected finite and >= 0"),
        ([0.5, np.nan, 0.5], "particle 2: weight nan"),
        ([0.0, 0.0, 0.0], "every weight is 0"),
    ],
)
def test_bad_particle_weights_are_refused(tmp_path: Path, weights: list[float], match: str) -> None:
    pts = np.array([[1.0, 1.0, 0.0], [1.1, 1.0, 0.0], [0.9, 1.0, 0.0]])
    clouds = [(0.0, pts, np.array([1.0, 1.0, 1.0])), (1.0, pts, np.array(weights))]
    bag = write_bag(tmp_path / "pc", "rosbag2", None, clouds=clouds)
    _refused(tmp_path, [bag], "message 2 of '/particle_cloud'.*" + match.replace("(", r"\("))


def test_a_missing_file_for_some_seeds_lists_them_and_stores_nothing(tmp_path: Path) -> None:
    write_tumcov(tmp_path / "out-0.txt", T, MEAN, COV)
    msg = _refused(tmp_path, [tmp_path / "out-{seed}.txt"], "no output file for 2 of 3 seeds", seeds=(0, 1, 2))
    assert "seed 1:" in msg and "seed 2:" in msg


def test_the_command_prints_one_line_and_exits_nonzero(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    f = tmp_path / "short.txt"
    f.write_text("0.0 1.0 1.0 0.0 0.01 0.0 0.0 0.01 0.0\n")  # nine fields
    code = main(["import", "--name", "x", "--dataset", "room", "--seed", "0", str(f), "--results", str(tmp_path / "r")])
    err = capsys.readouterr().err.strip().splitlines()
    assert code != 0 and len(err) == 1
    assert "short.txt:1" in err[0] and "9 fields" in err[0] and "10 (tumcov)" in err[0]


@pytest.mark.parametrize("fmt", ["rosbag2", "rosbag1"])
def test_a_message_recorded_before_its_stamp_names_the_file_topic_and_message(tmp_path: Path, fmt: str) -> None:
    # the second pose recorded 3 ms before the time of the data it is for: a negative latency
    bag = write_bag(
        tmp_path / ("early.bag" if fmt == "rosbag1" else "early"), fmt, (T, MEAN, COV), delays_ns=[0, -3_000_000, 0]
    )
    msg = _refused(
        tmp_path, [bag], r"message 2 of '/amcl_pose': recorded at 0\.997 s, 0\.003 s before its header stamp"
    )
    assert str(bag) in msg


def test_a_cloud_recorded_before_its_stamp_is_refused(tmp_path: Path) -> None:
    clouds = [(t, MEAN, np.ones(3)) for t in T]
    # on an exported bag's clock (+1000 s), 1 ns early
    bag = write_bag(tmp_path / "earlycloud", "rosbag2", None, clouds=clouds, cloud_delay_ns=-1, offset=1000.0)
    _refused(tmp_path, [bag], r"message 1 of '/particle_cloud': recorded at 999\.999999999 s, 1e-09 s before")
