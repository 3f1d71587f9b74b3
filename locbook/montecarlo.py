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

from ._validate import check_scalar

__all__ = ["spawn_generators", "streams", "mc_standard_error", "bootstrap_standard_error", "replicate_standard_error",
           "seed_from_values", "canonical_encoding"]


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
    """Standard error of the mean along ``axis``: ``std(ddof=1) / sqrt(N)``."""
    samples = np.asarray(samples, float)
    n = samples.shape[axis]
    if n < 2:
        raise ValueError("a standard error needs at least two Monte-Carlo samples")
    return np.std(samples, axis=axis, ddof=1) / np.sqrt(n)


def bootstrap_standard_error(samples, statistic, rng: np.random.Generator, n_resamples: int = 200) -> float:
    """Bootstrap standard error of ``statistic`` over independent run-level ``samples`` (1-D).

    ``statistic(x, axis=-1)`` is evaluated on ``n_resamples`` resamples drawn with replacement, all in one
    array; the standard error is their standard deviation. For statistics without a simple closed form
    (median, percentiles); the samples must be independent (one value per Monte-Carlo run, not per step).
    """
    x = np.asarray(samples, float).ravel()
    check_scalar("n_resamples", n_resamples, ge=2, integer=True)
    if x.size < 2:
        raise ValueError("a standard error needs at least two Monte-Carlo samples")
    resamples = x[rng.integers(0, x.size, size=(n_resamples, x.size))]
    return float(np.std(statistic(resamples, axis=-1), ddof=1))



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
