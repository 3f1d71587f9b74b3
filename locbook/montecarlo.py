"""Monte-Carlo helpers: independent random streams and standard errors.

Streams come from ``numpy.random.SeedSequence(seed).spawn``; the global RNG is never touched. A named
stream per random component (``streams(seed, "calibration", "tracking")``) keeps components independent:
changing how one is drawn does not shift the others.

What is guaranteed: the same seed and the same parameters give the same numbers, bit for bit (the suite's
tests rerun notebooks and compare). What is not: run ``i`` keeping its numbers when the number of runs
changes. That holds only for the first array drawn from a stream with the run on the leading axis (numpy
fills C-order); a stream that draws several arrays in sequence shifts the later ones with the run count.

Seeds that depend on parameter values (e.g. one stream per simulated setting) come from
:func:`seed_from_values`, a hash of a canonical encoding of the values, never of Python's ``repr``.
"""
from __future__ import annotations

import hashlib
import json
import math
from numbers import Integral, Real

import numpy as np

from ._deprecation import keyword_rng
from ._validate import as_array, check_scalar
from .errors import ParameterError

__all__ = ["spawn_generators", "streams", "mc_standard_error", "bootstrap_standard_error", "jackknife_standard_error",
           "replicate_standard_error", "single_run_interval", "seed_from_values", "canonical_encoding",
           "moving_block_indices", "circular_block_indices"]


def spawn_generators(seed: int | np.random.SeedSequence, n: int) -> list[np.random.Generator]:
    """``n`` statistically independent generators from one seed."""
    check_scalar("n", n, ge=0, integer=True)
    ss = seed if isinstance(seed, np.random.SeedSequence) else np.random.SeedSequence(seed)
    return [np.random.default_rng(child) for child in ss.spawn(n)]


def streams(seed: int, *names: str) -> dict[str, np.random.Generator]:
    """Independent generators keyed by component name, in the order given."""
    if len(set(names)) != len(names):
        raise ValueError(f"stream names must be unique, got {names}")
    return dict(zip(names, spawn_generators(seed, len(names))))


def mc_standard_error(samples, axis: int = 0) -> np.ndarray:
    """Standard error of the mean along ``axis``: ``std(ddof=1) / sqrt(N)``. NaN (or a masked entry, which is a NaN)
    gives NaN: a standard error is never taken silently over fewer samples than it claims."""
    samples = as_array("samples", samples, nan_ok=True, inf_ok=True)
    if (not isinstance(axis, (int, np.integer)) or isinstance(axis, (bool, np.bool_))
            or not -samples.ndim <= axis < samples.ndim):
        raise ValueError(f"axis must be an axis of samples (shape {samples.shape}), got {axis!r}")
    n = samples.shape[axis]
    if n < 2:
        raise ValueError("a standard error needs at least two Monte-Carlo samples")
    return np.std(samples, axis=axis, ddof=1) / np.sqrt(n)


@keyword_rng(2, "n_resamples")
def bootstrap_standard_error(samples, statistic, *, rng: np.random.Generator, n_resamples: int = 200) -> float:
    """Bootstrap standard error of ``statistic`` over independent run-level ``samples`` (1-D).

    ``statistic(x, axis=-1)`` is evaluated on ``n_resamples`` resamples drawn with replacement, all in one
    array; the standard error is their standard deviation. For statistics without a simple closed form
    (median, percentiles); the samples must be independent (one value per Monte-Carlo run, not per step).
    ``rng`` and ``n_resamples`` are keyword-only (the positional form ``(samples, statistic, rng, n_resamples)`` is
    deprecated).
    """
    x = np.asarray(samples, float).ravel()
    check_scalar("n_resamples", n_resamples, ge=2, integer=True)
    if x.size < 2:
        raise ValueError("a standard error needs at least two Monte-Carlo samples")
    resamples = x[rng.integers(0, x.size, size=(n_resamples, x.size))]
    return float(np.std(statistic(resamples, axis=-1), ddof=1))


def _block_arguments(n, block_length, n_resamples, rng) -> tuple[int, int, int]:
    """The checked ``(n, L, n_resamples)`` of a block bootstrap, ``L = min(block_length, n)``."""
    check_scalar("n", n, ge=1, integer=True)
    check_scalar("block_length", block_length, ge=1, integer=True)
    check_scalar("n_resamples", n_resamples, ge=1, integer=True)
    if not isinstance(rng, np.random.Generator):
        raise ParameterError(f"rng must be a numpy.random.Generator, got {type(rng).__name__}")
    return int(n), min(int(block_length), int(n)), int(n_resamples)


@keyword_rng(3)
def moving_block_indices(n: int, block_length: int, n_resamples: int, *, rng: np.random.Generator) -> np.ndarray:
    """Index arrays ``(n_resamples, n)`` of the moving-block bootstrap (Kuensch 1989): each resample joins
    ``ceil(n / L)`` blocks of ``L = min(block_length, n)`` consecutive indices, each block starting uniformly in
    ``[0, n - L]``, cut to ``n``. ``block_length = 1`` is the ordinary bootstrap. For series whose neighbours are
    correlated (a track's errors, calibration points recorded along a path), whose ordinary bootstrap understates
    the spread of a statistic.

    An index near either end lies in fewer possible blocks than one in the middle (index 0 in one of the
    ``n - L + 1``, an index at least ``L - 1`` from both ends in ``L``), so the ends are under-weighted and the
    resampled mean is biased away from the sample mean when the ends differ from the middle;
    :func:`circular_block_indices` has no such bias. ``rng`` is keyword-only (the positional form ``(n,
    block_length, n_resamples, rng)`` is deprecated)."""
    n, length, n_resamples = _block_arguments(n, block_length, n_resamples, rng)
    n_blocks = -(-n // length)
    starts = rng.integers(0, n - length + 1, size=(n_resamples, n_blocks))
    return (starts[..., None] + np.arange(length)).reshape(n_resamples, -1)[:, :n]


@keyword_rng(3)
def circular_block_indices(n: int, block_length: int, n_resamples: int, *, rng: np.random.Generator) -> np.ndarray:
    """Index arrays ``(n_resamples, n)`` of the circular block bootstrap (Politis and Romano 1992, "A circular
    block-resampling procedure for stationary data", in LePage and Billard (eds.), *Exploring the Limits of
    Bootstrap*, Wiley, pp. 263-270): the series is wrapped on a circle, and each resample joins ``ceil(n / L)``
    blocks of ``L = min(block_length, n)`` indices ``(s, s + 1, ..., s + L - 1) mod n``, each start ``s`` uniform in
    ``[0, n - 1]``, cut to ``n``.

    Every position of a resample holds each index with probability exactly ``1 / n`` (``s -> (s + j) mod n`` is a
    bijection), so every epoch is equally likely and the bootstrap expectation of the resampled mean is the sample
    mean, where :func:`moving_block_indices` under-weights both ends. ``block_length = 1`` draws the same starts
    from ``rng`` as :func:`moving_block_indices` and is the ordinary (i.i.d.) bootstrap. ``rng`` is keyword-only (the
    positional form ``(n, block_length, n_resamples, rng)`` is deprecated)."""
    n, length, n_resamples = _block_arguments(n, block_length, n_resamples, rng)
    n_blocks = -(-n // length)
    starts = rng.integers(0, n, size=(n_resamples, n_blocks))
    # index (s + j) mod n: the block wraps past the last epoch to the first
    return ((starts[..., None] + np.arange(length)) % n).reshape(n_resamples, -1)[:, :n]


def jackknife_standard_error(statistic, *per_run) -> float:
    """Delete-one jackknife standard error over runs of ``statistic(*per_run)``, where each array of ``per_run``
    holds one run-level value per run along axis 0 (Efron and Tibshirani 1993, Eq. (11.5)):
    ``sqrt((n - 1) / n * sum_i (theta_(i) - theta_(.))^2)``, for statistics that are not means of run-level values,
    such as a reduction of pooled RMSEs. For the mean it is ``s / sqrt(n)`` exactly."""
    if not per_run:
        raise ParameterError("per_run: the jackknife needs at least one array of run-level values")
    arrays = [np.asarray(a) for a in per_run]
    n = arrays[0].shape[0] if arrays[0].ndim else 0
    if n < 2 or any(a.ndim == 0 or a.shape[0] != n for a in arrays):
        raise ParameterError(f"per_run: arrays with the same number (at least two) of runs on axis 0, got shapes "
                         f"{[a.shape for a in arrays]}")
    keep = ~np.eye(n, dtype=bool)
    leave = np.array([statistic(*(a[keep[i]] for a in arrays)) for i in range(n)])
    return float(np.sqrt((n - 1) / n * np.sum((leave - leave.mean()) ** 2)))



def replicate_standard_error(estimate, seeds) -> float:
    """Standard error of an estimate that is not a mean of independent run-level values (the minimum of a bound
    averaged over simulated trajectories, the time of that minimum): the sample standard deviation (``ddof=1``) of
    independent replicates of the same size, ``estimate(numpy.random.default_rng(seed))`` for each seed.

    For an estimate with variance ``s^2`` the expected squared result is ``s^2`` (the unbiased sample variance);
    with few replicates it is itself uncertain (its relative standard error is about ``1 / sqrt(2 (k - 1))`` for
    ``k`` Gaussian replicates)."""
    seeds = list(seeds)
    if len(seeds) < 2:
        raise ValueError(f"seeds: a replicate standard error needs at least two replicates, got {len(seeds)}")
    values = [estimate(np.random.default_rng(seed)) for seed in seeds]
    return float(np.std(values, ddof=1))


def single_run_interval(per_run, coverage: float = 0.90) -> tuple[float, float]:
    """The central ``coverage`` interval of a run-level statistic (the ``(1 - coverage) / 2`` and
    ``(1 + coverage) / 2`` sample quantiles over runs, linear interpolation): where a single run, e.g. one measured
    walk, should fall if the simulation's model were the experiment's."""
    if not 0.0 < coverage < 1.0:
        raise ParameterError(f"coverage must lie in (0, 1), got {coverage}")
    tail = 50.0 * (1.0 - coverage)
    lo, hi = np.percentile(np.asarray(per_run, float), [tail, 100.0 - tail])
    return float(lo), float(hi)

def _canonical(value):
    """JSON-ready form: every real number by its exact binary value (``float.hex``; 1 and 1.0 are one value),
    booleans, strings and None as themselves, sequences as lists, mappings with sorted string keys."""
    if value is None or isinstance(value, (bool, np.bool_)):
        return None if value is None else bool(value)
    if isinstance(value, str):
        return value
    if isinstance(value, (Integral, Real)):
        number = float(value)
        if isinstance(value, Integral) and number != value:       # an integer beyond 2**53: keep it exact
            return {"int": str(int(value))}
        if math.isnan(number):
            raise ValueError("a NaN cannot key a random stream")
        return {"real": number.hex()}
    if isinstance(value, dict):
        return {"map": [[str(k), _canonical(value[k])] for k in sorted(value, key=str)]}
    if isinstance(value, (list, tuple, np.ndarray)):
        return [_canonical(v) for v in (value.tolist() if isinstance(value, np.ndarray) else value)]
    raise TypeError(f"cannot key a random stream by a {type(value).__name__}: {value!r}")


def canonical_encoding(*values) -> bytes:
    """The bytes :func:`seed_from_values` hashes (exposed for tests and for documenting a seed)."""
    return json.dumps(_canonical(list(values)), separators=(",", ":"), sort_keys=True).encode()


def seed_from_values(*values) -> int:
    """A 64-bit seed from parameter values, independent of Python's float formatting: equal values give the
    same seed whatever their type (1, 1.0, np.float64(1.0)); 0.1 + 0.2 and 0.30000000000000004 are one value,
    0.3 another."""
    return int.from_bytes(hashlib.sha256(canonical_encoding(*values)).digest()[:8], "little")
