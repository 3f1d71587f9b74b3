"""The pages of the two sweeps: a study's ``index.html`` (its table, each point's replicates joined by their mean
and its standard error, and its plots) and a bracket's ``index.html`` (a strip chart per printed number: each
interpretation's value and window, the printed value, the verdicts).

Written beside the sweep's CSV files whenever those are (:func:`locbook.suite.study.write_study_outputs`,
:func:`locbook.suite.bracket.write_bracket_outputs`), atomically; points are named by their settings, never by
their folders' hashes.
"""
from __future__ import annotations

import html
import math
from collections import Counter
from pathlib import Path

from .. import __version__
from .files import read_csv, write_text_atomic
from .pages import number_text, render
from .spec import finite_float

__all__ = ["replicate_mean_se", "study_table", "write_study_page", "strip_svg", "bracket_strips", "write_bracket_page"]


# -- a study ------------------------------------------------------------------------------------------------------

def replicate_mean_se(values: list[float], mc_std_error) -> float:
    """The standard error of the mean of a point's replicate values: their sample standard deviation over sqrt(R)
    for R >= 2, else the one run's Monte-Carlo standard error (0 where it has none)."""
    n = len(values)
    if n >= 2:
        mean = sum(values) / n
        return math.sqrt(sum((v - mean) ** 2 for v in values) / (n - 1) / n)
    return finite_float(mc_std_error) or 0.0


def study_table(rows: list[dict], parameters: list[str], labels: dict[str, str]) -> list[dict]:
    """One row per (experiment, printed quantity, parameter point) of study.csv's ``rows``: the point's label
    (its settings), the replicates' mean, the standard error of that mean (the replicates' sample standard
    deviation over sqrt(R) when R >= 2, else the one run's Monte-Carlo standard error), R, and the replicates'
    verdicts counted."""
    groups: dict[tuple, list[dict]] = {}
    for r in rows:
        groups.setdefault((r["experiment"], r["printed_id"], r["point"]), []).append(r)
    out = []
    for (eid, _pid, point), group in groups.items():
        values = [v for v in (finite_float(r["ours"]) for r in group) if v is not None]
        mean = sum(values) / len(values) if values else None
        se = replicate_mean_se(values, group[0]["mc_std_error"]) if values else None
        first = group[0]
        settings = ", ".join(f"{p}={first[p]}" for p in parameters if p in first)
        verdicts = Counter(r["verdict"] for r in group if r["verdict"])
        out.append({"experiment": eid, "quantity": first["quantity"], "where": first["where"],
                    "unit": first["unit"], "point": point, "settings": settings, "printed": first["printed"],
                    "mean": number_text(mean, 4) if mean is not None else "",
                    "se": number_text(se, 2) if se is not None else "", "replicates": len(group),
                    "verdicts": ", ".join(f"{n} {v}" for v, n in sorted(verdicts.items())),
                    "folders": [(labels.get(r["folder"], r["folder"]), r["folder"]) for r in group]})
    return out


def write_study_page(study, rows: list[dict], folder: Path, labels: dict[str, str],
                     plots: list[tuple[Path, str]]) -> Path:
    """``<folder>/index.html`` of a study: what it swept, its table (:func:`study_table`) and its plots (each
    file with its caption)."""
    params = list(study.parameters)
    table = study_table(rows, params, labels)
    for r in table:   # link a replicate's report page where it has one
        r["links"] = [(label, f"{key}/report.html") for label, key in r.pop("folders")
                      if (folder / key / "report.html").is_file()]
    path = folder / "index.html"
    write_text_atomic(path, render(
        "study.html", version=__version__, name=study.name, profile=study.profile,
        experiments=[e.id for e in study.experiments], replicates=study.replicates,
        parameters=[{"name": p, "sampler": s, "spec": str(v)} for p, (s, v) in study.parameters.items()],
        table=table, plots=[(p.relative_to(folder).as_posix(), caption) for p, caption in plots if p.is_file()],
        csv_name="study.csv"))
    return path


# -- a bracket ----------------------------------------------------------------------------------------------------

_WIDTH, _LEFT, _RIGHT, _ROW, _TOP = 680, 250, 20, 18, 22


def _x_range(values: list[float]) -> tuple[float, float]:
    low, high = min(values), max(values)
    if high == low:
        pad = abs(high) * 0.1 or 1.0
    else:
        pad = (high - low) * 0.06
    return low - pad, high + pad


def strip_svg(printed: float | None, points: list[dict], unit: str = "", limit: float | None = None) -> str:
    """One strip chart as inline SVG: a row per point (``label``, ``value``, ``window_low``, ``window_high``,
    ``verdict``, ``default``), the point's value a dot on its window's bar coloured by its verdict, the printed value
    a dashed vertical line. ``limit``: values beyond it (implausible, the experiment's largest plausible error) are
    drawn at the chart's edge with their value written beside it, so they do not squash the others."""
    shown = [v for p in points for v in (p["value"], p["window_low"], p["window_high"])
             if v is not None and (limit is None or abs(v) <= limit)]
    if printed is not None:
        shown.append(printed)
    if not shown:
        return ""
    x0, x1 = _x_range(shown)
    span = _WIDTH - _LEFT - _RIGHT

    def x(v: float) -> float:
        return _LEFT + (min(max(v, x0), x1) - x0) / (x1 - x0) * span

    height = _TOP + _ROW * len(points) + 22
    parts = [f'<svg class="strip" viewBox="0 0 {_WIDTH} {height}" width="{_WIDTH}" height="{height}" '
             f'role="img" aria-label="each interpretation\'s value against the printed value">',
             f'<line class="axis" x1="{_LEFT}" x2="{_WIDTH - _RIGHT}" y1="{height - 18}" y2="{height - 18}"/>']
    for tick in (x0 + (x1 - x0) * f for f in (0.06, 0.5, 0.94)):
        parts.append(f'<text class="tick" x="{x(tick):.1f}" y="{height - 5}" text-anchor="middle">'
                     f'{html.escape(number_text(tick, 3))}{(" " + html.escape(unit)) if unit else ""}</text>')
    if printed is not None:
        parts.append(f'<line class="printed" x1="{x(printed):.1f}" x2="{x(printed):.1f}" y1="{_TOP - 12}" '
                     f'y2="{height - 18}"/>')
        parts.append(f'<text class="printed-label" x="{x(printed):.1f}" y="{_TOP - 14}" text-anchor="middle">'
                     f'printed {html.escape(number_text(printed, 4))}</text>')
    for i, p in enumerate(points):
        y = _TOP + _ROW * i + _ROW / 2
        label = p["label"] if len(p["label"]) <= 40 else p["label"][:39] + "\u2026"
        verdict = p["verdict"] if p["verdict"] in ("within", "loose", "miss") else "none"
        parts.append(f'<g class="v-{verdict}{" default" if p["default"] else ""}"><title>'
                     f'{html.escape(p["label"])}: {html.escape(number_text(p["value"], 4))} '
                     f'({html.escape(p["verdict"])})'
                     f'</title><text class="label" x="{_LEFT - 8}" y="{y + 4:.1f}" text-anchor="end">'
                     f'{html.escape(label)}</text>')
        if p["window_low"] is not None and p["window_high"] is not None:
            parts.append(f'<line class="window" x1="{x(p["window_low"]):.1f}" x2="{x(p["window_high"]):.1f}" '
                         f'y1="{y:.1f}" y2="{y:.1f}"/>')
        if p["value"] is not None:
            beyond = limit is not None and abs(p["value"]) > limit
            parts.append(f'<circle class="ours" cx="{x(p["value"]):.1f}" cy="{y:.1f}" r="4"/>')
            if beyond:
                parts.append(f'<text class="beyond" x="{x(p["value"]) - 8:.1f}" y="{y + 4:.1f}" text-anchor="end">'
                             f'{html.escape(number_text(p["value"], 3))} (beyond the plausible)</text>')
        parts.append("</g>")
    parts.append("</svg>")
    return "".join(parts)


def bracket_strips(rows: list[dict], values: list[dict], folder: Path, limit: float | None) -> list[dict]:
    """Per bracket.csv row, its strip (:func:`strip_svg`) from values.csv's rows and each point's window (its own
    report's numbers.csv, when the folder still holds it)."""
    windows: dict[str, dict] = {}

    def window(point: str, printed_id: str):
        if point not in windows:
            windows[point] = {r["printed_id"]: r for r in read_csv(folder / point / "numbers.csv")}
        row = windows[point].get(printed_id, {})
        return finite_float(row.get("window_low")), finite_float(row.get("window_high"))

    by_row: dict[tuple, list[dict]] = {}
    for v in values:
        by_row.setdefault((v["experiment"], v["printed_id"]), []).append(v)
    out = []
    for r in rows:
        points = []
        for v in by_row.get((r["experiment"], r["printed_id"]), []):
            low, high = window(v["point"], v["printed_id"])
            points.append({"label": v["interpretation"], "value": finite_float(v["ours"]), "window_low": low,
                           "window_high": high, "verdict": v["verdict"], "default": v["basis"] == "default"})
        out.append({**r, "svg": strip_svg(finite_float(r["printed"]), points, r.get("unit", ""), limit),
                    "n_points": len(points)})
    return out


def write_bracket_page(exp, rows: list[dict], values: list[dict], folder: Path, profile: str) -> Path:
    """``<folder>/index.html`` of a bracket: its verdicts counted, then per printed number its strip chart and
    verdict."""
    from ..reproduce.scoring import BRACKETS
    counts = Counter(r["bracket"] for r in rows)
    path = folder / "index.html"
    write_text_atomic(path, render(
        "bracket.html", version=__version__, exp=exp, profile=profile,
        counts=[(b, counts[b]) for b in BRACKETS if counts[b]],
        strips=bracket_strips(rows, values, folder, exp.largest_error_m)))
    return path
