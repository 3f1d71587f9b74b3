"""Input checks at the public boundary: every failure names the argument, what it got and what it expects.

The library's one rule for missing values (docs/filters.md, "Missing readings"): a NaN received power means "not
heard" (the anchor got no packet in that epoch). Measurement arrays therefore accept NaN and each estimator
says how it uses the readings present; every other input (anchors, model parameters, covariances, grids)
must be finite, and infinities are never a reading.
"""
from __future__ import annotations

from collections.abc import Sequence

import numpy as np

__all__ = ["as_array", "check_trailing_shape", "check_scalar", "check_choice"]


def as_array(name: str, value, *, ndim: int | None = None, min_ndim: int | None = None,
             trailing: Sequence[int | None] | None = None, nan_ok: bool = False, dtype=float) -> np.ndarray:
    """``value`` as a float array, checked.

    ``trailing``: the required sizes of the last axes (``None`` = any size), e.g. ``(m, 2)``.
    ``nan_ok``: NaN entries are allowed (missing readings); infinities never are.
    """
    try:
        arr = np.asarray(value, dtype=dtype)
    except (TypeError, ValueError) as exc:
        raise ValueError(f"{name} must be numeric, got {type(value).__name__}: {exc}") from None
    if ndim is not None and arr.ndim != ndim:
        raise ValueError(f"{name} must have {ndim} axes, got shape {arr.shape}")
    if min_ndim is not None and arr.ndim < min_ndim:
        raise ValueError(f"{name} must have at least {min_ndim} axes, got shape {arr.shape}")
    if trailing is not None:
        check_trailing_shape(name, arr, trailing)
    if np.issubdtype(arr.dtype, np.floating):
        bad = np.isinf(arr) if nan_ok else ~np.isfinite(arr)
        if bad.any():
            what = "infinite" if nan_ok else "NaN or infinite"
            raise ValueError(f"{name} must be finite{' (NaN = missing is allowed)' if nan_ok else ''}; "
                             f"got {int(bad.sum())} {what} value(s), the first at index "
                             f"{tuple(int(i) for i in np.argwhere(bad)[0])}")
    return arr


def check_trailing_shape(name: str, arr: np.ndarray, trailing: Sequence[int | None]) -> None:
    """Raise unless the last ``len(trailing)`` axes of ``arr`` have the given sizes (``None`` = any)."""
    k = len(trailing)
    want = "(..., " + ", ".join("*" if t is None else str(t) for t in trailing) + ")"
    if arr.ndim < k or any(t is not None and s != t for s, t in zip(arr.shape[arr.ndim - k:], trailing)):
        raise ValueError(f"{name} must have shape {want}, got {arr.shape}")


def check_scalar(name: str, value, *, gt: float | None = None, ge: float | None = None,
                 le: float | None = None, lt: float | None = None, allow_inf: bool = False,
                 integer: bool = False) -> float:
    """A real scalar within the stated bounds, else ``ValueError`` naming ``name``."""
    if isinstance(value, (bool, np.bool_)) or not np.isscalar(value) and np.ndim(value) != 0:
        raise ValueError(f"{name} must be a real number, got {value!r}")
    try:
        v = float(value)
    except (TypeError, ValueError):
        raise ValueError(f"{name} must be a real number, got {value!r}") from None
    if np.isnan(v) or (np.isinf(v) and not allow_inf):
        raise ValueError(f"{name} must be finite, got {value!r}")
    if integer and v != int(v):
        raise ValueError(f"{name} must be an integer, got {value!r}")
    for bound, ok, text in ((gt, lambda b: v > b, ">"), (ge, lambda b: v >= b, ">="),
                            (le, lambda b: v <= b, "<="), (lt, lambda b: v < b, "<")):
        if bound is not None and not ok(bound):
            raise ValueError(f"{name} must be {text} {bound}, got {value!r}")
    return v


def check_choice(name: str, value, choices: Sequence) -> None:
    if value not in choices:
        raise ValueError(f"{name} must be one of {tuple(choices)}, got {value!r}")
