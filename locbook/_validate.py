"""Input checks at the public boundary: every failure names the argument, what it got and what it expects.

The library's one rule for missing values (docs/filters.md, "Missing readings"): a NaN received power means "not
heard" (the anchor got no packet in that epoch). Measurement arrays therefore accept NaN and each estimator
says how it uses the readings present; every other input (anchors, model parameters, covariances, grids)
must be finite, and infinities are never a reading. A numpy masked array follows the same rule, here in the one
converter every public entry uses: a masked entry is a reading not heard (NaN) where readings are accepted, and an
error naming the argument elsewhere (its data under the mask is never used). Complex values are refused (their
imaginary part would be dropped), and a list holding None gets a hint to use NaN for a missing value.
"""
from __future__ import annotations

import inspect
import reprlib
from collections.abc import Sequence

import numpy as np

__all__ = ["as_array", "check_trailing_shape", "check_scalar", "check_choice", "function_output", "call_user"]

_COMPLEX = "{name} must be real, got complex values (their imaginary part would be dropped)"


def as_array(name: str, value, *, ndim: int | None = None, min_ndim: int | None = None,
             trailing: Sequence[int | None] | None = None, nan_ok: bool = False, dtype=float,
             inf_ok: bool = False) -> np.ndarray:
    """``value`` as a float array, checked.

    ``trailing``: the required sizes of the last axes (``None`` = any size), e.g. ``(m, 2)``.
    ``nan_ok``: NaN entries are allowed (missing readings); infinities never are, except with ``inf_ok`` (a statistic
    of values that may overflow, e.g. Monte-Carlo samples, which then propagates them).
    """
    if not np.ma.isMaskedArray(value) and isinstance(value, (list, tuple)) and _holds_masked(value):
        value = _stack_masked(name, value)      # np.asarray of a list of masked rows would drop their masks
    if np.ma.isMaskedArray(value):
        value = _unmasked(name, value, nan_ok)
    if nan_ok and isinstance(value, (list, tuple)):
        value = _none_rows(value)               # filterpy's z = None: a step without a reading
    if _is_complex(value):                      # numpy would drop the imaginary part with a warning
        raise ValueError(_COMPLEX.format(name=name))
    try:
        arr = np.asarray(value, dtype=dtype)
    except (TypeError, ValueError) as exc:
        raise ValueError(_not_numeric(name, value, exc)) from None
    if ndim is not None and arr.ndim != ndim:
        raise ValueError(f"{name} must have {ndim} axes, got shape {arr.shape}")
    if min_ndim is not None and arr.ndim < min_ndim:
        raise ValueError(f"{name} must have at least {min_ndim} axes, got shape {arr.shape}")
    if trailing is not None:
        check_trailing_shape(name, arr, trailing)
    if np.issubdtype(arr.dtype, np.floating) and not (nan_ok and inf_ok):
        bad = np.isinf(arr) if nan_ok else ~np.isfinite(arr)
        if bad.any():
            what = "infinite" if nan_ok else "NaN or infinite"
            raise ValueError(f"{name} must be finite{' (NaN = missing is allowed)' if nan_ok else ''}; "
                             f"got {int(bad.sum())} {what} value(s), the first at index "
                             f"{tuple(int(i) for i in np.argwhere(bad)[0])}")
    return arr


def _holds_masked(value, depth: int = 0) -> bool:
    """Whether a (nested) list or tuple holds a masked array."""
    for v in value:
        if isinstance(v, np.ma.MaskedArray) or (isinstance(v, (list, tuple)) and depth < 32
                                                and _holds_masked(v, depth + 1)):
            return True
    return False


def _stack_masked(name: str, value) -> np.ma.MaskedArray:
    """A nested list holding masked arrays as one masked array, every element's mask kept."""
    try:
        return np.ma.stack([_stack_masked(name, v) if isinstance(v, (list, tuple)) else v for v in value])
    except (TypeError, ValueError):
        raise ValueError(f"{name} must be a rectangular array of numbers; got a list whose rows (some masked) have "
                         "different shapes") from None


def _is_complex(value) -> bool:
    """Whether an array or numpy scalar holds complex numbers (a Python complex fails the conversion itself)."""
    try:
        return np.issubdtype(getattr(value, "dtype", np.float64), np.complexfloating)
    except TypeError:                           # a dtype numpy does not know (e.g. a pandas extension type)
        return False


def _unmasked(name: str, value, nan_ok: bool) -> np.ndarray:
    """A masked array's values with its masked entries as NaN (``nan_ok``: readings, NaN = not heard), else an error
    naming the argument; an array with nothing masked is its data."""
    mask = np.ma.getmaskarray(value)
    if not mask.any():
        return np.ma.getdata(value)
    if not nan_ok:
        raise ValueError(f"{name} must not be masked (a mask means a missing reading, allowed only in readings); got "
                         f"{int(mask.sum())} masked value(s), the first at index "
                         f"{tuple(int(i) for i in np.argwhere(mask)[0])}")
    try:
        return np.ma.filled(value.astype(float), np.nan)
    except (TypeError, ValueError):
        raise ValueError(f"{name} must be numeric, got a masked array of dtype {value.dtype}") from None


def _none_rows(value):
    """A list of readings where a whole row is None (filterpy's ``z = None``: nothing read at that step) with those
    rows as NaN, the length of the other rows; rows of different lengths, or a None inside a row, stay for the checks
    (a None entry of a row is NaN by numpy's conversion of a float array; see :func:`_not_numeric`)."""
    rows = [v for v in value if v is not None]
    if len(rows) == len(value) or not rows:
        return value
    if all(isinstance(v, (list, tuple, np.ndarray)) for v in rows):
        shapes = {np.shape(v) for v in rows}
        if len(shapes) == 1:
            blank = np.full(shapes.pop(), np.nan)
            return [blank if v is None else v for v in value]
    return value


def _none_at(value, at=()):
    """The index of the first None in nested lists or tuples, else None."""
    if value is None:
        return at
    if isinstance(value, (list, tuple)):
        for i, item in enumerate(value):
            found = _none_at(item, at + (i,))
            if found is not None:
                return found
    return None


def _not_numeric(name: str, value, exc: Exception) -> str:
    """The one-line error for a value numpy cannot make a float array of: a None (use NaN), or numpy's reason."""
    where = _none_at(value) if isinstance(value, (list, tuple)) else None
    if where is not None:
        return (f"{name} holds None at index {where}: use NaN (float('nan') or np.nan) for a missing value, in an "
                "array with the same number of entries in every row")
    if "complex" in str(exc):
        return _COMPLEX.format(name=name)
    if "inhomogeneous" in str(exc) or "sequence" in str(exc):
        return (f"{name} is a ragged sequence (its rows have different lengths, or mix numbers and lists): give every "
                "row the same number of entries, NaN where a value is missing")
    return f"{name} must be numeric, got {type(value).__name__} {' '.join(reprlib.repr(value).split())}"


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


def function_output(name: str, value, shape: tuple, tail_ndim: int, input_shape: tuple | None = None, *,
                    broadcast: bool = True) -> np.ndarray:
    """The output of a user-supplied function ``name`` (e.g. ``"bearing: h"``) as floats of ``shape``, checked: real
    (complex values are refused, not cut to their real part), numeric, ending in the ``tail_ndim`` axes of ``shape``
    exactly and with leading axes that broadcast to its leading ones (a constant output may drop the run axes).
    ``input_shape``: the shape the function was called with, named in the error. ``broadcast=False``: return a
    valid output as it came (without its broadcast to ``shape``)."""
    called = f" for input of shape {input_shape}" if input_shape is not None else ""
    if _is_complex(value):
        raise ValueError(f"{name} returned complex values{called}: it must return real numbers (the imaginary part "
                         "would be dropped)")
    try:
        arr = np.asarray(value, dtype=float)
    except (TypeError, ValueError):
        raise ValueError(f"{name} returned {type(value).__name__}{called}, not an array of real numbers of shape "
                         f"{shape}") from None
    tail = tuple(shape[len(shape) - tail_ndim:])
    if arr.ndim == 0 and tail == (1,):           # a scalar for one component (m = 1): unambiguous
        arr = arr.reshape(1)
    ok = arr.ndim >= tail_ndim and arr.shape[arr.ndim - tail_ndim:] == tail and arr.ndim <= len(shape)
    if ok and arr.shape != tuple(shape):
        try:
            ok = np.broadcast_shapes(arr.shape, shape) == tuple(shape)
        except ValueError:
            ok = False
    if not ok:
        raise ValueError(f"{name} returned shape {arr.shape}{called}; it must return shape {tuple(shape)} (ending in "
                         f"{tail})")
    return arr if arr.shape == tuple(shape) or not broadcast else np.broadcast_to(arr, shape)


def call_user(fn, args: tuple, mismatch):
    """``fn(*args)`` for a user-supplied function. A function whose signature cannot take ``args`` (a peer library's
    form, e.g. filterpy's ``fx(x, dt)`` or ``h(x, *hx_args)``) is a ``ValueError`` of one line, ``mismatch(exc)``;
    a TypeError raised inside a function that does take them reaches the caller unchanged."""
    try:
        return fn(*args)
    except TypeError as exc:
        try:
            inspect.signature(fn).bind(*args)
        except TypeError:
            raise ValueError(mismatch(exc)) from None
        except ValueError:          # no signature to inspect (a builtin): the function's own error
            pass
        raise
