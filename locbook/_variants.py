"""One spelling of a source's literal form across the library (issue 47): the keyword ``variant=``, the default
``"corrected"``, and ``"literal_<source>"`` for an equation as its source prints it (flagged). The old keywords
(``form=``, ``weights=``) and values (``"correct"``, ``"standard"``, ``"ozkaya_printed"``) are accepted for one
release: a ``DeprecationWarning`` naming the new spelling (attributed to the caller's line), then the same result.
"""
from __future__ import annotations

import functools
import sys
import warnings

from ._validate import check_choice

__all__ = ["RENAMED_CRLB_FORMS", "RENAMED_KF_VARIANTS", "warn_deprecated", "check_variant",
           "renamed_keyword", "old_keyword"]

#: the bounds' ``form=`` values before issue 47 and their variants (:data:`locbook.bounds.crlb.CRLB_VARIANTS`)
RENAMED_CRLB_FORMS = {"correct": "corrected", "ozkaya_printed": "literal_ozkaya2011"}
#: the Kalman filter's ``variant=`` value before issue 47 (:data:`locbook.tracking.kalman.KF_VARIANTS`)
RENAMED_KF_VARIANTS = {"standard": "corrected"}


def warn_deprecated(old: str, new: str, *, skip=()) -> None:
    """The one ``DeprecationWarning`` ``"<old> is deprecated: use <new>"``, attributed to the first frame outside this
    module and the modules named in ``skip`` (the caller of the deprecated form)."""
    skip = {__name__, *skip}
    level, frame = 2, sys._getframe(1)
    while frame is not None and frame.f_globals.get("__name__") in skip:
        level, frame = level + 1, frame.f_back
    warnings.warn(f"{old} is deprecated: use {new}", DeprecationWarning, stacklevel=level)


def check_variant(value, choices, *, where: str, renamed=None, name: str = "variant"):
    """``value`` checked against ``choices`` (a ValueError naming ``name`` and the choices); an old value
    (``renamed``: old -> new) gives a ``DeprecationWarning`` naming ``where(name=new)``, attributed to the caller of
    the function that asks (the first frame outside its module), and then the new value."""
    if renamed and isinstance(value, str) and value in renamed:
        new = renamed[value]
        warn_deprecated(f"{where}({name}={value!r})", f"{where}({name}={new!r})",
                        skip=(sys._getframe(1).f_globals.get("__name__"),))
        value = new
    check_choice(name, value, choices)
    return value


def renamed_keyword(old: str, new: str, values=None):
    """Decorator: the function's keyword ``old`` is its keyword ``new`` for one release, with a
    ``DeprecationWarning`` naming the new spelling (``values``: old values -> new ones, mapped with it); giving both
    is a TypeError. The function keeps its own signature (``inspect.signature`` follows ``__wrapped__``)."""
    values = dict(values or {})

    def wrap(fn):
        @functools.wraps(fn)
        def call(*args, **kwargs):
            if old in kwargs:
                if new in kwargs:
                    raise TypeError(f"{fn.__name__}() got {old}= (deprecated) and {new}=: give {new}= only")
                value = kwargs.pop(old)
                mapped = values.get(value, value) if isinstance(value, str) else value
                warn_deprecated(f"{fn.__name__}({old}={value!r})", f"{fn.__name__}({new}={mapped!r})")
                kwargs[new] = mapped
            return fn(*args, **kwargs)
        return call
    return wrap


def old_keyword(where: str, old: str, old_value, new: str, new_value, default):
    """The value of keyword ``new`` when the function also takes its old name ``old`` in its signature (default None,
    for one release): ``new_value``, or a given ``old_value`` after a ``DeprecationWarning`` naming ``where(new=...)``
    (attributed to the caller of the function that asks); both given is a TypeError. For a function whose frames are
    counted by a warning of its own (a decorator would add one)."""
    if old_value is None:
        return new_value
    if new_value != default:
        raise TypeError(f"{where}() got {old}= (deprecated) and {new}=: give {new}= only")
    warn_deprecated(f"{where}({old}={old_value!r})", f"{where}({new}={old_value!r})",
                    skip=(sys._getframe(1).f_globals.get("__name__"),))
    return old_value
