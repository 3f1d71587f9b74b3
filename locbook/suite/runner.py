"""Execute the notebook suite with papermill: validation, caching, parallel processes, reports.

Layout of ``reports/<profile>/``::

    index.html, index.md, numbers.csv        the whole suite (numbers.csv: every printed number)
    <id>/<id>.ipynb, <id>.html               the executed notebook and its HTML page
    <id>/summary.md, *.png, *.csv            lightweight results (committed for the full profile)
    <id>/run.json                            cache key, parameters, status and time of the last good run
    .staging/<id>/                           a run in progress
    .failed/<id>/                            the last failed attempt, kept for inspection
    status.json                              the last attempt of each experiment

A run executes into ``.staging``; only a successful run replaces ``<id>/``, so a failure never removes
the last good report.
"""
from __future__ import annotations

import csv
import hashlib
import json
import multiprocessing
import os
import shutil
import subprocess
import sys
import time
from concurrent.futures import ProcessPoolExecutor, as_completed
from dataclasses import dataclass
from html import escape
from importlib import metadata
from pathlib import Path

import nbformat

from ..report import NUMBER_COLUMNS, Table
from .spec import Experiment, Suite

__all__ = ["KERNEL_NAME", "run_suite", "cache_key", "Outcome", "write_suite_reports"]

#: Every notebook runs on this kernel; jupyter_client maps it to the running interpreter.
KERNEL_NAME = "python3"
_DEPENDENCIES = ("numpy", "scipy", "cvxpy", "clarabel", "osqp", "scs", "matplotlib", "papermill",
                 "nbclient", "nbconvert", "nbformat", "ipykernel")
_SINGLE_THREAD = {"OMP_NUM_THREADS": "1", "OPENBLAS_NUM_THREADS": "1", "MKL_NUM_THREADS": "1",
                  "BLIS_NUM_THREADS": "1", "VECLIB_MAXIMUM_THREADS": "1", "NUMEXPR_NUM_THREADS": "1"}


@dataclass
class Outcome:
    id: str
    status: str  # "ok", "cached" or "failed"
    seconds: float
    error: str = ""


def locbook_version() -> str:
    from .. import __version__
    return __version__


def _source_fingerprint() -> str:
    package = Path(__file__).resolve().parents[1]
    h = hashlib.sha256()
    for path in sorted(package.rglob("*.py")):
        h.update(str(path.relative_to(package)).encode())
        h.update(path.read_bytes())
    return h.hexdigest()


def _dependency_versions() -> dict[str, str]:
    versions = {"python": sys.version.split()[0]}
    for name in _DEPENDENCIES:
        try:
            versions[name] = metadata.version(name)
        except metadata.PackageNotFoundError:
            versions[name] = "absent"
    return versions


def _notebook_fingerprint(path: Path) -> str:
    nb = nbformat.read(str(path), as_version=4)
    h = hashlib.sha256()
    for cell in nb.cells:  # sources and tags only: outputs and execution counts do not matter
        h.update(cell.cell_type.encode())
        h.update(cell.source.encode())
        h.update(json.dumps(cell.get("metadata", {}).get("tags", [])).encode())
    return h.hexdigest()


def cache_key(exp: Experiment, profile: str, params: dict, *, source: str | None = None,
              versions: dict | None = None) -> str:
    """Hash of everything that can change a report: notebook, parameters, profile, locbook, dependencies."""
    payload = {
        "experiment": exp.id, "profile": profile, "parameters": params,
        "notebook": _notebook_fingerprint(exp.notebook),
        "locbook": source or _source_fingerprint(),
        "versions": versions or _dependency_versions(),
    }
    return hashlib.sha256(json.dumps(payload, sort_keys=True).encode()).hexdigest()


def _git_stamp(root: Path) -> str:
    try:
        rev = subprocess.run(["git", "-C", str(root), "rev-parse", "--short", "HEAD"], capture_output=True,
                             text=True, timeout=10).stdout.strip()
        dirty = subprocess.run(["git", "-C", str(root), "status", "--porcelain", "--", "locbook", "notebooks"],
                               capture_output=True, text=True, timeout=10).stdout.strip()
    except (OSError, subprocess.SubprocessError):
        return ""
    return f"{rev}{' + uncommitted changes' if dirty else ''}" if rev else ""


# ---------------------------------------------------------------------------------------------------
# worker side

def _execute(task: dict) -> dict:
    """Run one notebook with papermill in this (worker) process; never raises."""
    import papermill as pm
    from nbconvert import HTMLExporter

    os.environ.update(_SINGLE_THREAD)
    os.environ.update({"LOCBOOK_OUTPUT_DIR": task["staging"],
                       "LOCBOOK_EXPERIMENT": task["id"], "PYDEVD_DISABLE_FILE_VALIDATION": "1"})
    staging = Path(task["staging"])
    out_nb = staging / f"{task['id']}.ipynb"
    # the kernel inherits this process's stderr: keep its chatter in a log beside the report
    log_fd = os.open(staging / "kernel-stderr.log", os.O_WRONLY | os.O_CREAT | os.O_TRUNC)
    os.dup2(log_fd, 2)
    os.close(log_fd)
    start = time.perf_counter()
    error = ""
    try:
        pm.execute_notebook(task["notebook"], str(out_nb), parameters=task["parameters"],
                            kernel_name=KERNEL_NAME, cwd=str(Path(task["notebook"]).parent),
                            progress_bar=False, log_output=False, execution_timeout=task["timeout"])
    except pm.PapermillExecutionError as exc:
        error = f"{exc.ename}: {exc.evalue}"
    except Exception as exc:  # kernel death, timeout, I/O: the run fails, the suite goes on
        error = f"{type(exc).__name__}: {exc}"
    seconds = time.perf_counter() - start
    if out_nb.exists():
        try:
            body, _ = HTMLExporter(template_name="lab").from_filename(str(out_nb))
            (staging / f"{task['id']}.html").write_text(body, encoding="utf-8")
        except Exception as exc:  # an HTML failure must not hide the notebook's own result
            error = error or f"HTML export failed: {exc}"
    return {"id": task["id"], "error": error, "seconds": seconds}


# ---------------------------------------------------------------------------------------------------
# main process

def _read_json(path: Path, default):
    try:
        return json.loads(path.read_text())
    except (OSError, ValueError):
        return default


def _is_cached(report_dir: Path, exp: Experiment, key: str) -> bool:
    run = _read_json(report_dir / exp.id / "run.json", {})
    return (run.get("cache_key") == key and run.get("status") == "ok"
            and (report_dir / exp.id / f"{exp.id}.ipynb").exists())


def _replace_dir(new: Path, final: Path):
    """Swap ``new`` into place of ``final`` with renames, removing the old copy afterwards."""
    old = final.with_name(f".old-{final.name}")
    if old.exists():
        shutil.rmtree(old)
    if final.exists():
        final.rename(old)
    new.rename(final)
    if old.exists():
        shutil.rmtree(old)


def _read_csv(path: Path) -> list[dict]:
    if not path.exists():
        return []
    with open(path, newline="") as fh:
        return list(csv.DictReader(fh))


def _summary_markdown(exp: Experiment, profile: str, params: dict, folder: Path, stamp: str) -> str:
    manifest = _read_json(folder / "manifest.json", {"figures": [], "tables": []})
    numbers = _read_csv(folder / "numbers.csv")
    assumptions = _read_csv(folder / "assumptions.csv")
    doc = exp.document
    lines = [
        f"# {exp.title}",
        "",
        f"Experiment `{exp.id}`, reproducing **{exp.section}** of {doc.authors}, *{doc.title}* ({doc.year}).",
        "",
        f"Profile `{profile}`; generated by locbook {stamp}. Notebook: `notebooks/"
        f"{exp.notebook.relative_to(exp.notebook.parents[1]).as_posix()}`.",
        "",
        "## Reproduced versus printed",
        "",
    ]
    if numbers:
        cols = ("quantity", "where", "unit", "reported", "reproduced", "lower", "upper", "within_tolerance",
                "tolerance_basis")
        lines.append(Table([{c: r.get(c, "") for c in cols} for r in numbers]).to_markdown())
    else:
        lines.append("The source prints no number for this experiment; its figures are qualitative.")
    declared = exp.declared_parameters()
    rows = [{"name": name, "value": json.dumps(params.get(name, p.default)),
             "set by": "profile / -p" if name in params else "notebook default", "meaning": p.help}
            for name, p in declared.items()]
    lines += ["", "## Parameters", "", Table(rows).to_markdown(), ""]
    if assumptions:
        lines += ["## Assumptions", "", Table(assumptions).to_markdown(), ""]
    if manifest.get("figures"):
        lines += ["## Figures", ""]
        for fig in manifest["figures"]:
            lines += [f"![{fig['caption'] or fig['name']}]({fig['file']})", "", f"*{fig['caption']}*", ""]
    if manifest.get("tables"):
        lines += ["## Tables", ""]
        lines += [f"- [{t['file']}]({t['file']}): {t['caption']}" for t in manifest["tables"]]
        lines.append("")
    return "\n".join(lines)


def write_suite_reports(suite: Suite, report_dir: Path) -> None:
    """Rebuild ``numbers.csv``, ``index.html`` and ``index.md`` from the experiment folders present."""
    status = _read_json(report_dir / "status.json", {})
    rows, entries = [], []
    for exp in suite.experiments:
        folder = report_dir / exp.id
        run = _read_json(folder / "run.json", {})
        numbers = _read_csv(folder / "numbers.csv") if run else []
        rows += numbers
        last = status.get(exp.id, {})
        verdicts = [n["within_tolerance"] for n in numbers if n.get("within_tolerance") not in ("", None)]
        entries.append({"exp": exp, "run": run, "last": last, "n_numbers": len(numbers),
                        "n_within": sum(v == "True" for v in verdicts), "n_judged": len(verdicts)})
    with open(report_dir / "numbers.csv", "w", newline="") as fh:
        writer = csv.DictWriter(fh, fieldnames=NUMBER_COLUMNS)
        writer.writeheader()
        for r in rows:
            writer.writerow({c: r.get(c, "") for c in NUMBER_COLUMNS})
    (report_dir / "index.html").write_text(_index_html(suite, report_dir, entries), encoding="utf-8")
    (report_dir / "index.md").write_text(_index_md(suite, report_dir, entries), encoding="utf-8")


def _index_md(suite: Suite, report_dir: Path, entries) -> str:
    lines = [f"# locbook reports, profile `{report_dir.name}`", "",
             "Every printed number beside its reproduction: [numbers.csv](numbers.csv).", "",
             "| experiment | source | reproduces | numbers within tolerance | report |", "|---|---|---|---|---|"]
    for e in entries:
        exp = e["exp"]
        link = f"[summary]({exp.id}/summary.md)" if e["run"] else "not run"
        judged = f"{e['n_within']} / {e['n_judged']}" if e["n_judged"] else "-"
        lines.append(f"| `{exp.id}` | {exp.document.authors} ({exp.document.year}) | {exp.section} | {judged} | {link} |")
    return "\n".join(lines) + "\n"


def _index_html(suite: Suite, report_dir: Path, entries) -> str:
    rows = []
    for e in entries:
        exp, run, last = e["exp"], e["run"], e["last"]
        state = last.get("status", "not run")
        links = []
        if run:
            links += [f'<a href="{exp.id}/{exp.id}.html">report</a>', f'<a href="{exp.id}/{exp.id}.ipynb">notebook</a>',
                      f'<a href="{exp.id}/summary.md">summary</a>', f'<a href="{exp.id}/numbers.csv">numbers</a>']
        if state == "failed":
            links.append(f'<a href=".failed/{exp.id}/{exp.id}.ipynb">failed notebook</a>')
        judged = f"{e['n_within']} / {e['n_judged']}" if e["n_judged"] else "-"
        err = f'<div class="err">{escape(last.get("error", ""))}</div>' if state == "failed" else ""
        shown = " (showing the last good report)" if state == "failed" and run else ""
        rows.append(
            f"<tr class='{escape(state)}'><td><code>{escape(exp.id)}</code><br>{escape(exp.title)}</td>"
            f"<td>{escape(exp.document.authors)} ({escape(exp.document.year)})<br>{escape(exp.section)}</td>"
            f"<td>{escape(state)}{shown}{err}</td><td>{last.get('seconds', run.get('seconds', 0)):.1f} s</td>"
            f"<td>{judged}</td><td>{' · '.join(links)}</td></tr>")
    return f"""<!doctype html><html><head><meta charset="utf-8"><title>locbook reports ({escape(report_dir.name)})</title>
<style>body{{font-family:sans-serif;margin:2em}}table{{border-collapse:collapse}}td,th{{border:1px solid #ccc;padding:4px 8px;vertical-align:top}}
tr.failed{{background:#fdd}}tr.ok,tr.cached{{background:#efe}}.err{{font-family:monospace;font-size:small;color:#900}}</style></head>
<body><h1>locbook reports, profile <code>{escape(report_dir.name)}</code></h1>
<p>locbook {escape(locbook_version())}. All printed numbers beside their reproductions: <a href="numbers.csv">numbers.csv</a>.</p>
<table><thead><tr><th>experiment</th><th>source</th><th>last run</th><th>time</th><th>numbers within tolerance</th><th>outputs</th></tr></thead>
<tbody>{''.join(rows)}</tbody></table></body></html>
"""


def run_suite(suite: Suite, experiments: list[Experiment], profile: str, *, jobs: int = 1, force: bool = False,
              overrides: dict[str, str] | None = None, report_root: Path | None = None,
              timeout_s: int = 1800, log=print) -> list[Outcome]:
    """Run experiments; parameters of all of them are checked before any executes (raises ParameterError)."""
    report_dir = Path(report_root or suite.root / "reports") / profile
    report_dir.mkdir(parents=True, exist_ok=True)
    resolved = {exp.id: exp.parameters(profile, overrides) for exp in experiments}  # validation first
    source, versions = _source_fingerprint(), _dependency_versions()
    git = _git_stamp(suite.root)
    stamp = locbook_version() + (f" (source {git})" if git else "")
    status_path = report_dir / "status.json"
    status = _read_json(status_path, {})
    outcomes: list[Outcome] = []
    todo, keys = [], {}
    start = time.perf_counter()
    total = len(experiments)

    def finish(outcome: Outcome):
        outcomes.append(outcome)
        status[outcome.id] = {"status": outcome.status, "seconds": round(outcome.seconds, 2), "error": outcome.error}
        status_path.write_text(json.dumps(status, indent=1, sort_keys=True))
        log(f"[{len(outcomes)}/{total}] {outcome.id}: {outcome.status} in {outcome.seconds:.1f} s"
            f" (elapsed {time.perf_counter() - start:.0f} s){'  ' + outcome.error if outcome.error else ''}")

    for exp in experiments:
        keys[exp.id] = cache_key(exp, profile, resolved[exp.id], source=source, versions=versions)
        if not force and _is_cached(report_dir, exp, keys[exp.id]):
            finish(Outcome(exp.id, "cached", 0.0))
        else:
            todo.append(exp)

    by_id = {e.id: e for e in experiments}
    tasks = []
    for exp in todo:
        staging = report_dir / ".staging" / exp.id
        if staging.exists():
            shutil.rmtree(staging)
        staging.mkdir(parents=True)
        tasks.append({"id": exp.id, "notebook": str(exp.notebook), "parameters": resolved[exp.id],
                      "staging": str(staging), "timeout": timeout_s})
    if tasks:
        ctx = multiprocessing.get_context("spawn")
        with ProcessPoolExecutor(max_workers=max(1, min(jobs, len(tasks))), mp_context=ctx) as pool:
            futures = {}
            for task in tasks:
                log(f"running {task['id']} ...")
                futures[pool.submit(_execute, task)] = task
            for fut in as_completed(futures):
                task = futures[fut]
                try:
                    res = fut.result()
                except Exception as exc:  # a crashed worker process
                    res = {"id": task["id"], "error": f"{type(exc).__name__}: {exc}", "seconds": 0.0}
                exp, staging = by_id[task["id"]], Path(task["staging"])
                if res["error"]:
                    failed = report_dir / ".failed" / exp.id
                    failed.parent.mkdir(exist_ok=True)
                    _replace_dir(staging, failed)
                    finish(Outcome(exp.id, "failed", res["seconds"], res["error"]))
                    continue
                (staging / "summary.md").write_text(
                    _summary_markdown(exp, profile, resolved[exp.id], staging, stamp), encoding="utf-8")
                (staging / "run.json").write_text(json.dumps({
                    "cache_key": keys[exp.id], "status": "ok", "seconds": round(res["seconds"], 2),
                    "profile": profile, "parameters": resolved[exp.id], "locbook": stamp}, indent=1))
                _replace_dir(staging, report_dir / exp.id)
                finish(Outcome(exp.id, "ok", res["seconds"]))
    shutil.rmtree(report_dir / ".staging", ignore_errors=True)
    write_suite_reports(suite, report_dir)
    order = {exp.id: i for i, exp in enumerate(experiments)}
    return sorted(outcomes, key=lambda o: order[o.id])
