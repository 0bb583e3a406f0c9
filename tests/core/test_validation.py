"""Every parameter is checked when the spec is parsed: a bad one is a one-line error and nothing is stored."""

from __future__ import annotations

import dataclasses
import inspect
from dataclasses import dataclass, field
from pathlib import Path

import pytest

from locbench.cli import main
from locbench.core.errors import ConfigError
from locbench.core.tunable import TUNABLE_KEY, TunableRange
from locbench.filters.base import BOUND_KEY, POSITIVE, POSITIVE_OR_DATASET, Bound, FilterConfig, bound
from locbench.registry import FILTERS


@pytest.mark.parametrize(
    ("filt", "dataset", "expected"),
    [
        (
            "odometry",
            "room[kidnap_m=-1]",
            "[kidnap_m=-1]: parameter 'kidnap_m' must be a distance >= 0 m, got -1.0",
        ),
        ("odometry", "office[kidnap_rad=4]", "kidnap_rad"),
        ("odometry", "office[pose_fix_sigma_m=0]", "pose_fix_sigma_m"),
        ("odometry", "lap[people=-1]", "lap[people=-1]: parameter 'people' must be a count in [0, 100]"),
        (
            "odometry",
            "lap[people=1000000]",
            "[people=1000000]: parameter 'people' must be a count in [0, 100], got 1000000",
        ),
        (
            "odometry",
            "room[laser_beams=100000000]",
            "[laser_beams=100000000]: parameter 'laser_beams' is 100000000, expected at most",
        ),
        ("odometry", "line_room[laser_beams=20000]", "line_room[laser_beams=20000]: parameter 'laser_beams' is 20000"),
        (
            "pf[particles=100000000]",
            "room",
            "[particles=100000000]: a set of particles=100000000 would take about 16 GB",
        ),
        ("pf[adaptive=kld,max_particles=100000000]", "room", "lower 'max_particles'"),
        (
            "pf[use_laser=true,laser_beams=1000000]",
            "lap",
            "[laser_beams=1000000,use_laser=true]: parameter 'laser_beams' is 1000000",
        ),
        ("odometry", "line_room[laser_sigma_m=0]", "laser_sigma_m"),
        ("odometry", "scan_grid[grid_step_m=2]", "grid_step_m"),
        ("odometry", "landmark_geometry[initial_offset_m=-2]", "initial_offset_m"),
        ("odometry", "rosbag[map=m.yaml]", "rosbag[map=m.yaml]: parameter 'path' is required"),
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


# --- bounds declared on the config fields, checked once by the config base ---------------------------------


@dataclass(frozen=True, kw_only=True)
class _Bounded(FilterConfig):
    gain: float = field(default=1.0, metadata=POSITIVE)
    margin_m: float = field(default=0.0, metadata=bound(0.0, unit="m"))
    share: float = field(default=0.5, metadata=bound(0.0, 1.0, high_open=True))
    sigma_m: float | None = field(default=None, metadata=POSITIVE_OR_DATASET)
    count: int = field(default=3, metadata=bound(2, what="an integer"))
    scale: float = field(default=1.0, metadata=bound(0.0, low_open=True, finite=True, what="a finite factor"))


@pytest.mark.parametrize(
    ("values", "message"),
    [
        ({"gain": 0.0}, "gain must be > 0, got 0.0"),
        ({"gain": float("nan")}, "gain must be > 0, got nan"),
        ({"margin_m": -0.1}, "margin_m must be >= 0 m, got -0.1"),
        ({"share": 1.0}, "share must be in [0, 1), got 1.0"),
        ({"sigma_m": 0.0}, "sigma_m must be > 0 (or None for the dataset's value), got 0.0"),
        ({"count": 1}, "count must be an integer >= 2, got 1"),
        ({"scale": float("inf")}, "scale must be a finite factor > 0, got inf"),
        ({"gain": None}, "gain must be > 0, got None"),
    ],
)
def test_field_bounds_are_checked_by_the_config_base(values: dict[str, object], message: str) -> None:
    with pytest.raises(ConfigError) as exc:
        _Bounded(**values)  # type: ignore[arg-type]
    assert str(exc.value) == message


def test_field_bounds_accept_their_ends_and_none_where_optional() -> None:
    _Bounded(margin_m=0.0, share=0.0, sigma_m=None, count=2, gain=1e-12)
    assert Bound(0.0, 1.0, low_open=True).describe() == "in (0, 1]"
    assert Bound(0.0, optional=True, none_means="").describe() == ">= 0"


def _bounded_fields() -> list[tuple[str, str, Bound, TunableRange]]:
    out = []
    for fid in FILTERS.ids():
        try:
            cls = FILTERS.load(fid).Config
        except Exception:  # an optional filter whose extra is not installed
            continue
        for f in dataclasses.fields(cls):
            b, r = f.metadata.get(BOUND_KEY), f.metadata.get(TUNABLE_KEY)
            if isinstance(b, Bound) and isinstance(r, TunableRange) and r.kind != "choice":
                out.append((fid, f.name, b, r))
    return out


def test_every_tunable_range_lies_inside_its_field_bound() -> None:
    pairs = _bounded_fields()
    assert len(pairs) > 10  # the tuned fields of the EKFs, the PF, ekf_icp, kf_linear ... declare both
    bad = [(fid, name, r.describe()) for fid, name, b, r in pairs if not (b.accepts(r.low) and b.accepts(r.high))]
    assert not bad, f"a tuner could propose a value the config refuses: {bad}"


def test_filter_configs_declare_their_bounds_instead_of_looping_over_names() -> None:
    # the pattern this replaces: a __post_init__ that loops over field names to check each one's range
    for fid in FILTERS.ids():
        try:
            cls = FILTERS.load(fid).Config
        except Exception:
            continue
        post = cls.__dict__.get("__post_init__")
        if post is not None:
            assert "getattr(self, name)" not in inspect.getsource(post), fid
