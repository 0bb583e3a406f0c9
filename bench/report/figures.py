"""Figure drawing: pure functions from arrays to a matplotlib axis or figure (no I/O, no store).

Each function takes the axis (or figure, for small multiples), the arrays to draw and the
:class:`~locbench.report.style.LineStyle` of each series; callers take the styles from the report's one
:class:`~locbench.present.palette.Palette`, so that a filter keeps its colour and marker in every figure.
"""

from __future__ import annotations

import math
import re
from collections.abc import Mapping, Sequence
from dataclasses import dataclass, field

import numpy as np
from matplotlib.axes import Axes
from matplotlib.figure import Figure
from matplotlib.patches import Ellipse, Rectangle
from matplotlib.transforms import offset_copy
from scipy import stats

from locbench.present.docfmt import LineStyle

_CHI2_2D_95 = float(stats.chi2.ppf(0.95, 2))


def finish(
    ax: Axes, xlabel: str, ylabel: str, title: str, absent: Mapping[str, str] | None = None, note: str = ""
) -> None:
    """Axis labels, the title, the legend outside the axes (on the right, or below them when it is long), and
    below the figure its key: the full spec of every configuration shown by a short name (:func:`short_names`)
    and a ``note``; each configuration of the figure's table that is ``absent`` is a legend entry with the reason
    (by its short name too).

    Every line figure's frame: nothing of it is drawn over the data area."""
    ax.set_xlabel(xlabel)
    ax.set_ylabel(ylabel)
    fig = ax.get_figure(root=True)
    assert fig is not None  # an axis of the report's figures always has one
    # left-aligned and wrapped to the figure's width: centred over axes that the legend narrows, a long
    # title would run off the canvas on both sides
    size = float(ax.title.get_fontsize())
    ax.set_title(wrap_words(title, title_chars(fig.get_figwidth(), size)), loc="left", fontsize=size)
    handles, labels = ax.get_legend_handles_labels()
    short = short_names(labels)
    labels = [short[x] for x in labels]
    # a configuration of the figure's table drawn nowhere: a text entry of the legend with the reason (a long name
    # by its short name, the full spec in the key as for a drawn one)
    gone = short_names(list(absent or {}))
    for name, why in (absent or {}).items():
        handles.append(Rectangle((0, 0), 0, 0, visible=False))
        labels.append(wrap_label(f"not shown: {gone[name]} ({why})", 60))
    short = {**short, **gone}
    if len(labels) > LEGEND_RIGHT_MAX:
        # a long legend beside the axes would leave the data a narrow strip: below them, in columns
        ax.legend(
            handles,
            labels,
            loc="upper left",
            # below the tick labels and the x label (points, whatever the axes' height)
            bbox_to_anchor=(0.0, 0.0),
            bbox_transform=offset_copy(ax.transAxes, fig=fig, y=-30.0, units="points"),
            borderaxespad=0.0,
            ncols=max(1, min(4, int(fig.get_figwidth() * 72.0 / (CHAR_EM * 7.0 * (max(map(len, labels)) + 6))))),
        )
    else:
        ax.legend(
            handles,
            labels,
            loc="upper left",
            bbox_to_anchor=(1.01, 1.0),
            borderaxespad=0.0,
            ncols=legend_columns(fig.get_figheight(), labels),
        )
    figure_key(fig, short, note)


#: Most legend entries placed beside the axes; a longer legend goes below them.
LEGEND_RIGHT_MAX = 12
#: A configuration name longer than this is shown by a short name in figures (:func:`short_names`).
SHORT_MAX = 40
#: The figure's key (the full specs of short names, a note) is a figure legend of this label.
KEY_LABEL = "key"


def short_names(labels: Sequence[str]) -> dict[str, str]:
    """Each label as a figure or a table shows it: a configuration name longer than :data:`SHORT_MAX` characters
    becomes ``filter[#abcd]`` (the first hex digits of the full name's sha256, so that a configuration has one
    short name in every figure and table), anything after the name kept (``pf[#abcd] (20 runs)``); shorter labels
    as given."""
    out: dict[str, str] = {}
    for lab in labels:
        m = re.match(r"^([A-Za-z0-9_]+)\[([^\]]*)\](.*)$", lab, flags=re.S)
        name = lab[: len(lab) - len(m.group(3))] if m else lab
        if m is None or len(name) <= SHORT_MAX:
            out[lab] = lab
            continue
        out[lab] = f"{short_name(name)}{m.group(3)}"
    return out


def short_name(name: str) -> str:
    """``filter[#abcd]`` for a configuration name (:func:`short_names`), whatever its length."""
    import hashlib

    return f"{name.split('[', 1)[0]}[#{hashlib.sha256(name.encode()).hexdigest()[:4]}]"


def key_lines(short: Mapping[str, str], note: str = "", wrap: int | None = None) -> list[str]:
    """The lines of a figure's key: ``short = full spec`` for each shortened name, then the note, each broken
    into lines of about ``wrap`` characters (default :data:`KEY_WRAP`)."""
    width = KEY_WRAP if wrap is None else wrap
    lines = []
    for full, sh in short.items():
        if sh != full:
            name = full[: len(full) - (len(sh) - sh.index("]") - 1)]
            lines.append(wrap_label(f"{sh[: sh.index(']') + 1]} = {name}", width))
    if note:
        lines.append(wrap_words(note, width))
    return lines


#: Characters of a key line before it is wrapped.
KEY_WRAP = 110


def figure_key(fig: Figure, short: Mapping[str, str], note: str = "", wrap: int | None = None) -> None:
    """The figure's key below everything else (a figure legend of text lines, placed by the layout, or at the
    figure's lower left where a figure reserves the space itself)."""
    lines = key_lines(short, note, wrap)
    # one key per figure: the panels of a figure add their lines to it
    for old in [leg for leg in fig.legends if leg.get_label() == KEY_LABEL]:
        lines = list(dict.fromkeys([*(t.get_text() for t in old.get_texts()), *lines]))
        old.remove()
    if not lines:
        return
    blank = [Rectangle((0, 0), 0, 0, visible=False) for _ in lines]
    leg = fig.legend(
        blank,
        lines,
        loc="outside lower left",
        handlelength=0,
        handletextpad=0,
        frameon=False,
        fontsize=6.5,
        title=None,
    )
    leg.set_label(KEY_LABEL)


#: Mean width of a character of the report's sans-serif font, in font sizes (DejaVu Sans, mixed text).
CHAR_EM = 0.56


def title_chars(fig_width_in: float, fontsize_pt: float) -> int:
    """How many characters of a title fit on one line of a figure ``fig_width_in`` inches wide (less the
    y-axis label's margin)."""
    return max(20, int((fig_width_in - 0.7) * 72.0 / (CHAR_EM * fontsize_pt)))


def wrap_words(text: str, width: int) -> str:
    """``text`` broken between words into lines of at most ``width`` characters (a longer word stays whole)."""
    import textwrap

    return "\n".join(textwrap.wrap(text, width, break_long_words=False, break_on_hyphens=False)) or text


#: Height of one legend entry in legend font sizes (matplotlib's default label spacing and handle height).
LEGEND_ENTRY_EM = 1.45


def legend_columns(fig_height_in: float, labels: Sequence[str], fontsize_pt: float = 7.0) -> int:
    """Columns a legend of ``labels`` needs to fit in a figure ``fig_height_in`` inches tall (a legend taller
    than its figure is cut off at the canvas edge)."""
    lines = sum(1 + label.count("\n") for label in labels)
    per_col = max(1, int((fig_height_in - 0.4) * 72.0 / (LEGEND_ENTRY_EM * fontsize_pt)))
    return max(1, math.ceil(lines / per_col))


#: Legend labels longer than this (a tuned configuration's spec) are wrapped after commas.
LABEL_WRAP = 80


def wrap_label(label: str, width: int = LABEL_WRAP) -> str:
    """A long label broken after commas into lines of at most about ``width`` * 3/4 characters; short ones as given."""
    if len(label) <= width:
        return label
    lines, line = [], ""
    for part in label.split(","):
        piece = part + ","
        if line and len(line) + len(piece) > width * 3 // 4:
            lines.append(line)
            line = ""
        line += piece
    lines.append(line.rstrip(","))
    return "\n".join(lines)


def pareto_front(x: np.ndarray, y: np.ndarray) -> np.ndarray:
    """Indices of the points no other point beats on both axes (x higher is better, y lower is better).

    Sorted by x descending; a point is on the front when its y is below every y of a point with a higher
    or equal x (ties in x keep the lower y only).
    """
    x = np.asarray(x, dtype=np.float64)
    y = np.asarray(y, dtype=np.float64)
    ok = np.flatnonzero(np.isfinite(x) & np.isfinite(y))
    order = ok[np.lexsort((y[ok], -x[ok]))]
    front: list[int] = []
    best = math.inf
    for i in order:
        if y[i] < best:
            front.append(int(i))
            best = float(y[i])
    return np.asarray(front, dtype=np.intp)


@dataclass(frozen=True)
class ParetoPoint:
    """One filter configuration: its label, the group (filter id) its curve joins, x and y."""

    label: str
    group: str
    x: float
    y: float


@dataclass(frozen=True)
class ParetoLayers:
    """What a Pareto panel draws, in data: each group's markers and front line, and the overall front.

    The PNG (:func:`draw_pareto`) and the interactive figure are both drawn from this, so they show the
    same markers, lines and front.
    """

    #: (group, points of the group in input order, indices of the group's own front, sorted by x descending)
    groups: tuple[tuple[str, tuple[ParetoPoint, ...], tuple[int, ...]], ...]
    #: the overall front's points, x descending (drawn as a step, ``where="post"``)
    front: tuple[ParetoPoint, ...]


def pareto_layers(points: Sequence[ParetoPoint]) -> ParetoLayers:
    """Group the points by ``group`` (sorted) and find each group's front and the overall front."""
    groups = []
    for g in sorted({p.group for p in points}):
        pts = tuple(p for p in points if p.group == g)
        fr = pareto_front(np.array([p.x for p in pts]), np.array([p.y for p in pts]))
        groups.append((g, pts, tuple(int(i) for i in fr)))
    fr_all = pareto_front(np.array([p.x for p in points]), np.array([p.y for p in points]))
    return ParetoLayers(tuple(groups), tuple(points[int(i)] for i in fr_all))


def draw_pareto(
    ax: Axes,
    points: Sequence[ParetoPoint],
    styles: Mapping[str, LineStyle],
    xlabel: str,
    ylabel: str,
    title: str,
    per_config: bool = True,
) -> None:
    """Accuracy against speed, ann-benchmarks style: a marker per configuration (its own shade of the
    group's colour, edged in the group's colour), each group's own front as a line through its configurations,
    the overall front dotted; both axes logarithmic.

    ``styles`` holds the style of every group and of every point's label; the legend lists each
    configuration when ``per_config``, else each group.
    """
    layers = pareto_layers(points)
    drawn: list[tuple[float, float]] = []
    for g, pts, fr in layers.groups:
        st = styles[g]
        for p in pts:
            face = styles[p.label].color if p.label in styles else st.color
            # a marker on top of one drawn before is drawn larger and beneath it: both stay visible
            under = any(_near_log(p.x, p.y, x, y) for x, y in drawn)
            drawn.append((p.x, p.y))
            ax.plot(
                [p.x],
                [p.y],
                ls="none",
                marker=st.marker,
                color=face,
                mec=st.color,
                ms=9 if under else 5,
                zorder=1.9 if under else 2.0,
                label=p.label if per_config else None,
            )
        if not per_config:
            ax.plot([], [], ls="-", marker=st.marker, color=st.color, ms=5, label=g)
        if len(fr) > 1:
            ax.plot([pts[i].x for i in fr], [pts[i].y for i in fr], color=st.color, lw=0.8, ls=st.linestyle)
    if layers.front:
        fx = [p.x for p in layers.front]
        fy = [p.y for p in layers.front]
        ax.step(fx, fy, where="post", color="0.3", lw=0.8, ls=":", label="front (all)")
    ax.set_xscale("log")
    ax.set_yscale("log")
    finish(ax, xlabel, ylabel, title)


#: Two markers closer than this on both log axes (decades) overlap at the report's marker size.
NEAR_DECADES = 0.02


def _near_log(x0: float, y0: float, x1: float, y1: float) -> bool:
    """Whether two positive points are within :data:`NEAR_DECADES` of each other on both log axes."""
    if min(x0, y0, x1, y1) <= 0 or not all(map(math.isfinite, (x0, y0, x1, y1))):
        return False
    return abs(math.log10(x0 / x1)) < NEAR_DECADES and abs(math.log10(y0 / y1)) < NEAR_DECADES


@dataclass(frozen=True)
class World:
    """What every trajectory panel shows behind the estimate: walls, landmarks, the truth and the waypoints."""

    segments: np.ndarray  # (n, 4) x1 y1 x2 y2, m
    landmarks: np.ndarray  # (m, 2), m
    truth_xy: np.ndarray  # (k, 2), m
    truth_label: str = "ground truth"
    waypoints_xy: np.ndarray = field(default_factory=lambda: np.zeros((0, 2)))


@dataclass(frozen=True)
class Track:
    """One estimated trajectory with position covariances at a few times for the 95 % ellipses."""

    label: str
    xy: np.ndarray  # (n, 2), m
    ellipse_xy: np.ndarray  # (e, 2), m
    ellipse_cov: np.ndarray  # (e, 2, 2), m^2


def world_limits(world: World, pad_fraction: float = 0.08) -> tuple[tuple[float, float], tuple[float, float]]:
    """Axis limits that frame the world (truth, map, waypoints), never a runaway estimate."""
    pts = [world.truth_xy, world.segments.reshape(-1, 2), world.landmarks, world.waypoints_xy]
    allp = np.vstack([p for p in pts if len(p)])
    lo, hi = allp.min(axis=0), allp.max(axis=0)
    pad = pad_fraction * float(np.max(hi - lo)) + 0.3
    return (float(lo[0] - pad), float(hi[0] + pad)), (float(lo[1] - pad), float(hi[1] + pad))


def _draw_world(ax: Axes, world: World) -> None:
    for x1, y1, x2, y2 in world.segments:
        ax.plot([x1, x2], [y1, y2], color="0.65", lw=1.0, solid_capstyle="butt")
    if len(world.landmarks):
        ax.plot(world.landmarks[:, 0], world.landmarks[:, 1], ls="none", marker="^", ms=3.5, color="0.5")
    ax.plot(world.truth_xy[:, 0], world.truth_xy[:, 1], color="black", lw=0.8)
    if len(world.waypoints_xy):
        wp = world.waypoints_xy
        ax.plot(wp[:, 0], wp[:, 1], ls="none", marker="x", ms=5, color="black")


#: Width of one trajectory panel, inches, and the panels of one row.
PANEL_W = 3.4
PANEL_COLS = 3
#: A panel title's font size, pt, and the height of one of its lines, inches.
PANEL_TITLE_PT = 7.5
PANEL_TITLE_LINE_IN = 0.15


def panel_title(label: str) -> str:
    """A trajectory panel's title: the label broken after commas to the panel's width."""
    return wrap_label(label, title_chars(PANEL_W, PANEL_TITLE_PT) * 4 // 3)


#: The font size of a trajectory figure's key, pt, and the height of one of its lines, inches.
KEY_PT = 6.5
KEY_LINE_IN = 0.125


def track_key(tracks: Sequence[Track]) -> tuple[dict[str, str], list[str]]:
    """Each track's label as its panel shows it (:func:`short_names`) and the lines of the figure's key (the full
    spec of every shortened name), wrapped to the width of the figure's panels."""
    short = short_names([tr.label for tr in tracks])
    width = PANEL_W * min(PANEL_COLS, max(len(tracks), 1)) + PANEL_MARGINS_IN["left"]
    return short, key_lines(short, wrap=key_chars(width))


def key_chars(fig_width_in: float) -> int:
    """How many characters of a :data:`KEY_PT` key line fit across a figure ``fig_width_in`` inches wide."""
    return max(30, int((fig_width_in - 0.3) * 72.0 / (CHAR_EM * KEY_PT)))


def key_height(lines: Sequence[str]) -> float:
    """The height (inches) a figure reserves below its panels for a key of ``lines`` (none without lines)."""
    n = sum(1 + line.count("\n") for line in lines)
    return KEY_LINE_IN * n + 0.1 if n else 0.0


#: Fixed margins of a trajectory figure, inches: left (y tick labels and the y label), below each panel (x tick
#: labels and the x label), right, the gap between columns (the next panel's y label), above each panel's title.
PANEL_MARGINS_IN = {"left": 0.62, "xband": 0.42, "right": 0.08, "wspace": 0.62, "title_pad": 0.1}
#: A panel's title line saying that its estimate leaves the view (the axes frame the world, not the estimate).
LEAVES_VIEW = "(estimate leaves the view)"


def leaves_view(world: World, track: Track) -> bool:
    """Whether any finite point of ``track`` lies outside :func:`world_limits` (that part is clipped)."""
    (x0, x1), (y0, y1) = world_limits(world)
    xy = track.xy[np.all(np.isfinite(track.xy), axis=1)]
    return bool(len(xy)) and bool(np.any((xy[:, 0] < x0) | (xy[:, 0] > x1) | (xy[:, 1] < y0) | (xy[:, 1] > y1)))


def track_titles(world: World, tracks: Sequence[Track]) -> list[str]:
    """Each panel's title: the label (a long one by its short name, :func:`track_key`) broken to the panel's width,
    and a line when the estimate leaves the view."""
    short, _ = track_key(tracks)
    return [panel_title(short[tr.label]) + (f"\n{LEAVES_VIEW}" if leaves_view(world, tr) else "") for tr in tracks]


def _panel_rows(world: World, titles: Sequence[str]) -> tuple[int, int, float, float]:
    """Columns, rows, the height of a panel's axes and of its title band (inches) of a trajectory figure."""
    n = max(len(titles), 1)
    ncols = min(PANEL_COLS, n)
    (x0, x1), (y0, y1) = world_limits(world)
    aspect = (y1 - y0) / max(x1 - x0, 1e-9)
    lines = 1 + max((t.count("\n") for t in titles), default=0)
    title = PANEL_TITLE_LINE_IN * lines + PANEL_MARGINS_IN["title_pad"]
    return ncols, math.ceil(n / ncols), max(1.25, PANEL_W * aspect * 0.95), title


def trajectory_size(world: World, tracks: Sequence[Track]) -> tuple[float, float]:
    """The size (inches) of :func:`draw_trajectories`' figure: panels :data:`PANEL_W` wide in rows of
    :data:`PANEL_COLS`, as tall as the world's aspect asks, each with space for the longest title and its axis
    labels."""
    ncols, nrows, axes_h, title_h = _panel_rows(world, track_titles(world, tracks))
    m = PANEL_MARGINS_IN
    return PANEL_W * ncols + m["left"], nrows * (axes_h + title_h + m["xband"]) + key_height(track_key(tracks)[1])


def _fixed_panel_layout(fig: Figure, world: World, titles: Sequence[str], key_in: float = 0.0) -> dict[str, float]:
    """The grid of the panels by fixed margins instead of the constrained layout (about half of a trajectory
    figure's drawing time): the sizes of everything around a panel are known in advance, the key's ``key_in``
    inches below them too."""
    ncols, _, axes_h, title_h = _panel_rows(world, titles)
    w, h = fig.get_figwidth(), fig.get_figheight()
    m = PANEL_MARGINS_IN
    fig.set_layout_engine("none")
    return {
        "left": m["left"] / w,
        "right": 1.0 - m["right"] / w,
        "bottom": (m["xband"] + key_in) / h,
        "top": 1.0 - title_h / h,
        "wspace": m["wspace"] * ncols / (w - m["left"] - m["right"] - m["wspace"] * (ncols - 1)),
        "hspace": (title_h + m["xband"]) / axes_h,
    }


def draw_trajectories(fig: Figure, world: World, tracks: Sequence[Track], styles: Mapping[str, LineStyle]) -> None:
    """Small multiples: one panel per filter with the world, the truth and the waypoints in each, axes fitted to
    the world (what leaves it is clipped to the panel, and the panel's title says so), the estimate and its 95 %
    position ellipses; every panel has its axis labels (m, world frame) and a title of at most about a panel's
    width (a long configuration name by its short name, the full spec in the key below the panels)."""
    n = max(len(tracks), 1)
    ncols = min(PANEL_COLS, n)
    nrows = math.ceil(n / ncols)
    (x0, x1), (y0, y1) = world_limits(world)
    titles = track_titles(world, tracks)
    _, key = track_key(tracks)
    grid = _fixed_panel_layout(fig, world, titles, key_height(key))
    axes = fig.subplots(nrows, ncols, squeeze=False, sharex=True, sharey=True, gridspec_kw=grid)
    for k, ax in enumerate(axes.flat):
        if k >= len(tracks):
            ax.set_axis_off()
            continue
        tr = tracks[k]
        st = styles[tr.label]
        _draw_world(ax, world)
        ax.plot(tr.xy[:, 0], tr.xy[:, 1], color=st.color, lw=0.9)
        for m, cov in zip(tr.ellipse_xy, tr.ellipse_cov, strict=True):
            w, v = np.linalg.eigh(0.5 * (cov + cov.T))
            if not np.all(np.isfinite(w)):
                continue
            w = np.clip(w, 0.0, None)
            angle = float(np.degrees(np.arctan2(v[1, 1], v[0, 1])))
            ax.add_patch(
                Ellipse(
                    (m[0], m[1]),
                    2.0 * np.sqrt(_CHI2_2D_95 * w[1]),
                    2.0 * np.sqrt(_CHI2_2D_95 * w[0]),
                    angle=angle,
                    fill=False,
                    color=st.color,
                    lw=0.6,
                )
            )
        ax.set_xlim(x0, x1)
        ax.set_ylim(y0, y1)
        ax.set_aspect("equal", adjustable="box")
        # a tuned configuration's long name by its short name, the full spec in the figure's key
        ax.set_title(titles[k], fontsize=PANEL_TITLE_PT)
        ax.tick_params(labelsize=6.5, labelbottom=True, labelleft=True)
        ax.set_xlabel("x (m)", fontsize=7, labelpad=1.0)
        ax.set_ylabel("y (m)", fontsize=7, labelpad=1.0)
    if key:
        leg = fig.legend(
            [Rectangle((0, 0), 0, 0, visible=False) for _ in key],
            key,
            loc="lower left",
            bbox_to_anchor=(0.1 / fig.get_figwidth(), 0.0),
            handlelength=0,
            handletextpad=0,
            borderpad=0.2,
            frameon=False,
            fontsize=KEY_PT,
        )
        leg.set_label(KEY_LABEL)


#: Two series closer than this relative difference at every point are drawn over each other (on a log axis
#: 1 % is under a marker's width): :func:`coinciding` names them.
COINCIDE_RTOL = 0.01


def coinciding(labels: Sequence[str], ys: Sequence[np.ndarray], rtol: float = COINCIDE_RTOL) -> dict[str, str]:
    """For each series that coincides with an earlier one (every finite point within ``rtol``, same length and
    gaps), the label of the first series it coincides with."""
    out: dict[str, str] = {}
    for j, (lj, yj) in enumerate(zip(labels, ys, strict=True)):
        for li, yi in zip(labels[:j], ys[:j], strict=True):
            if li in out or yi.shape != yj.shape or not yi.size:
                continue
            fi, fj = np.isfinite(yi), np.isfinite(yj)
            if np.array_equal(fi, fj) and fi.any() and np.allclose(yi[fi], yj[fj], rtol=rtol, atol=0.0):
                out[lj] = li
                break
    return out


def draw_waypoint_rmse(
    ax: Axes, labels: Sequence[str], rmse_cm: Sequence[np.ndarray], styles: Mapping[str, LineStyle], title: str
) -> None:
    """RMSE at each waypoint per filter, log scale (1-5 cm filters stay visible beside dead reckoning's metres).

    Series that coincide (:func:`coinciding`) are offset sideways and their legend entries name the series
    they lie on, so that one line showing for several says so."""
    same = coinciding(labels, rmse_cm)
    n_same: dict[str, int] = {}
    for label, y in zip(labels, rmse_cm, strict=True):
        st = styles[label]
        x = np.arange(1, y.size + 1, dtype=np.float64)
        text = label
        if label in same:
            k = n_same[same[label]] = n_same.get(same[label], 0) + 1
            x = x + 0.08 * k
            text = f"{label} (= {same[label]} within {COINCIDE_RTOL:.0%})"
        ax.plot(
            x,
            y,
            color=st.color,
            marker=st.marker,
            ls=st.linestyle,
            ms=4,
            label=text,
            mfc="none" if label in same else None,
        )
    n = max((y.size for y in rmse_cm), default=0)
    ax.set_xticks(np.arange(1, n + 1))
    ax.set_yscale("log")
    finish(ax, "waypoint", "RMSE over runs (cm)", title)


@dataclass(frozen=True)
class NeesSeries:
    """Mean NEES over a filter's runs on a common time grid."""

    label: str
    mean: np.ndarray
    runs: int


def draw_nees(
    ax: Axes,
    t: np.ndarray,
    series: Sequence[NeesSeries],
    bands: Mapping[int, tuple[float, float]],
    styles: Mapping[str, LineStyle],
    title: str,
) -> None:
    """Mean NEES against time, log y, with the chi-square(3N)/N band of each run count N in its own style."""
    hatches = ("", "////", "\\\\\\\\", "xx", "..")
    for k, (n, (lo, hi)) in enumerate(sorted(bands.items())):
        ax.axhspan(
            lo,
            hi,
            facecolor="0.5",
            alpha=0.12 + 0.08 * (k % 2),
            hatch=hatches[k % len(hatches)],
            edgecolor="0.45",
            lw=0.6,
            label=f"95 % band, {n} runs",
        )
    for s in series:
        st = styles[s.label]
        y = np.where(np.isfinite(s.mean) & (s.mean > 0), s.mean, np.nan)
        ax.plot(t, y, color=st.color, ls=st.linestyle, lw=0.9, label=f"{s.label} ({s.runs} runs)")
    ax.axhline(3.0, color="black", lw=0.6, ls="--")
    ax.set_yscale("log")
    finish(ax, "t (s)", "mean NEES", title)


@dataclass(frozen=True)
class RateCurve:
    """Recovery rate against kidnap distance with its 95 % Wilson interval."""

    label: str
    style_key: str
    d: np.ndarray
    rate: np.ndarray
    low: np.ndarray
    high: np.ndarray


def draw_recovery(ax: Axes, curves: Sequence[RateCurve], styles: Mapping[str, LineStyle], title: str) -> None:
    """Recovery rate against kidnap distance, a line per filter, sideways offsets so equal rates stay apart."""
    all_d = sorted({float(d) for c in curves for d in c.d})
    log_x = bool(all_d) and all_d[0] > 0 and len(all_d) > 1
    for i, c in enumerate(curves):
        shift = (i - (len(curves) - 1) / 2.0) * 0.02
        x = c.d * 2.0**shift if log_x else c.d + shift
        # the Wilson bounds can land a rounding error inside a rate of exactly 0 or 1
        err = np.clip(np.vstack([c.rate - c.low, c.high - c.rate]), 0.0, None)
        st = styles[c.style_key]
        ax.errorbar(
            x, c.rate, yerr=err, color=st.color, marker=st.marker, ls=st.linestyle, ms=4, capsize=3, label=c.label
        )
    if log_x:
        ax.set_xscale("log", base=2)
    ax.set_xticks(all_d, [f"{d:g}" for d in all_d])
    ax.minorticks_off()
    ax.set_ylim(-0.05, 1.05)
    finish(ax, "kidnap distance D (m)", "recovery rate", title)
