"""What a user can discover before running anything: the experiment list with coverage and run times
(``locbook list``), every parameter of an experiment with its type, default, allowed range, description and the
last result (``locbook show KEY``), and a copy of the notebooks for interactive work (``locbook notebooks DEST``).
"""
from __future__ import annotations

import csv
import math
import shutil
from pathlib import Path

from .files import machine_label, read_json
from .params import FINITE, is_numeric_annotation
from .spec import PROFILES, Experiment, Suite, SuiteError

__all__ = ["last_result", "list_text", "show_text", "copy_notebooks"]




def last_result(exp: Experiment, reports_root: Path, profile: str, *, counts: bool = True) -> dict:
    """The experiment's last report at a profile: ``{"seconds", "status", "counts", "stamp"}`` (empty if none);
    ``counts=False`` leaves out the verdict counts (``locbook list`` shows none, and they need numpy)."""
    folder = reports_root / profile / exp.id
    report = read_json(folder / "report.json", {})
    status = read_json(reports_root / profile / "status.json", {}).get(exp.id, {})
    status = status if isinstance(status, dict) else {}
    out = {}
    seconds = report.get("seconds", status.get("seconds"))
    if isinstance(seconds, (int, float)) and not isinstance(seconds, bool) and math.isfinite(seconds):
        out["seconds"] = float(seconds)
    if status.get("status"):
        out["status"] = status["status"]
    elif report:
        out["status"] = "ok"
    if report.get("locbook"):
        out["stamp"] = report["locbook"]
    if isinstance(report.get("machine"), str):
        out["machine"] = report["machine"]
    if not counts:
        return out
    # here, not at the top: reproduce.scoring imports numpy, which `locbook list` never loads
    from ..reproduce.scoring import scoreboard_counts
    try:
        with open(folder / "numbers.csv", newline="", encoding="utf-8") as fh:
            out["counts"] = scoreboard_counts(list(csv.DictReader(fh)))
    except (OSError, ValueError, csv.Error):      # missing or damaged (not UTF-8): no counts to show
        pass
    return out


def _counts_text(counts) -> str:
    if not counts:
        return "no printed numbers"
    from ..reproduce.scoring import verdict_counts_text  # here: as scoreboard_counts in last_result (numpy)
    return "; ".join(f"{kind}: {verdict_counts_text(c)}" for kind, c in counts.items())


def _seconds_text(result: dict) -> str:
    return f"{result['seconds']:.0f} s" if "seconds" in result else "-"


def list_text(suite: Suite, reports_root: Path) -> str:
    """One line per experiment: id, document, what it covers, last run time at each profile."""
    here = machine_label()
    lines = [f"{'experiment':34s} {'document':15s} {'quick':>7s} {'full':>7s}  covers"]
    machines = {p: set() for p in PROFILES}
    for exp in suite.experiments:
        results = [last_result(exp, reports_root, p, counts=False) for p in PROFILES]
        for p, r in zip(PROFILES, results):
            if "seconds" in r:
                machines[p].add(r.get("machine", "a machine not recorded"))
        times = [_seconds_text(r) for r in results]
        lines.append(f"{exp.id:34s} {exp.document.key:15s} {times[0]:>7s} {times[1]:>7s}  {exp.section}")
    lines.append(f"\n{len(suite.experiments)} experiments; run times from the reports under {reports_root} "
                 "('-': not run there yet). `locbook show ID` lists an experiment's parameters.")
    for p in PROFILES:           # the times compare only on one machine: say where each profile's came from
        if machines[p]:
            # a label names a CPU model, not a machine: a committed report may come from another of that model
            same = " (the CPU model of this machine)"
            where = "; ".join(sorted(m + (same if m == here else "") for m in machines[p]))
            lines.append(f"{p} times measured on: {where}")
    return "\n".join(lines)


def show_text(suite: Suite, key: str, reports_root: Path) -> str:
    """Every parameter of the experiments selected by ``key`` (an id, or a document key): type, default, the
    value at each profile, allowed range, description; then the last result at each profile."""
    blocks = []
    for exp in suite.select([key]):
        declared = exp.declared_parameters()
        lines = [f"{exp.id}: {exp.title}", f"  document: {exp.document.key} ({exp.document.title})",
                 f"  covers: {exp.section}", f"  notebook: {exp.notebook}", "  parameters:"]
        for p in declared.values():
            rule = exp.rules.get(p.name)
            allowed = rule.describe() if rule else (FINITE.describe() if is_numeric_annotation(p.annotation) else "")
            if p.annotation.startswith("Literal["):
                allowed = "one of " + p.annotation[len("Literal["):-1]
            profiles = ", ".join(f"{prof} {exp.profiles[prof][p.name]!r}" for prof in PROFILES
                                 if p.name in exp.profiles[prof])
            lines.append(f"    {p.name}: {p.annotation} = {p.default!r}"
                         + (f"   [{profiles}]" if profiles else "")
                         + (f"   allowed: {allowed}" if allowed else ""))
            if p.help:
                lines.append(f"        {p.help}")
        lines.append("  last result:")
        for prof in PROFILES:
            r = last_result(exp, reports_root, prof)
            if not r:
                lines.append(f"    {prof}: not run under {reports_root}")
                continue
            lines.append(f"    {prof}: {r.get('status', '?')} in {_seconds_text(r)}"
                         + (f", {r['stamp']}" if r.get("stamp") else "") + f"; {_counts_text(r.get('counts'))}")
        blocks.append("\n".join(lines))
    return "\n\n".join(blocks)


def copy_notebooks(suite: Suite, dest: Path, *, force: bool = False) -> Path:
    """Copy the suite's notebooks and experiment list to ``dest`` (created) for interactive work. An existing
    notebook is never overwritten unless ``force``; ``locbook run`` inside ``dest``'s parent uses the copy when
    ``dest`` is named ``notebooks``, or pass ``--suite dest/experiments.toml``."""
    source = suite.path.parent
    dest = Path(dest)
    files = [suite.path] + sorted({exp.notebook for exp in suite.experiments})
    targets = [(f, dest / f.relative_to(source)) for f in files]
    clashes = [str(t) for _, t in targets if t.exists()]
    if clashes and not force:
        raise SuiteError(f"{len(clashes)} file(s) already exist under {dest} (e.g. {clashes[0]}); "
                         "pass --force to overwrite them, or choose an empty folder")
    for src, target in targets:
        target.parent.mkdir(parents=True, exist_ok=True)
        shutil.copyfile(src, target)
    return dest
