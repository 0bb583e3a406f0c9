"""Every numeric parameter of every registered dataset and filter is bounded when its spec is parsed."""

from __future__ import annotations

import dataclasses
import json
from pathlib import Path
from typing import Any

import numpy as np
import pytest

from locbench.cli import main
from locbench.core.errors import ConfigError, LocbenchError
from locbench.core.spec import MAX_MAGNITUDE, param_fields, parse_bound
from locbench.registry import DATASETS, FILTERS, make_dataset, make_filter, resolve_dataset, resolve_filter

#: Values no physical parameter takes; an integer field also gets integers too large for a float or a C long.
EXTREMES = ("1e308", "-1e308", "1e300", "nan", "inf", "-inf")
INT_EXTREMES = (str(10**30), str(-(10**30)), str(2**63))
#: Synthetic datasets whose build is fast enough to run for every accepted extreme value.
#: Parameters a dataset requires, given beside the one under test.
REQUIRED = {"rosbag": "map=m.yaml,path=x.bag,"}
SYNTHETIC = {"room", "lap", "line_room", "landmark_geometry", "tiny_line", "tiny_circle", "office", "scan_grid"}


def _numeric_fields(kind: str) -> list[tuple[str, str, Any, Any]]:
    """(id, field, its dataclass field, its parse bound) of every numeric parameter of every registered entry."""
    reg, attr = (DATASETS, "Params") if kind == "dataset" else (FILTERS, "Config")
    out = []
    for ident in reg.ids():
        if reg.missing_dependency(ident):
            continue
        cls = getattr(reg.load(ident), attr)
        declared = {f.name: f for f in dataclasses.fields(cls)}
        for name, tp in param_fields(cls).items():
            b = parse_bound(declared[name], tp)
            if b is not None:
                out.append((ident, name, declared[name], b))
    return out


DATASET_FIELDS = _numeric_fields("dataset")
FILTER_FIELDS = _numeric_fields("filter")


def _extremes(f: Any) -> tuple[str, ...]:
    return EXTREMES + (INT_EXTREMES if "int" in str(f.type) else ())


def test_the_fields_are_found() -> None:
    """The enumeration is not empty by accident: the parameters the bounds were written for are in it."""
    names = {(i, n) for i, n, _, _ in DATASET_FIELDS + FILTER_FIELDS}
    for cell in [("room", "kidnap_m"), ("plaza", "range_offset_m"), ("lost_in_the_woods", "t_start_s")]:
        assert cell in names
    assert ("pf", "particles") in names and len(FILTER_FIELDS) > 100


@pytest.mark.parametrize(("ident", "name", "f", "b"), DATASET_FIELDS + FILTER_FIELDS, ids=lambda v: str(v)[:30])
def test_every_numeric_field_has_a_finite_bound_that_holds_its_default(ident: str, name: str, f: Any, b: Any) -> None:
    assert b.finite and -MAX_MAGNITUDE <= b.low <= b.high <= max(MAX_MAGNITUDE, b.high)
    assert np.isfinite(b.low) and np.isfinite(b.high), f"{ident}.{name}: {b.describe()}"
    if f.default is not dataclasses.MISSING:
        assert b.accepts(f.default), f"{ident}.{name}: default {f.default!r} outside {b.describe()}"


def _refused_or_built(kind: str, ident: str, name: str, value: str, b: Any) -> None:
    spec = f"{ident}[{REQUIRED.get(ident, '')}{name}={value}]" if kind == "dataset" else f"{ident}[{name}={value}]"
    resolve = resolve_dataset if kind == "dataset" else resolve_filter
    try:
        resolve(spec)
    except ConfigError as exc:
        text = str(exc)
        assert len(text.splitlines()) == 1, text
        assert text.split(":")[0].startswith(f"{ident}[") and name in text and value in text, text
        # the parse bound, or the class's own rule (checked first: it says more), says what is expected
        assert b.describe() in text or any(w in text for w in ("must", "expected", "need")), text
        return
    # accepted: then the build (synthetic datasets) or the reset must not meet trouble
    if kind == "dataset":
        if ident in SYNTHETIC:
            make_dataset(spec, 0)
        return
    _reset_on_any(make_filter(spec), ident)


def _reset_on_any(filt: Any, ident: str) -> None:
    for d in ("tiny_line", "line_room", "office"):
        ds = make_dataset(d, 0)
        if filt.requires <= ds.world.kinds():
            filt.reset(ds.initial, ds.world, ds.sensors, np.random.default_rng(0))
            return
    pytest.fail(f"{ident}: no dataset of the test has its maps")


@pytest.mark.parametrize(("ident", "name", "f", "b"), DATASET_FIELDS, ids=lambda v: str(v)[:30])
def test_an_extreme_dataset_value_is_refused_when_parsed_or_builds(ident: str, name: str, f: Any, b: Any) -> None:
    for value in _extremes(f):
        _refused_or_built("dataset", ident, name, value, b)


@pytest.mark.parametrize(("ident", "name", "f", "b"), FILTER_FIELDS, ids=lambda v: str(v)[:30])
def test_an_extreme_filter_value_is_refused_when_parsed_or_resets(ident: str, name: str, f: Any, b: Any) -> None:
    for value in _extremes(f):
        _refused_or_built("filter", ident, name, value, b)


@pytest.mark.parametrize(
    "spec",
    ["room[kidnap_m=1e308]", "plaza[range_offset_m=1e6]", "lost_in_the_woods[t_start_s=1e300]", "office[kidnap_m=26]"],
)
def test_the_values_that_failed_at_build_are_refused_when_parsed(spec: str) -> None:
    with pytest.raises(ConfigError, match=r"must be .* in \[") as info:
        resolve_dataset(spec)
    assert str(info.value).startswith(spec)


@pytest.mark.parametrize("spec", ["room[kidnap_m=7.28]", "lap[kidnap_m=0]", "room[kidnap_m=0]"])
def test_a_kidnap_inside_the_world_is_accepted(spec: str) -> None:
    resolve_dataset(spec)


def test_the_cli_refuses_an_unbounded_value_in_one_line(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    args = ["run", "--filter", "odometry", "--dataset", "room[kidnap_m=1e308]", "--results", str(tmp_path)]
    assert main([*args, "--no-progress"]) == 2
    err = capsys.readouterr().err.strip()
    assert len(err.splitlines()) == 1 and "room[kidnap_m=1e308]" in err and "7.28011" in err
    assert not (tmp_path / "runs").exists()


def test_a_textlog_whose_events_is_null_is_one_line_naming_file_and_field(tmp_path: Path) -> None:
    folder = tmp_path / "log"
    assert main(["export", "--format", "textlog", "--dataset", "tiny_line", "--out", str(folder)]) == 0
    manifest = folder / "textlog.json"
    for key in ("events", "truth"):
        data = json.loads(manifest.read_text(encoding="utf-8"))
        data[key] = None
        manifest.write_text(json.dumps(data), encoding="utf-8")
        with pytest.raises(LocbenchError) as info:
            make_dataset(f"textlog[path={folder}]", 0)
        text = str(info.value)
        assert len(text.splitlines()) == 1 and str(manifest) in text and f"'{key}'" in text and "null" in text
        data[key] = {"events": "events.jsonl", "truth": "truth.tum"}[key]
        manifest.write_text(json.dumps(data), encoding="utf-8")
