"""Plotting helpers shared by the notebooks (kept out of the notebooks, as in the filterpy book)."""
from __future__ import annotations

import numpy as np

__all__ = ["HOUSE_COLORS", "HOUSE_STYLE", "use_house_style",
           "draw_room", "draw_path", "points_view_m", "mark_beyond_view", "map_row", "mean_with_band", "error_cdf",
           "heat_map", "heat_map_notes", "map_view_m",
           "map_layout", "map_panels", "draw_floor", "MAP_MARGIN_M", "MAP_FIGURE_WIDTH_IN", "MAP_FIGURE_ASPECT",
           "MAP_PANEL_PAD_IN", "MAP_MAX_PANEL_HEIGHT_IN", "tracks_figure"]


#: the colour cycle of every report figure: Okabe and Ito's palette for colour-blind readers (blue, vermillion,
#: bluish green, reddish purple, orange, sky blue, black, yellow), distinct also in greyscale pairs
HOUSE_COLORS = ("#0072B2", "#D55E00", "#009E73", "#CC79A7", "#E69F00", "#56B4E9", "#000000", "#F0E442")

#: matplotlib settings of the house style (:func:`use_house_style`) beside the palette: legends that fit (smaller
#: text, a translucent frame, placed where they cover least), lines and markers one size everywhere
HOUSE_STYLE = {
    "legend.fontsize": "small", "legend.framealpha": 0.85, "legend.loc": "best", "legend.borderaxespad": 0.4,
    "lines.linewidth": 1.6, "lines.markersize": 5,
}


def use_house_style() -> None:
    """Set the house style (:data:`HOUSE_STYLE`) in matplotlib's rcParams: every figure drawn afterwards in this
    process uses it. :class:`locbook.Report` calls it when a notebook makes its report, so every report figure
    shares one palette and one look; a colour a notebook passes explicitly still wins."""
    import matplotlib
    from cycler import cycler
    matplotlib.rcParams.update({**HOUSE_STYLE, "axes.prop_cycle": cycler(color=list(HOUSE_COLORS))})


def draw_room(ax, size_m, anchors_m=None, *, label_anchors: bool = True, margin_m: float = 0.0):
    """Outline a rectangular room ``(width, length)`` with anchors as squares."""
    w, h = size_m
    ax.plot([0, w, w, 0, 0], [0, 0, h, h, 0], color="0.3", lw=1.5)
    if anchors_m is not None:
        anchors_m = np.asarray(anchors_m)
        ax.plot(anchors_m[:, 0], anchors_m[:, 1], "s", color="tab:red", ms=8, label="anchors")
        if label_anchors:
            for i, (x, y) in enumerate(anchors_m, start=1):
                ax.annotate(f"A{i}", (x, y), textcoords="offset points", xytext=(5, 5), color="tab:red")
    ax.set_aspect("equal")
    ax.set_xlabel("X (m)")
    ax.set_ylabel("Y (m)")
    if margin_m:
        ax.set_xlim(-margin_m, w + margin_m)
        ax.set_ylim(-margin_m, h + margin_m)


def draw_path(ax, path_m, *, numbered: bool = False, **style):
    """A path as a line with markers; ``numbered`` labels the points 1..N (the paper's crosses)."""
    path_m = np.asarray(path_m)
    ax.plot(path_m[:, 0], path_m[:, 1], **style)
    if numbered:
        for i, (x, y) in enumerate(path_m, start=1):
            ax.annotate(str(i), (x, y), textcoords="offset points", xytext=(4, -3), fontsize=7)


def points_view_m(view_m, points_m, *, reach_m: float, pad_m: float = 0.3) -> tuple[float, float, float, float]:
    """The view ``(x0, x1, y0, y1)`` (m) widened to hold every finite point of ``points_m`` (N, 2) that lies within
    ``reach_m`` of ``view_m`` (``pad_m`` beyond the farthest): estimates that leave a room are seen, not clipped by a
    view drawn around the room. Points farther out stay outside (:func:`mark_beyond_view` marks them)."""
    pts = np.asarray(points_m, float).reshape(-1, 2)
    pts = pts[np.all(np.isfinite(pts), axis=1)]
    x0, x1, y0, y1 = (float(v) for v in view_m)
    lo, hi = np.array([x0, y0]), np.array([x1, y1])
    near = pts[np.linalg.norm(np.maximum(np.maximum(lo - pts, pts - hi), 0.0), axis=1) <= reach_m]
    if near.size:
        lo, hi = np.minimum(lo, near.min(axis=0) - pad_m), np.maximum(hi, near.max(axis=0) + pad_m)
    return float(lo[0]), float(hi[0]), float(lo[1]), float(hi[1])


def mark_beyond_view(ax, points_m, *, color="0.25") -> int:
    """Mark every finite point of ``points_m`` (N, 2) outside the view of ``ax`` on the view's edge, in its direction
    from the view's centre (an open diamond), with a note in the lower corner: how many, and how far beyond the view
    the farthest lies. Returns how many. Call it once the view is set."""
    pts = np.asarray(points_m, float).reshape(-1, 2)
    pts = pts[np.all(np.isfinite(pts), axis=1)]
    (x0, x1), (y0, y1) = sorted(ax.get_xlim()), sorted(ax.get_ylim())     # an inverted axis too
    lo, hi = np.array([x0, y0]), np.array([x1, y1])
    beyond = np.linalg.norm(np.maximum(np.maximum(lo - pts, pts - hi), 0.0), axis=1)
    far = pts[beyond > 0]
    if far.size:
        centre = (lo + hi) / 2
        with np.errstate(divide="ignore"):   # the segment from the centre to the point meets the edge at this scale
            scale = np.min((hi - centre) / np.abs(far - centre), axis=1)
        edge = centre + (far - centre) * scale[:, None]
        ax.plot(edge[:, 0], edge[:, 1], "D", mfc="none", mec=color, ms=6, clip_on=False)
        ax.annotate(f"{len(far)} beyond the view (on its edge), the farthest {beyond.max():.1f} m out",
                    (0.02, 0.02), xycoords="axes fraction", fontsize=7, color=color)
    return int(len(far))


def map_row(views_m, *, height_in: float, pad_in: float = 1.5, max_width_in: float = 15.0):
    """A figure of one row of map panels at one scale, ``(fig, axes)``: panel i shows the view ``views_m[i]``
    ``(x0, x1, y0, y1)`` (m) at equal scale on both axes, its width in proportion to its x range (a view widened
    by :func:`points_view_m` is not shrunk beside its neighbours); the figure ``height_in`` high (``pad_in`` of it
    for the titles, labels and legend) and as wide as the panels need (at most ``max_width_in``)."""
    import matplotlib.pyplot as plt
    views = [tuple(float(v) for v in view) for view in views_m]
    widths = [x1 - x0 for x0, x1, _, _ in views]
    tallest = max(y1 - y0 for _, _, y0, y1 in views)
    scale = (height_in - pad_in) / tallest                 # inches per metre
    width_in = min(max_width_in, sum(widths) * scale + pad_in * (1 + 0.5 * len(views)))
    fig, axes = plt.subplots(1, len(views), figsize=(width_in, height_in), squeeze=False,
                             gridspec_kw={"width_ratios": widths})
    axes = list(axes[0])
    for ax, (x0, x1, y0, y1) in zip(axes, views):
        ax.set_xlim(x0, x1)
        ax.set_ylim(y0, y1)
        ax.set_aspect("equal")
    return fig, axes


def mean_with_band(ax, x, samples, *, axis: int = 0, z: float = 1.96, label: str = "", omit_nan: bool = False,
                   **style):
    """Plot the mean of ``samples`` along ``axis`` with a +-z standard-error band (Monte-Carlo CI).
    ``omit_nan``: leave out NaN samples (runs that produced no estimate; the caller reports how many)."""
    samples = np.asarray(samples, float)
    if omit_nan:
        count = np.sum(np.isfinite(samples), axis=axis)
        mean = np.nanmean(samples, axis=axis)
        se = np.nanstd(samples, axis=axis, ddof=1) / np.sqrt(count)
    else:
        mean = samples.mean(axis=axis)
        se = samples.std(axis=axis, ddof=1) / np.sqrt(samples.shape[axis])
    line, = ax.plot(x, mean, label=label, **style)
    ax.fill_between(x, mean - z * se, mean + z * se, color=line.get_color(), alpha=0.2, lw=0)
    return mean, se


def error_cdf(ax, errors_m, label: str = "", **style):
    """Empirical CDF of errors."""
    x = np.sort(np.ravel(errors_m))
    ax.plot(x, np.arange(1, x.size + 1) / x.size, label=label, **style)
    ax.set_xlabel("error (m)")
    ax.set_ylabel("CDF")


#: Hatch of a cell whose ratio is n/a (a degenerate bound): unlike the "//" of a column that does not apply.
NA_CELL_HATCH = "xx"
#: Face colour of an n/a cell: a neutral grey, outside the map's blue-red scale.
NA_CELL_COLOUR = "0.88"


def _ratio(value) -> float:
    """A row's ratio as a float (a table's empty cell, ``None``, is NaN: no ratio)."""
    return float("nan") if value is None else float(value)


def _na_note(row) -> str:
    """The note of a row drawn as an n/a cell (NaN ratio and a note saying why), else ``""``."""
    note = row.get("ratio_note") or ""
    return note if note and np.isnan(_ratio(row["ratio"])) else ""


def heat_map(ax, rows, kind: str, methods, scenarios, not_applicable=None, *, vmax_log2: float = 3.0):
    """Error / bound (RMSE over RMS bound) of each method (rows) on each scenario (columns), log2 colour scale centred
    on 1; a column that does not apply is hatched and labelled. A row whose ``ratio`` is NaN (or ``None``) and whose
    ``ratio_note`` is not empty (e.g. the bound is degenerate, :func:`locbook.bounds.summary.error_bound_ratio`) is a
    grey cell hatched ``"xx"`` and labelled "n/a", never coloured and never given a number; its note belongs in the
    caption (:func:`heat_map_notes`)."""
    import matplotlib.colors as mcolors
    from matplotlib.patches import Rectangle

    grid = np.full((len(methods), len(scenarios)), np.nan)
    na_cell = np.zeros(grid.shape, dtype=bool)
    for r in rows:
        if r["kind"] == kind and r["method"] in methods and r["scenario"] in scenarios:
            i, j = list(methods).index(r["method"]), list(scenarios).index(r["scenario"])
            grid[i, j] = _ratio(r["ratio"])
            na_cell[i, j] = bool(_na_note(r))
    norm = mcolors.TwoSlopeNorm(vcenter=0.0, vmin=-vmax_log2, vmax=vmax_log2)
    with np.errstate(divide="ignore", invalid="ignore"):
        image = ax.imshow(np.clip(np.log2(grid), -vmax_log2, vmax_log2), cmap="RdBu_r", norm=norm, aspect="auto")
    for i in range(grid.shape[0]):
        for j in range(grid.shape[1]):
            if np.isfinite(grid[i, j]):
                ax.text(j, i, f"{grid[i, j]:.2f}", ha="center", va="center", fontsize=8,
                        color="white" if abs(np.log2(grid[i, j])) > 0.6 * vmax_log2 else "black")
    column_na = [bool(not_applicable and key in not_applicable) for key in scenarios]
    for i, j in zip(*np.nonzero(na_cell)):
        if not column_na[j]:            # a column that does not apply is labelled once, as a whole
            ax.add_patch(Rectangle((j - 0.5, i - 0.5), 1, 1, facecolor=NA_CELL_COLOUR, hatch=NA_CELL_HATCH,
                                   edgecolor="0.6", lw=0.0))
            ax.text(j, i, "n/a", ha="center", va="center", fontsize=8, color="0.3")
    for j, key in enumerate(scenarios):
        if column_na[j]:
            ax.add_patch(Rectangle((j - 0.5, -0.5), 1, len(methods), fill=False, hatch="//", edgecolor="0.6"))
            ax.text(j, (len(methods) - 1) / 2, "n/a", ha="center", va="center", fontsize=9, color="0.3")
    ax.set_xticks(range(len(scenarios)), scenarios, rotation=30, ha="right", fontsize=8)
    ax.set_yticks(range(len(methods)), methods, fontsize=8)
    return image


def heat_map_notes(rows, kind: str) -> list[str]:
    """Why each n/a cell of :func:`heat_map` has no ratio, for the figure's caption: ``"scenario / method: note"``
    for every row of ``kind`` with a NaN ratio and a ``ratio_note``, in the rows' order; the methods of one scenario
    that share a note are named together (``"scenario / a, b: note"``)."""
    grouped: dict[tuple[str, str], list[str]] = {}
    for r in rows:
        note = _na_note(r) if r["kind"] == kind else ""
        if note:
            methods = grouped.setdefault((r["scenario"], note), [])
            if r["method"] not in methods:
                methods.append(r["method"])
    return [f"{scenario} / {', '.join(methods)}: {note}" for (scenario, note), methods in grouped.items()]


# -- maps of a floor: the measured experiments' map and track figures -------------------------------------------
#: margin (m) of a map's view around the floor outline
MAP_MARGIN_M = 0.5
#: a map figure's widest width (in): the report pages' figure width
MAP_FIGURE_WIDTH_IN = 15.0
#: the width / height a map figure's grid of panels aims at: near-square on a screen, so a long room gets fewer,
#: wider columns (a 26 m x 9 m hall: 2 columns, not 4 of tiny panels) and a square room more
MAP_FIGURE_ASPECT = 1.0
#: height (in) each panel needs beyond the floor's own drawing: its title and tick labels
MAP_PANEL_PAD_IN = 0.7
#: the tallest a panel's floor drawing gets (in): a long narrow corridor drawn upright stays on a screen
MAP_MAX_PANEL_HEIGHT_IN = 8.0


def map_view_m(outline_m, margin_m: float = MAP_MARGIN_M) -> tuple[float, float, float, float]:
    """The view ``(x0, x1, y0, y1)`` (m) of a map: the outline's box with ``margin_m`` around it."""
    outline_m = np.asarray(outline_m, float)
    lo, hi = outline_m.min(axis=0) - margin_m, outline_m.max(axis=0) + margin_m
    return float(lo[0]), float(hi[0]), float(lo[1]), float(hi[1])


def map_layout(view_m, n_panels: int, *, width_in: float = MAP_FIGURE_WIDTH_IN, aspect: float = MAP_FIGURE_ASPECT,
               pad_in: float = MAP_PANEL_PAD_IN, max_panel_height_in: float = MAP_MAX_PANEL_HEIGHT_IN):
    """``(nrows, ncols, (width_in, height_in))`` of a figure of ``n_panels`` maps of the view ``(x0, x1, y0, y1)``.

    Each panel's slot has the floor's own aspect (its drawing, at equal scale on both axes, fills the slot's width:
    ``slot height = slot width x (y1 - y0) / (x1 - x0) + pad_in``, the drawing at most ``max_panel_height_in``
    high), and the number of columns is the one whose whole figure is nearest ``aspect`` (width over height) in
    ratio, ``|log(figure aspect / aspect)|`` smallest (ties: fewer columns); the figure size follows."""
    x0, x1, y0, y1 = (float(v) for v in view_m)
    if not (x1 > x0 and y1 > y0) or n_panels < 1:
        raise ValueError(f"map_layout needs a view with x1 > x0, y1 > y0 and at least one panel, got {view_m}, "
                         f"{n_panels}")
    ratio = (y1 - y0) / (x1 - x0)
    best = None
    for ncols in range(1, n_panels + 1):
        nrows = -(-n_panels // ncols)
        slot_w = min(width_in / ncols, max_panel_height_in / ratio)
        size = (ncols * slot_w, nrows * (slot_w * ratio + pad_in))
        score = abs(np.log(size[0] / size[1] / aspect))
        if best is None or score < best[0] - 1e-12:
            best = (score, nrows, ncols, size)
    return best[1], best[2], (round(best[3][0], 3), round(best[3][1], 3))


def map_panels(data, n_panels: int, **layout):
    """A figure of ``n_panels`` map panels of a data set's floor (:func:`map_layout` of its :func:`map_view_m`):
    ``(fig, axes)``, ``axes`` the ``n_panels`` axes in reading order, the grid's spare slots hidden. ``data``: a
    :class:`locbook.data.dataset.Dataset` (its ``outline_m``)."""
    import matplotlib.pyplot as plt
    nrows, ncols, size = map_layout(map_view_m(data.outline_m), n_panels, **layout)
    fig, grid = plt.subplots(nrows, ncols, figsize=size, squeeze=False)
    axes = list(grid.ravel())
    for ax in axes[n_panels:]:
        ax.set_visible(False)
    return fig, axes[:n_panels]


def draw_floor(ax, data, *, anchor_ms: float = 5.0, view_m=None) -> None:
    """A data set's floor on a map panel: its floor plan under everything (``floor_plan`` at
    ``floor_plan_extent_m``, matplotlib's imshow extent, image top at y1; zorder below every line), the outline,
    the anchors (black triangles), the view (:func:`map_view_m`) at equal scale. ``data``: a
    :class:`locbook.data.dataset.Dataset` (``outline_m``, ``anchors_m``, ``floor_plan``, ``floor_plan_extent_m``)."""
    plan = getattr(data, "floor_plan", None)
    if plan is not None:
        from .data.floors import plan_image
        ax.imshow(plan_image(plan), extent=tuple(data.floor_plan_extent_m), origin="upper", zorder=0,
                  interpolation="nearest")
    outline = np.vstack([data.outline_m, data.outline_m[:1]])
    ax.plot(outline[:, 0], outline[:, 1], "k-", lw=1)
    ax.plot(data.anchors_m[:, 0], data.anchors_m[:, 1], "k^", ms=anchor_ms)
    x0, x1, y0, y1 = map_view_m(data.outline_m) if view_m is None else view_m
    ax.set_xlim(x0, x1)
    ax.set_ylim(y0, y1)
    ax.set_aspect("equal")


def tracks_figure(data, tracks, trackers, **layout):
    """The tracks figure of a data set: one map panel per tracker (:func:`map_panels`, every name in
    ``trackers``, yours included, in that order), each drawing its estimates of every track in one colour per track
    (tab10; the first run where a tracker has several) over the truth (grey points) or the reference path (grey
    segments), on the floor (:func:`draw_floor`). ``tracks``: ``{name: (truth_m (T, 2) with NaN rows where
    unknown, reference path (S, 2, 2) or None, {tracker: (R, T, 2)})}``; a tracker a track lacks is not drawn
    there. Returns the figure."""
    import matplotlib.pyplot as plt
    colours = plt.get_cmap("tab10").colors
    fig, axes = map_panels(data, len(trackers), **layout)
    for ax, tracker in zip(axes, trackers):
        draw_floor(ax, data, anchor_ms=4)
        for i, (name, (truth_m, path_m, est)) in enumerate(tracks.items()):
            if np.isfinite(truth_m[:, 0]).any():
                ax.plot(truth_m[:, 0], truth_m[:, 1], ".", color="0.6", ms=2)
            for seg in ([] if path_m is None else path_m):
                ax.plot(seg[:, 0], seg[:, 1], "-", color="0.5", lw=3)
            if tracker in est:
                ax.plot(est[tracker][0, :, 0], est[tracker][0, :, 1], lw=0.8, color=colours[i % len(colours)],
                        label=name)
        ax.set_title(tracker, fontsize=9)
    if axes and axes[0].get_legend_handles_labels()[0]:
        axes[0].legend(fontsize=7, title="track", title_fontsize=7)
    return fig
