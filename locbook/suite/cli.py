"""``locbook`` command line: list the experiments, run the notebook suite, run a study or an interpretation bracket.

Exit status of ``run``, ``study`` and ``bracket`` (docs/running.md, "Interrupts, concurrent runs and the cache"): 0 all
good; 1 some experiment failed (or the Dask scheduler was lost), or a method of your own (``--method``, ``--tracker``, a
data set's ``[[method]]``) failed in a report that is otherwise complete; 2 bad input (parameters, experiment list,
notebook file, unwritable folder, a method's name or spec); 3 no space left on the device (or quota) holding the
reports: the run stopped, the path is named, earlier reports are kept; 130 / 143 interrupted by SIGINT / SIGTERM
(finished reports are kept). ``data check`` exits 1 when a registered method does not import.
"""
from __future__ import annotations

import argparse
import signal
import sys
from pathlib import Path

from ..errors import LocbookError, ParameterError
from ..reproduce.interpretations import InterpretationsError

#: exit statuses of ``locbook run`` (module docstring)
EXIT_OK, EXIT_FAILED, EXIT_BAD_INPUT, EXIT_DISK_FULL = 0, 1, 2, 3

PROFILE_HELP = "quick: reduced Monte-Carlo counts (default); full: the source's own counts"


def _parse_overrides(items: list[str]) -> dict[str, str]:
    out = {}
    for item in items:
        name, sep, value = item.partition("=")
        if not sep or not name.strip():
            raise ParameterError(f"-p expects NAME=VALUE (VALUE a TOML value, e.g. q_grid=[0.1, 0.2]), got {item!r}")
        out[name.strip()] = value
    return out


def _interpretations_option(args):
    """``--interpretations CSV``, or the same file given by its old spelling ``--readings`` (deprecated, not shown in
    the help; silent, so that a bad file is still one line on stderr); both is an error."""
    if args.old_readings is None:
        return args.interpretations
    if args.interpretations is not None:
        raise ParameterError("give --interpretations only (--readings is its deprecated spelling)")
    return args.old_readings


def _positive(kind, text: str):
    """argparse type: a positive, finite number (``kind`` float) or whole number (``kind`` int)."""
    try:
        value = kind(text)
    except ValueError:
        raise argparse.ArgumentTypeError(f"expects a {'whole ' if kind is int else ''}number, got {text!r}") from None
    if not value > 0 or value == float("inf"):
        raise argparse.ArgumentTypeError(f"must be a positive, finite number, got {text!r}")
    return value


def _print_summary(run, progress: str = "plain", see: Path | None = None, rebuilt: str = "") -> None:
    """The scoreboard and the end of a run. ``rebuilt``: what the run's aggregate files hold now (for ``run``: the
    index and numbers.csv; a study's or bracket's :class:`~locbook.suite.sweep.Aggregate`), said after a stop."""
    names = {"ok": "executed", "cached": "cached", "failed": "failed", "interrupted": "interrupted",
             "not run": "not started"}
    counts = ", ".join(f"{run.count(s)} {w}" for s, w in names.items()
                       if run.count(s) or s in ("ok", "cached", "failed"))
    from .progress import print_scoreboard
    print_scoreboard(run, progress)
    print(f"done: {counts}; see {see or run.report_dir / 'index.html'}")
    if run.interrupted_by is not None or run.disk_full is not None or run.executor_error:
        if run.interrupted_by is not None:
            sig = signal.Signals(run.interrupted_by).name
            print(f"interrupted by {sig}: finished reports are kept" + (f"; {rebuilt}" if rebuilt else "") + ".",
                  file=sys.stderr)
        for status in ("interrupted", "not run"):
            ids = [run.name(o.id) for o in run.outcomes if o.status == status]
            if ids:
                print(f"  {names[status]}: {', '.join(ids)}", file=sys.stderr)
    failed = [o for o in run.outcomes if o.status == "failed"]
    if failed:
        print("failed: " + ", ".join(f"{run.name(o.id)} ({o.error})" for o in failed), file=sys.stderr)
    if run.executor_error:
        print(f"locbook: error: {run.executor_error}; the run stopped, and its experiments on the cluster were "
              "asked to stop", file=sys.stderr)
    if run.disk_full is not None:
        print(f"locbook: error: no space left on device writing {run.disk_full}; the run stopped (earlier "
              "reports are kept; free some space and run again)", file=sys.stderr)
    if rebuilt and run.interrupted_by is None and (run.disk_full is not None or run.executor_error
                                                   or run.count("failed") or run.count("not run")):
        print(f"  {rebuilt}", file=sys.stderr)


def _reports_folder(text: str, reports: Path) -> Path:
    """``locbook compare``'s BASE or VARIANT: a folder as given, else the folder of that name in ``reports`` (a
    profile, a ``-p`` run's folder)."""
    path = Path(text)
    if not path.exists() and path.name == text and (Path(reports) / text).is_dir():
        return Path(reports) / text
    return path


METHOD_HELP = ("a static method of your own beside the battery's (repeatable): NAME=SPEC, SPEC package.module:function "
               "or path/to/file.py:function (relative to this folder); the signature: locbook.MethodInput")
TRACKER_HELP = "a tracker of your own beside the battery's (repeatable): NAME=SPEC as for --method"


def _method_options(command: argparse.ArgumentParser) -> None:
    command.add_argument("--method", dest="methods", action="append", default=[], metavar="NAME=SPEC",
                         help=METHOD_HELP)
    command.add_argument("--tracker", dest="trackers", action="append", default=[], metavar="NAME=SPEC",
                         help=TRACKER_HELP)


def _user_methods(args) -> tuple[list, list]:
    """The ``--method`` and ``--tracker`` options as :class:`locbook.user_methods.UserMethod` (a file relative to
    the current folder), or one ParameterError line."""
    if not (args.methods or args.trackers):
        return [], []
    from ..user_methods import parse_method_option
    return ([parse_method_option(t, "static") for t in args.methods],
            [parse_method_option(t, "tracker") for t in args.trackers])


def _print_method_failures(failures) -> None:
    """One line per user method that failed (:func:`locbook.suite.run.user_method_failures`)."""
    for f in failures:
        print(f"locbook: user method {f['method']!r} ({f['kind']}, {f['function']}) failed in "
              f"{', '.join(f['experiments'])}: {f['error']}; its traceback: {f['page']}", file=sys.stderr)


def _point_options(command: argparse.ArgumentParser, writes: str) -> None:
    """The runner options of a command that runs many points (study, bracket)."""
    command.add_argument("--jobs", "-j", type=lambda t: _positive(int, t), default=2,
                         help="points run in parallel processes (default 2)")
    command.add_argument("--force", action="store_true", help="execute even the points whose report is up to date")
    command.add_argument("--reports", type=Path, help=f"reports folder (default: <repository>/reports); {writes}")
    command.add_argument("--timeout", type=lambda t: _positive(float, t), default=1800,
                         help="seconds allowed per notebook cell (default 1800)")
    command.add_argument("--progress", choices=("auto", "live", "plain", "quiet"), default="auto",
                         help="as for run")
    command.add_argument("--quiet", "-q", dest="progress", action="store_const", const="quiet",
                         help="--progress quiet")
    command.add_argument("--executor", choices=("local", "dask"), default="local",
                         help="local: worker processes here (default); dask: each point a task on dask.distributed")
    command.add_argument("--scheduler", metavar="ADDRESS", help="as for run")


def main(argv: list[str] | None = None) -> int:
    from .. import __version__
    from .._lazy import skip_iri_format_checker
    skip_iri_format_checker()      # `locbook show` and the runner read notebooks with nbformat (and jsonschema)

    parser = argparse.ArgumentParser(prog="locbook", description="Rerun published RSSI localization experiments.")
    parser.add_argument("--version", action="version", version=f"locbook {__version__}")
    suite_help = ("experiment list (default: notebooks/experiments.toml here or in a parent folder, else the one "
                  "installed with locbook); accepted before or after the command")
    parser.add_argument("--suite", type=Path, help=suite_help)
    sub = parser.add_subparsers(dest="command", required=True)
    lst = sub.add_parser("list", help="list the experiments (with KEY: every parameter of those experiments)")
    lst.add_argument("key", nargs="?", help="an experiment id or document key")
    lst.add_argument("--reports", type=Path, help="reports folder the run times are read from")
    show = sub.add_parser("show", help="every parameter of an experiment (type, default, range, description) and "
                                       "its last result")
    show.add_argument("key", help="an experiment id or document key")
    show.add_argument("--reports", type=Path, help="reports folder the last results are read from")
    cmp = sub.add_parser("compare", help="two runs side by side: every printed number in each, the difference, its "
                                         "standard error and whether the change exceeds it (compare-<BASE>.html, .csv)")
    cmp.add_argument("base", metavar="BASE", help="a reports folder (a path, or a folder name in --reports: quick, "
                                                  "full, a -p run's folder)")
    cmp.add_argument("variant", metavar="VARIANT", help="the run compared with BASE, given as BASE is")
    cmp.add_argument("--reports", type=Path, help="reports folder a folder name is looked up in (default: "
                                                  "<repository>/reports)")
    cmp.add_argument("--out", type=Path, help="write compare-<BASE>.html and .csv here (default: VARIANT's folder)")
    nbs = sub.add_parser("notebooks", help="copy the notebooks and the experiment list to DEST for Jupyter")
    nbs.add_argument("dest", type=Path, help="destination folder (created)")
    nbs.add_argument("--force", action="store_true", help="overwrite notebooks already in DEST")
    run = sub.add_parser("run", help="execute experiments and write reports/<profile>/")
    run.add_argument("ids", nargs="*", help="experiment ids or document keys (default: all)")
    run.add_argument("--profile", choices=("quick", "full"), default="quick", help=PROFILE_HELP)
    run.add_argument("--jobs", "-j", type=lambda t: _positive(int, t), default=2,
                     help="notebooks run in parallel processes (default 2)")
    run.add_argument("--force", action="store_true", help="execute even when a cached report is up to date")
    run.add_argument("-p", "--parameter", action="append", default=[], metavar="NAME=VALUE",
                     help="override a notebook parameter (a TOML value, checked against its type and range); "
                          "the reports go to their own folder, never to reports/<profile>/")
    run.add_argument("--data", metavar="DIR_OR_NAME",
                     help="run on this data set (a folder with dataset.toml, or a shipped name such as "
                          "kolakowski2021): every experiment that takes one and that the data set can run (default: "
                          "all of them; one it cannot run is left out, in one line, and asking for it by id is an "
                          "error); the reports go to <reports>/<profile>/data-<name>/; a data set with floors runs "
                          "each floor as its own data run (data-<name>-<floor>/), DIR@FLOOR one of them")
    _method_options(run)
    run.add_argument("--split", choices=("loro",),
                     help="with --data: loro, leave one recording out: for each recording with true positions, the "
                          "battery with the channel fitted on every other one and scored on it (each split its own "
                          "cached reports), and one table and plot of every split and their spread in "
                          "<reports>/<profile>/data-<name>/loro/")
    run.add_argument("--reports", type=Path, help="reports folder (default: <repository>/reports)")
    run.add_argument("--out", type=Path, help="write this run's reports to this folder (a path; its last part "
                                                "[a-z0-9-] only)")
    run.add_argument("--timeout", type=lambda t: _positive(float, t), default=1800,
                     help="seconds allowed per notebook cell (default 1800; rounded up to whole seconds)")
    run.add_argument("--progress", choices=("auto", "live", "plain", "quiet"), default="auto",
                     help="auto (default): a live table on a terminal, one line per event otherwise; plain: one "
                          "line per event; quiet: only the end")
    run.add_argument("--quiet", "-q", dest="progress", action="store_const", const="quiet", help="--progress quiet")
    run.add_argument("--executor", choices=("local", "dask"), default="local",
                     help="local: worker processes here (default); dask: each experiment a task on dask.distributed")
    run.add_argument("--scheduler", metavar="ADDRESS",
                     help="with --executor dask: a scheduler address (tcp://host:8786) or scheduler file; default: "
                          "a LocalCluster of --jobs workers")
    study = sub.add_parser("study", help="run a declared parameter study and write reports/studies/<name>/ "
                                         "(study.csv, plots/)")
    study.add_argument("study", metavar="NAME_OR_PATH",
                       help="a study declared in the experiment list ([[study]]) or a TOML file holding one; or "
                            "anchor-density with --data DIR (the battery on subsets of the data set's anchors)")
    _point_options(study, "the study writes <reports>/studies/<name>/")
    study.add_argument("--data", metavar="DIR_OR_NAME",
                       help="anchor-density: the data set whose anchor subsets are swept (writes "
                            "<reports>/<profile>/data-<name>/anchor-density/)")
    study.add_argument("--profile", choices=("quick", "full"),
                       help="anchor-density: the profile of its runs (default quick; a declared study names its own)")
    study.add_argument("--subsets", type=lambda t: _positive(int, t), default=None, metavar="S",
                       help="anchor-density: subsets drawn per size (default 5; every subset where there are fewer)")
    study.add_argument("--sizes", type=_sizes, metavar="K,K,...",
                       help="anchor-density: the subset sizes (default 3..m, at most 4 evenly spaced, m included)")
    study.add_argument("--sample-seed", type=int, default=0,
                       help="anchor-density: the seed of the subsets' draws (default 0)")
    bracket = sub.add_parser("bracket", help="run an experiment under each declared interpretation of what its source "
                                             "left unprinted and give every scored row a bracket verdict "
                                             "(reports/brackets/<experiment>/)")
    bracket.add_argument("experiment", help="an experiment id (`locbook list`)")
    bracket.add_argument("--profile", choices=("quick", "full"), default="quick", help=PROFILE_HELP)
    bracket.add_argument("--interpretations", type=Path, metavar="CSV",
                         help="an interpretations file of your own (the columns of "
                              "locbook/data/interpretations/*.csv) instead of the declared interpretations")
    # the option's name before "reading" meant only a sensor measurement: still taken, not shown
    bracket.add_argument("--readings", type=Path, dest="old_readings", help=argparse.SUPPRESS)
    _point_options(bracket, "the bracket writes <reports>/brackets/<experiment>/")
    data = sub.add_parser("data", help="measured data sets: check one (`check DIR`), or write the synthetic "
                                       "example (`example DIR`)")
    data.add_argument("action", choices=("check", "example"),
                      help="check: read a data set as `locbook run --data` will and print what it holds; example: "
                           "write the synthetic example data set (raw packets with known truth) to DIR")
    data.add_argument("dataset", metavar="DIR_OR_NAME", help="the data set's folder (or its dataset.toml), or a "
                                                            "shipped name; for example: the folder to create")
    data.add_argument("--seed", type=int, default=1, help="example: the generator's seed (default 1)")
    data.add_argument("--name", default="example",
                      help="example: the data set's name in its manifest (names the reports folder; default example)")
    data.add_argument("--force", action="store_true", help="example: write into a folder that already holds files")
    data.add_argument("--speed", type=lambda t: _positive(float, t), metavar="M_S",
                      help="example: the walkers' speed in m/s (default: the example site's, 1 m/s)")
    data.add_argument("--roles", type=_roles, metavar="ROLES",
                      help="example: the recordings written, a comma list of calibration, static, track with "
                           "calibration among them (default: all three; calibration,static: a static-only set)")
    data.add_argument("--two-d", action="store_true",
                      help="example: anchors without heights (a 2-D site: distances in the plane)")
    data.add_argument("--native-scans", action="store_true",
                      help="example: the tracks written as scans (every anchor of a scan at one time, window_s = 0)")
    data.add_argument("--ranges", action="store_true",
                      help="example: a ranges file per recording (RTT-like ranges, 0.3 m std, reported)")
    data.add_argument("--inertial", action="store_true",
                      help="example: a 50 Hz accelerometer and gyroscope file per recording (walks with rounded "
                           "corners); the tracking battery adds its fusion trackers")
    data.add_argument("--floors", type=lambda t: _positive(int, t), default=1, metavar="N",
                      help="example: a building of N floors (F1, F2, ...; the same hall on each, 8 anchors per floor, "
                           "readings across floors 15 dB weaker per floor; default 1)")
    data.add_argument("--floor-plan", action="store_true",
                      help="example: also write plan.png, a floor plan drawn under the maps, with its extent")
    data.add_argument("--method", dest="methods", action="append", default=[], metavar="NAME=SPEC",
                      help="check: also import this static method of your own (as for run)")
    data.add_argument("--tracker", dest="trackers", action="append", default=[], metavar="NAME=SPEC",
                      help="check: also import this tracker of your own (as for run)")
    # --suite after the command too; SUPPRESS keeps one given before it
    for command in (lst, show, cmp, nbs, run, study, bracket, data):
        command.add_argument("--suite", type=Path, default=argparse.SUPPRESS, help=suite_help)
    args = parser.parse_args(argv)

    from .spec import load_suite  # each command imports what it needs: `locbook list` loads no numpy

    try:
        suite = load_suite(args.suite)
        if args.command in ("list", "show"):
            from .catalog import list_text, show_text
            reports = args.reports or suite.default_reports()
            print(show_text(suite, args.key, reports) if args.key else list_text(suite, reports))
            return 0
        if args.command == "compare":
            from .compare import compare_folders, write_comparison
            reports = args.reports or suite.default_reports()
            comparison = write_comparison(compare_folders(_reports_folder(args.base, reports),
                                                          _reports_folder(args.variant, reports), suite), args.out)
            print(f"{comparison.summary()}; see {comparison.written[0]}")
            return 0
        if args.command == "data":
            if args.action == "example":
                import numpy as np

                from ..data.example import EXAMPLE_ROLES, write_example_dataset
                folder = write_example_dataset(args.dataset, np.random.default_rng(args.seed), seed_note=args.seed,
                                               name=args.name, force=args.force, speed_m_s=args.speed,
                                               roles=args.roles or EXAMPLE_ROLES, two_d=args.two_d,
                                               native_scans=args.native_scans, ranges=args.ranges,
                                               inertial=args.inertial, floors=args.floors,
                                               floor_plan=args.floor_plan)
                print(f"wrote the example data set to {folder}; check it with `locbook data check {folder}` and run "
                      f"the battery with `locbook run --data {folder}`")
                return 0
            methods, trackers = _user_methods(args)
            text, unimportable = _dataset_check(args.dataset, suite, methods, trackers)
            print(text)
            return EXIT_FAILED if unimportable else 0
        if args.command == "notebooks":
            from .catalog import copy_notebooks
            dest = copy_notebooks(suite, args.dest, force=args.force)
            print(f"copied {len(suite.experiments)} notebooks and experiments.toml to {dest}; open them with "
                  f"`jupyter lab {dest}`, or run them with `locbook run --suite {dest / 'experiments.toml'}`")
            return 0
        if args.command == "study" and (args.data is not None or args.study == DENSITY_STUDY):
            from .splits import DENSITY_SUBSETS, run_density
            if args.study != DENSITY_STUDY:
                raise ParameterError(f"--data belongs to the built-in study {DENSITY_STUDY!r} (a declared study "
                                     "names its experiments' parameters); run `locbook study "
                                     f"{DENSITY_STUDY} --data DIR`")
            if args.data is None:
                raise ParameterError(f"the study {DENSITY_STUDY!r} sweeps the anchors of a data set: give it with "
                                     "--data DIR (a shipped one by name: --data kolakowski2021)")
            result = run_density(suite, args.data, profile=args.profile or "quick",
                                 subsets=args.subsets or DENSITY_SUBSETS, sizes=args.sizes,
                                 sample_seed=args.sample_seed, report_root=args.reports, jobs=args.jobs,
                                 force=args.force, timeout_s=args.timeout, progress=args.progress,
                                 executor=args.executor, scheduler=args.scheduler)
            see = result.aggregate.path
        elif args.command == "study":
            if args.profile or args.subsets or args.sizes or args.sample_seed:
                raise ParameterError("--profile, --subsets, --sizes and --sample-seed belong to the built-in study "
                                     f"{DENSITY_STUDY!r}; a declared study names them in its declaration")
            from .study import load_study, run_study, study_folder
            declared = load_study(suite, args.study)
            see = study_folder(suite, declared, args.reports) / "study.csv"
            result = run_study(suite, declared, report_root=args.reports, jobs=args.jobs, force=args.force,
                               timeout_s=args.timeout, progress=args.progress, executor=args.executor,
                               scheduler=args.scheduler)
        elif args.command == "bracket":
            from .bracket import bracket_folder, find_experiment, read_interpretations_option, run_bracket
            exp = find_experiment(suite, args.experiment)
            see = bracket_folder(suite, exp, args.reports) / "bracket.csv"
            result = run_bracket(suite, exp, profile=args.profile,
                                 interpretations=read_interpretations_option(_interpretations_option(args)),
                                 report_root=args.reports, jobs=args.jobs, force=args.force,
                                 timeout_s=args.timeout, progress=args.progress, executor=args.executor,
                                 scheduler=args.scheduler)
        else:
            if args.data is not None and not args.ids:     # every experiment that takes a data set
                experiments = [e for e in suite.experiments if "data" in e.declared_parameters()]
            else:
                experiments = suite.select(args.ids)
            # an experiment named by its exact id must run on the data set; one selected by a document key or with
            # no ids is left out when the data set cannot run it (run.select_for_data)
            requested = {i for i in args.ids if any(e.id == i for e in suite.experiments)}
            from .run import run_suite, split_overrides
            overrides = _parse_overrides(args.parameter)
            methods, trackers = _user_methods(args)
            if (methods or trackers) and args.data is None and "data" not in overrides:
                raise ParameterError("--method and --tracker run beside the battery on a data set: give one with "
                                     "--data DIR (a shipped one by name: --data kolakowski2021)")
            if args.split is not None:
                if args.data is None:
                    raise ParameterError(f"--split {args.split} splits the recordings of one data set: give it with "
                                         "--data DIR (a shipped one by name: --data kolakowski2021)")
                if args.out is not None:
                    raise ParameterError("--split loro writes each split to its own folder and the table to "
                                         "<reports>/<profile>/data-<name>/loro/: --out does not apply")
                from .splits import run_loro
                loro = run_loro(suite, suite.select(args.ids) if args.ids else [], args.profile, data=args.data,
                                overrides=overrides, report_root=args.reports, progress=args.progress,
                                methods=methods, trackers=trackers, jobs=args.jobs, force=args.force,
                                timeout_s=args.timeout, executor=args.executor, scheduler=args.scheduler)
                return _loro_summary(loro, args.progress)
            kept, own, left_out = split_overrides(experiments, overrides)
            if left_out:
                taken = sorted({k for e in kept for k in own[e.id] if k != "data"})
                print(f"-p {', '.join(taken)}: {len(kept)} of {len(experiments)} selected experiments declare it and "
                      f"run ({', '.join(e.id for e in kept)}); left out: {', '.join(left_out)}")
            # a data set with floors runs floor by floor, each its own data run (locbook.data.floors.floor_runs)
            from ..data.floors import floor_runs
            given = args.data if args.data is not None else overrides.get("data")
            floor_results = []
            for one in floor_runs(given) if given is not None else [None]:
                result = run_suite(suite, experiments, args.profile, jobs=args.jobs, force=args.force,
                                   overrides={**overrides, **({"data": one} if "data" in overrides else {})},
                                   report_root=args.reports, out_dir=args.out, timeout_s=args.timeout,
                                   progress=args.progress, executor=args.executor, scheduler=args.scheduler,
                                   data=one if args.data is not None else None, requested=requested,
                                   methods=methods, trackers=trackers)
                floor_results.append((one, result))
    except (ParameterError, InterpretationsError, LocbookError) as exc:   # LocbookError: a malformed data set too
        print("locbook: error: " + " ".join(str(exc).split("\n")), file=sys.stderr)   # one line, whatever raised it
        return EXIT_BAD_INPUT
    except KeyboardInterrupt:  # before the run started its own handling (loading, checking parameters)
        print("locbook: interrupted before any experiment started; nothing was changed", file=sys.stderr)
        return 130
    except OSError as exc:   # a read-only or full disk before any experiment ran (the folder, its lock)
        from .worker import disk_full_path
        path = disk_full_path(exc, "")
        if path is not None:
            print(f"locbook: error: no space left on device writing {path or 'the reports folder'}; nothing "
                  "was run", file=sys.stderr)
            return EXIT_DISK_FULL
        where = f" ({exc.filename})" if exc.filename else ""
        print(f"locbook: error: {exc.strerror or exc}{where}", file=sys.stderr)
        return EXIT_BAD_INPUT
    aggregate = getattr(result, "aggregate", None)    # a study's or bracket's study.csv / bracket.csv
    rebuilt = aggregate.describe() if aggregate is not None else ""
    if args.command == "study":
        _print_summary(result, args.progress, see, rebuilt)
        return _exit_status(result)
    if args.command == "bracket":
        from .bracket import counts, load_bracket
        _print_summary(result, args.progress, see, rebuilt)
        if aggregate is not None and aggregate.written:
            found = counts(load_bracket(see.parent))
            print(f"bracket of {args.experiment}: " + ", ".join(f"{n} {b}" for b, n in found.items())
                  + f" (scored rows at the {args.profile} profile; the next `locbook run --profile {args.profile}` "
                    f"rebuilds the site's columns, findings and conclusions pages from it)")
        else:
            print(f"bracket of {args.experiment} incomplete: its default point has no up-to-date report, so no "
                  "verdict was written (an earlier bracket.csv is kept as it was)", file=sys.stderr)
        return _exit_status(result)
    from .run import user_method_failures
    worst = EXIT_OK
    for data, result in floor_results:        # one run, or one per floor of a data set with floors
        if result.report_dir.name != args.profile and data is not None:
            print(f"reports of this run: {result.report_dir.resolve()} (data set {data})")
        elif result.report_dir.name != args.profile:
            print(f"reports of this run: {result.report_dir.resolve()} (reports/{args.profile}/ is unchanged)")
        _print_summary(result, args.progress)
        failures = user_method_failures(result)
        _print_method_failures(failures)
        status = _exit_status(result)
        worst = max(worst, EXIT_FAILED if failures and status == EXIT_OK else status)
    return worst


#: the built-in study of a data set's anchor subsets (locbook.suite.splits.run_density)
DENSITY_STUDY = "anchor-density"


def _sizes(text: str) -> tuple[int, ...]:
    """argparse type of ``--sizes``: a comma list of whole numbers (the study checks their range)."""
    try:
        sizes = tuple(int(t) for t in text.split(",") if t.strip())
    except ValueError:
        raise argparse.ArgumentTypeError(f"expects a comma list of whole numbers such as 3,4,6, got {text!r}") from None
    if not sizes:
        raise argparse.ArgumentTypeError(f"expects a comma list of whole numbers such as 3,4,6, got {text!r}")
    return sizes


def _loro_summary(loro, progress: str) -> int:
    """The end of ``--split loro``: each split's scoreboard line, where the table is, and the exit status (the
    worst of the splits': an interrupt, a full disk, a failure, a method of your own that failed)."""
    from .run import user_method_failures
    failures = []
    for held, calibration, run, note in loro.splits:
        if run is None:
            print(f"split {held}: {note}")
            continue
        print(f"split {held} (the channel fitted on {', '.join(calibration)}):")
        _print_summary(run, progress)
        failures += [f for f in user_method_failures(run) if f not in failures]
    _print_method_failures(failures)
    if loro.written:
        print(f"leave-one-recording-out: {sum(r is not None for _h, _c, r, _n in loro.splits)} split(s); table "
              f"{loro.folder / 'loro.csv'} (and loro.md), plot {loro.folder / 'loro.png'}")
    elif loro.kept:
        print(f"leave-one-recording-out: stopped before its last split; the earlier table {loro.folder / 'loro.csv'} "
              "is kept as it was", file=sys.stderr)
    else:
        print("leave-one-recording-out: no split has an up-to-date report; no table was written", file=sys.stderr)
    statuses = [_exit_status(run) for run in loro.runs]
    worst = next((s for s in statuses if s not in (EXIT_OK, EXIT_FAILED)), None)
    if worst is not None:
        return worst
    return EXIT_FAILED if (EXIT_FAILED in statuses or failures) else EXIT_OK


def _roles(text: str) -> tuple[str, ...]:
    """argparse type of ``--roles``: a comma list of recording roles (the generator checks which it accepts)."""
    roles = tuple(r.strip() for r in text.split(",") if r.strip())
    if not roles:
        raise argparse.ArgumentTypeError(f"expects a comma list such as calibration,static, got {text!r}")
    return roles


def _dataset_check(path: str, suite=None, methods=(), trackers=()) -> tuple[str, list[str]]:
    """``locbook data check``: :func:`_dataset_text` and a line per method of your own (the manifest's
    ``[[method]]``, then ``--method`` / ``--tracker``) saying whether it imports; returns ``(text, the names of the
    methods that do not import)``."""
    from ..data.dataset import load_dataset
    from ..user_methods import check_import, registered_methods
    text = _dataset_text(path, suite)
    registered = registered_methods(load_dataset(path), methods=methods, trackers=trackers)
    if not registered:
        return text, []
    lines, failed = ["", f"methods of your own ({len(registered)}; they run beside the battery's):"], []
    for m in registered:
        why = check_import(m)
        where = "[[method]]" if m.source == "manifest" else ("--method" if m.kind == "static" else "--tracker")
        lines.append(f"  {m.name} ({m.kind}, {where}): {m.described}: " + (f"does not import: {why}" if why else
                                                                              "imports"))
        if why:
            failed.append(m.name)
    return text + "\n" + "\n".join(lines), failed


def _dataset_text(path: str, suite=None) -> str:
    """What ``locbook data`` prints: the data set's provenance, geometry, notes and one line per recording; with the
    experiment list ``suite``, which experiments ``locbook run --data`` runs on it and which it leaves out."""
    from ..data.dataset import dataset_summary, load_dataset
    from ..data.floors import floor_slug
    from ..reproduce.report import Table
    ds = load_dataset(path)
    lo, hi = ds.outline_m.min(axis=0), ds.outline_m.max(axis=0)
    lines = [f"data set {ds.name!r}: {ds.title}", f"  folder: {ds.root}", f"  licence: {ds.license}",
             f"  attribution: {ds.attribution}",
             f"  anchors: {len(ds.anchor_ids)} ({', '.join(ds.anchor_ids[:12])}"
             f"{', ...' if len(ds.anchor_ids) > 12 else ''})",
             *([f"  run anchors: {len(ds.run_anchors)} of {len(ds.anchor_ids)} ({', '.join(ds.run_anchors)}; "
                f"[run] anchors: a run ignores the other anchors' readings, -p anchors=... replaces it)"]
               if getattr(ds, "run_anchors", ()) else []),
             f"  geometry: {ds.geometry_text}",     # 2-D (no heights) or 3-D with the tag's height and its source
             f"  outline: {len(ds.outline_m)} vertices, x {lo[0]:g}..{hi[0]:g} m, y {lo[1]:g}..{hi[1]:g} m"]
    lines += [f"  {key.replace('_', ' ')}: {note}" for key, note in ds.notes.items()]
    lines += ["", Table(dataset_summary(ds)).to_markdown(), ""]
    if suite is None:
        lines.append(f"ok: `locbook run --data {path}` runs the measured-data experiments and the benchmark on it")
        return "\n".join(lines)
    from .run import data_kinds
    kinds = data_kinds(ds)
    why = {e.id: e.data_run.missing(kinds) for e in suite.experiments if e.data_run is not None}
    runs = [eid for eid, reason in why.items() if not reason]
    if ds.floors and ds.floor is None:      # a building: each floor is a data run of its own (locbook.data.floors)
        lines.append(f"ok: `locbook run --data {path}` runs each floor as a data set of its own: "
                     + ", ".join(f"{f} (--data {path}@{f}, reports data-{ds.name}-{floor_slug(f)}/)"
                                 for f in ds.floors))
        return "\n".join(lines)
    lines.append(f"ok: `locbook run --data {path}` runs {', '.join(runs) or 'no experiment'}"
                 + "".join(f"; {eid}: left out: {reason}" for eid, reason in why.items() if reason))
    return "\n".join(lines)


def _exit_status(result) -> int:
    if result.interrupted_by is not None:
        return 128 + int(result.interrupted_by)
    if result.disk_full is not None:
        return EXIT_DISK_FULL
    return EXIT_FAILED if result.count("failed") or result.executor_error else EXIT_OK


if __name__ == "__main__":  # pragma: no cover
    sys.exit(main())
