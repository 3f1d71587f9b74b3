"""Error metrics for position estimates (Eq. (15) of George and Vadivukkarasi; Ozkaya 2011, Sec. 7.2.1).

All functions take estimates and truths of shape ``(..., dim)`` or precomputed errors, and reduce
over ``axis`` (default: all axes), so a ``(runs, steps)`` error array gives one number, or one per run
with ``axis=-1``.

Missing estimates: a problem an estimator could not solve has a NaN position (the library's missing-reading
rule), and NaN propagates through these summaries on purpose, so a statistic is never silently computed over
fewer problems than it claims. A numpy masked array follows the same rule: a masked entry is a NaN (the library's
one converter, :func:`locbook._validate.as_array`), never left out silently. Drop them explicitly
(``e[np.isfinite(e)]``) and report how many were dropped.
Infinite errors are never valid (an overflowed estimate is a failure to mark NaN, not a distance): they raise
``ValueError`` naming the argument, as do empty inputs and out-of-range options.
"""
from __future__ import annotations

import warnings

import numpy as np

from ._deprecation import keyword_rng
from ._validate import as_array, check_scalar
from .montecarlo import circular_block_indices

__all__ = [
    "position_error_m", "mean_error_m", "rmse_m", "median_error_m", "percentile_error_m",
    "error_std_m", "empirical_cdf", "reduction_pct", "error_summary", "error_summary_per_run",
    "rmse_standard_error_m", "accuracy_metrics", "ACCURACY_STATISTICS", "MIN_BLOCKS",
]


def _errors(name: str, error_m, *, min_size: int = 1) -> np.ndarray:
    """``error_m`` through the one converter (:func:`locbook._validate.as_array`): finite or NaN (a missing estimate),
    a masked entry a NaN (so it follows the NaN rule of the statistic, never dropped silently); numbers kept in their
    own dtype (a float32 or integer array reduces as before)."""
    arr = as_array(name, error_m, nan_ok=True)
    if arr.size < min_size:
        raise ValueError(f"{name} must hold at least {min_size} value(s), got shape {arr.shape}")
    if np.ma.isMaskedArray(error_m) and np.ma.getmaskarray(error_m).any():
        return arr
    kept = as_array(name, error_m, nan_ok=True, dtype=None)
    return kept if kept.dtype.kind in "biuf" else arr


def position_error_m(estimate_m, truth_m):
    """Euclidean distance between estimates and truths, ``(..., dim) -> (...)``.

    ``truth_m`` may be shared by leading axes of ``estimate_m`` (e.g. ``(runs, T, 2)`` against ``(T, 2)``);
    the last (coordinate) axis must match. A NaN estimate (not solved) gives a NaN error."""
    estimate_m = as_array("estimate_m", estimate_m, min_ndim=1, nan_ok=True)
    truth_m = as_array("truth_m", truth_m, min_ndim=1)
    if estimate_m.shape[-1] != truth_m.shape[-1]:
        raise ValueError(f"estimate_m {estimate_m.shape} and truth_m {truth_m.shape} must end in the same dimension")
    try:
        np.broadcast_shapes(estimate_m.shape, truth_m.shape)
    except ValueError:
        raise ValueError(f"estimate_m {estimate_m.shape} and truth_m {truth_m.shape} do not pair up: truth_m must "
                         "have the shape of estimate_m or of its trailing axes") from None
    diff = estimate_m - truth_m
    return np.sqrt(np.sum(diff**2, axis=-1))


def mean_error_m(error_m, axis=None):
    """Mean Euclidean error, ``C = (1/N) sum_i |p_i - p_hat_i|`` (Eq. (15) of George and Vadivukkarasi)."""
    error_m = _errors("error_m", error_m)
    return np.mean(error_m, axis=axis)


def rmse_m(error_m, axis=None):
    """Root mean square of the Euclidean errors.

    Examples
    --------
    >>> import numpy as np
    >>> import locbook as lb
    >>> errors = lb.position_error_m(np.array([[3.0, 4.0], [0.0, 0.0]]), np.zeros(2))
    >>> print(errors, round(float(lb.rmse_m(errors)), 4))              # sqrt((25 + 0) / 2)
    [5. 0.] 3.5355
    """
    error_m = _errors("error_m", error_m)
    return np.sqrt(np.mean(np.square(error_m), axis=axis))


def rmse_standard_error_m(error_m, axis=None):
    """Monte-Carlo standard error of :func:`rmse_m` by the delta method:
    ``SE(sqrt(m2)) = SE(m2) / (2 sqrt(m2))`` with ``m2`` the mean squared error."""
    e2 = np.square(np.asarray(_errors("error_m", error_m), float))
    n = e2.size if axis is None else e2.shape[axis]
    if n < 2:
        raise ValueError(f"a standard error needs at least two errors along axis {axis}, got {n}")
    se_m2 = np.std(e2, axis=axis, ddof=1) / np.sqrt(n)
    return se_m2 / (2.0 * np.sqrt(np.mean(e2, axis=axis)))


def median_error_m(error_m, axis=None):
    """Median of the errors."""
    error_m = _errors("error_m", error_m)
    return np.median(error_m, axis=axis)


def percentile_error_m(error_m, q: float = 90.0, axis=None):
    """``q``-th percentile of the errors (linear interpolation, numpy's default)."""
    error_m = _errors("error_m", error_m)
    check_scalar("q", q, ge=0, le=100)
    return np.percentile(error_m, q, axis=axis)


def error_std_m(error_m, axis=None, ddof: int = 0):
    """Standard deviation of the error magnitudes (population form by default; RMSE^2 = mean^2 + std^2)."""
    error_m = _errors("error_m", error_m)
    check_scalar("ddof", ddof, ge=0, integer=True)
    return np.std(error_m, axis=axis, ddof=ddof)


def empirical_cdf(error_m):
    """Sorted errors and their empirical CDF values ``i/N``, for plotting (NaN errors sort last)."""
    error_m = _errors("error_m", error_m, min_size=0)
    x = np.sort(np.ravel(error_m))
    return x, np.arange(1, x.size + 1) / x.size


def reduction_pct(before, after):
    """Relative reduction ``100 (before - after) / before``.

    George and Vadivukkarasi: 2.2867 -> 1.0378 m is 54.62 %."""
    before_arr, after_arr = as_array("before", before, nan_ok=True), as_array("after", after, nan_ok=True)
    if before_arr.ndim and after_arr.ndim and before_arr.shape != after_arr.shape:
        raise ValueError(f"before {before_arr.shape} and after {after_arr.shape} must have the same shape "
                         "(or one be a scalar)")
    if np.any(before_arr == 0):
        raise ValueError("before must be non-zero: a reduction is relative to it")
    return 100.0 * (before_arr - after_arr) / before_arr


def error_summary(error_m) -> dict[str, float]:
    """All summary statistics of a set of errors, as plain floats."""
    error_m = _errors("error_m", error_m)
    e = np.ravel(error_m)
    return {
        "mean_m": float(mean_error_m(e)), "rmse_m": float(rmse_m(e)),
        "median_m": float(median_error_m(e)), "p90_m": float(percentile_error_m(e, 90)),
        "std_m": float(error_std_m(e)), "n": int(e.size),
    }


def error_summary_per_run(error_m) -> dict[str, np.ndarray]:
    """The statistics of :func:`error_summary` for each run separately: errors ``(R, ...)`` (one row per
    independent run, e.g. a synthetic test bed or a Monte-Carlo replicate, with any number of estimates each)
    -> ``{"rmse_m", "mean_m", "median_m", "p90_m", "std_m"}``, each an ``(R,)`` array taken over all axes but
    the first (std in population form, percentiles by linear interpolation, as in :func:`error_summary`).

    Their spread across runs gives a standard error of their mean over runs (``std(ddof=1) / sqrt(R)``), and
    says how far the statistic of one run may fall from that mean."""
    e = np.asarray(_errors("error_m", error_m), float)
    if e.ndim < 2 or e[0].size == 0:
        raise ValueError(f"error_m must have shape (runs, estimates, ...) with at least one estimate per run, "
                         f"got {e.shape}")
    e = e.reshape(e.shape[0], -1)
    return {"rmse_m": rmse_m(e, axis=-1), "mean_m": mean_error_m(e, axis=-1), "median_m": median_error_m(e, axis=-1),
            "p90_m": percentile_error_m(e, 90, axis=-1), "std_m": error_std_m(e, axis=-1)}


#: the statistics of :func:`accuracy_metrics`, in the conventions of ISO/IEC 18305 and the EvAAL/IPIN competitions
ACCURACY_STATISTICS = ("mean_m", "median_m", "rmse_m", "p75_m", "p90_m", "ce95_m", "max_m")


def _nan_percentiles(e, q) -> np.ndarray:
    """``np.nanpercentile(e, q, axis=-1)`` of a 2-D ``e`` (method "linear"), bit for bit, without numpy's Python
    loop over rows (its NaN path takes each row alone). Each row is sorted (NaN last) and, with ``c`` values, read at
    numpy's virtual index ``(c - 1) q / 100`` by numpy's own interpolation (``a + (b - a) g``, from the upper
    neighbour ``b - (b - a)(1 - g)`` where ``g >= 0.5``); a percentile is set by order statistics, so the values'
    order in a row does not change it. Shape ``(len(q), rows)``; an all-NaN row gives NaN."""
    counts = (~np.isnan(e)).sum(axis=-1)
    ordered = np.sort(e, axis=-1)
    last = np.maximum(counts - 1, 0)
    virtual = (counts - 1) * np.true_divide(np.asarray(q, float), 100)[:, None]        # (len(q), rows)
    lower = np.floor(virtual)
    past = virtual >= counts - 1                    # numpy reads the last value there (and both neighbours are it)
    lower[past] = -1.0
    lower[virtual < 0] = 0.0
    gamma = virtual - lower.astype(np.intp)
    below = np.where(past, last, np.clip(lower, 0, None)).astype(np.intp)
    above = np.where(past, last, np.minimum(below + 1, last))
    a = np.take_along_axis(ordered, below.T, axis=-1).T
    b = np.take_along_axis(ordered, above.T, axis=-1).T
    diff = b - a
    out = np.where(gamma >= 0.5, b - diff * (1 - gamma), a + diff * gamma)
    out[:, counts == 0] = np.nan
    return out


def _accuracy_stats(e):
    """The statistics of :data:`ACCURACY_STATISTICS` over the last axis of ``e`` (one series, or resamples in rows),
    NaN entries (no estimate) left out."""
    with np.errstate(invalid="ignore"), warnings.catch_warnings():
        warnings.simplefilter("ignore", RuntimeWarning)       # an all-NaN resample gives NaN, said by coverage
        p75, p90, p95 = (np.nanpercentile(e, [75, 90, 95], axis=-1) if e.ndim == 1 else
                         _nan_percentiles(e, [75, 90, 95]))
        return {
            "mean_m": np.nanmean(e, axis=-1), "median_m": np.nanmedian(e, axis=-1),
            "rmse_m": np.sqrt(np.nanmean(np.square(e), axis=-1)),
            "p75_m": p75, "p90_m": p90, "ce95_m": p95, "max_m": np.nanmax(e, axis=-1),
        }


#: the fewest blocks (finite epochs / block length) for which :func:`accuracy_metrics` gives a bootstrap interval: a
#: rule of ours, argued in docs/your-data.md, "Intervals"
MIN_BLOCKS = 10

#: relative slack of the check that an interval holds its estimate: a resample holding the series' values in another
#: order sums them in another order, and its statistic can differ from the estimate by rounding, not an exclusion
_EXCLUSION_RTOL = 1e-9

#: an exclusion in a series of fewer than this many times ``min_blocks`` blocks names the block count as its likely
#: cause (our rule: near the minimum the resampled statistic still takes few distinct values); above it, the skew
_FEW_BLOCKS_FACTOR = 3

#: statistics set by the few largest errors; their bootstrap distribution lies mostly at or below the estimate (a
#: resample's maximum never exceeds the sample's), so an interval that misses them is a skew at the edge
_EDGE_STATISTICS = ("p90_m", "ce95_m", "max_m")

_LABELS = {"mean_m": "mean", "median_m": "median", "rmse_m": "RMSE", "p75_m": "75th percentile",
           "p90_m": "90th percentile", "ce95_m": "CE95", "max_m": "maximum"}


def _distinct_text(estimate: float, low: float, high: float) -> tuple[str, str, str]:
    """The three numbers with the fewest decimals (2 to 6) at which the estimate still reads outside the interval,
    so the note never says "0.80 outside [0.54, 0.80]"."""
    for digits in range(2, 7):
        e, lo, hi = (f"{v:.{digits}f}" for v in (estimate, low, high))
        if not float(lo) <= float(e) <= float(hi):
            break
    return e, lo, hi


def _below_text(value: float, limit: float) -> str:
    """``value`` (below ``limit``) to 3 significant digits, more if those would round it up to ``limit``."""
    for digits in range(3, 16):
        text = f"{value:.{digits}g}"
        if float(text) < limit:
            return text
    return repr(value)


def _exclusion_note(name: str, estimate: float, low: float, high: float, boot: np.ndarray, n_blocks: float,
                    block_length: int, min_blocks: float) -> str:
    """"" when ``[low, high]`` holds ``estimate`` (or either is NaN), else one line saying it does not and why."""
    if not (np.isfinite(estimate) and np.isfinite(low) and np.isfinite(high)):
        return ""
    slack = _EXCLUSION_RTOL * max(abs(estimate), abs(low), abs(high))
    if low - slack <= estimate <= high + slack:
        return ""
    b = boot[np.isfinite(boot)]
    side = "below" if estimate > high else "above"
    share = float(np.mean(b < estimate) if side == "below" else np.mean(b > estimate))
    label = _LABELS[name]
    if name in _EDGE_STATISTICS:
        reason = (f"the {label} is a skewed statistic at the edge of its bootstrap distribution "
                  "(set by the few largest errors)")
    elif n_blocks < _FEW_BLOCKS_FACTOR * min_blocks:
        few = (f"blocks for the {label} ({n_blocks:.3g} blocks of {block_length} epochs)" if block_length > 1 else
               f"epochs for the {label} ({n_blocks:g})")
        reason = f"few {few}, so the resampled statistic takes few distinct values"
    else:
        reason = f"the bootstrap distribution of the {label} is skewed"
    e, lo, hi = _distinct_text(estimate, low, high)
    return (f"the interval excludes the estimate ({e} outside [{lo}, {hi}]): {reason}; "
            f"{100 * share:.1f} % of the resamples fall {side} it")


@keyword_rng(1)
def accuracy_metrics(error_m, *, rng: np.random.Generator, n_bootstrap: int = 1000, level: float = 0.95,
                     block_length: int = 1, min_blocks: float = MIN_BLOCKS, values_per_epoch: int = 1) -> dict:
    """Point-accuracy statistics of one method on one data set, with bootstrap intervals.

    ``error_m``: horizontal errors ``(n,)`` of every epoch scored, in time order, NaN where the method gave no
    estimate (too few anchors heard, a failed solve). The statistics (:data:`ACCURACY_STATISTICS`: mean, median,
    RMSE, 75th and 90th percentile, CE95 = the 95th percentile of the horizontal error, and the maximum; ISO/IEC
    18305 and EvAAL/IPIN) are taken over the epochs with an estimate, and ``coverage`` says what fraction that is (a
    method is never scored silently on fewer epochs than it claims).

    Intervals: the percentile bootstrap at ``level`` over ``n_bootstrap`` resamples of the epochs (the NaN epochs
    resampled with the others and left out of each resample's statistic). ``block_length = 1`` resamples single
    epochs (the i.i.d. bootstrap); ``block_length > 1`` resamples blocks of that many consecutive epochs by the
    circular block bootstrap (Politis and Romano 1992; :func:`locbook.montecarlo.circular_block_indices`), needed
    for a track whose errors are correlated in time, and unbiased for the mean where the moving-block bootstrap is
    not. With fewer than ``min_blocks`` blocks (``n_blocks`` = epochs with an estimate / ``block_length``;
    :data:`MIN_BLOCKS`) the intervals are not estimable: every ``_low`` / ``_high`` is NaN and ``interval_note``
    says why. An interval that does not hold its own estimate is kept as computed (never widened) and flagged in
    ``<stat>_note``.

    ``values_per_epoch = k``: ``error_m`` holds ``k`` values per epoch, epoch-major (the errors of ``k`` runs of a
    randomised method at each epoch): the statistics are taken over every value, and the bootstrap resamples epochs,
    each with all its ``k`` values (blocks and ``n_blocks`` count epochs; an epoch with an estimate is one where any
    run has one). ``rng`` (keyword-only; the positional form ``accuracy_metrics(error_m, rng)`` is deprecated) draws
    the resamples.

    Returns ``{stat: value, stat + "_low": ..., stat + "_high": ..., stat + "_note": "" or why the interval excludes
    the estimate, "coverage": ..., "n": ..., "n_blocks": float, "interval": how it was taken, "interval_note": ""
    or why there is none}``."""
    e = as_array("error_m", error_m, ndim=1, nan_ok=True)
    if e.size < 2:
        raise ValueError(f"error_m needs at least 2 epochs, got {e.size}")
    if np.any(e[np.isfinite(e)] < 0):
        raise ValueError("error_m must be non-negative distances (NaN = no estimate)")
    if not isinstance(rng, np.random.Generator):
        raise ValueError(f"rng must be a numpy.random.Generator, got {type(rng).__name__}")
    check_scalar("n_bootstrap", n_bootstrap, ge=2, integer=True)
    check_scalar("level", level, gt=0, lt=1)
    check_scalar("block_length", block_length, ge=1, integer=True)
    check_scalar("min_blocks", min_blocks, ge=1)
    check_scalar("values_per_epoch", values_per_epoch, ge=1, integer=True)
    k = int(values_per_epoch)
    if e.size % k:
        raise ValueError(f"error_m holds {e.size} values, not a whole number of epochs of values_per_epoch = {k}")
    n, block, n_boot = e.size // k, int(block_length), int(n_bootstrap)
    n_finite = int(np.isfinite(e.reshape(n, k)).any(axis=1).sum())
    n_blocks = n_finite / block
    # drawn whatever the block count, so a stream shared by several calls advances the same way
    idx = circular_block_indices(n, block, n_boot, rng=rng)
    if k > 1:                          # every value of a drawn epoch, in order
        idx = (idx[..., None] * k + np.arange(k)).reshape(n_boot, -1)
    point, boot = _accuracy_stats(e), _accuracy_stats(e[idx])
    estimable = n_blocks >= min_blocks
    tail = 50.0 * (1.0 - level)
    how = (f"bootstrap over epochs (i.i.d., {n_boot} resamples)" if block == 1 else
           f"circular block bootstrap, blocks of {block} epochs ({n_boot} resamples)")
    if estimable:
        note = ""
    elif block == 1:
        note = f"not estimable: {n_finite} epochs with an estimate; the rule needs at least {min_blocks:g}"
    else:
        held = "epochs" if n_finite == n else "epochs with an estimate"
        note = (f"not estimable: {n_finite} {held} hold {_below_text(n_blocks, min_blocks)} blocks of {block}; the "
                f"rule needs at least {min_blocks:g} blocks")
    out = {"n": int(e.size), "coverage": float(np.mean(np.isfinite(e))), "n_blocks": float(n_blocks), "interval": how,
           "interval_note": note}
    for name in ACCURACY_STATISTICS:
        out[name] = float(point[name])
        if estimable and np.isfinite(boot[name]).any():
            low, high = (float(v) for v in np.nanpercentile(boot[name], [tail, 100.0 - tail]))
        else:
            low = high = float("nan")
        out[name + "_low"], out[name + "_high"] = low, high
        out[name + "_note"] = _exclusion_note(name, out[name], low, high, boot[name], n_blocks, block,
                                             min_blocks)
    return out
