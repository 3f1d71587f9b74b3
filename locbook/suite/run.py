"""``locbook run``'s front end: a run of experiments (:func:`run_suite`) and a data set's part in it (the ``--data``
argument checked and hashed, the experiments it can run, its reports folder claimed), over the runner.

The runner (:mod:`locbook.suite.runner`) executes tasks and imports no page code; this module passes it the suite's
reports (:mod:`locbook.suite.site`) as its callbacks. :func:`run_tasks` is the runner's with the site's pages: the
sweeps (studies, brackets, splits) run through it.
"""
from __future__ import annotations

import csv
import hashlib
import json
import os
import re
from pathlib import Path

from ..errors import ParameterError
from . import runner
from .files import read_json, write_text_atomic
from .progress import make_progress
from .runner import KERNEL_NAME, SuiteRun, Task, check_options
from .site import write_experiment_pages, write_suite_reports
from .spec import PROFILES, SAFE_NAME, Experiment, Suite, SuiteError

__all__ = ["run_suite", "run_tasks", "override_folder_name", "split_overrides", "data_kinds", "select_for_data",
           "user_method_failures", "USER_METHODS_TABLE", "load_data_argument", "claim_dataset_folder"]


def run_tasks(suite: Suite, tasks: list[Task], profile: str, report_dir: Path, *, write_reports,
              **options) -> SuiteRun:
    """:func:`locbook.suite.runner.run_tasks` with the site's pages for every report
    (:func:`locbook.suite.site.write_experiment_pages`); ``options`` as there."""
    return runner.run_tasks(suite, tasks, profile, report_dir, write_reports=write_reports,
                            write_pages=write_experiment_pages, **options)


def override_folder_name(profile: str, overrides: dict[str, str]) -> str:
    """Folder of a run with ``-p`` overrides: the profile, the overrides in words, and a hash of them
    (``quick-sigma-db-2-5-a1b2c3d4``), ``[a-z0-9-]`` only."""
    words = "-".join(f"{k}-{overrides[k]}" for k in sorted(overrides))
    slug = re.sub(r"[^a-z0-9]+", "-", words.lower()).strip("-")[:60].strip("-")
    digest = hashlib.sha256(json.dumps(overrides, sort_keys=True).encode()).hexdigest()[:8]
    return "-".join(p for p in (profile, slug, digest) if p)


def _absolute(path) -> Path:
    """``path`` (``~`` expanded) as an absolute path, without resolving symbolic links."""
    return Path(os.path.abspath(Path(path).expanduser()))


def split_overrides(experiments: list[Experiment], overrides: dict[str, str]):
    """``-p`` on several experiments: each takes the overrides its notebook declares, and one that declares none of
    them is left out (it would only rerun its defaults). Returns ``(kept experiments, {id: its overrides}, left-out
    ids)``. A name that no selected experiment declares is refused (ParameterError naming the experiments); with one
    experiment every name must be its own (the usual check, in :meth:`Experiment.parameters`)."""
    names = [k for k in overrides if k != "data"]
    if len(experiments) <= 1 or not names:
        return list(experiments), {e.id: dict(overrides) for e in experiments}, []
    declared = {e.id: e.declared_parameters() for e in experiments}
    nobody = [k for k in names if not any(k in d for d in declared.values())]
    if nobody:
        raise ParameterError(f"unknown parameter {', '.join(repr(k) for k in nobody)}: none of the "
                             f"{len(experiments)} selected experiments declares it "
                             f"({', '.join(e.id for e in experiments)}); `locbook show ID` lists an experiment's")
    kept, each, left_out = [], {}, []
    for e in experiments:
        mine = {k: v for k, v in overrides.items() if k in declared[e.id] or k == "data"}
        if any(k in declared[e.id] for k in names):
            kept.append(e)
            each[e.id] = mine
        else:
            left_out.append(e.id)
    return kept, each, left_out


def run_suite(suite: Suite, experiments: list[Experiment], profile: str, *, jobs: int = 1, force: bool = False,
              overrides: dict[str, str] | None = None, report_root: Path | None = None,
              out_dir: Path | None = None, timeout_s: float = 1800, retries: int = 1,
              kernel_name: str = KERNEL_NAME, progress="plain", executor: str = "local",
              scheduler: str | None = None, data: str | None = None, requested=None, methods=(),
              trackers=()) -> SuiteRun:
    """Run experiments and write their reports; see the module docstring for the guarantees.

    ``data``: a data set (a shipped name or a folder with ``dataset.toml``; :func:`locbook.data.dataset.load_dataset`
    checks it first) for every selected experiment, each of which must take one (a ``data`` parameter: the measured-
    data experiments and the cross-document benchmark). Its reports go to ``data-<name>/`` inside the folder the run
    would otherwise write (``<report_root>/<profile>/data-<name>/``), and its files join the cache key. An experiment
    whose ``[experiment.data_run] needs`` the data set does not meet is left out before anything runs (one message
    each; :attr:`SuiteRun.left_out`; recorded for the data set's page), unless its id is in ``requested`` (the ids
    asked for by name; default: every experiment given): that is an error (:func:`select_for_data`). The values of
    ``[experiment.data_run] parameters`` apply to a data run, under ``overrides``.

    ``methods`` / ``trackers``: static methods and trackers of your own (:class:`locbook.user_methods.UserMethod`,
    ``--method`` / ``--tracker``), a data run's only: each experiment that declares a ``methods`` (``trackers``)
    parameter gets them, ``NAME=SPEC`` with a file absolute, so they join its cache key (and the kernel records the
    content of the code it ran, :func:`locbook._datalog.record_read`); the report folder stays the data run's. A
    name the data set's own ``[[method]]`` tables use too is refused before anything runs.

    Parameters of every selected experiment are checked before any executes (raises ParameterError); with several
    experiments, each takes the ``overrides`` it declares and those declaring none are left out
    (:func:`split_overrides`).
    The reports go to ``<report_root>/<profile>/``, or, with ``overrides``, to their own folder
    (:func:`override_folder_name`) so that the profile's default report is never touched; ``out_dir``
    names the folder explicitly. ``retries``: further attempts for an experiment whose worker or kernel died.
    ``progress``: a mode of :func:`locbook.suite.progress.make_progress` ("auto", "live", "plain", "quiet") or
    a view object. ``executor``: "local" (worker processes on this machine, ``jobs`` at a time) or "dask"
    (each experiment a task on dask.distributed: the cluster at ``scheduler``, or a LocalCluster of ``jobs``
    workers); both run the same worker, so caching, locking, retries and numbers are the same.
    """
    overrides = dict(overrides or {})
    check_options(timeout_s, jobs, executor, scheduler)
    data_roots: list[str] = []
    per_experiment: dict[str, dict] = {}
    dataset_name = identity = None
    facts: dict = {}
    left_out: dict[str, str] = {}
    if "data" in overrides:
        if data is not None:
            raise SuiteError("give the data set once: --data or -p data=..., not both")
        data = overrides.pop("data")          # -p data=X is --data X: checked, hashed, its own folder
    given = [k for k in ("methods", "trackers") if k in overrides]
    if given:
        raise SuiteError(f"-p {given[0]}: give methods of your own with --method NAME=SPEC and --tracker NAME=SPEC "
                         "(a file relative to this folder)")
    methods, trackers = list(methods or ()), list(trackers or ())
    if (methods or trackers) and data is None:
        raise SuiteError("--method and --tracker run on a data set: give one with --data DIR")
    chosen = [k for k in ("calibration", "anchors") if k in overrides]
    if chosen and data is None:
        raise SuiteError(f"-p {chosen[0]} names {'recordings' if chosen[0] == 'calibration' else 'anchors'} of one "
                         "data set: give it with --data DIR (a shipped one by name: --data kolakowski2021)")
    if data is not None:
        ds, dataset_name, value, data_roots, identity = load_data_argument(data)
        # the split and anchor subset every experiment will see (locbook.data.selection.select): a bad value is one
        # line here, before anything runs, and an experiment the selection leaves nothing to run on is left out
        from ..data.selection import select
        ds = select(ds, calibration=overrides.get("calibration", ""), anchors=overrides.get("anchors", ""))
        from ..user_methods import registered_methods
        registered_methods(ds, methods=methods, trackers=trackers)        # a name given twice: one line, here
        for exp in experiments:
            declared = exp.declared_parameters()
            if "data" not in declared:
                takes = [e.id for e in suite.experiments if "data" in e.declared_parameters()]
                raise SuiteError(f"experiment {exp.id!r} takes no data set; with --data run the experiments that do: "
                                 f"{', '.join(takes)} (`locbook run --data DIR` runs them all)")
            as_list = str(declared["data"].annotation).replace(" ", "").startswith("list")
            # override text as `-p` takes it: a str parameter verbatim, a list as a TOML array
            per_experiment[exp.id] = {"data": json.dumps([value]) if as_list else value}
            for name, mine in (("methods", methods), ("trackers", trackers)):
                if mine and name in declared:
                    per_experiment[exp.id][name] = json.dumps([m.option() for m in mine])
        kinds = data_kinds(ds)
        experiments, left_out = select_for_data(experiments, kinds, requested)
        facts = _dataset_facts(ds, identity, suite, kinds)
    # every user path made absolute here, once: the workers and kernels run in other folders (a kernel runs in
    # its notebook's folder), so a relative staging path would point elsewhere there
    root = _absolute(report_root) if report_root else _absolute(suite.default_reports())
    if out_dir is not None:
        report_dir = _absolute(out_dir)
        if not SAFE_NAME.match(report_dir.name):
            raise SuiteError(f"output folder name {report_dir.name!r} must be lower-case letters, digits and "
                             "hyphens ([a-z0-9-])")
    elif overrides:
        report_dir = root / override_folder_name(profile, overrides)
    else:
        report_dir = root / profile
    if dataset_name is not None and out_dir is None:
        report_dir = report_dir / f"data-{dataset_name}"
    if identity is not None:
        claim_dataset_folder(report_dir, dataset_name, identity, facts)
    experiments, own, _ = split_overrides(experiments, overrides)
    tasks = [Task(exp.id, exp, exp.parameters(profile, {**own[exp.id], **per_experiment.get(exp.id, {})},
                                              data_run=data is not None))
             for exp in experiments]  # validation first
    custom_folder = bool(overrides) or out_dir is not None or dataset_name is not None
    # the run a -p (or --out) run is compared with: the profile's own folder (of the same data set)
    base_dir = root / profile / (f"data-{dataset_name}" if dataset_name is not None else "")
    compare_with = base_dir if base_dir != report_dir else None
    if isinstance(progress, str):
        progress = make_progress(progress)
    for eid, why in left_out.items():
        progress.message(f"{eid}: left out: {why}")
    for flag, name, mine in (("--method", "methods", methods), ("--tracker", "trackers", trackers)):
        takers = [e.id for e in experiments if name in e.declared_parameters()]
        if mine and not takers:
            every = [e.id for e in suite.experiments if name in e.declared_parameters()]
            progress.message(f"{flag} {', '.join(m.name for m in mine)}: no experiment of this run takes it (those "
                             f"that do: {', '.join(every)})")
        elif mine and name == "trackers" and not ds.has_role("track"):
            progress.message(f"--tracker {', '.join(m.name for m in mine)}: the data set has no track recording, so "
                             "no report runs it")
    run = run_tasks(suite, tasks, profile, report_dir, jobs=jobs, force=force, timeout_s=timeout_s,
                    retries=retries, kernel_name=kernel_name, progress=progress, executor=executor,
                    scheduler=scheduler, data_roots=data_roots,
                    write_reports=lambda folder, _outcomes: _write_reports(
                        suite, folder, custom_folder, dataset_name is not None and out_dir is None, compare_with))
    run.left_out = dict(left_out)
    return run


#: the table a data run's notebook saves when it runs methods of your own (:func:`locbook.scenarios.measured.
#: user_method_rows`): which ran, which failed and why
USER_METHODS_TABLE = "user_methods.csv"


def user_method_failures(run: SuiteRun) -> list[dict]:
    """The methods of your own that failed in the reports of ``run`` (executed or cached: a cached report's failure
    is still the state of that method), read from each report's :data:`USER_METHODS_TABLE`: one dict per method,
    ``{method, kind, function, error, experiments, page}`` (``page``: the first report that shows its traceback)."""
    out: dict[str, dict] = {}
    for o in run.outcomes:
        if o.status not in ("ok", "cached"):
            continue
        folder = run.report_dir / o.id
        table = folder / USER_METHODS_TABLE
        if not table.is_file():
            continue
        try:
            with open(table, newline="", encoding="utf-8") as fh:
                rows = list(csv.DictReader(fh))
        except (OSError, UnicodeDecodeError, csv.Error):
            continue
        for r in rows:
            if r.get("status") != "failed" or not r.get("method"):
                continue
            f = out.setdefault(r["method"], {"method": r["method"], "kind": r.get("kind", ""),
                                             "function": r.get("function", ""), "error": r.get("error", ""),
                                             "experiments": [], "page": str(folder / "report.html")})
            if o.id not in f["experiments"]:
                f["experiments"].append(o.id)
    return list(out.values())


def data_kinds(ds) -> frozenset[str]:
    """The kinds of :data:`locbook.suite.spec.DATA_KINDS` a loaded data set (:class:`locbook.data.dataset.Dataset`)
    holds: each role with a recording, and "scored" when it has a recording the static methods are scored on
    (:func:`locbook.scenarios.measured.scored_recordings`)."""
    from ..data.dataset import ROLES
    from ..scenarios.measured import scored_recordings
    kinds = {role for role in ROLES if ds.has_role(role)}
    if scored_recordings(ds):
        kinds.add("scored")
    return frozenset(kinds)


def select_for_data(experiments: list[Experiment], kinds, requested=None) -> tuple[list[Experiment], dict[str, str]]:
    """The experiments a data set holding ``kinds`` (:func:`data_kinds`) can run: ``(kept, {id: why left out})``,
    by each one's ``[experiment.data_run] needs`` (one without the table runs on every data set). ``requested``:
    the ids asked for by name (default: all of ``experiments``); one of them that the data set cannot run is an
    error (SuiteError, one line), as is a selection of which none can run."""
    requested = {e.id for e in experiments} if requested is None else set(requested)
    kept, left_out = [], {}
    for exp in experiments:
        why = exp.data_run.missing(kinds) if exp.data_run is not None else ""
        if not why:
            kept.append(exp)
        elif exp.id in requested:
            raise SuiteError(f"{exp.id} cannot run on this data set: {why} (`locbook run --data DIR` without ids "
                             "runs every experiment the data set can run)")
        else:
            left_out[exp.id] = why
    if experiments and not kept:
        raise SuiteError("no selected experiment can run on this data set: " + "; ".join(
            f"{eid}: {why}" for eid, why in left_out.items()))
    return kept, left_out


def _write_reports(suite: Suite, folder: Path, custom_folder: bool, nested: bool,
                   compare_with: Path | None = None) -> None:
    write_suite_reports(suite, folder, list_all=not custom_folder, compare_with=compare_with)
    parent = folder.parent
    if nested and (parent / "index.html").is_file():     # the profile's index links its data-<name>/ folders
        from filelock import FileLock, Timeout
        lock = FileLock(str(parent / ".lock"))
        try:
            lock.acquire(timeout=0)       # a run writing that folder rebuilds its index itself, link included
        except Timeout:
            return
        try:
            write_suite_reports(suite, parent, list_all=parent.name in PROFILES)
        finally:
            lock.release()


def load_data_argument(data: str):
    """``(data set, name, parameter value, data roots, identity)`` of a data set given to ``--data``: checked by
    loading it (a malformed one fails here, before anything runs). A shipped data set is passed by name, any other
    by its absolute folder. The roots hold every file its manifest names (a symbolic link's target folder too), so
    that each file a report read joins its cache record; the identity ("shipped:<name>" or the folder) tells two
    data sets of one name apart."""
    from ..data.dataset import datasets_dir, load_dataset
    from ..data.floors import require_one_floor
    ds = load_dataset(data)
    require_one_floor(ds)                 # a building runs floor by floor (floors.floor_runs: the CLI's loop)
    base = ds.manifest_name or ds.name    # one floor of a data set: DIR@F1, its name the manifest's and the floor's
    shipped = ds.root.resolve() == (datasets_dir() / base).resolve()
    roots = sorted({str(ds.root), *(str(Path(f).resolve().parent) for f in ds.files)})
    return (ds, ds.name, (base if shipped else str(ds.root)) + ds.selector, roots,
            (f"shipped:{base}" if shipped else str(ds.root)) + ds.selector)


def _dataset_argument(data: str) -> tuple[str, str, list[str], str]:
    """``(name, parameter value, data roots, identity)`` of :func:`load_data_argument`."""
    return load_data_argument(data)[1:]


def _dataset_facts(ds, identity: str, suite: Suite, kinds) -> dict:
    """What a data set's page says of it, read from the loaded data set (its manifest): title, attribution,
    licence, the manifest's path (a shipped one's inside the package, so that committed reports name no machine's
    folder), the geometry sentence, and every experiment of the suite it cannot run, with why."""
    from ..data.dataset import MANIFEST
    manifest = (f"locbook/data/datasets/{ds.name}/{MANIFEST}" if identity.startswith("shipped:")
                else str(Path(ds.root) / MANIFEST))
    left_out = {e.id: e.data_run.missing(kinds) for e in suite.experiments
                if e.data_run is not None and e.data_run.missing(kinds)}
    return {"title": ds.title, "attribution": ds.attribution, "licence": ds.license, "manifest": manifest,
            "geometry": getattr(ds, "geometry_text", ""), "left out": left_out}


def claim_dataset_folder(report_dir: Path, name: str, identity: str, facts: dict | None = None) -> None:
    """``data-<name>/`` holds one data set's reports: refuse a different data set of the same name (its reports
    would replace the others'), else record which one it holds and what its page says of it (``dataset.json``:
    name, identity, and ``facts``, :func:`_dataset_facts`), rewritten at every run."""
    record = report_dir / "dataset.json"
    held = read_json(record, {}).get("data set")
    if held and held != identity:
        raise SuiteError(f"{report_dir} holds the reports of another data set named {name!r} ({held}); give yours "
                         "another name in its dataset.toml (name = ...), or remove that folder")
    if not held or facts:
        report_dir.mkdir(parents=True, exist_ok=True)
        write_text_atomic(record, json.dumps({"name": name, "data set": identity, **(facts or {})}, indent=1) + "\n")
