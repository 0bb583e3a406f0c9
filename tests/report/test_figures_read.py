"""Every figure of a report reads: legends and texts on the canvas and off the data, axis labels on every panel,
every configuration of its table drawn or named as not shown (:func:`figure_support.figure_problems`).

It runs on a small store of fake runs made here; with ``LOCBENCH_FIGURE_STORE=<results folder>`` it runs on
that store's runs instead (``results/`` after a full sweep).
"""

from __future__ import annotations

import dataclasses
import os
from pathlib import Path

import pytest
from figure_support import figure_problems
from matplotlib.figure import Figure
from test_report import _fake_run, _fake_truth

from locbench.report import figures as fg
from locbench.report.build import build_sections
from locbench.report.collect import collect
from locbench.report.context import Report
from locbench.report.doc import Plot
from locbench.report.render import plots_of
from locbench.run.store import Store

#: ``ekf_landmarks`` and ``ukf_landmarks`` get the same fake estimates (names of one length, one drift): they
#: coincide in every figure, as two filters of one model do on a benchmark.
CONFIGS = (
    "odometry",
    "ekf_landmarks",
    "ukf_landmarks",
    "pf",
    "pf[particles=100]",
    "pf[particles=300]",
    "ekf_icp[correspondence_sigmas=5.657,max_iterations=580,r_theta_rad2=0.0607,r_x_m2=0.07418]",
    "ekf_lines[chi2_threshold=27.47,odometry_sigma_theta_per_m=0.3266,sigma_rho_m=0.3632]",
)


def _store(root: Path) -> Store:
    st = Store(root)
    for seed in range(2):
        truth = _fake_truth(seed)
        st.write_truth(truth)
        for i, f in enumerate(CONFIGS):
            same = f in ("ekf_landmarks", "ukf_landmarks")
            run = _fake_run(
                truth, f, drift=0.0004 if same else 0.0005 * (i + 1), sigma=0.006 if same else 0.004 + i / 1e3
            )
            st.write_run(dataclasses.replace(run, step_ns=run.step_ns * (i + 1)))
    return st


@pytest.fixture(scope="module")
def plots(tmp_path_factory: pytest.TempPathFactory) -> list[Plot]:
    given = os.environ.get("LOCBENCH_FIGURE_STORE")
    st = Store(given) if given else _store(tmp_path_factory.mktemp("readable") / "results")
    return plots_of(build_sections(Report(collect(st))))


def test_every_figure_reads(plots: list[Plot]) -> None:
    assert len(plots) >= 5
    problems = {p.name: figure_problems(p) for p in plots}
    assert not {k: v for k, v in problems.items() if v}


def test_figures_name_what_they_show(plots: list[Plot]) -> None:
    if os.environ.get("LOCBENCH_FIGURE_STORE"):
        pytest.skip("the fake store's configurations only")
    shows = {p.name: set(p.shows) for p in plots}
    for stem in ("room_trajectories", "room_waypoint_rmse", "room_nees", "room_errors", "room_pareto"):
        assert shows[stem] == set(CONFIGS), stem


def _texts(plot: Plot) -> str:
    import matplotlib.style

    from locbench.report.render import _figure
    from locbench.report.style import MPL_STYLE

    with matplotlib.style.context(["default", MPL_STYLE]):
        fig = _figure(plot)
        fig.canvas.draw()
        return " | ".join(t.get_text().replace("\n", "") for t in fig.findobj(lambda a: hasattr(a, "get_text")))


def test_long_names_are_short_in_the_legend_with_the_full_spec_in_the_key(plots: list[Plot]) -> None:
    if os.environ.get("LOCBENCH_FIGURE_STORE"):
        pytest.skip("the fake store's configurations only")
    (par,) = (p for p in plots if p.name == "room_pareto")
    text = _texts(par)
    for name in CONFIGS[6:]:
        assert f"{fg.short_name(name)} = {name}" in text
    (wp,) = (p for p in plots if p.name == "room_waypoint_rmse")
    # the two coinciding series: one names the other
    assert "ukf_landmarks (= ekf_landmarks within 1%)" in _texts(wp)


def test_short_names_and_coinciding_series() -> None:
    import numpy as np

    long1, long2 = "pf[" + "a=1," * 10 + "b=2]", "pf[" + "c=1," * 10 + "]"
    short = fg.short_names(["pf", "pf[particles=100]", long1 + " (20 runs)", long2])
    assert list(short.values()) == [
        "pf",
        "pf[particles=100]",
        fg.short_name(long1) + " (20 runs)",
        fg.short_name(long2),
    ]
    assert fg.short_name(long1) != fg.short_name(long2) and fg.short_name(long1).startswith("pf[#")
    same = fg.coinciding(["a", "b", "c"], [np.array([1.0, 2.0]), np.array([1.005, 2.0]), np.array([1.2, 2.0])])
    assert same == {"b": "a"}


def _check(draw_fn: object, shows: tuple[str, ...] = ()) -> list[str]:
    return figure_problems(Plot("t", "", draw_fn, size=(5.0, 3.5), shows=shows))  # type: ignore[arg-type]


def test_the_check_finds_a_legend_over_data_a_missing_label_and_a_missing_configuration() -> None:
    """The check must be able to fail, on each of its rules."""

    def inside(fig: Figure) -> None:
        ax = fig.add_subplot()
        ax.plot([0, 1], [0, 1], label="a")
        ax.set_xlabel("x (m)")
        ax.set_ylabel("y (m)")
        ax.legend(loc="center")

    def unlabelled(fig: Figure) -> None:
        ax = fig.add_subplot()
        ax.plot([0, 1], [0, 1], label="a")
        fg.finish(ax, "x (m)", "", "t")

    def fine(fig: Figure) -> None:
        ax = fig.add_subplot()
        ax.plot([0, 1], [0, 1], label="a")
        fg.finish(ax, "x (m)", "y (m)", "t", absent={"b": "never lost"})

    assert any(p.startswith("legend 'a' over the data") for p in _check(inside))
    assert any("without an axis label" in p for p in _check(unlabelled))
    assert _check(fine, ("a", "b")) == []
    assert _check(fine, ("a", "c")) == ["configuration 'c' neither drawn nor named as not shown"]


def test_tuning_figure_labels_every_panel_and_names_coinciding_filters() -> None:
    from locbench.report.sections.tuned import trials_plot

    studies = [
        {"world": w, "filter": f, "trials": [{"value": v} for v in vals]}
        for w in ("room", "office")
        for f, vals in (
            ("ekf_landmarks", [0.05, 0.04, 0.03]),
            ("ukf_landmarks", [0.05, 0.04, 0.03]),
            ("pf", [0.2, 0.1]),
        )
    ]
    plot = trials_plot(studies)
    assert figure_problems(plot) == []
    assert "ukf_landmarks (= ekf_landmarks)" in _texts(plot)


def test_pareto_markers_on_top_of_each_other_stay_visible() -> None:
    from locbench.present.docfmt import LineStyle

    pts = [
        fg.ParetoPoint("a", "a", 100.0, 0.03),
        fg.ParetoPoint("b", "b", 101.0, 0.0301),
        fg.ParetoPoint("c", "c", 300.0, 0.03),
    ]
    styles = {k: LineStyle("#112233", "o", "-") for k in "abc"}
    fig = Figure()
    ax = fig.add_subplot()
    fg.draw_pareto(ax, pts, styles, "rtf", "ATE (cm)", "t")
    sizes = {ln.get_label(): ln.get_markersize() for ln in ax.get_lines() if ln.get_label() in "abc"}
    assert sizes == {"a": 5, "b": 9, "c": 5}


def _drawn(plot: Plot) -> Figure:
    import matplotlib.style

    from locbench.report.render import _figure
    from locbench.report.style import MPL_STYLE

    with matplotlib.style.context(["default", MPL_STYLE]):
        fig = _figure(plot)
        fig.canvas.draw()
    return fig


def test_trajectory_panels_have_short_titles_a_key_units_and_keep_their_tracks_inside(plots: list[Plot]) -> None:
    if os.environ.get("LOCBENCH_FIGURE_STORE"):
        pytest.skip("the fake store's configurations only")
    (traj,) = (p for p in plots if p.name == "room_trajectories")
    fig = _drawn(traj)
    panels = [ax for ax in fig.axes if ax.axison]
    assert len(panels) == len(CONFIGS)
    titles = [ax.get_title().replace("\n", "") for ax in panels]
    for name in CONFIGS[6:]:  # long: a short name over the panel, the full spec in the key
        assert fg.short_name(name) in titles and name not in titles
        assert f"{fg.short_name(name)} = {name}" in _texts(traj)
    assert "pf[particles=100]" in titles  # short enough: as it is
    for ax in panels:
        assert ax.get_xlabel() == "x (m)" and ax.get_ylabel() == "y (m)"
        for art in [*ax.get_lines(), *ax.patches]:  # every track and ellipse clipped to its own panel
            assert art.get_clip_on() and art.get_clip_box() is not None
            assert tuple(art.get_clip_box().extents) == pytest.approx(tuple(ax.bbox.extents))


def test_a_track_that_runs_away_stays_inside_its_panel() -> None:
    import numpy as np

    from locbench.present.docfmt import LineStyle

    world = fg.World(np.array([[0.0, 0.0, 4.0, 0.0]]), np.zeros((0, 2)), np.array([[0.0, 0.0], [4.0, 1.0]]))
    away = fg.Track("odometry", np.array([[0.0, 0.0], [40.0, -30.0]]), np.array([[30.0, 0.0]]), 4.0 * np.eye(2)[None])
    home = fg.Track("pf", np.array([[0.0, 0.0], [4.0, 1.0]]), np.zeros((0, 2)), np.zeros((0, 2, 2)))
    styles = {k: LineStyle("#112233", "o", "-") for k in ("odometry", "pf")}
    plot = Plot("t", "", lambda fig: fg.draw_trajectories(fig, world, [away, home], styles),
                size=fg.trajectory_size(world, [away, home]), shows=("odometry", "pf"))  # fmt: skip
    assert figure_problems(plot) == []
    fig = _drawn(plot)
    ax = next(ax for ax in fig.axes if ax.get_title().startswith("odometry"))
    assert fg.LEAVES_VIEW in ax.get_title()
    (x0, x1), (y0, y1) = fg.world_limits(world)
    assert ax.get_xlim() == (x0, x1) and ax.get_ylim() == (y0, y1)  # framed on the world, not the runaway track
    for art in [*ax.get_lines(), *ax.patches]:
        assert art.get_clip_on() and tuple(art.get_clip_box().extents) == pytest.approx(tuple(ax.bbox.extents))


#: A configuration that stores no health signal: the lost-ROC figure names it with the reason.
NO_HEALTH = CONFIGS[7]


def _lost_store(root: Path) -> Store:
    """Runs that drift lost (past 0.25 m) as their covariance grows: ekf_landmarks and ukf_landmarks alike (one
    curve), pf apart, and :data:`NO_HEALTH` without a health signal."""
    st = Store(root)
    for seed in range(2):
        truth = _fake_truth(seed)
        st.write_truth(truth)
        for f in ("ekf_landmarks", "ukf_landmarks", "pf", NO_HEALTH):
            run = _fake_run(truth, f, drift=0.008 if f == "pf" else 0.01, sigma=0.006)
            st.write_run(run if f != NO_HEALTH else dataclasses.replace(run, health={}))
    return st


def test_the_lost_roc_names_coinciding_curves_and_filters_without_a_curve(tmp_path: Path) -> None:
    st = _lost_store(tmp_path / "results")
    (roc,) = (p for p in plots_of(build_sections(Report(collect(st)))) if p.name == "lost_roc")
    assert figure_problems(roc) == []
    text = _texts(roc)
    # ekf_landmarks and ukf_landmarks report the same signal: one curve, dashed over the other and named as such
    assert "(on ekf_landmarks)" in text
    fig = _drawn(roc)
    lines = {ln.get_label().split(":")[0]: ln for ax in fig.axes for ln in ax.get_lines()}
    under, over, apart = lines["ekf_landmarks"], lines["ukf_landmarks"], lines["pf"]
    assert over.get_zorder() > under.get_zorder() and over.get_linestyle() != under.get_linestyle()
    assert "(on " not in apart.get_label()
    assert f"not shown: {fg.short_name(NO_HEALTH)} (no health signal stored)" in text
    assert f"{fg.short_name(NO_HEALTH)} = {NO_HEALTH}" in text  # its full spec in the key
