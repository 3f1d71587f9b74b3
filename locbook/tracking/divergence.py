"""The NIS guard's flags over the runs of a Monte-Carlo study, and how a report states them.

Every Kalman-family filter flags a run ``diverged`` when its normalised innovation squared stays beyond a chi-square
bound for a window of consecutive updates (:mod:`locbook.tracking.results`, module docstring). The scenario functions
that run such a filter pass the flags on in one way:

- a function that returns positions (``george.track_with_kalman``, ``gudipati.track``, ``palvai.ekf_path``,
  ``dogan.only_acc_errors``) or several trackers' positions (``measured.tracks``,
  ``locbook.benchmark.run_trackers``, ``locbook.benchmark.tracking_cells``) takes ``with_divergence=False``; with
  ``True`` it returns ``(what it returned, flags)``, ``flags`` a :class:`DivergenceFlags` (one filter; None for a
  method that runs no Kalman-family filter) or ``{tracker: DivergenceFlags}`` for the Kalman-family trackers among
  several;
- a function that already returns the filter's own result returns it with the guard's fields filled and mapped onto
  the scenario's step grid (``dogan.run_filter``: a ``KalmanResult``), and ``dogan.ChannelRun.divergence`` holds the
  :class:`DivergenceFlags` of every filter case, keyed like its ``errors``.

Where a study runs a filter on a subset of its runs or in segments, the flags are combined here: runs left out are
not flagged and not counted (:meth:`DivergenceFlags.scatter`), and segments are judged on their concatenated NIS
(:meth:`DivergenceFlags.from_nis`), since the window counts consecutive updates across segment boundaries.
The notebooks report the flags beside every error statistic of such a filter (:meth:`DivergenceFlags.row`,
:func:`divergence_note`) and keep every run in the statistic when the source averaged every run.
"""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from .results import DIVERGENCE_PROBABILITY, DIVERGENCE_WINDOW, nis_divergence

__all__ = ["DivergenceFlags", "divergence_note", "divergence_rows"]


@dataclass(frozen=True)
class DivergenceFlags:
    """The NIS guard's verdict on the runs of one filter in one setting.

    ``diverged`` ``batch`` (bool) and ``diverged_step`` ``batch`` (the first step of the first window of
    exceedances, on the scenario's step grid; -1 where not diverged); ``window`` consecutive updates beyond
    ``chi2.ppf(probability, dof)``; ``filtered`` ``batch`` (bool): the runs the filter ran on (None: all), the others
    are neither flagged nor counted.
    """

    diverged: np.ndarray
    diverged_step: np.ndarray
    window: int = DIVERGENCE_WINDOW
    probability: float = DIVERGENCE_PROBABILITY
    filtered: np.ndarray | None = None

    @classmethod
    def of(cls, result, *, step_offset: int = 0, window: int = DIVERGENCE_WINDOW,
           probability: float = DIVERGENCE_PROBABILITY) -> "DivergenceFlags":
        """The flags of a Kalman-family filter result (a ``KalmanResult``) whose step ``k`` is the
        scenario's step ``k + step_offset``. ``window`` and ``probability``: those the filter ran with."""
        diverged = np.asarray(result.diverged, bool)
        step = np.asarray(result.diverged_step, np.int64)
        return cls(diverged, np.where(diverged, step + int(step_offset), -1), int(window), float(probability))

    @classmethod
    def from_nis(cls, nis, nis_dof, *, step_offset: int = 0, window: int = DIVERGENCE_WINDOW,
                 probability: float = DIVERGENCE_PROBABILITY) -> "DivergenceFlags":
        """The flags of the NIS ``batch + (T,)`` of one filter run assembled from segments (the guard's rule,
        :func:`locbook.tracking.results.nis_divergence`, applied to the whole sequence)."""
        diverged, step = nis_divergence(nis, nis_dof, window, probability)
        return cls(diverged, np.where(diverged, step + int(step_offset), -1), int(window), float(probability))

    def scatter(self, mask) -> "DivergenceFlags":
        """These flags, computed on the runs ``mask`` (bool, the full batch) selects, placed back in the full batch:
        the other runs are not flagged and not counted (``filtered`` False)."""
        mask = np.asarray(mask, bool)
        diverged = np.zeros(mask.shape, bool)
        step = np.full(mask.shape, -1, np.int64)
        diverged[mask] = self.diverged
        step[mask] = self.diverged_step
        inner = np.ones(mask.sum(), bool) if self.filtered is None else self.filtered
        filtered = np.zeros(mask.shape, bool)
        filtered[mask] = inner
        return DivergenceFlags(diverged, step, self.window, self.probability, filtered)

    @property
    def n_runs(self) -> int:
        """The number of runs the filter ran on."""
        return int(np.size(self.diverged) if self.filtered is None else np.count_nonzero(self.filtered))

    @property
    def n_diverged(self) -> int:
        """The number of runs flagged ``diverged``."""
        return int(np.count_nonzero(self.diverged))

    @property
    def median_first_step(self) -> float:
        """The median first step of the flagged runs (NaN when none is flagged)."""
        steps = np.asarray(self.diverged_step)[np.asarray(self.diverged, bool)]
        return float(np.median(steps)) if steps.size else float("nan")

    def unflagged(self, per_run) -> np.ndarray:
        """The entries of ``per_run`` (runs on axis 0, the batch of these flags) of the runs the filter ran on and did
        not flag: for a statistic shown beside the one over every run, never in its place."""
        keep = ~np.asarray(self.diverged, bool).reshape(-1)
        if self.filtered is not None:
            keep &= np.asarray(self.filtered, bool).reshape(-1)
        return np.asarray(per_run)[keep]

    def clause(self) -> str:
        """A short note for a reproduced statistic of this filter ("" when no run is flagged)."""
        if self.n_diverged == 0:
            return ""
        return (f"{self.n_diverged} of {self.n_runs} runs flagged diverged by the NIS guard ({self.window} updates "
                f"beyond chi2 {self.probability:g})")

    def row(self, filter_name: str, setting: str = "", *, step_s: float | None = None) -> dict:
        """One row of a notebook's divergence table: filter, setting, runs flagged / runs, and the median first step
        (or, with the step length ``step_s``, the median first time in seconds) of the flagged runs."""
        row = {"filter": filter_name, "setting": setting, "runs flagged": self.n_diverged, "runs": self.n_runs}
        first = self.median_first_step
        if step_s is None:
            row["median first step"] = first
        else:
            row["median first time (s)"] = first * float(step_s)
        return row


def divergence_note(note: str, flags, *, averaged: bool | str = True) -> str:
    """``note`` followed by the divergence clause of ``flags`` (one :class:`DivergenceFlags`, or ``{filter name:
    DivergenceFlags}`` for a statistic that combines several filters; None entries are skipped). ``averaged``: True
    says the statistic keeps every run, as the source averaged every run; a string says so in its own words; False
    adds nothing (e.g. a maximum over runs). Unchanged when nothing is flagged."""
    if flags is None:
        return note
    items = flags.items() if isinstance(flags, dict) else [("", flags)]
    parts = [f"{name}: {f.clause()}" if name else f.clause() for name, f in items if f is not None and f.clause()]
    if not parts:
        return note
    tail = "averaged here as the source averaged every run" if averaged is True else (averaged or "")
    clause = "; ".join(parts) + (f"; {tail}" if tail else "")
    return f"{note}; {clause}" if note else clause


def divergence_rows(flags: dict, *, step_s: float | None = None) -> list[dict]:
    """Rows of a divergence table from ``{(filter, setting) or filter: DivergenceFlags}`` (None entries skipped)."""
    rows = []
    for key, f in flags.items():
        if f is None:
            continue
        name, setting = key if isinstance(key, tuple) else (key, "")
        rows.append(f.row(str(name), str(setting), step_s=step_s))
    return rows
