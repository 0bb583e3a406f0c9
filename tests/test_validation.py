"""Every parameter is checked when the spec is parsed: a bad one is a one-line error and nothing is stored."""

from __future__ import annotations

from pathlib import Path

import pytest

from locbench.cli import main


@pytest.mark.parametrize(
    ("filt", "dataset", "expected"),
    [
        ("odometry", "room[kidnap_m=-1]", "room: parameter 'kidnap_m' must be a distance >= 0 m, got -1.0"),
        ("odometry", "office[kidnap_rad=4]", "kidnap_rad"),
        ("odometry", "office[pose_fix_sigma_m=0]", "pose_fix_sigma_m"),
        ("odometry", "lap[people=-1]", "lap: parameter 'people' must be a count in [0, 100]"),
        ("odometry", "lap[people=1000000]", "lap: parameter 'people' must be a count in [0, 100], got 1000000"),
        ("odometry", "room[laser_beams=100000000]", "room: parameter 'laser_beams' is 100000000, expected at most"),
        ("odometry", "line_room[laser_beams=20000]", "line_room: parameter 'laser_beams' is 20000"),
        ("pf[particles=100000000]", "room", "pf: a set of particles=100000000 would take about 16 GB"),
        ("pf[adaptive=kld,max_particles=100000000]", "room", "lower 'max_particles'"),
        ("pf[use_laser=true,laser_beams=1000000]", "lap", "pf: parameter 'laser_beams' is 1000000"),
        ("odometry", "line_room[laser_sigma_m=0]", "laser_sigma_m"),
        ("odometry", "scan_grid[grid_step_m=2]", "grid_step_m"),
        ("odometry", "landmark_geometry[initial_offset_m=-2]", "initial_offset_m"),
        ("odometry", "rosbag[map=m.yaml]", "rosbag: parameter 'path' is required"),
        ("pf[particles=1]", "room", "particles"),
        ("gtsam_fls[lag_s=0]", "room", "lag_s must be > 0 s"),
        ("ekf_landmarks[gate_probability=1.5]", "room", "gate_probability must be in (0, 1)"),
        ("pf[particles=100|0]", "room", "particles"),  # every point of a grid is checked
    ],
)
def test_bad_parameters_fail_before_anything_runs(
    filt: str, dataset: str, expected: str, tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    # a spec naming an optional filter or loader is validated once its extra is installed
    for ident, module in (("gtsam_fls", "gtsam"), ("rosbag", "rosbags")):
        if ident in filt or ident in dataset:
            pytest.importorskip(module, reason=f"{ident} needs {module}")
    res = tmp_path / "res"
    assert main(["run", "--filter", filt, "--dataset", dataset, "--results", str(res), "--no-progress"]) == 2
    err = capsys.readouterr().err
    assert expected in err and err.count("\n") == 1 and "rosbag: rosbag:" not in err
    assert not res.exists()  # nothing stored, not even a folder
