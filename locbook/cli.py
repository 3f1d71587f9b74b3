"""``locbook`` command line: list the experiments and run the notebook suite."""
from __future__ import annotations

import argparse
import sys
from pathlib import Path

from .errors import ParameterError

PROFILE_HELP = "quick: reduced Monte-Carlo counts (default); full: the source's own counts"


def _parse_overrides(items: list[str]) -> dict[str, str]:
    out = {}
    for item in items:
        name, sep, value = item.partition("=")
        if not sep or not name.strip():
            raise ParameterError(f"-p expects NAME=VALUE, got {item!r}")
        out[name.strip()] = value
    return out


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(prog="locbook", description="Rerun published RSSI localization experiments.")
    parser.add_argument("--suite", type=Path, help="experiment list (default: notebooks/experiments.toml)")
    sub = parser.add_subparsers(dest="command", required=True)
    sub.add_parser("list", help="list the experiments and their parameters")
    run = sub.add_parser("run", help="execute experiments and write reports/<profile>/")
    run.add_argument("ids", nargs="*", help="experiment ids or document keys (default: all)")
    run.add_argument("--profile", choices=("quick", "full"), default="quick", help=PROFILE_HELP)
    run.add_argument("--jobs", "-j", type=int, default=2, help="notebooks run in parallel processes (default 2)")
    run.add_argument("--force", action="store_true", help="execute even when a cached report is up to date")
    run.add_argument("-p", "--parameter", action="append", default=[], metavar="NAME=VALUE",
                     help="override a notebook parameter (checked against its type)")
    run.add_argument("--reports", type=Path, help="reports folder (default: <repository>/reports)")
    run.add_argument("--timeout", type=int, default=1800, help="seconds allowed per notebook cell")
    args = parser.parse_args(argv)

    from .suite import load_suite, run_suite

    try:
        suite = load_suite(args.suite)
        if args.command == "list":
            for exp in suite.experiments:
                params = exp.declared_parameters()
                print(f"{exp.id:34s} {exp.section}")
                print(f"{'':34s} {exp.title}")
                print(f"{'':34s} parameters: {', '.join(f'{p.name}: {p.annotation}' for p in params.values())}")
            return 0
        if args.jobs < 1:
            raise ParameterError(f"--jobs must be at least 1, got {args.jobs}")
        experiments = suite.select(args.ids)
        outcomes = run_suite(suite, experiments, args.profile, jobs=args.jobs, force=args.force,
                             overrides=_parse_overrides(args.parameter), report_root=args.reports,
                             timeout_s=args.timeout)
    except ParameterError as exc:
        print(f"locbook: error: {exc}", file=sys.stderr)
        return 2
    report_dir = (args.reports or suite.root / "reports") / args.profile
    failed = [o for o in outcomes if o.status == "failed"]
    counts = {s: sum(o.status == s for o in outcomes) for s in ("ok", "cached", "failed")}
    print(f"done: {counts['ok']} executed, {counts['cached']} cached, {counts['failed']} failed; "
          f"see {report_dir / 'index.html'}")
    if failed:
        print("failed: " + ", ".join(f"{o.id} ({o.error})" for o in failed), file=sys.stderr)
        return 1
    return 0


if __name__ == "__main__":  # pragma: no cover
    sys.exit(main())
