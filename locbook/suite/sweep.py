"""The sweep engine under studies and interpretation brackets: many parameter points of experiments run in one runner
session into one folder, then an aggregate table rebuilt from every point whose report is up to date.

Two front ends declare the points: :mod:`locbook.suite.study` (grids, paired lists, random and Latin-hypercube draws,
replicates: ``locbook study``) and :mod:`locbook.suite.bracket` (each declared interpretation of a document: ``locbook
bracket``); the anchor-density study of :mod:`locbook.suite.splits` is a study. Each front end gives its tasks and
the function that writes its aggregate; :func:`run_sweep` runs them and says what the aggregate holds
(:class:`Aggregate`); :func:`current_points` is the status of every point the aggregate is built from.
"""
from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path

from . import cachekey
from .cachekey import cache_key, dependency_versions
from .run import run_tasks
from .runner import KERNEL_NAME, Task, report_cached

__all__ = ["Aggregate", "current_points", "run_sweep"]


def current_points(folder: Path, profile: str, points, outcomes) -> dict[str, str]:
    """Each point's status for an aggregate (study.csv, bracket.csv): its outcome in this run when ``ok`` or
    ``cached``; else ``cached`` when its folder still holds the up-to-date report of an earlier run (the runner's own
    cache test: an interrupted, failed or full-disk ``--force`` run leaves those reports as they were, and they
    count); else its outcome (``failed``, ``interrupted``, ``not run``). ``points``: ``(key, experiment, parameters,
    figures)`` of every point."""
    status = {o.id: o.status for o in outcomes}
    fingerprint = None
    out = {}
    for key, exp, parameters, figures in points:
        state = status.get(key, "not run")
        if state not in ("ok", "cached") and (folder / key / "run.json").is_file():
            if fingerprint is None:      # computed once: it hashes the runner's sources
                fingerprint = {"source": cachekey.runner_fingerprint(), "versions": dependency_versions()}
            up_to_date, _damaged = report_cached(folder / key, exp, cache_key(exp, profile, parameters, figures=figures,
                                                                        **fingerprint), figures)
            if up_to_date:
                state = "cached"
        out[key] = state
    return out


@dataclass(frozen=True)
class Aggregate:
    """What a study or bracket wrote: ``path`` (study.csv, bracket.csv) from ``kept`` of ``points`` points (those
    with an up-to-date report); ``written`` False when nothing was rewritten (the earlier file is as it was)."""

    path: Path
    kept: int
    points: int
    written: bool = True

    def describe(self) -> str:
        if not self.written:
            return f"{self.path.name} was not rewritten (an earlier one is kept as it was)"
        rest = "" if self.kept == self.points else (f"; the other {self.points - self.kept} have no up-to-date "
                                                    "report yet: run it again to complete it")
        return (f"{self.path.name} was rebuilt from the {self.kept} of {self.points} points with an up-to-date "
                f"report{rest}")


def run_sweep(suite, tasks: list[Task], profile: str, folder: Path, write_outputs, aggregate_path: Path, *,
              kernel_name: str | None = None, **options):
    """Run ``tasks`` (one per point, checked) into ``folder`` in one runner session
    (:func:`locbook.suite.run.run_tasks`: lock, staging, cache per point, retries, interrupts); after it (also an
    interrupted, failed or full-disk run) ``write_outputs(folder, outcomes, wrote)`` rebuilds the aggregate and
    appends its :class:`Aggregate` to ``wrote`` as soon as the table is in place. Returns the runner's
    :class:`~locbook.suite.runner.SuiteRun` with ``aggregate``: what ``aggregate_path`` holds now (not rewritten
    when ``write_outputs`` appended nothing: a failed write)."""
    wrote: list[Aggregate] = []
    run = run_tasks(suite, tasks, profile, folder, kernel_name=kernel_name or KERNEL_NAME,
                    write_reports=lambda where, outcomes: write_outputs(where, outcomes, wrote), **options)
    run.aggregate = wrote[-1] if wrote else Aggregate(aggregate_path, 0, len(tasks), written=False)
    return run
