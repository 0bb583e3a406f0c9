"""One experiment's section, a user's own dataset's section, and the figures of one dataset name: trajectories with
the map, position error over time, waypoint RMSE, NEES, particle count."""

from __future__ import annotations

from typing import TYPE_CHECKING

import numpy as np
from matplotlib.figure import Figure

from locbench.evaluate.aggregate import mean_over_runs, waypoint_stats
from locbench.evaluate.hold import estimate_at
from locbench.evaluate.metrics import CONFIDENCE, PARTICLES_MEAN, POSE_DOF, chi2_band
from locbench.present.experiments import Experiment, sections_for
from locbench.report import figures as fg
from locbench.report import interactive as ia
from locbench.report import tables as tb
from locbench.report.doc import Plot, Section, Table, Text
from locbench.report.names import slug

if TYPE_CHECKING:
    from locbench.report.context import Report

#: Most panels of one trajectory figure before it is split into defaults and one figure per sweep.
MAX_TRACK_PANELS = 12
#: Most series of one NEES or waypoint figure before it is split the same way.
MAX_LINE_SERIES = 10
#: Ellipses drawn along each track.
ELLIPSES_PER_TRACK = 10


def experiment_section(rep: Report, e: Experiment) -> Section:
    sec = Section(e.title, f"exp-{slug(e.dataset)}")
    text = e.text + (f" Source: {e.source.citation}." if e.source else "")
    sec.add(Text(text))
    base = e.dataset
    if not e.fold_variants and base in rep.col.datasets:
        sec.add(*dataset_blocks(rep, base))
    # with the bound's rows: an experiment's own tables show the accuracy limit too
    rows = rep.df[rep.df["dataset"].isin(rep.variants_of(e.dataset))]
    for fn in sections_for(e.dataset):
        sec.add(*fn(rows, slug(e.dataset)))
    return sec


def own_section(rep: Report, dataset: str) -> Section:
    """A user's own dataset (no built-in suite runs it): every table and figure that applies, as for a main
    comparison; its summary table and accuracy-runtime figure are in those sections."""
    shown = rep.col.display(dataset)
    sec = Section(rep.own_title(dataset), f"own-{slug(dataset)}")
    truth = next((tr for (d, _), tr in sorted(rep.col.truths.items()) if d == dataset), None)
    label = truth.truth_label if truth is not None else "reference"
    sec.add(
        Text(
            f"Every filter configuration stored on `{shown}`, scored against its {label} as the built-in worlds "
            "are; the summary table above gives each configuration's needs and, for those skipped, the reason."
        ),
        *dataset_blocks(rep, dataset),
    )
    return sec


def dataset_blocks(rep: Report, dataset: str) -> list[Table | Plot]:
    """The comparison and waypoint tables and the figures of one dataset name (those that apply)."""
    filters = rep.filters_on(dataset)
    bounds = rep.bounds_on(dataset)
    out: list[Table | Plot] = []
    shown = rep.col.display(dataset)
    if filters:
        caption = f"`{shown}`: mean ± 95 % interval over seeds"
        out.append(tb.comparison_table(rep.rows(dataset), filters, caption, bounds, rep.eligible(filters)))
    wt = tb.waypoint_table(rep.rows(dataset), filters + bounds, f"`{shown}`: RMSE at each waypoint over runs (cm)")
    if wt is not None:
        out.append(wt)
    count = count_plot(rep, dataset)
    out += [
        *trajectory_plots(rep, dataset),
        *error_plots(rep, dataset),
        *waypoint_plots(rep, dataset),
        *nees_plots(rep, dataset),
        *([count] if count is not None else []),
    ]
    return out


def error_plots(rep: Report, dataset: str) -> list[Plot]:
    """Each configuration's position error over time on the first seed (log scale): one figure, or the defaults
    and one per sweep past :data:`MAX_LINE_SERIES`, so that no configuration is left out."""
    keys = sorted(k for k in rep.col.ok_dirs if k[0] == dataset and not rep.col.is_global(k[1]))
    if not keys:
        return []
    seed = keys[0][2]
    names = rep.col.filter_order({k[1] for k in keys if k[2] == seed})
    truth = rep.col.truths[(dataset, seed)]
    gt = truth.ground_truth
    errors: dict[str, np.ndarray] = {}
    for f in names:
        run = rep.col.read_run(dataset, f, seed)
        est = estimate_at(run.t, run.mean, gt.t)[:, :2]
        errors[f] = np.linalg.norm(est - gt.xy, axis=1) * 100.0
    t = gt.t - gt.t[0]
    plots: list[Plot] = []
    for key, part in rep.split(names, MAX_LINE_SERIES):
        series = [(f, errors[f]) for f in part]
        styles = rep.styles_for(part)
        title = f"seed {seed}{_part(key)}: position error over time (log scale)"
        caption = f"`{rep.col.display(dataset)}`, {title}, against the {truth.truth_label}"

        def draw(fig: Figure, series: list = series, styles: dict = styles, title: str = title) -> None:
            ax = fig.add_subplot()
            for f, err in series:
                st = styles[f]
                ok = np.isfinite(err) & (err > 0)
                ax.plot(t[ok], err[ok], color=st.color, ls=st.linestyle, lw=0.9, label=f)
            ax.set_yscale("log")
            fg.finish(ax, "t from the start (s)", "position error (cm)", title)

        stem = f"{slug(dataset)}_errors{_stem_part(key)}"
        plots.append(Plot(stem, caption, draw, size=(7.5, 4.2), shows=tuple(part)))
    return plots


def trajectory_plots(rep: Report, dataset: str) -> list[Plot]:
    """Every configuration's estimate on the first seed: one figure, or, past :data:`MAX_TRACK_PANELS`, one
    of the defaults and one per sweep (:meth:`Report.split`), so that no configuration is left out."""
    keys = [k for k in rep.col.ok_dirs if k[0] == dataset and not rep.col.is_global(k[1])]
    if not keys:
        return []
    seed = min(k[2] for k in keys)
    truth = rep.col.truths[(dataset, seed)]
    filters = rep.col.filter_order({k[1] for k in keys if k[2] == seed})
    gt = truth.ground_truth
    world = fg.World(
        truth.map_segments,
        truth.map_landmarks,
        gt.xy,
        truth.truth_label,
        truth.waypoints.xy if truth.waypoints is not None else np.zeros((0, 2)),
    )
    t_marks = np.linspace(gt.t[0], gt.t[-1], ELLIPSES_PER_TRACK + 2)[1:-1]
    tracks: dict[str, fg.Track] = {}
    for f in filters:
        run = rep.col.read_run(dataset, f, seed)
        tracks[f] = fg.Track(
            f,
            run.mean[:, :2],
            estimate_at(run.t, run.mean, t_marks)[:, :2],
            estimate_at(run.t, run.cov, t_marks)[:, :2, :2],
        )
    plots = []
    for key, names in rep.split(filters, MAX_TRACK_PANELS):
        what = {"": "each filter's", "defaults": "each filter's default"}.get(key, f"`{key}`'s configurations'")
        caption = (
            f"`{dataset}`, seed {seed}: {what} estimate (colour) with 95 % position ellipses, the "
            f"{truth.truth_label} (black), the map (grey) and the waypoints (x)"
        )
        stem = f"{slug(dataset)}_trajectories{_stem_part(key)}"
        title = f"{dataset}{_part(key)}, seed {seed}: trajectories"
        plots.append(_trajectory_plot(rep, stem, caption, title, world, [tracks[f] for f in names]))
    return plots


def _trajectory_plot(rep: Report, stem: str, caption: str, title: str, world: fg.World, tracks: list[fg.Track]) -> Plot:
    styles = rep.styles_for([tr.label for tr in tracks])

    def draw(fig: Figure) -> None:
        fg.draw_trajectories(fig, world, tracks, styles)

    size = fg.trajectory_size(world, tracks)
    interactive = ia.tracks(title, world, tracks, styles)
    return Plot(stem, caption, draw, size=size, interactive=interactive, shows=tuple(tr.label for tr in tracks))


def count_plot(rep: Report, dataset: str) -> Plot | None:
    """The particle count over time of the filters whose count adapts (KLD sampling), first seed."""
    keys = sorted(k for k in rep.col.ok_dirs if k[0] == dataset and not rep.col.is_global(k[1]))
    if not keys or not (rep.rows(dataset)["metric"] == PARTICLES_MEAN).any():
        return None
    seed = keys[0][2]
    series: list[tuple[str, np.ndarray, np.ndarray]] = []
    for f in rep.filters_on(dataset):
        sub = rep.rows(dataset)
        if (dataset, f, seed) not in rep.col.ok_dirs or not len(tb.values(sub[sub["filter"] == f], PARTICLES_MEAN)):
            continue
        run = rep.col.read_run(dataset, f, seed)
        count = run.diagnostics.get("particles")
        if count is None or not np.isfinite(count).any():
            continue
        ok = np.isfinite(count)
        if np.nanmax(count) > np.nanmin(count):
            series.append((f, run.t[ok], count[ok]))
    if not series:
        return None
    styles = rep.styles_for([f for f, _, _ in series])
    title = f"{dataset}, seed {seed}: particle count after each step (adaptive filters)"

    def draw(fig: Figure) -> None:
        ax = fig.add_subplot()
        for f, t, c in series:
            st = styles[f]
            ax.step(t, c, where="post", color=st.color, ls=st.linestyle, lw=0.9, label=f)
        ax.set_yscale("log")
        fg.finish(ax, "t (s)", "particles", title)

    return Plot(f"{slug(dataset)}_particle_count", title, draw)


def waypoint_plots(rep: Report, dataset: str) -> list[Plot]:
    """RMSE at each waypoint: one figure, or the defaults and one per sweep past :data:`MAX_LINE_SERIES`."""
    ws = waypoint_stats(rep.rows(dataset))
    if not len(ws):
        return []
    filters = [f for f in rep.filters_on(dataset) if (ws["filter"] == f).any()]
    bounds = [b for b in rep.bounds_on(dataset) if (ws["filter"] == b).any()]
    plots = []
    for key, names in rep.split(filters, MAX_LINE_SERIES):
        labels = names + bounds
        series = [
            ws[ws["filter"] == f].sort_values("waypoint")["rmse_m"].to_numpy(dtype=np.float64) * 100.0 for f in labels
        ]
        styles = rep.bound_styles(labels)
        title = f"{dataset}{_part(key)}: waypoint RMSE over runs (log scale; black: the bound)"

        def draw(
            fig: Figure,
            labels: list[str] = labels,
            series: list = series,
            styles: dict = styles,
            title: str = title,
        ) -> None:
            fg.draw_waypoint_rmse(fig.add_subplot(), labels, series, styles, title)

        plots.append(Plot(f"{slug(dataset)}_waypoint_rmse{_stem_part(key)}", title, draw, shows=tuple(labels)))
    return plots


def nees_plots(rep: Report, dataset: str) -> list[Plot]:
    """Mean NEES over runs: one figure, or the defaults and one per sweep past :data:`MAX_LINE_SERIES`."""
    entries = sorted((f, s) for (d, f), s in rep.col.nees.items() if d == dataset and not rep.col.is_global(f))
    if not entries:
        return []
    seed = min(k[2] for k in rep.col.ok_dirs if k[0] == dataset)
    grid = rep.col.truths[(dataset, seed)].ground_truth.t
    order = rep.col.filter_order({f for f, _ in entries})
    by = dict(entries)
    mean = {f: fg.NeesSeries(f, mean_over_runs(grid, by[f])[0], len(by[f])) for f in order}
    plots = []
    for key, names in rep.split(order, MAX_LINE_SERIES):
        series = [mean[f] for f in names]
        bands = {n: chi2_band(POSE_DOF, n, CONFIDENCE) for n in sorted({s.runs for s in series})}
        styles = rep.styles_for(names)
        title = f"{dataset}{_part(key)}: mean NEES over runs"
        caption = f"{title} (pose, heading wrapped; runs from a uniform prior left out)"

        def draw(
            fig: Figure, series: list = series, bands: dict = bands, styles: dict = styles, title: str = title
        ) -> None:
            fg.draw_nees(fig.add_subplot(), grid, series, bands, styles, title)

        stem = f"{slug(dataset)}_nees{_stem_part(key)}"
        plots.append(Plot(stem, caption, draw, size=(7.5, 4.2), shows=tuple(names)))
    return plots


def _part(key: str) -> str:
    """A split figure's part in its title: ``, defaults`` or ``, pf's configurations``."""
    return {"": "", "defaults": ", defaults"}.get(key, f", {key}'s configurations")


def _stem_part(key: str) -> str:
    """A split figure's part in its file stem: the defaults keep the figure's own name."""
    return f"_{slug(key)}" if key and key != "defaults" else ""
