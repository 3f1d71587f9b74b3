"""Two runs side by side (``locbook compare BASE VARIANT``): every printed number's value in each run, the
difference, its standard error and whether the change exceeds it, and each experiment's parameters that differ.

A row is one printed quantity, joined on ``(experiment, printed_id)`` of the two folders' ``numbers.csv``. The
standard error of a difference is ``sqrt(se_base**2 + se_variant**2)`` from the rows' Monte-Carlo standard
errors, the error of the difference of two independent runs. Two runs of locbook with the same seed share their
random streams wherever the change leaves them alone, which makes their values positively correlated and the true
error of the difference smaller: "changed" (beyond 2 SE) is then conservative (a change it reports is real; a small
real change may read "within 2 SE"). A row without a Monte-Carlo error (a closed form, a bound, one measured walk
analysed exactly) "changed" when its value changed at all.

Written as ``compare-<base folder>.csv`` and ``compare-<base folder>.html`` in the variant's folder (or ``out``);
a ``-p`` run writes its comparison with the profile's own folder there (:func:`locbook.suite.site.
write_suite_reports`), and its index links it.
"""
from __future__ import annotations

import csv
import io
import math
from collections import Counter
from dataclasses import dataclass, field
from pathlib import Path

from ..errors import ParameterError
from .files import read_csv, read_json, write_text_atomic
from .pages import number_text, render
from .spec import finite_float

__all__ = ["COMPARE_COLUMNS", "CHANGES", "Comparison", "compare_rows", "parameter_changes", "compare_folders",
           "write_comparison", "comparison_name"]

#: compare-<base>.csv's columns
COMPARE_COLUMNS = ("experiment", "printed_id", "quantity", "where", "unit", "kind", "printed", "base", "variant",
                   "difference", "difference_se", "change", "base_verdict", "variant_verdict")

#: what happened to a row, in the order the page counts them
CHANGES = ("changed", "within 2 SE", "identical", "only in base", "only in variant", "no number")

#: the multiple of the difference's standard error beyond which a change is reported (the windows' 2 SE)
SE_MULTIPLE = 2.0


def _se(text) -> float:
    """A row's Monte-Carlo standard error; a blank one (no Monte-Carlo error) is 0."""
    x = finite_float(text)
    return abs(x) if x is not None else 0.0


def _change(base: dict | None, variant: dict | None) -> tuple[str, float | None, float | None]:
    """(change, difference, its standard error) of one printed quantity in the two runs."""
    if base is None:
        return "only in variant", None, None
    if variant is None:
        return "only in base", None, None
    b, v = finite_float(base.get("reproduced")), finite_float(variant.get("reproduced"))
    if b is None or v is None:
        tb, tv = str(base.get("reproduced", "")).strip(), str(variant.get("reproduced", "")).strip()
        if not tb and not tv:
            return "no number", None, None
        return ("identical" if tb == tv else "changed"), None, None
    diff = v - b
    se = math.hypot(_se(base.get("mc_std_error")), _se(variant.get("mc_std_error")))
    if diff == 0:
        return "identical", diff, se
    if se > 0 and abs(diff) <= SE_MULTIPLE * se:
        return "within 2 SE", diff, se
    return "changed", diff, se


#: a data run's statistics compared (its experiments' results.csv): (column, interval low, interval high, name)
DATA_STATISTICS = (("rmse_m", "rmse_low_m", "rmse_high_m", "RMSE"), ("mean_m", "mean_low_m", "mean_high_m",
                                                                        "mean error"))
#: the two-sided normal quantile of the results' bootstrap intervals (95 %: locbook.metrics.accuracy_metrics)
DATA_INTERVAL_Z = 1.959963984540054


def data_rows(folder: Path) -> list[dict]:
    """A data run's results (``<experiment>/results.csv`` of a folder holding ``dataset.json``) as rows like
    numbers.csv's, for :func:`compare_rows`: one per experiment, recording, method and statistic of
    :data:`DATA_STATISTICS` (kind ``data``, no printed value), its ``mc_std_error`` the bootstrap interval's
    half-width over :data:`DATA_INTERVAL_Z` (the uncertainty over the recording's epochs). Not a data run: []."""
    folder = Path(folder)
    if not (folder / "dataset.json").is_file():
        return []
    out = []
    for results in sorted(folder.glob("*/results.csv")):
        if results.parent.name.startswith("."):      # a crash's .old-<id> or another run's staging
            continue
        for r in read_csv(results):
            if not r.get("method") or not r.get("recording"):
                continue
            for column, low, high, name in DATA_STATISTICS:
                if column not in r:
                    continue
                lo, hi = finite_float(r.get(low)), finite_float(r.get(high))
                se = (hi - lo) / (2 * DATA_INTERVAL_Z) if lo is not None and hi is not None else None
                out.append({"experiment": results.parent.name,
                            "printed_id": f"{r.get('kind', '')}: {r['recording']}: {r['method']}: {column}",
                            "quantity": f"{r['method']} {name}", "where": "; ".join(
                                part for part in (r["recording"], r.get("settings", "")) if part),
                            "unit": "m", "kind": "data", "printed": "", "reproduced": r[column],
                            "mc_std_error": "" if se is None else repr(se), "verdict": ""})
    return out


def compare_rows(base_rows: list[dict], variant_rows: list[dict]) -> list[dict]:
    """One row of :data:`COMPARE_COLUMNS` per printed quantity of either run (numbers.csv rows), in the variant's
    order, then the base's rows the variant does not hold. Numbers as written in numbers.csv; the difference and
    its standard error as floats (None where there is none)."""
    def key(r):
        return (r.get("experiment", ""), r.get("printed_id", ""))
    base = {key(r): r for r in base_rows}
    variant = {key(r): r for r in variant_rows}
    order = list(variant) + [k for k in base if k not in variant]
    out = []
    for k in order:
        b, v = base.get(k), variant.get(k)
        change, diff, se = _change(b, v)
        first = v or b or {}
        out.append({"experiment": k[0], "printed_id": k[1], **{c: first.get(c, "") for c in (
            "quantity", "where", "unit", "kind", "printed")},
            "base": (b or {}).get("reproduced", ""), "variant": (v or {}).get("reproduced", ""),
            "difference": diff, "difference_se": se, "change": change,
            "base_verdict": (b or {}).get("verdict", ""), "variant_verdict": (v or {}).get("verdict", "")})
    return out


#: a parameter a run did not set (it took the notebook's default)
_DEFAULT = object()


def _value_text(value, default=_DEFAULT) -> str:
    if value is not _DEFAULT:
        return repr(value)
    return "(the notebook's default)" if default is _DEFAULT else f"{default!r} (the notebook's default)"


def parameter_changes(base_dir: Path, variant_dir: Path, experiments: list[str],
                      defaults: dict[str, dict] | None = None) -> list[dict]:
    """Per experiment of both folders, the profile and the parameters its two runs set differently (each report's
    ``report.json``: a parameter a run did not set took the notebook's default, shown from ``defaults``, experiment
    id -> {name: the notebook's default now}, where given)."""
    out = []
    for eid in experiments:
        mine = (defaults or {}).get(eid, {})
        rb, rv = read_json(base_dir / eid / "report.json", {}), read_json(variant_dir / eid / "report.json", {})
        if not rb or not rv:
            continue
        pb, pv = rb.get("parameters", {}) or {}, rv.get("parameters", {}) or {}
        changed = [{"name": name, "base": _value_text(pb.get(name, _DEFAULT), mine.get(name, _DEFAULT)),
                    "variant": _value_text(pv.get(name, _DEFAULT), mine.get(name, _DEFAULT))}
                   for name in sorted(set(pb) | set(pv)) if pb.get(name, _DEFAULT) != pv.get(name, _DEFAULT)]
        if changed or rb.get("profile") != rv.get("profile"):
            out.append({"experiment": eid, "base_profile": rb.get("profile", ""),
                        "variant_profile": rv.get("profile", ""), "parameters": changed})
    return out


@dataclass
class Comparison:
    """Two runs compared: their folders, the rows (:func:`compare_rows`), the parameters that differ
    (:func:`parameter_changes`) and, once written, the page and CSV."""
    base_dir: Path
    variant_dir: Path
    rows: list[dict]
    parameters: list[dict]
    written: list[Path] = field(default_factory=list)

    @property
    def has_data_rows(self) -> bool:
        """Whether any row is a data set's result (:func:`data_rows`), not a printed number."""
        return any(r["kind"] == "data" for r in self.rows)

    def counts(self) -> dict[str, int]:
        c = Counter(r["change"] for r in self.rows)
        return {name: c[name] for name in CHANGES if c[name]}

    def verdict_changes(self) -> list[tuple[str, str, int]]:
        """(base verdict, variant verdict, rows) for every verdict that changed between rows of both runs."""
        c = Counter((r["base_verdict"] or "no verdict", r["variant_verdict"] or "no verdict") for r in self.rows
                    if r["change"] not in ("only in base", "only in variant")
                    and r["base_verdict"] != r["variant_verdict"])
        return [(a, b, n) for (a, b), n in sorted(c.items())]

    def summary(self) -> str:
        """One line for the console: the counts by change and the verdicts that changed."""
        n = len(self.rows)
        counts = ", ".join(f"{v} {k}" for k, v in self.counts().items()) or "nothing to compare"
        verdicts = self.verdict_changes()
        moved = sum(v for _a, _b, v in verdicts)
        what = "number" if self.has_data_rows else "printed number"
        return (f"{n} {what}{'s' if n != 1 else ''} compared: {counts}; "
                + (f"{moved} verdict{'s' if moved != 1 else ''} changed" if moved else "no verdict changed"))


def _report_folder(path: Path, role: str) -> Path:
    path = Path(path)
    if not path.is_dir():
        raise ParameterError(f"compare: {role} {path} is not a folder")
    if not (path / "numbers.csv").is_file():
        raise ParameterError(f"compare: {role} {path} holds no numbers.csv (not a reports folder: give "
                             "reports/<profile> or a -p run's folder)")
    return path


def compare_folders(base_dir: Path, variant_dir: Path, suite=None) -> Comparison:
    """Compare two reports folders (each holding ``numbers.csv``); a folder that is not one is one
    :class:`~locbook.errors.ParameterError` line naming it. ``suite`` (a :class:`~locbook.suite.spec.Suite`): its
    notebooks' defaults name the value of a parameter a run did not set."""
    base_dir = _report_folder(base_dir, "base")
    variant_dir = _report_folder(variant_dir, "variant")
    rows = compare_rows(read_csv(base_dir / "numbers.csv") + data_rows(base_dir),
                        read_csv(variant_dir / "numbers.csv") + data_rows(variant_dir))
    experiments = list(dict.fromkeys(r["experiment"] for r in rows))
    defaults = {}
    if suite is not None:
        for exp in suite.experiments:
            if exp.id in experiments:
                try:
                    defaults[exp.id] = {n: p.default for n, p in exp.declared_parameters().items()}
                except ParameterError:        # a notebook that no longer reads: its defaults go unnamed
                    pass
    return Comparison(base_dir, variant_dir, rows, parameter_changes(base_dir, variant_dir, experiments, defaults))


def comparison_name(base_dir: Path) -> str:
    """The file stem of a comparison with ``base_dir``: ``compare-<its folder name>``."""
    return f"compare-{Path(base_dir).name}"


def comparison_pages(report_dir: Path) -> list[tuple[str, str]]:
    """(base folder, file name) of the comparisons in a reports folder (``compare-<base>.html``), for its index."""
    return [(p.stem[len("compare-"):], p.name) for p in sorted(Path(report_dir).glob("compare-*.html"))]


def _csv_text(rows: list[dict]) -> str:
    out = io.StringIO()
    writer = csv.DictWriter(out, fieldnames=COMPARE_COLUMNS, lineterminator="\n")
    writer.writeheader()
    for r in rows:
        writer.writerow({c: ("" if r[c] is None else (repr(r[c]) if isinstance(r[c], float) else r[c]))
                         for c in COMPARE_COLUMNS})
    return out.getvalue()


def _shown(r: dict) -> dict:
    return {**r, "printed": number_text(r["printed"], 4), "base": number_text(r["base"], 4),
            "variant": number_text(r["variant"], 4),
            "difference": "" if r["difference"] is None else f"{r['difference']:+.3g}",
            "difference_se": "" if not r["difference_se"] else f"{r['difference_se']:.2g}"}


def _relative(target: Path, start: Path) -> str:
    import os
    return Path(os.path.relpath(target, start)).as_posix()


def comparison_html(comparison: Comparison, out_dir: Path, version: str, csv_name: str) -> str:
    """The comparison's page, its links relative to ``out_dir`` (where it is written)."""
    rows = [_shown(r) for r in comparison.rows]
    by_experiment: dict[str, list[dict]] = {}
    for r in rows:
        by_experiment.setdefault(r["experiment"], []).append(r)
    return render("compare.html", version=version, base=comparison.base_dir.name,
                  variant=comparison.variant_dir.name,
                  base_link=_relative(comparison.base_dir / "index.html", out_dir),
                  variant_link=_relative(comparison.variant_dir / "index.html", out_dir),
                  counts=comparison.counts(), verdicts=comparison.verdict_changes(),
                  parameters=comparison.parameters, by_experiment=by_experiment, csv_name=csv_name,
                  summary=comparison.summary(), se_multiple=SE_MULTIPLE,
                  data=comparison.has_data_rows)


def write_comparison(comparison: Comparison, out_dir: Path | None = None) -> Comparison:
    """Write ``compare-<base>.csv`` and ``compare-<base>.html`` into ``out_dir`` (default: the variant's folder),
    each atomically."""
    from .. import __version__
    out_dir = Path(out_dir) if out_dir is not None else comparison.variant_dir
    out_dir.mkdir(parents=True, exist_ok=True)
    stem = comparison_name(comparison.base_dir)
    csv_path, html_path = out_dir / f"{stem}.csv", out_dir / f"{stem}.html"
    write_text_atomic(csv_path, _csv_text(comparison.rows))
    write_text_atomic(html_path, comparison_html(comparison, out_dir, __version__, csv_path.name))
    comparison.written = [html_path, csv_path]
    return comparison
