"""A per-epoch bound summarised over a recording, and the error / bound ratio, without letting a few epochs lie.

On measured data each epoch has its own bound (the anchors it heard, the geometry at its true position). An RMS
over the epochs is dominated by its largest terms: one epoch that heard two anchors has a near-singular information
and a bound of 1e8 m, and the RMS of the recording's bound becomes 1e8 m, so that every method's RMSE / RMS bound
reads 0.00 ("far better than the bound"). Here

- the epochs where the bound says nothing (NaN with a reason, :func:`locbook.bounds.crlb.rss_crlb_checked_m`) are
  left out and counted by kind (:attr:`BoundSummary.excluded`);
- the bound is summarised by its RMS, median and a trimmed RMS (:data:`TRIM_FRACTION`) over the epochs left;
- the summary is *degenerate* when too few epochs are left (fewer than :data:`MIN_VALID_EPOCHS`, or under
  :data:`MIN_VALID_FRACTION` of the epochs), and then it has no statistics and no ratio can be drawn from it:
  :func:`error_bound_ratio` gives NaN with a note naming the reason.
"""
from __future__ import annotations

import re
from dataclasses import dataclass, field

import numpy as np

from .._validate import as_array
from ..errors import ParameterError
from .crlb import NO_TRUTH_REASON

__all__ = ["TRIM_FRACTION", "MIN_VALID_FRACTION", "MIN_VALID_EPOCHS", "BoundSummary", "summarize_bound",
           "error_bound_ratio"]

#: Fraction of the valid epochs, the largest bounds, left out of the trimmed RMS (``floor(0.05 n)`` epochs, none
#: below 20). The RMS is dominated by the worst geometry; the trimmed RMS says what a typical epoch allows, next to
#: the median.
TRIM_FRACTION = 0.05

#: Least fraction of a recording's epochs at which the bound must be defined for a summary of the recording: below
#: it the summary describes the minority of epochs with good geometry, not the recording, and no ratio is given.
MIN_VALID_FRACTION = 0.5

#: Least number of epochs with a defined bound for a summary (one epoch has no spread, no median of a recording).
MIN_VALID_EPOCHS = 2

#: The kinds an excluded epoch is counted under, in the order they are listed.
_KIND_ORDER = ("no truth", "too few anchors", "near-singular", "undefined")
_TOO_FEW = re.compile(r"^heard \d+ anchors?, a plan fix needs (\d+)$")


def _kind(reason: str) -> tuple[str, str]:
    """``(kind, phrase)`` of an epoch's reason: the kind it is counted under and how ``excluded_why`` says it."""
    match = _TOO_FEW.match(reason)
    if match:
        return "too few anchors", f"heard fewer than {match.group(1)} anchors"
    if reason.startswith(("near-singular", "singular", "infinite")):
        return "near-singular", "near-singular"
    if reason == NO_TRUTH_REASON or reason.startswith("no truth"):
        return "no truth", "without a true position"
    if reason in ("", "undefined") or reason.startswith("no information"):
        return "undefined", "undefined"
    return reason, reason           # a caller's own reason is counted under its own words


@dataclass(frozen=True)
class BoundSummary:
    """A per-epoch bound ``(E,)`` over a recording (:func:`summarize_bound`).

    ``valid`` ``(E,)``: where the bound is defined (finite, no reason); ``bound_m`` ``(E,)``: the bound there, NaN
    elsewhere; ``excluded``: the epochs left out, counted by kind (``"too few anchors"``, ``"near-singular"``,
    ``"no truth"``, ``"undefined"`` = NaN without a reason, or a caller's own reason). ``rms_m``, ``median_m`` and
    ``trimmed_rms_m`` (:data:`TRIM_FRACTION`) are over the valid epochs, and NaN when the summary is ``degenerate``
    (``degenerate_reason`` says why; ``""`` when it is not).
    """

    n_epochs: int
    n_valid: int
    excluded: dict = field(compare=False)
    rms_m: float
    median_m: float
    trimmed_rms_m: float
    valid: np.ndarray = field(repr=False, compare=False)
    degenerate: bool
    degenerate_reason: str
    bound_m: np.ndarray = field(repr=False, compare=False)
    excluded_why: str = ""

    def row(self, prefix: str = "bound_") -> dict:
        """The summary as table columns: ``{prefix}median_m``, ``rms_m``, ``trimmed_rms_m``, ``epochs`` (epochs with a
        defined bound), ``excluded`` (epochs left out) and ``excluded_why`` (e.g. ``"12 heard fewer than 3 anchors;
        1 near-singular"``, ``""`` when none)."""
        return {f"{prefix}median_m": self.median_m, f"{prefix}rms_m": self.rms_m,
                f"{prefix}trimmed_rms_m": self.trimmed_rms_m, f"{prefix}epochs": self.n_valid,
                f"{prefix}excluded": self.n_epochs - self.n_valid, f"{prefix}excluded_why": self.excluded_why}


def _readonly(a: np.ndarray) -> np.ndarray:
    a = np.array(a)
    a.flags.writeable = False
    return a


def _percent(fraction: float) -> str:
    return f"{100 * fraction:.3g} %"


def summarize_bound(bound_m, reason=None) -> BoundSummary:
    """Summarise a per-epoch bound ``bound_m`` ``(E,)`` (m) over the epochs where it is defined.

    ``reason`` ``(E,)`` (str, ``""`` = defined; :func:`locbook.bounds.crlb.rss_crlb_checked_m`) marks the epochs to
    leave out; without it, or where it is ``""``, a NaN bound counts as ``"undefined"`` and an infinite one (the
    unchecked :func:`locbook.bounds.crlb.rss_crlb_m` where the information is singular) as ``"near-singular"``.
    RMS ``sqrt(mean b^2)``, median, and the trimmed RMS without the ``floor(TRIM_FRACTION n)`` largest of the ``n``
    valid epochs; all NaN when the summary is degenerate (fewer than :data:`MIN_VALID_EPOCHS` valid epochs, or a
    valid fraction below :data:`MIN_VALID_FRACTION`).
    """
    b = as_array("bound_m", bound_m, ndim=1, nan_ok=True, inf_ok=True)
    if np.any(b < 0):
        first = int(np.argmax(b < 0))
        raise ParameterError(f"bound_m must be >= 0 (a bound on an error in m), got bound_m[{first}] = {b[first]}")
    n = b.size
    if reason is None:
        why = np.full(n, "", dtype=object)
    else:
        why = np.asarray(reason, dtype=object)
        if why.shape != b.shape:
            raise ParameterError(f"reason must have the shape of bound_m {b.shape} (one per epoch), got {why.shape}")
        if not all(isinstance(r, str) for r in why):
            raise ParameterError("reason must hold strings (\"\" where the bound is defined)")
    valid = np.isfinite(b) & (why == "")
    # an epoch without a reason but without a finite bound gets one: NaN is undefined, inf is singular
    why = np.where(~valid & (why == "") & np.isinf(b), "infinite", why)
    counts: dict[str, int] = {}
    phrases: dict[str, list[str]] = {}
    for r in np.unique(why[~valid]).tolist():       # a few distinct reasons, not one pass per epoch
        kind, phrase = _kind(r)
        counts[kind] = counts.get(kind, 0) + int(np.sum(~valid & (why == r)))
        phrases.setdefault(kind, [])
        if phrase not in phrases[kind]:
            phrases[kind].append(phrase)
    order = sorted(counts, key=lambda k: (_KIND_ORDER.index(k) if k in _KIND_ORDER else len(_KIND_ORDER), k))
    excluded = {k: counts[k] for k in order}
    said = {k: (phrases[k][0] if len(phrases[k]) == 1 else
                "heard too few anchors" if k == "too few anchors" else " or ".join(phrases[k])) for k in order}
    excluded_why = "; ".join(f"{excluded[k]} {said[k]}" for k in order)
    n_valid = int(valid.sum())
    if n == 0:
        degenerate_reason = "there are no epochs"
    elif n_valid / n < MIN_VALID_FRACTION:
        detail = said[order[0]] if len(order) == 1 else excluded_why
        degenerate_reason = f"the bound is undefined at {_percent(1 - n_valid / n)} of epochs ({detail})"
    elif n_valid < MIN_VALID_EPOCHS:
        degenerate_reason = (f"the bound is defined at only {n_valid} epoch{'' if n_valid == 1 else 's'}, a summary "
                             f"needs {MIN_VALID_EPOCHS}")
    else:
        degenerate_reason = ""
    degenerate = bool(degenerate_reason)
    if degenerate:
        rms = median = trimmed = float("nan")
    else:
        v = np.sort(b[valid])
        keep = v.size - int(np.floor(TRIM_FRACTION * v.size + 1e-9))    # + 1e-9: 0.05 * 60 is 3.0000000000000004
        rms = float(np.sqrt(np.mean(v**2)))                              # sqrt(mean_e b_e^2)
        median = float(np.median(v))
        trimmed = float(np.sqrt(np.mean(v[:keep] ** 2)))
    return BoundSummary(n_epochs=n, n_valid=n_valid, excluded=excluded, rms_m=rms, median_m=median,
                        trimmed_rms_m=trimmed, valid=_readonly(valid), degenerate=degenerate,
                        degenerate_reason=degenerate_reason, bound_m=_readonly(np.where(valid, b, np.nan)),
                        excluded_why=excluded_why)


def error_bound_ratio(error_m, summary: BoundSummary) -> tuple[float, str]:
    """``(ratio, note)``: RMSE over RMS bound on the same epochs, or NaN with a note saying why there is none.

    ``error_m`` ``(E,)`` or ``(R, E)`` (``R`` runs, NaN = no estimate) at the ``E`` epochs of ``summary``. The
    ratio is ``sqrt(mean e^2) / sqrt(mean b^2)`` over the (run, epoch) pairs where the bound is valid and the error
    finite, runs pooled (an epoch's bound counts once per run with an error there). ``note`` is ``""`` with a
    ratio; with NaN it begins ``"n/a: "`` and names the reason (a degenerate summary, e.g. ``"n/a: the bound is
    undefined at 60 % of epochs (heard fewer than 3 anchors)"``, or too few epochs with both an error and a bound).
    """
    if not isinstance(summary, BoundSummary):
        raise ParameterError(f"summary must be a BoundSummary (summarize_bound), got {type(summary).__name__}")
    e = as_array("error_m", error_m, nan_ok=True)
    if e.ndim not in (1, 2) or e.shape[-1] != summary.n_epochs:
        raise ParameterError(f"error_m must be (E,) or (R, E) with E = {summary.n_epochs} (the bound's epochs), got "
                             f"shape {e.shape}")
    if np.any(e < 0):
        raise ParameterError("error_m must be >= 0 (position errors in m; NaN = no estimate)")
    if summary.degenerate:
        return float("nan"), f"n/a: {summary.degenerate_reason}"
    e = np.atleast_2d(e)
    use = summary.valid[None, :] & np.isfinite(e)                   # (R, E)
    n_epochs = int(use.any(axis=0).sum())
    if n_epochs < MIN_VALID_EPOCHS:
        return float("nan"), (f"n/a: an error and a defined bound at {n_epochs} epoch{'' if n_epochs == 1 else 's'}, "
                              f"a ratio needs {MIN_VALID_EPOCHS}")
    b = np.broadcast_to(summary.bound_m, e.shape)[use]
    rms_bound = float(np.sqrt(np.mean(b**2)))
    if not rms_bound > 0:
        return float("nan"), "n/a: the bound is 0 at every epoch scored"
    return float(np.sqrt(np.mean(e[use] ** 2)) / rms_bound), ""             # RMSE / RMS bound, same pairs
