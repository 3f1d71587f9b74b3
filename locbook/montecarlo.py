"""Monte-Carlo helpers: independent random streams and standard errors.

Streams come from ``numpy.random.SeedSequence(seed).spawn``; the global RNG is never touched. A named
stream per random component (``streams(seed, "calibration", "tracking")``) keeps components independent:
changing how one is drawn does not shift the others. Draws are vectorized with the run on the leading
axis, so run ``i`` gets the same numbers whatever the number of runs (numpy fills C-order).
"""
from __future__ import annotations

import numpy as np

__all__ = ["spawn_generators", "streams", "mc_standard_error"]


def spawn_generators(seed: int | np.random.SeedSequence, n: int) -> list[np.random.Generator]:
    """``n`` statistically independent generators from one seed."""
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
