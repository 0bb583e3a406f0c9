"""The report's figures: one style per filter id in PNG and plotly alike, every configuration shown, no text
off the canvas. On a temporary store of fake runs with more configurations than one figure holds."""

from __future__ import annotations

import dataclasses
from pathlib import Path

import numpy as np
import pytest
from figure_support import texts_off_canvas
from matplotlib.colors import to_hex
from matplotlib.figure import Figure
from matplotlib.lines import Line2D
from test_report import _fake_run, _fake_truth

from locbench.present.palette import FILTER_COLORS, Palette, shade, split_by_sweep
from locbench.report import figures as fg
from locbench.report.build import build_sections
from locbench.report.collect import collect
from locbench.report.context import Report
from locbench.report.doc import Plot
from locbench.report.render import plots_of
from locbench.report.sections.experiment import MAX_LINE_SERIES, MAX_TRACK_PANELS
from locbench.report.style import MPL_STYLE
from locbench.run.store import Store

#: Eight defaults and a sweep of seven: more than one trajectory figure's panels and one line figure's series.
DEFAULTS = ("odometry", "ekf_landmarks", "ekf_icp", "ekf_lines", "gtsam_fls", "kf_linear", "pf", "ukf_landmarks")
SWEEP = tuple(f"pf[particles={n}]" for n in (100, 200, 300, 500, 2000, 3000, 10000))
#: A tuned configuration's long name (legends wrap it).
LONG = "ekf_landmarks[" + ",".join(f"param_{k}=0.{k}1234567" for k in range(8)) + "]"
CONFIGS = (*DEFAULTS, *SWEEP, LONG)


@pytest.fixture(scope="module")
def report(tmp_path_factory: pytest.TempPathFactory) -> Report:
    st = Store(tmp_path_factory.mktemp("figures") / "results")
    for seed in range(2):
        truth = _fake_truth(seed)
        st.write_truth(truth)
        for i, f in enumerate(CONFIGS):
            # along the sweep: more accurate and slower, so its configurations form a front
            k = SWEEP.index(f) + 1 if f in SWEEP else 1
            run = _fake_run(truth, f, drift=0.0005 * (i + 1) / k**2, sigma=0.005 + 0.001 * i)
            st.write_run(dataclasses.replace(run, step_ns=run.step_ns * k))
    return Report(collect(st))


@pytest.fixture(scope="module")
def plots(report: Report) -> list[Plot]:
    return plots_of(build_sections(report))


def _drawn(plot: Plot) -> Figure:
    import matplotlib.style

    with matplotlib.style.context(["default", MPL_STYLE]):
        fig = Figure(figsize=plot.size)
        plot.draw(fig)
    return fig


def test_no_text_leaves_the_canvas_in_any_figure(plots: list[Plot]) -> None:
    assert len(plots) > 5
    bad = {p.name: texts_off_canvas(p) for p in plots}
    assert not {k: v for k, v in bad.items() if v}


def test_the_check_finds_a_clipped_title() -> None:
    """The check must be able to fail: a title wider than its figure, centred, runs off both sides."""

    def draw(fig: Figure) -> None:
        ax = fig.add_subplot()
        ax.set_title("a title far too long for a figure this narrow " * 3)

    (hit,) = texts_off_canvas(Plot("clipped", "", draw, size=(3.0, 2.0)))
    assert hit.startswith("'a title far too long")


def test_every_configuration_is_in_a_trajectory_figure(report: Report, plots: list[Plot]) -> None:
    traj = [p for p in plots if p.name.startswith("room_trajectories")]
    assert len(CONFIGS) > MAX_TRACK_PANELS
    # the defaults, then each filter's configurations beside its default
    assert [p.name for p in traj] == ["room_trajectories", "room_trajectories_ekf_landmarks", "room_trajectories_pf"]
    titles: set[str] = set()
    for p in traj:
        # a long name's panel is titled by its short name (the full spec in the figure's key)
        mine = {_full_name(ax.get_title().replace("\n", "")) for ax in _drawn(p).axes if ax.get_title()}
        assert p.interactive is not None
        assert {t["name"] for t in p.interactive["data"]} >= mine
        titles |= mine
    assert titles == set(CONFIGS)


def _full_name(title: str) -> str:
    """The configuration of :data:`CONFIGS` a panel title names (by its name or its short name)."""
    return {fg.short_names([c])[c]: c for c in CONFIGS}.get(title, title)


def test_crowded_nees_waypoint_and_error_figures_are_split(plots: list[Plot]) -> None:
    for stem in ("room_nees", "room_waypoint_rmse", "room_errors"):
        parts = [p for p in plots if p.name == stem or p.name.startswith(stem + "_")]
        assert [p.name for p in parts] == [stem, f"{stem}_ekf_landmarks", f"{stem}_pf"]
        labels: set[str] = set()
        for p in parts:
            (ax,) = (a for a in _drawn(p).axes if a.get_legend() is not None)
            shown = [t.get_text().split(" (")[0] for t in ax.get_legend().get_texts()]
            assert len([s for s in shown if not s.startswith(("95 %", "pcrb"))]) <= MAX_LINE_SERIES
            labels |= {s.replace("\n", "") for s in shown}
        # a long name is shown short, with its full spec in the figure's key
        assert {fg.short_names([c])[c] for c in CONFIGS} <= labels


def _panel_colors(fig: Figure) -> dict[str, str]:
    """Each trajectory panel's title -> the colour of its estimate (the one line not black or grey)."""
    out = {}
    for ax in fig.axes:
        colors = {to_hex(ln.get_color()) for ln in ax.get_lines()} - {"#000000", "#a6a6a6", "#808080"}
        if ax.get_title():
            (out[_full_name(ax.get_title().replace("\n", ""))],) = colors
    return out


def test_a_filter_has_one_colour_in_png_and_plotly(report: Report, plots: list[Plot]) -> None:
    pal = report.palette
    seen: dict[str, str] = {}
    for p in (p for p in plots if p.name.startswith("room_trajectories")):
        png = _panel_colors(_drawn(p))
        assert p.interactive is not None
        ly = {t["name"]: t["line"]["color"] for t in p.interactive["data"] if t["name"] in png}
        assert {k: v.upper() for k, v in png.items()} == {k: v.upper() for k, v in ly.items()}
        for name, color in png.items():
            assert seen.setdefault(name, color) == color  # the default pf in both figures
            assert color.upper() == pal.style(name).color.upper()
    # the Pareto's markers: the same colours and symbols in the PNG and the interactive figure
    (par,) = (p for p in plots if p.name == "room_pareto")
    assert par.interactive is not None
    ly_marker = {t["name"]: t["marker"] for t in par.interactive["data"] if t.get("mode") == "markers"}
    ax = _drawn(par).axes[0]
    png_marker = {
        ln.get_label(): (to_hex(ln.get_markerfacecolor()), ln.get_marker())
        for ln in ax.get_lines()
        if isinstance(ln, Line2D) and ln.get_linestyle() == "None" and ln.get_label() in ly_marker
    }
    assert png_marker.keys() == ly_marker.keys() == set(CONFIGS)
    symbols = {"o": "circle", "s": "square", "^": "triangle-up", "D": "diamond", "v": "triangle-down"}
    symbols |= {"P": "cross", "X": "x", "<": "triangle-left", "*": "star"}
    for name, (color, marker) in png_marker.items():
        assert color.upper() == ly_marker[name]["color"].upper() == pal.style(name).color.upper()
        assert symbols[str(marker)] == ly_marker[name]["symbol"]


def test_plotly_pareto_has_the_pngs_lines_and_front(plots: list[Plot]) -> None:
    (par,) = (p for p in plots if p.name == "room_pareto")
    assert par.interactive is not None
    traces = par.interactive["data"]
    front = [t for t in traces if t["name"] == "front (all)"]
    assert len(front) == 1 and front[0]["line"]["shape"] == "hv"
    ax = _drawn(par).axes[0]
    (step,) = (ln for ln in ax.get_lines() if ln.get_label() == "front (all)")
    # matplotlib's step line holds the corner points too; its first and last x are the front's ends
    xs = np.asarray(step.get_xdata(), dtype=float)
    assert front[0]["x"][0] == pytest.approx(xs[0]) and front[0]["x"][-1] == pytest.approx(xs[-1])
    # each group's front line: the same points in both (the PNG's are the unlabelled lines without markers)
    png_lines = {
        (tuple(np.round(ln.get_xdata(), 9)), tuple(np.round(ln.get_ydata(), 9)))
        for ln in ax.get_lines()
        if ln.get_marker() in ("None", "", None) and ln.get_label().startswith("_") and len(ln.get_xdata()) > 1
    }
    ly_lines = {
        (tuple(np.round(t["x"], 9)), tuple(np.round(t["y"], 9)))
        for t in traces
        if t["mode"] == "lines" and t["name"] != "front (all)"
    }
    assert png_lines == ly_lines
    (pf_line,) = (t for t in traces if t["name"] == "pf front")
    assert len(pf_line["x"]) >= 3


def test_palette_is_keyed_by_filter_id_whatever_a_figure_shows() -> None:
    full = Palette(CONFIGS)
    alone = Palette(["pf", "odometry"])
    # a filter id's colour and marker do not depend on the other filters of the report
    for ident in DEFAULTS:
        assert full.style(ident)[:2] == Palette([ident]).style(ident)[:2]
    assert alone.style("pf") == full.style("pf")
    colors = [full.style(i).color for i in DEFAULTS]
    assert len(set(colors)) == len(DEFAULTS) and set(colors) <= set(FILTER_COLORS)
    assert len({full.style(i).marker for i in DEFAULTS}) == len(DEFAULTS)
    # a sweep's configurations: shades of the filter's colour, each distinct, the filter's marker
    sweep = [full.style(n) for n in SWEEP]
    assert len({s.color for s in sweep}) == len(SWEEP) and full.style("pf").color not in {s.color for s in sweep}
    assert {s.marker for s in sweep} == {full.style("pf").marker}
    # the bound's rows are black without markers
    assert full.style("pcrb").color == "#000000" and full.style("pcrb").marker == ""


def test_shade_mixes_towards_white_and_black() -> None:
    assert shade("#336699", 0.0) == "#336699"
    assert shade("#336699", 1.0) == "#FFFFFF"
    assert shade("#336699", -1.0) == "#000000"
    assert shade("#000000", 0.5) == "#808080"


def test_split_keeps_every_configuration_and_few_stay_together() -> None:
    few = ["odometry", "pf", "pf[particles=100]"]
    assert split_by_sweep(few, 10) == [("", few)]
    groups = split_by_sweep(list(CONFIGS), MAX_LINE_SERIES)
    assert [k for k, _ in groups] == ["defaults", "ekf_landmarks", "pf"]
    assert dict(groups)["pf"] == ["pf", *SWEEP]
    assert {n for _, names in groups for n in names} == set(CONFIGS)


def test_legend_columns_fit_the_figure() -> None:
    assert fg.legend_columns(4.2, ["x"] * 5) == 1
    assert fg.legend_columns(4.2, ["x"] * 60) >= 2
    assert fg.wrap_words("one two three four", 9) == "one two\nthree\nfour"


def test_report_writes_the_split_figures(tmp_path: Path, report: Report) -> None:
    """The Markdown names every figure it shows once, the split ones included."""
    from locbench.report.render import to_markdown

    md = to_markdown("t", [], build_sections(report))
    for stem in ("room_trajectories", "room_trajectories_pf", "room_nees_pf", "room_waypoint_rmse_pf"):
        assert md.count(f"(figures/{stem}.png)") == 1, stem


def test_render_png_writes_savefigs_pixels_as_rgb(plots: list[Plot]) -> None:
    """``render_png`` (one draw, then the buffer encoded without its alpha channel) gives the pixels of ``savefig``
    (which draws twice under a layout engine) for every figure of the report: constrained layouts with legends
    outside, the trajectory figures' fixed layout, log axes; the figures are opaque, so RGB loses nothing."""
    import io

    import matplotlib.style
    from PIL import Image

    from locbench.report.render import _figure, render_png
    from locbench.report.style import FIG_DPI

    assert len(plots) > 5
    for plot in plots:
        with matplotlib.style.context(["default", MPL_STYLE]):
            fig = _figure(plot)
            buf = io.BytesIO()
            fig.savefig(buf, format="png", dpi=FIG_DPI)
        ref = np.asarray(Image.open(io.BytesIO(buf.getvalue())))
        ours = Image.open(io.BytesIO(render_png(plot)))
        assert ours.mode == "RGB" and (ref[..., 3] == 255).all(), plot.name
        assert np.array_equal(np.asarray(ours), ref[..., :3]), plot.name
