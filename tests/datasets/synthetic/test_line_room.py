"""The ``line_room`` scenario (report 002) and the report 002 claims evaluated on it."""

from __future__ import annotations

import numpy as np
import pandas as pd
import pytest

from locbench import claims
from locbench.core.errors import ConfigError
from locbench.core.events import LaserScan, Odometry
from locbench.datasets.dataset import MapKind
from locbench.datasets.synthetic.line_room import line_room_world
from locbench.registry import make_dataset
from locbench.report.doc import Plot, Table
from locbench.report.render import render_png


@pytest.fixture(scope="module")
def small() -> object:
    return make_dataset("line_room[laser_beams=31]", 0)


def test_world_is_polygonal_with_short_lines() -> None:
    w = line_room_world()
    lm = w.line_map()
    normals = np.round(np.degrees(lm.rho_psi()[:, 1])) % 180
    assert len(set(normals.tolist())) >= 4  # slanted walls: more than two directions
    assert np.min(lm.lengths()) <= 0.4 + 1e-9  # the pillar
    assert w.landmarks.shape == (0, 2)


def test_build_contract(small: object) -> None:
    ds = small
    ds.check()  # type: ignore[attr-defined]
    assert ds.world.kinds == frozenset({MapKind.LINES, MapKind.OCCUPANCY})  # type: ignore[attr-defined]
    assert len(ds.waypoints) == 7  # type: ignore[attr-defined]
    scans = [e for e in ds.events if isinstance(e, LaserScan)]  # type: ignore[attr-defined]
    assert scans and scans[0].ranges.shape == (31,)
    assert any(isinstance(e, Odometry) and e.d_left is not None for e in ds.events)  # type: ignore[attr-defined]
    assert ds.sensors.laser_sigma_m == 0.01  # type: ignore[attr-defined]
    # the robot (about 0.2 m in radius) keeps clear of every wall, door jambs included
    assert float(np.min(line_room_world().wall_distance(ds.ground_truth.xy))) > 0.3  # type: ignore[attr-defined]


def test_same_seed_same_data_and_sigma_reaches_spec() -> None:
    a = make_dataset("line_room[laser_beams=31,laser_sigma_m=0.05]", 3)
    b = make_dataset("line_room[laser_beams=31,laser_sigma_m=0.05]", 3)
    assert a.sensors.laser_sigma_m == 0.05
    sa = [e.ranges for e in a.events if isinstance(e, LaserScan)]
    sb = [e.ranges for e in b.events if isinstance(e, LaserScan)]
    assert all(np.array_equal(x, y) for x, y in zip(sa, sb, strict=True))


@pytest.mark.parametrize("spec", ["line_room[laser_sigma_m=0]", "line_room[laser_beams=1]", "line_room[kidnap_m=-1]"])
def test_bad_params_raise(spec: str) -> None:
    with pytest.raises(ConfigError):
        make_dataset(spec, 0)


# --- claims of report 002 ------------------------------------------------------------------------------


def _rows(
    ds: str, flt: str, ate: list[float], acc: list[float] | None = None
) -> list[tuple[str, str, int, str, float]]:
    out = [(ds, flt, s, "ate_m", v) for s, v in enumerate(ate)]
    if acc is not None:
        out += [(ds, flt, s, "accepted_fraction", v) for s, v in enumerate(acc)]
    return out


#: Seeds of the synthetic metrics: enough for the claims' one-sided paired tests to find a difference.
SEEDS = 8


def _frame(with_acc: bool, length_helps: bool) -> pd.DataFrame:
    rows = []
    for ds, scale in (("line_room", 1.0), ("line_room[laser_sigma_m=0.05]", 3.0)):
        for chi2, ate, acc in ((2.0, 0.05, 0.6), (9.21, 0.01, 0.95)):
            for flag in (True, False):
                extra = 0.0 if flag or not length_helps else 0.002
                name = f"ekf_lines[chi2_threshold={chi2:g},reject_longer={'true' if flag else 'false'}]"
                # a per-seed wobble: paired differences that are not all tied
                wobble = [1e-4 * s for s in range(SEEDS)]
                ates = [scale * ate + extra + w for w in wobble]
                rows += _rows(ds, name, ates, [acc + w for w in wobble] if with_acc else None)
        rows += _rows(ds, "odometry", [1.0] * SEEDS)
    return pd.DataFrame(rows, columns=["dataset", "filter", "seed", "metric", "value"])


def _verdicts(df: pd.DataFrame) -> dict[str, str]:
    return {c.id: c.evaluate(df).verdict for c in claims.claims_for("line_room", across_variants=True)}


def test_claims_on_synthetic_metrics() -> None:
    v = _verdicts(_frame(with_acc=True, length_helps=True))
    assert v == {
        "line_room_gate_lowers_error": "reproduced",
        "line_room_gate_accepts_more": "reproduced",
        "line_room_length_check_helps": "reproduced",
    }
    v = _verdicts(_frame(with_acc=False, length_helps=False))
    assert v["line_room_gate_accepts_more"] == "not evaluated"
    assert v["line_room_length_check_helps"] == "not reproduced"
    empty = pd.DataFrame(columns=["dataset", "filter", "seed", "metric", "value"])
    assert set(_verdicts(empty).values()) == {"not evaluated"}


def test_gate_claims_are_not_judged_on_one_length_check_setting() -> None:
    # Worded "with the length check on and off": a sweep stored with the check on only is not evaluated.
    df = _frame(with_acc=True, length_helps=True)
    on_only = df[~df["filter"].str.contains("reject_longer=false")]
    v = _verdicts(on_only)
    assert v["line_room_gate_lowers_error"] == "not evaluated"
    assert v["line_room_gate_accepts_more"] == "not evaluated"
    assert (
        "length check on and with it off"
        in claims.claims_for("line_room", across_variants=True)[0].evaluate(on_only).measured
    )


def test_gate_section_gives_table_and_figure() -> None:
    (fn,) = claims.sections_for("line_room")
    table, plot = fn(_frame(with_acc=True, length_helps=True), "line_room")
    assert isinstance(table, Table) and isinstance(plot, Plot)
    assert plot.name == "line_room_chi2_sweep"
    assert "accepted lines (%)" in table.header and table.rows
    assert render_png(plot)[:4] == b"\x89PNG"
