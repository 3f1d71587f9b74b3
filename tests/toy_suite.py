"""What the suite's and the report site's tests build: the toy suite (a throw-away repository of toy notebooks whose
arithmetic is known), the processes it starts, and a data set's reports folder written by hand. Imported by name
(``from toy_suite import ...``) like builders.py; the fixtures over it (``toy``, ``stoy``) are in
tests/suite/conftest.py."""
from __future__ import annotations

import csv
import json
import os
import subprocess
import sys
import time
from pathlib import Path

import nbformat
import numpy as np
import pandas as pd
import psutil
from nbformat.v4 import new_code_cell, new_notebook

from builders import toml_key, toml_value
from locbook.data.dataset import load_dataset
from locbook.data.example import EXAMPLE_ROLES, write_example_dataset
from locbook.reproduce.interpretations import INTERPRETATION_COLUMNS
from locbook.suite import run as suite_run
from locbook.suite import site
from locbook.suite.cli import main

GOOD = """\
import os, time
import numpy as np
import locbook as lb
report = lb.Report("toy")
offset = float(open("../../shared/data/offset.csv").read().split()[-1]) if read_data else 0.0
x = lb.streams(seed, "a")["a"].normal(size=n)
printed = lb.Printed("george", "Table 1", "mean", "", "", repr(offset))
report.number("mean", printed, float(x.mean()) + offset, kind="reproduction",
              ambiguity=lb.Ambiguity(1.0, "test window", "toy Sec. 1"))
time.sleep(sleep_s)
if kill_worker:
    os.kill(os.getppid(), 9)          # the kernel's parent is the worker process: simulate an OOM kill
if fail:
    raise RuntimeError("deliberate failure")
"""


# -- a toy suite's experiments.toml --------------------------------------------------------------------------------


def _spaced(value) -> str:
    """A TOML value, inline tables written ``{ a = 1 }`` as the files people write them (tests edit that text)."""
    if isinstance(value, dict):
        return "{ " + ", ".join(f"{toml_key(k)} = {_spaced(v)}" for k, v in value.items()) + " }"
    return toml_value(value)


def _toml_table(header: str, values: dict | None) -> str:
    return f"[{header}]\n" + "".join(f"{toml_key(k)} = {_spaced(v)}\n" for k, v in (values or {}).items())


def document_toml(name: str = "george", *, year: str = "2015", title: str = "t", authors: str = "a") -> str:
    """A ``[documents.<name>]`` table (``source = "s"``)."""
    return _toml_table(f"documents.{name}", {"title": title, "authors": authors, "year": year, "source": "s"})


def experiment_toml(id: str, notebook: str, *, title: str, section: str = "Table 1", document: str = "george",
                    quick: dict | None = None, full: dict | None = None, rules: dict | None = None,
                    extra: str = "") -> str:
    """One ``[[experiment]]``: its keys, its ``parameter_rules`` (``rules``, a name -> inline-table dict), ``extra``
    TOML text (e.g. a data_run table) and its quick and full profiles' parameters."""
    text = "[[experiment]]\n" + "".join(f"{k} = {toml_value(v)}\n" for k, v in (
        ("id", id), ("document", document), ("title", title), ("section", section), ("notebook", notebook)))
    if rules:
        text += _toml_table("experiment.parameter_rules", rules)
    if extra:
        text += extra.rstrip("\n") + "\n"
    return text + _toml_table("experiment.profiles.quick", quick) + _toml_table("experiment.profiles.full", full)


def suite_toml(*experiments: str, document: str | None = None, rules: dict | None = None) -> str:
    """A toy suite's experiments.toml: george's document table (or ``document``), the experiments
    (:func:`experiment_toml`) and the suite-wide ``[parameter_rules]``."""
    text = (document if document is not None else document_toml()) + "".join(experiments)
    return text + (_toml_table("parameter_rules", rules) if rules else "")


def _notebook(path, params_src, body=GOOD):
    nb = new_notebook()
    nb.metadata["kernelspec"] = {"name": "python3", "display_name": "Python 3", "language": "python"}
    params = new_code_cell(params_src)
    params.metadata["tags"] = ["parameters"]
    nb.cells = [new_code_cell("from typing import Literal"), params, new_code_cell(body)]
    nbformat.write(nb, str(path))


PARAMS = ('seed: int = 1  # seed\nn: int = 10  # samples\nfail: bool = False  # raise\n'
          'mode: Literal["a", "b"] = "a"  # a mode\nsleep_s: float = 0.0  # wait\n'
          'kill_worker: bool = False  # die\nread_data: bool = False  # read ../shared/data/offset.csv\n'
          'weights: list[float] = [1.0]  # a list\n')


def run(toy, *args):
    return main(["--suite", str(toy / "notebooks" / "experiments.toml"), "run", "--reports", str(toy / "reports"),
                 *args])


# -- processes: concurrency, data files, dying workers, signals --------------------------------------------
def cli(toy, *args):
    return subprocess.Popen([sys.executable, "-m", "locbook.suite.cli", "--suite",
                             str(toy / "notebooks" / "experiments.toml"),
                             "run", "--reports", str(toy / "reports"), *args],
                            stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True)


def processes_mentioning(text: str) -> dict[int, str]:
    """Live processes whose command line or environment mentions ``text`` (the runner and its workers carry the
    toy's paths; kernels inherit LOCBOOK_OUTPUT_DIR), and all their descendants."""
    chosen = {}
    for proc in psutil.process_iter():
        if proc.pid == os.getpid():
            continue
        try:
            if proc.status() == psutil.STATUS_ZOMBIE:
                continue
            cmd = " ".join(proc.cmdline())
            if text in cmd or any(text in v for v in proc.environ().values()):
                chosen[proc.pid] = proc
        except psutil.Error:          # gone, or not ours to read
            continue
    for proc in list(chosen.values()):
        try:
            chosen.update({c.pid: c for c in proc.children(recursive=True) if c.status() != psutil.STATUS_ZOMBIE})
        except psutil.Error:
            pass
    out = {}
    for pid, proc in sorted(chosen.items()):
        try:
            out[pid] = " ".join(proc.cmdline())
        except psutil.Error:
            pass
    return out


def alive(pids) -> list[int]:
    """The pids of ``pids`` still running (zombies count as gone)."""
    out = []
    for pid in pids:
        try:
            if psutil.Process(pid).status() != psutil.STATUS_ZOMBIE:
                out.append(pid)
        except psutil.Error:
            pass
    return out


def wait_for(predicate, timeout_s: float):
    deadline = time.monotonic() + timeout_s
    while time.monotonic() < deadline:
        if predicate():
            return True
        time.sleep(0.1)
    return predicate()


def set_profile(toy, experiment: str, text: str):
    toml = toy / "notebooks" / "experiments.toml"
    marker = f'id = "{experiment}"'
    head, tail = toml.read_text().split(marker)
    tail = tail.replace("[experiment.profiles.quick]\n", "[experiment.profiles.quick]\n" + text + "\n", 1)
    toml.write_text(head + marker + tail)


STUDY_PARAMS = ('seed: int = 1  # seed\na: float = 1.0  # slope input\nb: float = 0.0  # offset\n'
                'tag: str = "x"  # a label\nsleep_s: float = 0.0  # wait\n')


#: value = 10 a + b + seed against a printed 16.0 (rounding 0.05: half a unit of its last digit); twice = 2 a
STUDY_BODY = """\
import time
import locbook as lb
report = lb.Report("toy")
report.number("value", lb.Printed("george", "Table 9", "value", "", "m", "16.0"), 10 * a + b + seed,
              kind="reproduction", mc_std_error=0.125 * seed, ambiguity=lb.Ambiguity(1.0, "test window", "toy"))
report.number("twice", lb.Printed("george", "Table 9", "twice", "", "m", "3.0"), 2 * a, kind="reproduction",
              ambiguity=lb.Ambiguity(1.0, "test window", "toy"))
time.sleep(sleep_s)
"""


TOY_STUDY = "\n" + experiment_toml("george-study", "study.ipynb", title="study", section="Table 9",
                                   rules={"a": {"ge": 0, "le": 5}}, quick={"seed": 3}) + """
[[study]]
name = "toy"
experiments = ["george-study"]
replicates = 2
collect = ["value"]
[study.parameters]
a = { grid = [1.0, 1.5] }
b = { list = [0.25, 0.5] }
tag = { list = ["p", "q"] }
"""


HEADER = ",".join(c for c in INTERPRETATION_COLUMNS if c != "quotes")   # a file without quotes loads


#: a = 1.3 gives value 16.0 (printed, within); b never reaches value; twice's window is always loose
READINGS = f"""{HEADER}
slope,george-study,a,,1.0,[1.3],,0.0,2.0,assumed,Table 9,toy slope
offset,george-study,b,,0.0,[0.5],,,,printed,Table 9,toy offset
"""


def example(folder: Path, roles=EXAMPLE_ROLES, *, truth: bool = True, name: str = "mine") -> Path:
    """A small example data set holding ``roles``; ``truth=False`` drops the tracks' true positions (a track with a
    reference path only, as many real walks are)."""
    out = write_example_dataset(folder, np.random.default_rng(3), name=name, walk_s=30.0, roles=roles)
    if not truth:
        ds = load_dataset(out)
        for rec in ds.recordings_with("track"):
            path = ds.recording(rec).file
            table = pd.read_csv(path)
            table.drop(columns=[c for c in ("x_m", "y_m", "z_m") if c in table]).to_csv(path, index=False)
    return out


def _row(kind, recording, method, mean, **more) -> dict:
    from locbook.scenarios.measured import RESULT_COLUMNS
    row = {c: "" for c in RESULT_COLUMNS}
    row.update(kind=kind, recording=recording, method=method, settings=f"{method} settings", epochs="40", runs="1",
               coverage="1", mean_m=mean, median_m="0.9", p90_m="2.1", ce95_m="2.6", rmse_m="1.3", mean_low_m="0.8",
               mean_high_m="1.4", bound="CRLB (fitted channel, anchors heard)", bound_median_m="1.25",
               bound_rms_m="1.3", ratio="1.05", ratio_note="")
    row.update(more)
    return row


def _write_rows(path: Path, rows: list[dict]) -> None:
    path.parent.mkdir(parents=True, exist_ok=True)
    with open(path, "w", newline="", encoding="utf-8") as fh:
        writer = csv.DictWriter(fh, fieldnames=list(rows[0]))
        writer.writeheader()
        writer.writerows(rows)


#: the hand-written static results: recordings listed before their pooled row, a degenerate bound, and a method
#: scored on one recording only (its pooled row is that recording)
STATIC_ROWS = [("points", "lls", "3.1"), ("pooled", "lls", "3.0"), ("walk_a", "lls", "2.9"),
               ("pooled", "grid_ml", "1.2"), ("points", "grid_ml", "1.3"), ("walk_a", "grid_ml", "1.1"),
               ("points", "knn", "1.5"), ("pooled", "knn", "1.5")]


def write_data_folder(report_dir: Path, folder: Path, suite) -> dict:
    """A data set's reports folder from hand-written files: dataset.json as a data run claims it (the data set at
    ``folder``, static-only: tracking left out), measured-localization's results.csv and cdf.png, measured-
    calibration's fits.csv; then its pages (site.write_suite_reports). Returns the dataset.json record."""
    ds = load_dataset(folder)
    identity = str(ds.root)
    suite_run.claim_dataset_folder(report_dir, ds.name, identity,
                                 suite_run._dataset_facts(ds, identity, suite, suite_run.data_kinds(ds)))
    loc = report_dir / "measured-localization"
    rows = [_row("static", r, m, mean) for r, m, mean in STATIC_ROWS]
    rows[1].update(ratio="", ratio_note="n/a: the bound is degenerate at 2 of 40 epochs")
    rows[3].update(ratio="0.94", ratio_note="below 1: it searches only inside the floor outline")
    _write_rows(loc / "results.csv", rows)
    import matplotlib
    matplotlib.use("Agg")
    import matplotlib.pyplot as plt
    fig, ax = plt.subplots(figsize=(3, 2))
    ax.plot([0, 1], [0, 1])
    fig.savefig(loc / "cdf.png")
    plt.close(fig)
    (loc / "summary.md").write_text("# summary\n")
    cal = report_dir / "measured-calibration"
    fits = [{"mode": "per_anchor", "fit": f, "anchor": a, "P_0 (dBm)": "-45", "n": "2.2", "residual sigma (dB)": "2.5",
             "samples": "300", "status": "ok"} for f in ("closed_form", "huber") for a in ("A1", "A2")]
    fits += [{"mode": "pooled", "fit": f, "anchor": "all", "P_0 (dBm)": "-44", "n": "2.3",
              "residual sigma (dB)": "3.1", "samples": "600", "status": "ok"} for f in ("closed_form", "huber")]
    _write_rows(cal / "fits.csv", fits)
    (cal / "summary.md").write_text("# summary\n")
    (report_dir / "status.json").write_text(json.dumps({"measured-calibration": {"status": "cached", "seconds": 0},
                                                        "measured-localization": {"status": "ok", "seconds": 3.2}}))
    site.write_suite_reports(suite, report_dir, list_all=False)
    return json.loads((report_dir / "dataset.json").read_text())
