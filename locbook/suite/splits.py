"""Leave-one-recording-out and the anchor-density study: runs of the battery under the split and subset parameters
of :mod:`locbook.data.selection`, by the suite's own runner, each gathered into one table and one plot.

**Leave-one-recording-out** (``locbook run --data DIR --split loro``, :func:`run_loro`). A split per recording that
can be scored (one with true positions, :func:`locbook.data.selection.scorable_recordings`, in manifest order): the
channel is fitted on every OTHER recording with truth (``-p calibration=<the others>``) and the battery is scored on
that one; recordings without truth (a track with only a reference path) keep their role. Each split is a data run of
its own (:func:`locbook.suite.run.run_suite` with that ``calibration``), so its reports are the cached reports of
that parameter, the same as ``locbook run --data DIR -p calibration=...`` writes. The experiments are
:data:`LORO_EXPERIMENTS` unless ids are given; one a split cannot feed (no track left) is left out of that split. The
held-out recording's own rows (``recording`` = its name) of each split's ``results.csv`` are gathered into
``<reports>/<profile>/data-<name>/loro/``:

- ``loro.csv`` and ``loro.md``, the table: one row per (kind, method): ``splits`` (how many gave a mean error), the
  mean, the standard deviation (``ddof = 1``: the splits are a sample of recordings; empty with one split), the
  minimum and the maximum over the splits of each split's mean error, then each split's mean error in a column
  ``mean_m <recording>``;
- ``splits.csv``: one row per split and method (the split, its calibration recordings, epochs, mean, median, RMSE, the
  bound ratio, the report folder);
- ``loro.png``: each method's mean error per split (static methods and trackers in two panels).

**Anchor density** (``locbook study anchor-density --data DIR``, :func:`anchor_density_study`, :func:`run_density`).
For each subset size k (:func:`density_sizes`: k = 3..m, or, with more than :data:`DENSITY_MAX_SIZES` sizes, that many
evenly spaced from 3 to m, m included) up to ``subsets`` (default :data:`DENSITY_SUBSETS`) subsets of k anchors drawn
by :func:`anchor_subsets` from ``numpy.random.default_rng(sample_seed)`` (every subset when there are no more), each
a point of ``measured-localization`` with ``-p anchors=<the subset>``: a :class:`locbook.suite.study.Study` of
``list`` points run by the study engine's runner session (:func:`locbook.suite.runner.run_tasks`; a point's folder
is its values' hash, cached across runs). Each point's ``pooled`` rows are gathered into
``<reports>/<profile>/data-<name>/anchor-density/``: ``density.csv`` and ``density.md`` (one row per (k, method): the
subsets, the mean, standard deviation (``ddof = 1``), minimum and maximum over the subsets of the pooled mean error),
``subsets.csv`` (one row per subset and method) and ``density.png`` (mean error against k per method, the band from
the smallest to the largest subset's error).
"""
from __future__ import annotations

import csv
import io
import itertools
import math
import os
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from ..errors import ParameterError
from .files import atomic_write, write_text_atomic
from .progress import make_progress
from .run import claim_dataset_folder, data_kinds, load_data_argument, run_suite, run_tasks
from .runner import Task
from .spec import Suite, SuiteError, finite_float
from .study import Study, expand_study, point_labels
from .sweep import Aggregate, current_points

__all__ = ["LORO_EXPERIMENTS", "DENSITY_EXPERIMENT", "DENSITY_SUBSETS", "DENSITY_MAX_SIZES", "SPLIT_MODES",
           "loro_splits", "run_loro", "loro_tables", "density_sizes", "anchor_subsets", "anchor_density_study",
           "run_density", "density_tables", "spread"]

#: the split modes of ``locbook run --split``
SPLIT_MODES = ("loro",)
#: the experiments a leave-one-recording-out run runs unless ids are given: the localization and tracking battery
#: (measured-calibration's fit and the benchmark's column repeat what these score)
LORO_EXPERIMENTS = ("measured-localization", "measured-tracking")
#: the experiment each subset of the anchor-density study runs: every static method (one scored problem per subset)
DENSITY_EXPERIMENT = "measured-localization"
#: subsets drawn per size (all of them when a size has no more)
DENSITY_SUBSETS = 5
#: the most subset sizes the density study runs by default (each size is ``subsets`` runs)
DENSITY_MAX_SIZES = 4
_STAT_COLUMNS = ("splits", "mean_m", "std_m", "min_m", "max_m")


def spread(values) -> dict:
    """``{n, mean_m, std_m, min_m, max_m}`` of the finite ``values`` (the standard deviation with ``ddof = 1``, None
    for fewer than 2 values; all None without a finite value)."""
    v = np.asarray([x for x in values if x is not None and np.isfinite(x)], float)
    if not v.size:
        return {"n": 0, "mean_m": None, "std_m": None, "min_m": None, "max_m": None}
    return {"n": int(v.size), "mean_m": _r(v.mean()), "std_m": _r(v.std(ddof=1)) if v.size > 1 else None,
            "min_m": _r(v.min()), "max_m": _r(v.max())}


def _r(x) -> float:
    return round(float(x), 4)


def _read_rows(path: Path) -> list[dict]:
    try:
        with open(path, newline="", encoding="utf-8") as fh:
            return list(csv.DictReader(fh))
    except (OSError, UnicodeDecodeError, csv.Error):
        return []


def _save_png(fig, path: Path) -> None:
    """A figure to ``path`` by the study's atomic write, closed whatever happens."""
    import matplotlib.pyplot as plt
    fig.tight_layout()
    try:
        atomic_write(path, lambda tmp: fig.savefig(tmp, format="png", dpi=100))
    finally:
        plt.close(fig)


def _write_csv(path: Path, rows: list[dict], columns) -> None:
    out = io.StringIO()
    writer = csv.DictWriter(out, fieldnames=list(columns), lineterminator="\n", extrasaction="ignore")
    writer.writeheader()
    writer.writerows([{k: ("" if r.get(k) is None else r.get(k)) for k in columns} for r in rows])
    write_text_atomic(path, out.getvalue())


def _markdown(rows: list[dict], columns) -> str:
    from ..reproduce.report import Table
    return Table([{k: ("" if r.get(k) is None else r.get(k)) for k in columns} for r in rows]).to_markdown()


# ------------------------------------------------------------------------------------- leave one recording out

def loro_splits(data) -> list[tuple[str, tuple[str, ...]]]:
    """``[(held-out recording, its calibration recordings)]``: one split per recording with truth, the channel
    fitted on every other one (manifest order). Fewer than 2 recordings with truth leave nothing to calibrate a
    split on: refused (ParameterError naming ``--split loro``)."""
    from ..data.selection import scorable_recordings
    names = scorable_recordings(data)
    if len(names) < 2:
        raise ParameterError(f"--split loro: data set {data.name!r} has {len(names)} recording(s) with true positions "
                             f"({', '.join(names) or 'none'}); leaving one out needs at least 2 (one to score, the "
                             "others to fit the channel on)")
    return [(n, tuple(o for o in names if o != n)) for n in names]


@dataclass
class LoroRun:
    """What ``--split loro`` did: per split ``(held-out, calibration, SuiteRun or None, note)``, the table folder, and
    the summary for the exit status and the console (``outcomes``, ``interrupted_by``, ``disk_full``,
    ``executor_error``, ``count``: the splits' runs together)."""

    splits: list = field(default_factory=list)
    folder: Path = Path()
    written: bool = False
    #: the run stopped before its last split (an interrupt, a full disk, an executor error)
    stopped: bool = False
    #: a stopped run left an earlier loro.csv (and its page and plot) as it was
    kept: bool = False

    @property
    def runs(self) -> list:
        return [s[2] for s in self.splits if s[2] is not None]

    @property
    def outcomes(self) -> list:
        return [o for run in self.runs for o in run.outcomes]

    @property
    def interrupted_by(self):
        return next((r.interrupted_by for r in self.runs if r.interrupted_by is not None), None)

    @property
    def disk_full(self):
        return next((r.disk_full for r in self.runs if r.disk_full is not None), None)

    @property
    def executor_error(self):
        return next((r.executor_error for r in self.runs if r.executor_error), "")

    def count(self, status: str) -> int:
        return sum(r.count(status) for r in self.runs)


def _data_folder(suite: Suite, report_root, profile: str, name: str) -> Path:
    root = Path(os.path.abspath(Path(report_root).expanduser())) if report_root else suite.default_reports()
    return root / profile / f"data-{name}"


def run_loro(suite: Suite, experiments, profile: str, *, data: str, overrides: dict | None = None,
             report_root: Path | None = None, progress="plain", methods=(), trackers=(), **runner) -> LoroRun:
    """Leave-one-recording-out on ``data`` (module docstring): one :func:`locbook.suite.run.run_suite` per split
    (``overrides`` and ``runner``'s options passed on to each; ``experiments`` default :data:`LORO_EXPERIMENTS`),
    then the table and the plot from every split whose reports are up to date. An interrupted or full-disk split
    stops the rest; the table then holds the splits done, unless an earlier run's table is there: a stopped run
    never replaces it with fewer splits (``kept``)."""
    from ..data.selection import select
    overrides = dict(overrides or {})
    if "calibration" in overrides:
        raise SuiteError("--split loro chooses the calibration recordings of each split: give --split loro or "
                         "-p calibration=..., not both")
    if "data" in overrides:
        raise SuiteError("with --split loro give the data set with --data DIR")
    ds, name, _value, _roots, identity = load_data_argument(data)
    base = select(ds, anchors=overrides.get("anchors", ""))
    splits = loro_splits(base)
    experiments = list(experiments) if experiments else [e for e in suite.experiments if e.id in LORO_EXPERIMENTS]
    for exp in experiments:
        if "calibration" not in exp.declared_parameters():
            takers = [e.id for e in suite.experiments if "calibration" in e.declared_parameters()]
            raise SuiteError(f"--split loro: experiment {exp.id!r} takes no calibration parameter; the experiments "
                             f"that do: {', '.join(takers)}")
    out = LoroRun(folder=_data_folder(suite, report_root, profile, name) / "loro")
    for held, calibration in splits:
        kinds = data_kinds(select(base, calibration=",".join(calibration)))
        mine = [e for e in experiments if e.data_run is None or not e.data_run.missing(kinds)]
        if not mine:
            out.splits.append((held, calibration, None, "no selected experiment can run on this split"))
            continue
        view = make_progress(progress) if isinstance(progress, str) else progress    # a view per split's session
        view.message(f"split {len(out.splits) + 1} of {len(splits)}: {held} scored, the channel fitted on "
                     f"{', '.join(calibration)}")
        run = run_suite(suite, mine, profile, overrides={**overrides, "calibration": ",".join(calibration)},
                        report_root=report_root, progress=view, data=data, requested=set(), methods=methods,
                        trackers=trackers, **runner)
        out.splits.append((held, calibration, run, ""))
        if run.interrupted_by is not None or run.disk_full is not None or run.executor_error:
            out.stopped = True
            break
    folder = out.folder
    folder.parent.mkdir(parents=True, exist_ok=True)
    claim_dataset_folder(folder.parent, name, identity)
    table, per_split = loro_tables(base, out.splits)
    # a stopped run holds fewer splits than the table an earlier run wrote: that table is kept, never shrunk
    out.kept = out.stopped and (folder / "loro.csv").exists()
    if per_split and not out.kept:
        folder.mkdir(exist_ok=True)
        split_names = [s[0] for s in splits]
        _write_csv(folder / "loro.csv", table, ["kind", "method", *_STAT_COLUMNS,
                                                *[f"mean_m {n}" for n in split_names]])
        _write_csv(folder / "splits.csv", per_split, _SPLIT_COLUMNS)
        listing = [{"split": held, "scored": held, "role in the manifest": base.recording(held).role,
                    "calibration": ", ".join(cal), "report": str(run.report_dir) if run is not None else note}
                   for held, cal, run, note in out.splits]
        write_text_atomic(folder / "loro.md", _loro_markdown(base, table, listing, split_names))
        _loro_plot(table, split_names, folder / "loro.png", base.name)
        out.written = True
    return out


_SPLIT_COLUMNS = ("split", "role", "calibration", "kind", "method", "epochs", "coverage", "mean_m", "median_m",
                  "rmse_m", "ratio", "failure", "report")


def loro_tables(data, splits) -> tuple[list[dict], list[dict]]:
    """``(table, per-split rows)`` of :func:`run_loro` from each split's reports (``splits``: ``(held-out,
    calibration, SuiteRun or None, note)``): the held-out recording's rows of measured-localization's and
    measured-tracking's ``results.csv`` (reports ``ok`` or ``cached`` only), and per (kind, method) their
    :func:`spread` over the splits."""
    per_split = []
    for held, calibration, run, _note in splits:
        if run is None:
            continue
        done = {o.id for o in run.outcomes if o.status in ("ok", "cached")}
        for eid in LORO_EXPERIMENTS:
            if eid not in done:
                continue
            for r in _read_rows(run.report_dir / eid / "results.csv"):
                if r.get("recording") != held:
                    continue
                per_split.append({"split": held, "role": data.recording(held).role,
                                  "calibration": ",".join(calibration), "kind": r.get("kind", ""),
                                  "method": r.get("method", ""), "epochs": r.get("epochs", ""),
                                  "coverage": r.get("coverage", ""), "mean_m": finite_float(r.get("mean_m")),
                                  "median_m": finite_float(r.get("median_m")), "rmse_m": finite_float(r.get("rmse_m")),
                                  "ratio": r.get("ratio", ""), "failure": r.get("failure", ""),
                                  "report": str(run.report_dir / eid)})
    table = []
    for kind, method in dict.fromkeys((r["kind"], r["method"]) for r in per_split):
        mine = [r for r in per_split if r["kind"] == kind and r["method"] == method]
        s = spread([r["mean_m"] for r in mine])
        table.append({"kind": kind, "method": method, "splits": s["n"], "mean_m": s["mean_m"], "std_m": s["std_m"],
                      "min_m": s["min_m"], "max_m": s["max_m"],
                      **{f"mean_m {r['split']}": r["mean_m"] for r in mine}})
    return table, per_split


def _loro_markdown(data, table, listing, split_names) -> str:
    head = (f"# Leave-one-recording-out: {data.name}\n\n{data.title}. {data.attribution}\n\n"
            "Each split fits the channel on every other recording with true positions and scores the battery on one "
            "(its own report: the `report` column below). Per method: the mean, standard deviation (ddof = 1), minimum "
            "and maximum over the splits of each split's mean horizontal error (m) on the held-out recording, then "
            "each split's mean error.\n\n")
    return (head + _markdown(table, ["kind", "method", *_STAT_COLUMNS, *[f"mean_m {n}" for n in split_names]])
            + "\n\n## The splits\n\n"
            + _markdown(listing, ["split", "role in the manifest", "calibration", "report"]) + "\n")


def _plot_scale(ax, values) -> None:
    v = np.asarray([x for x in values if x is not None and x > 0], float)
    if v.size and v.max() / v.min() > 20:          # one method far above the others (lls): every one readable
        ax.set_yscale("log")


def _loro_plot(table, split_names, path: Path, name: str) -> None:
    import matplotlib
    matplotlib.use("Agg")
    import matplotlib.pyplot as plt
    kinds = [k for k in ("static", "tracking") if any(r["kind"] == k for r in table)]
    fig, axes = plt.subplots(1, len(kinds), figsize=(6.5 * len(kinds), 4.2), squeeze=False)
    x = np.arange(len(split_names))
    for ax, kind in zip(axes[0], kinds):
        values = []
        for r in (r for r in table if r["kind"] == kind):
            y = [r.get(f"mean_m {n}") for n in split_names]
            values += y
            ax.plot(x, [np.nan if v is None else v for v in y], "o-", ms=4, label=r["method"])
        _plot_scale(ax, values)
        ax.set_xticks(x, split_names, rotation=30, ha="right", fontsize=8)
        ax.set_xlabel("held-out recording (scored; the channel fitted on the others)")
        ax.set_ylabel("mean horizontal error (m)")
        ax.set_title(f"{name}: {'static methods' if kind == 'static' else 'trackers'}, leave one recording out",
                     fontsize=9)
        ax.legend(fontsize=7)
    _save_png(fig, path)


# ------------------------------------------------------------------------------------------------ anchor density

def density_sizes(n_anchors: int, sizes=None) -> tuple[int, ...]:
    """The subset sizes of the density study: ``sizes`` if given (each from 3 to ``n_anchors``), else 3..m, or
    with more than :data:`DENSITY_MAX_SIZES` of them that many evenly spaced from 3 to m, m included (the deployed
    density is the curve's last point)."""
    from ..data.selection import MIN_SUBSET_ANCHORS as low
    if n_anchors < low:
        raise ParameterError(f"anchor-density: the data set has {n_anchors} anchors; a subset needs at least {low}")
    if sizes:
        bad = [k for k in sizes if isinstance(k, bool) or not isinstance(k, int) or not low <= k <= n_anchors]
        if bad or len(set(sizes)) != len(sizes):
            raise ParameterError(f"--sizes: {list(sizes)} must be distinct whole numbers from {low} to {n_anchors} "
                                 "(the data set's anchors)")
        return tuple(sorted(sizes))
    if n_anchors - low + 1 <= DENSITY_MAX_SIZES:
        return tuple(range(low, n_anchors + 1))
    return tuple(int(k) for k in np.unique(np.round(np.linspace(low, n_anchors, DENSITY_MAX_SIZES))))


def anchor_subsets(anchor_ids, sizes, per_size: int, *, rng: np.random.Generator) -> list[tuple[str, ...]]:
    """Up to ``per_size`` distinct subsets of ``anchor_ids`` of each size in ``sizes`` (each subset in the ids'
    order): every subset of a size with at most ``per_size`` of them (in ``itertools.combinations`` order), else
    ``per_size`` distinct draws, each a uniform k-subset (the first k of a permutation by ``rng``), a repeat drawn
    again. The same generator state gives the same subsets."""
    if not isinstance(rng, np.random.Generator):
        raise TypeError(f"rng must be a numpy.random.Generator, got {type(rng).__name__}")
    if isinstance(per_size, bool) or not isinstance(per_size, int) or per_size < 1:
        raise ParameterError(f"--subsets must be a whole number >= 1, got {per_size!r}")
    ids = tuple(anchor_ids)
    m, out = len(ids), []
    for k in sizes:
        if math.comb(m, k) <= per_size:
            out += [tuple(ids[i] for i in c) for c in itertools.combinations(range(m), k)]
            continue
        seen = []
        while len(seen) < per_size:       # comb(m, k) > per_size: a repeat is rare and the loop ends
            pick = tuple(sorted(rng.permutation(m)[:k].tolist()))
            if pick not in seen:
                seen.append(pick)
        out += [tuple(ids[i] for i in c) for c in seen]
    return out


def anchor_density_study(suite: Suite, data: str, *, profile: str = "quick", subsets: int = DENSITY_SUBSETS,
                         sizes=None, sample_seed: int = 0):
    """``(study, data set as run, subsets)``: the anchor-density study of ``data`` as a
    :class:`locbook.suite.study.Study` of ``list`` points (``anchors`` = each subset, ``data`` = the data set) of
    :data:`DENSITY_EXPERIMENT`; the subsets by :func:`anchor_subsets` from ``default_rng(sample_seed)`` among the
    anchors a run uses (the manifest's ``[run] anchors``, else every anchor)."""
    return _density_plan(suite, data, profile=profile, subsets=subsets, sizes=sizes, sample_seed=sample_seed)[:3]


def _density_plan(suite: Suite, data: str, *, profile: str, subsets: int, sizes, sample_seed: int):
    """:func:`anchor_density_study` and the data set's ``(name, data roots, identity)`` for the runner."""
    from ..data.selection import select
    if isinstance(sample_seed, bool) or not isinstance(sample_seed, int) or sample_seed < 0:
        raise ParameterError(f"--sample-seed must be a whole number >= 0, got {sample_seed!r}")
    ds, name, value, roots, identity = load_data_argument(data)
    ds = select(ds)
    ks = density_sizes(len(ds.anchor_ids), sizes)
    drawn = anchor_subsets(ds.anchor_ids, ks, subsets, rng=np.random.default_rng(sample_seed))
    exp = next((e for e in suite.experiments if e.id == DENSITY_EXPERIMENT), None)
    if exp is None or "anchors" not in exp.declared_parameters():
        raise SuiteError(f"anchor-density runs {DENSITY_EXPERIMENT!r} with an anchors parameter; this experiment list "
                         "has none")
    study = Study("anchor-density", (exp,), profile, 1, "seed", 0, sample_seed, (),
                  {"anchors": ("list", [",".join(s) for s in drawn]), "data": ("list", [value] * len(drawn))},
                  Path(f"<anchor-density of {value}>"))
    return study, ds, drawn, name, roots, identity


def run_density(suite: Suite, data: str, *, profile: str = "quick", subsets: int = DENSITY_SUBSETS, sizes=None,
                sample_seed: int = 0, report_root: Path | None = None, **runner):
    """Run the anchor-density study of ``data`` (module docstring) in one runner session into
    ``<reports>/<profile>/data-<name>/anchor-density/`` and write its table and plot (also after an interrupt: the
    points finished so far, by :func:`locbook.suite.sweep.current_points`). Returns the runner's SuiteRun with
    ``aggregate`` (:class:`locbook.suite.sweep.Aggregate` of density.csv)."""
    study, ds, _drawn, name, roots, identity = _density_plan(suite, data, profile=profile, subsets=subsets,
                                                             sizes=sizes, sample_seed=sample_seed)
    points = expand_study(study)            # every value checked before anything runs
    folder = _data_folder(suite, report_root, profile, name) / "anchor-density"
    folder.parent.mkdir(parents=True, exist_ok=True)
    claim_dataset_folder(folder.parent, name, identity)
    labels = point_labels(points)           # anchors='A1,A2,A3' rep 0 (the data set, the same for all, left out)
    tasks = [Task(p.key, p.experiment, p.parameters, label=labels[p.key]) for p in points]
    wrote: list = []

    def write(where: Path, outcomes) -> None:
        status = current_points(where, study.profile, [(p.key, p.experiment, p.parameters, True) for p in points],
                                outcomes)
        done = {k for k, st in status.items() if st in ("ok", "cached")}
        path = where / "density.csv"
        if not done:
            wrote.append(Aggregate(path, 0, len(points), written=False))
            return
        table, rows = density_tables(points, where, done, ds.anchor_ids)
        _write_csv(path, table, ["k", "method", "subsets", "mean_m", "std_m", "min_m", "max_m"])
        _write_csv(where / "subsets.csv", rows, ["k", "subset", "method", "epochs", "coverage", "mean_m", "median_m",
                                                 "rmse_m", "ratio", "folder"])
        write_text_atomic(where / "density.md", _density_markdown(ds, table, sample_seed, subsets))
        wrote.append(Aggregate(path, len(done), len(points)))
        _density_plot(table, where / "density.png", ds.name, len(ds.anchor_ids))

    run = run_tasks(suite, tasks, study.profile, folder, write_reports=write, data_roots=roots, **runner)
    run.aggregate = wrote[-1] if wrote else Aggregate(folder / "density.csv", 0, len(points), written=False)
    return run


def density_tables(points, folder: Path, done, anchor_ids) -> tuple[list[dict], list[dict]]:
    """``(table, per-subset rows)`` of the density study: each up-to-date point's ``pooled`` rows of its
    ``results.csv``, and per (k, method) their :func:`spread` over the subsets (k ascending, methods in the
    results' order)."""
    rows = []
    for p in points:
        if p.key not in done:
            continue
        subset = p.values["anchors"]
        k = len(subset.split(","))
        for r in _read_rows(folder / p.key / "results.csv"):
            if r.get("recording") != "pooled":
                continue
            rows.append({"k": k, "subset": subset, "method": r.get("method", ""), "epochs": r.get("epochs", ""),
                         "coverage": r.get("coverage", ""), "mean_m": finite_float(r.get("mean_m")),
                         "median_m": finite_float(r.get("median_m")), "rmse_m": finite_float(r.get("rmse_m")),
                         "ratio": r.get("ratio", ""), "folder": p.key})
    table = []
    methods = list(dict.fromkeys(r["method"] for r in rows))
    for k in sorted({r["k"] for r in rows}):
        for method in methods:
            mine = [r["mean_m"] for r in rows if r["k"] == k and r["method"] == method]
            if not mine:
                continue
            s = spread(mine)
            table.append({"k": k, "method": method, "subsets": len(mine), "mean_m": s["mean_m"], "std_m": s["std_m"],
                          "min_m": s["min_m"], "max_m": s["max_m"]})
    return table, rows


def _density_markdown(ds, table, sample_seed: int, subsets: int) -> str:
    return (f"# Anchor density: {ds.name}\n\n{ds.title}. {ds.attribution}\n\n"
            f"Every static method on subsets of k of the {len(ds.anchor_ids)} anchors (up to {subsets} per k, drawn "
            f"from numpy.random.default_rng({sample_seed}); every subset where there are no more): per k and method, "
            "the number of subsets, the mean, standard deviation (ddof = 1), minimum and maximum over the subsets of "
            "the pooled mean horizontal error (m). subsets.csv lists each subset's rows and report folder.\n\n"
            + _markdown(table, ["k", "method", "subsets", "mean_m", "std_m", "min_m", "max_m"]) + "\n")


def _density_plot(table, path: Path, name: str, n_anchors: int) -> None:
    import matplotlib
    matplotlib.use("Agg")
    import matplotlib.pyplot as plt
    fig, ax = plt.subplots(figsize=(7, 4.5))
    values = []
    for method in dict.fromkeys(r["method"] for r in table):
        mine = [r for r in table if r["method"] == method and r["mean_m"] is not None]
        if not mine:
            continue
        k = [r["k"] for r in mine]
        line, = ax.plot(k, [r["mean_m"] for r in mine], "o-", ms=4, label=method)
        ax.fill_between(k, [r["min_m"] for r in mine], [r["max_m"] for r in mine], color=line.get_color(), alpha=0.15)
        values += [r["min_m"] for r in mine] + [r["max_m"] for r in mine]
    _plot_scale(ax, values)
    ax.set_xlabel(f"anchors in the subset (of {n_anchors})")
    ax.set_ylabel("pooled mean horizontal error (m)")
    ax.set_title(f"{name}: mean error against the number of anchors (band: smallest to largest subset)", fontsize=9)
    ax.legend(fontsize=7)
    _save_png(fig, path)
