"""What a run shows while it works and when it ends.

Three views of the same events (``locbook run --progress``):

- ``live`` (the default on a terminal): a table redrawn in place by rich: queued, running (elapsed time and,
  where a previous run of the same folder recorded one, the expected time), finished (status and time);
- ``plain`` (the default when the output is not a terminal: CI logs, pipes): one line per event, no control
  characters;
- ``quiet``: nothing while running; only the end.

Every view ends with the same scoreboard, one row per experiment: status, time and its numbers counted by
kind and verdict (the scoring of ``locbook.reproduce.scoring``), then the path of the report.
"""
from __future__ import annotations

import sys
import time
from pathlib import Path

from ..reproduce.scoring import KINDS, scoreboard_counts, verdict_counts_text
from .files import read_csv, read_json

__all__ = ["MODES", "make_progress", "expected_seconds", "scoreboard_rows", "scoreboard_text", "print_scoreboard"]

MODES = ("auto", "live", "plain", "quiet")


def expected_seconds(report_dir: Path, ids) -> dict[str, float]:
    """Run time of each experiment's last report in this folder (``report.json``), where one is recorded."""
    out = {}
    for eid in ids:
        seconds = read_json(report_dir / eid / "report.json", {}).get("seconds")
        if isinstance(seconds, (int, float)) and seconds > 0:
            out[eid] = float(seconds)
    return out


def _fmt_s(seconds: float | None) -> str:
    if seconds is None:
        return ""
    seconds = float(seconds)
    return f"{seconds:.0f} s" if seconds < 120 else f"{seconds / 60:.1f} min"


def scoreboard_rows(run) -> list[dict]:
    """One row per experiment of a :class:`~locbook.suite.runner.SuiteRun`: id, status, time and, for each
    kind, its rows counted by verdict (read from the experiment's numbers.csv in the report folder; a failed
    or interrupted experiment shows its last good report's counts, marked as such)."""
    rows = []
    for o in run.outcomes:
        folder = run.report_dir / o.id
        numbers = read_csv(folder / "numbers.csv") if (folder / "summary.md").is_file() else []
        counts = scoreboard_counts(numbers)
        seconds = o.seconds if o.status in ("ok", "failed", "interrupted") else \
            read_json(folder / "report.json", {}).get("seconds")
        status = o.status
        if o.status in ("failed", "interrupted") and numbers:
            status += " (last good report kept)"
        rows.append({"experiment": run.name(o.id), "status": status, "time": _fmt_s(seconds),
                     **{kind: verdict_counts_text(c) for kind, c in counts.items()}})
    return rows


def _columns(rows) -> list[str]:
    kinds = [k for k in KINDS if any(r.get(k) for r in rows)]
    return ["experiment", "status", "time", *kinds]


#: the widest line of the plain scoreboard
SCOREBOARD_WIDTH = 100


def scoreboard_text(run, width: int = SCOREBOARD_WIDTH) -> str:
    """The end-of-run scoreboard as plain aligned text (no control characters), at most ``width`` columns: one
    column per kind where that fits, else each row's counts as ``kind: counts; ...`` wrapped under its own column."""
    rows = scoreboard_rows(run)
    cols = _columns(rows)
    widths = {c: max(len(c), *(len(str(r.get(c, ""))) for r in rows)) if rows else len(c) for c in cols}
    line = lambda r: "  ".join(str(r.get(c, "")).ljust(widths[c]) for c in cols).rstrip()
    table = [line({c: c for c in cols}), line({c: "-" * widths[c] for c in cols}), *map(line, rows)]
    if max(map(len, table)) <= width:
        return "\n".join(table)
    import textwrap
    lead, kinds = cols[:3], cols[3:]
    prefix = lambda r: "  ".join(str(r.get(c, "")).ljust(widths[c]) for c in lead) + "  "
    indent = len(prefix({}))
    if width - indent < 30:          # long names: the counts go on lines of their own
        indent = 4
    title = "numbers by kind and verdict"
    head = prefix({c: c for c in lead})
    out = [head + title] if len(head) + len(title) <= width else [head.rstrip(), " " * indent + title]
    out.append(prefix({c: "-" * widths[c] for c in lead}).rstrip())
    for r in rows:
        # a count ("28 no verdict") is never split across lines: its spaces are held until the wrap is done
        text = "; ".join(f"{k}: " + ", ".join(c.replace(" ", "\0") for c in r[k].split(", "))
                         for k in kinds if r.get(k)) or "-"
        first, *rest = [piece.replace("\0", " ") for piece in textwrap.wrap(text, width - indent)] or [""]
        head = prefix(r)
        if len(head) + len(first) > width:
            out.append(head.rstrip())
            rest = [first, *rest]
        else:
            out.append(head + first)
        out += [" " * indent + piece for piece in rest]
    return "\n".join(out)


def print_scoreboard(run, mode: str = "auto", stream=None) -> None:
    """Print the end-of-run scoreboard: a rich table on a terminal (``live``), aligned text otherwise."""
    stream = stream if stream is not None else sys.stdout
    if not run.outcomes:
        return
    if _resolve(mode, stream) != "live":
        print(scoreboard_text(run), file=stream, flush=True)
        return
    from rich.console import Console
    from rich.table import Table
    rows = scoreboard_rows(run)
    table = Table(title="scoreboard: numbers by kind and verdict", title_justify="left")
    for col in _columns(rows):
        table.add_column(col, justify="right" if col == "time" else "left")
    style = {"ok": "green", "cached": "green", "failed": "bold red", "interrupted": "yellow", "not run": "dim"}
    for r in rows:
        cells = [str(r.get(c, "")) for c in _columns(rows)]
        cells[1] = f"[{style.get(r['status'].split()[0], '')}]{cells[1]}[/]"
        table.add_row(*cells)
    Console(file=stream).print(table)


def _resolve(mode: str, stream) -> str:
    if mode not in MODES:
        raise ValueError(f"progress mode must be one of {', '.join(MODES)}, got {mode!r}")
    if mode == "auto":
        return "live" if getattr(stream, "isatty", lambda: False)() else "plain"
    return mode


class _Base:
    """Event sink of :func:`~locbook.suite.run.run_suite`."""

    def __init__(self, stream=None):
        self.stream = stream if stream is not None else sys.stdout
        self.start = time.perf_counter()
        self.total = 0
        self.done = 0
        self.expected: dict[str, float] = {}
        #: key -> what a person reads for it (a sweep point's settings); the runner sets it before :meth:`begin`
        self.labels: dict[str, str] = {}

    def name(self, key: str) -> str:
        return self.labels.get(key) or key

    def begin(self, ids, expected: dict[str, float]):
        self.total, self.expected = len(ids), expected

    def message(self, text: str):
        print(text, file=self.stream, flush=True)

    def started(self, eid: str, attempt: int):
        pass

    def finished(self, outcome):
        self.done += 1

    def end(self, run):
        pass

    def _finished_line(self, o) -> str:
        timing = f" in {o.seconds:.1f} s" if o.status in ("ok", "failed") else ""
        return (f"[{self.done}/{self.total}] {self.name(o.id)}: {o.status}{timing}"
                f" (elapsed {time.perf_counter() - self.start:.0f} s){'  ' + o.error if o.error else ''}")


class PlainProgress(_Base):
    """One line per event."""

    def started(self, eid, attempt):
        expected = self.expected.get(eid)
        print(f"running {self.name(eid)}{f' (attempt {attempt})' if attempt > 1 else ''}"
              f"{f' (last run {_fmt_s(expected)})' if expected else ''} ...", file=self.stream, flush=True)

    def finished(self, outcome):
        super().finished(outcome)
        print(self._finished_line(outcome), file=self.stream, flush=True)


class QuietProgress(_Base):
    """Nothing while running (messages such as waiting for a lock still print)."""


class LiveProgress(_Base):
    """A rich table redrawn in place: one row per experiment."""

    def __init__(self, stream=None):
        super().__init__(stream)
        self.state: dict[str, dict] = {}
        self.live = None

    def begin(self, ids, expected):
        from rich.console import Console
        from rich.live import Live
        super().begin(ids, expected)
        self.state = {eid: {"status": "queued", "since": None, "seconds": None, "attempt": 1} for eid in ids}
        self.console = Console(file=self.stream)
        self.live = Live(self, console=self.console, refresh_per_second=4, transient=False)
        self.live.start()

    def __rich__(self):
        from rich.table import Table
        now = time.perf_counter()
        table = Table(title=f"locbook run: {self.done}/{self.total} finished, elapsed {_fmt_s(now - self.start)}",
                      title_justify="left", expand=False)
        for col in ("experiment", "status", "time", "expected"):
            table.add_column(col, justify="right" if col in ("time", "expected") else "left")
        style = {"queued": "dim", "running": "bold cyan", "ok": "green", "cached": "green",
                 "failed": "bold red", "interrupted": "yellow", "not run": "dim"}
        for eid, s in self.state.items():
            if s["status"] == "running":
                elapsed = _fmt_s(now - s["since"])
            else:
                elapsed = _fmt_s(s["seconds"]) if s["seconds"] is not None else ""
            label = s["status"] + (f" (attempt {s['attempt']})" if s["attempt"] > 1 else "")
            table.add_row(self.name(eid), f"[{style.get(s['status'], '')}]{label}[/]", elapsed,
                          _fmt_s(self.expected.get(eid)))
        return table

    def message(self, text):
        if self.live is not None:
            self.live.console.print(text, markup=False, highlight=False)
        else:
            super().message(text)

    def started(self, eid, attempt):
        self.state[eid].update(status="running", since=time.perf_counter(), attempt=attempt)

    def finished(self, outcome):
        super().finished(outcome)
        state = self.state.setdefault(outcome.id, {"attempt": 1})
        # the runner's clock (Outcome.seconds: from the start this row showed to the finish), the scoreboard's too
        seconds = outcome.seconds if outcome.status in ("ok", "failed", "interrupted") else None
        state.update(status=outcome.status, seconds=seconds)
        if outcome.error and self.live is not None:
            self.live.console.print(f"{self.name(outcome.id)}: {outcome.status}: {outcome.error}", markup=False,
                                    highlight=False)

    def end(self, run):
        if self.live is not None:
            self.live.refresh()
            self.live.stop()
            self.live = None


def make_progress(mode: str = "auto", stream=None):
    """The view for ``mode`` (:data:`MODES`); ``auto`` is live on a terminal, plain otherwise (no control
    characters in logs)."""
    stream = stream if stream is not None else sys.stdout
    mode = _resolve(mode, stream)
    return {"live": LiveProgress, "plain": PlainProgress, "quiet": QuietProgress}[mode](stream)
