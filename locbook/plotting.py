"""Plotting helpers shared by the notebooks (kept out of the notebooks, as in the filterpy book)."""
from __future__ import annotations

import numpy as np

__all__ = ["draw_room", "draw_path", "mean_with_band", "error_cdf", "heat_map", "heat_map_notes"]


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
