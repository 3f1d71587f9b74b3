"""Error metrics for position estimates (Eq. (15) of George and Vadivukkarasi; Ozkaya 2011, Sec. 7.2.1).

All functions take estimates and truths of shape ``(..., dim)`` or precomputed errors, and reduce
over ``axis`` (default: all axes), so a ``(runs, steps)`` error array gives one number, or one per run
with ``axis=-1``.

Missing estimates: a problem an estimator could not solve has a NaN position (the library's missing-reading
rule), and NaN propagates through these summaries on purpose, so a statistic is never silently computed over
fewer problems than it claims. A numpy masked array follows the same rule: a masked entry is a NaN (the library's
one converter, :func:`locbook._validate.as_array`), never left out silently. Drop them explicitly (``e[np.isfinite(e)]``) and report how many were dropped.
Infinite errors are never valid (an overflowed estimate is a failure to mark NaN, not a distance): they raise
``ValueError`` naming the argument, as do empty inputs and out-of-range options.
"""
from __future__ import annotations

import warnings

import numpy as np

from ._validate import as_array, check_scalar
from .montecarlo import moving_block_indices

__all__ = [
    "position_error_m", "mean_error_m", "rmse_m", "median_error_m", "percentile_error_m",
    "error_std_m", "empirical_cdf", "reduction_pct", "error_summary", "error_summary_per_run",
    "rmse_standard_error_m", "accuracy_metrics", "ACCURACY_STATISTICS",
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
    """Root mean square of the Euclidean errors."""
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
    """Relative reduction ``100 (before - after) / before`` (George and Vadivukkarasi: 2.2867 -> 1.0378 m is 54.62 %)."""
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


def _accuracy_stats(e, axis=-1):
    """The statistics of :data:`ACCURACY_STATISTICS` over ``axis``, NaN entries (no estimate) left out."""
    with np.errstate(invalid="ignore"), warnings.catch_warnings():
        warnings.simplefilter("ignore", RuntimeWarning)       # an all-NaN resample gives NaN, said by coverage
        return {
            "mean_m": np.nanmean(e, axis=axis), "median_m": np.nanmedian(e, axis=axis),
            "rmse_m": np.sqrt(np.nanmean(np.square(e), axis=axis)),
            "p75_m": np.nanpercentile(e, 75, axis=axis), "p90_m": np.nanpercentile(e, 90, axis=axis),
            "ce95_m": np.nanpercentile(e, 95, axis=axis), "max_m": np.nanmax(e, axis=axis),
        }


def accuracy_metrics(error_m, rng: np.random.Generator, *, n_bootstrap: int = 1000, level: float = 0.95,
                     block_length: int = 1) -> dict:
    """Point-accuracy statistics of one method on one data set, with bootstrap intervals.

    ``error_m``: horizontal errors ``(n,)`` of every epoch scored, NaN where the method gave no estimate (too few
    anchors heard, a failed solve). The statistics (:data:`ACCURACY_STATISTICS`: mean, median, RMSE, 75th and 90th
    percentile, CE95 = the 95th percentile of the horizontal error, and the maximum; ISO/IEC 18305 and EvAAL/IPIN)
    are taken over the epochs with an estimate, and ``coverage`` says what fraction that is (a method is never
    scored silently on fewer epochs than it claims). Intervals: percentile bootstrap at ``level`` over
    ``n_bootstrap`` resamples of the epochs; ``block_length > 1`` resamples blocks of consecutive epochs (the
    moving-block bootstrap), needed for a track whose errors are correlated in time. Returns
    ``{stat: value, stat + "_low": ..., stat + "_high": ..., "coverage": ..., "n": ...}``."""
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
    n = e.size
    idx = moving_block_indices(n, int(block_length), int(n_bootstrap), rng)
    point, boot = _accuracy_stats(e), _accuracy_stats(e[idx], axis=-1)
    tail = 50.0 * (1.0 - level)
    out = {"n": int(n), "coverage": float(np.mean(np.isfinite(e)))}
    for name in ACCURACY_STATISTICS:
        out[name] = float(point[name])
        low, high = np.nanpercentile(boot[name], [tail, 100.0 - tail]) if np.isfinite(boot[name]).any() else (np.nan,) * 2
        out[name + "_low"], out[name + "_high"] = float(low), float(high)
    return out
