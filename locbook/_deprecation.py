"""The library's deprecation machinery: an old call form keeps working for one release, with one
``DeprecationWarning`` line naming the new form (attributed to the caller's line), then the same result.

- One spelling of a source's literal form: the keyword ``variant=``, the default ``"corrected"``, and
  ``"literal_<source>"`` for an equation as its source prints it (flagged). The old keywords (``form=``,
  ``weights=``) and values (``"correct"``, ``"standard"``, ``"ozkaya_printed"``) are accepted for one release
  (:func:`check_variant`, :func:`renamed_keyword`, :func:`old_keyword`).
- One argument convention: readings first, then the model, then keyword-only options, ``rng`` keyword-only. A public
  function whose signature changed is decorated with :func:`old_form` (any old form: a detector gives the new call's
  arguments) or :func:`keyword_rng` (``rng`` was positional). The wrapper is one more frame between the user and the
  function: a warning the function emits with a fixed ``stacklevel`` counts it out with :func:`past_wrappers`.
"""
from __future__ import annotations

import functools
import inspect
import sys
import warnings

import numpy as np

from ._validate import check_choice

__all__ = ["RENAMED_CRLB_FORMS", "RENAMED_KF_VARIANTS", "warn_deprecated", "check_variant",
           "renamed_keyword", "old_keyword", "old_form", "keyword_rng", "past_wrappers", "renamed_constants",
           "renamed_names"]

#: the bounds' earlier ``form=`` values and their variants (:data:`locbook.bounds.crlb.CRLB_VARIANTS`)
RENAMED_CRLB_FORMS = {"correct": "corrected", "ozkaya_printed": "literal_ozkaya2011"}
#: the Kalman filter's earlier ``variant=`` value (:data:`locbook.tracking.kalman.KF_VARIANTS`)
RENAMED_KF_VARIANTS = {"standard": "corrected"}


def warn_deprecated(old: str, new: str, *, skip=()) -> None:
    """The one ``DeprecationWarning`` ``"<old> is deprecated: use <new>"``, attributed to the first frame outside this
    module and the modules named in ``skip`` (the caller of the deprecated form)."""
    skip = {__name__, *skip}
    level, frame = 2, sys._getframe(1)
    while frame is not None and frame.f_globals.get("__name__") in skip:
        # warnings.warn does not count the import machinery's frames (an old module's import runs through them)
        internal = "importlib" in frame.f_code.co_filename and "_bootstrap" in frame.f_code.co_filename
        level, frame = level + (not internal), frame.f_back
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


def old_form(old_call):
    """Decorator of a public function whose signature changed (the new form, the one :func:`inspect.signature` shows,
    which follows ``__wrapped__``): ``old_call(function, args, kwargs)`` is None for a call in the new form, else
    ``(old, new, args, kwargs)``: the deprecated form and the one to use, named in one ``DeprecationWarning`` line
    attributed to the caller's line, and the same call's arguments in the new form (so the same numbers); or
    ``(old, new, run)`` where the old form is not a call of the new one: ``run(function)`` gives its result."""
    def wrap(function):
        @functools.wraps(function)
        def call(*args, **kwargs):
            old = old_call(function, args, kwargs)
            if old is None:
                return function(*args, **kwargs)
            if len(old) == 3:
                form, use, run = old
                warn_deprecated(form, use)
                return run(function)
            form, use, args, kwargs = old
            warn_deprecated(form, use)
            return function(*args, **kwargs)
        return call
    return wrap


def keyword_rng(index: int, *after: str):
    """:func:`old_form` of a function that took ``rng`` positionally in an earlier form, at position ``index`` (counting
    ``self`` for a method), followed by the positional parameters ``after``, all keyword-only now (``f(..., *, rng,
    ...)``). A call with more than ``index`` positional arguments is the old form: its argument ``index`` is ``rng``
    and the next ones are ``after``'s, passed by name; giving one of them twice is a TypeError, as it was. A value
    there that is no random generator (e.g. ``resample(weights, "multinomial")``) is a TypeError naming the new form.
    """
    def old_call(function, args, kwargs):
        if len(args) <= index:
            return None
        who = function.__qualname__
        names = [p.name for p in inspect.signature(function).parameters.values()
                 if p.kind in (p.POSITIONAL_ONLY, p.POSITIONAL_OR_KEYWORD)][:index]
        lead = [n for n in names if n != "self"]
        if not isinstance(args[index], (np.random.Generator, np.random.RandomState)):
            given = ", ".join([*lead, "rng=...", *(f"{name}=..." for name in after)])
            raise TypeError(f"{who}() takes {len(lead)} positional argument{'s' * (len(lead) != 1)} "
                            f"({', '.join(lead)}), got {len(args) - len(names) + len(lead)}: rng and the options are "
                            f"keyword-only: {who}({given})")
        moved = dict(zip(after, args[index + 1:]))
        if len(args) > index + 1 + len(after):
            raise TypeError(f"{who}() takes at most {index + 1 + len(after)} positional arguments in its deprecated "
                            f"form ({len(args)} given)")
        for name in ("rng", *moved):
            if name in kwargs:
                raise TypeError(f"{who}() got multiple values for argument {name!r}")
        old = ", ".join([*lead, "rng", *moved])
        new = ", ".join([*lead, "rng=rng", *(f"{name}={name}" for name in moved)])
        return f"{who}({old})", f"{who}({new})", args[:index], {"rng": args[index], **moved, **kwargs}
    return old_form(old_call)


def past_wrappers(stacklevel: int) -> int:
    """``stacklevel`` for a ``warnings.warn`` in the caller of this function, counted from there, plus one for every
    frame of this module's wrappers (:func:`old_form`) among the frames it counts: a warning with a fixed count of
    frames keeps pointing at the user's line when the public function it counts through is decorated here."""
    frame, level, extra = sys._getframe(1), 1, 0
    while frame is not None and level < stacklevel + extra:
        frame, level = frame.f_back, level + 1
        if frame is not None and frame.f_globals.get("__name__") == __name__:
            extra += 1
    return stacklevel + extra


def renamed_constants(module: str, renamed: dict):
    """A module ``__getattr__`` that gives each old constant name of ``renamed`` (``{old: (new name, value)}``) for one
    release, with a DeprecationWarning naming the new one."""
    def __getattr__(name):
        if name in renamed:
            new, value = renamed[name]
            warnings.warn(f"{module}.{name} is deprecated: use {module}.{new}", DeprecationWarning, stacklevel=2)
            return value
        raise AttributeError(f"module {module!r} has no attribute {name!r}")
    return __getattr__


def renamed_names(module: str, renamed: dict, fallback=None):
    """A module ``__getattr__`` that gives each old name of ``renamed`` (``{old: new}``, a function, class or
    constant of the module ``module``) for one release, with a DeprecationWarning naming the new one (attributed to
    the line that asks for it); ``fallback(name)`` answers any other name (an ``AttributeError`` without one)."""
    def __getattr__(name):
        if name in renamed:
            new = renamed[name]
            warn_deprecated(f"{module}.{name}", f"{module}.{new}")
            return getattr(sys.modules[module], new)
        if fallback is not None:
            return fallback(name)
        raise AttributeError(f"module {module!r} has no attribute {name!r}")
    return __getattr__
