"""Your own method beside the battery: a static estimator or a tracker registered as ``module:function``,
run by the measured-data protocol (:mod:`locbook.scenarios.measured`) on the same epochs as the battery's methods
(:mod:`locbook.battery`) and scored by the same rows, bound and figures, under the name you give it.

A method is registered in the data set's manifest (``[[method]]`` tables: ``name``, ``function``, ``kind``;
:mod:`locbook.data.dataset`) or on the command line (``locbook run --data DIR --method NAME=SPEC`` for a static
method, ``--tracker NAME=SPEC`` for a tracker). ``SPEC`` is ``package.module:function`` (importable) or
``path/to/file.py:function`` (a manifest's relative to its folder and inside it, a command line's relative to the
current folder). The function is called with one :class:`MethodInput` (the documented signature) and returns
positions ``(E, 2)``, optionally with covariances: :func:`check_output` is the rule its output meets.

A function that raises, or whose output breaks the rule, fails alone: :func:`run_method` returns a
:class:`MethodFailure` (its one-line error and its own traceback, the user's frames without locbook's) and every
other method's numbers are unchanged (each method's bootstrap stream is keyed by its name). The code a method runs
is recorded in the report's cache record (:func:`locbook._datalog.record_read`: the file's content hash), so editing
it reruns the reports that use it.
"""
from __future__ import annotations

import hashlib
import importlib
import os
import re
import sys
import traceback
import types
from dataclasses import dataclass
from pathlib import Path
from typing import TYPE_CHECKING, Any

import numpy as np

from .errors import ParameterError

if TYPE_CHECKING:                      # pragma: no cover
    from .models.channel import PathLossModel
    from .models.rss import RssModel

__all__ = ["MethodInput", "UserMethod", "MethodFailure", "METHOD_KINDS", "MAX_METHOD_NAME_CHARS",
           "RESERVED_METHOD_NAMES", "method_name_problem", "parse_method_option", "registered_methods",
           "check_output", "run_method", "user_traceback", "check_import"]

#: the kinds of a user method: a static estimator (every scored epoch on its own) or a tracker (each track in
#: time order)
METHOD_KINDS = ("static", "tracker")
#: the longest method name (it names rows, legends and bootstrap streams)
MAX_METHOD_NAME_CHARS = 64
#: names the reports use for themselves (the maps' bound panel, the pooled rows, the truth)
RESERVED_METHOD_NAMES = ("crlb", "pcrlb", "bound", "truth", "pooled")
_NAME = re.compile(r"[A-Za-z][A-Za-z0-9_-]*")
_IDENT = r"[A-Za-z_][A-Za-z0-9_]*"
_DOTTED = re.compile(rf"{_IDENT}(\.{_IDENT})*")
_SPEC_HELP = "package.module:function (importable) or path/to/file.py:function"


@dataclass(frozen=True, kw_only=True)
class MethodInput:
    """What a user method is called with: the documented signature of ``function(inp: MethodInput)``.

    A **static** method (``kind = "static"`` in the manifest, ``--method`` on the command line) is called once per
    scored recording (every static recording, and every track with a true position per epoch, on those epochs); each
    epoch is located on its own, as the battery's static methods do. A **tracker** (``kind = "tracker"``,
    ``--tracker``) is called once per track, its epochs in time order on the track's clock (a tick without readings
    is all NaN: predict through it). Every array is a read-only copy.

    Attributes
    ----------
    rss_dbm : ndarray, shape (E, m)
        The readings (dBm) of the ``E`` epochs at the ``m`` anchors, NaN where the anchor did not hear the tag; each
        device's receiver offset already removed (as for every method of the battery).
    time_s : ndarray, shape (E,)
        The epochs' times (s), increasing.
    recording : str
        The recording's name in the manifest.
    kind : str
        The recording's role, ``"static"`` or ``"track"``.
    tag_height_m : float or None
        The tag's known height (m), or None for a 2-D data set.
    anchors_m : ndarray, shape (m, 2) or (m, 3)
        The anchors (with their heights for a 3-D data set), in the order of the columns.
    channel : PathLossModel
        The fitted :class:`~locbook.models.channel.PathLossModel` (per-anchor ``P_0``, ``n`` and shadowing sigma,
        fitted on the calibration recordings only).
    model : RssModel
        The one :class:`~locbook.models.rss.RssModel` built from it, ``RssModel(anchors_m, channel,
        tag_height_m=...)``, whose ``mean_rss_dbm`` and ``log_likelihood`` the battery's likelihood methods evaluate.
    outline_m : ndarray, shape (V, 2)
        The floor outline (its vertices, m).
    rng : numpy.random.Generator or None
        A generator of your own, keyed by the data set, the recording and the method's name (a randomised method
        draws the same numbers on every page of a run).
    range_m, range_std_m : ndarray, shape (E, m), or None
        Where the recording has ranges (``ranges = "FILE"``, :mod:`locbook.data.ranges`): each epoch's range to each
        anchor (m; NaN = not measured) and its sigma (the reported std of the window's mean, else the data set's
        fitted rule; NaN where there is no range), on the same epochs as ``rss_dbm``; None without ranges.

    Notes
    -----
    The function returns the positions ``(E, 2)`` in metres (a NaN row: no fix at that epoch; a list or any
    array-like is taken), or the tuple ``(positions (E, 2), covariances (E, 2, 2))`` with a symmetric positive
    semi-definite covariance (m^2) per fix. Anything else (another shape, inf, half a position, complex values, None,
    text) fails the method with one line naming it and what it returned (:func:`check_output`).

    Examples
    --------
    A static method that puts each epoch at the anchor heard loudest, called as the protocol calls it:

    >>> import numpy as np
    >>> from locbook import MethodInput
    >>> from locbook.models.channel import PathLossModel
    >>> from locbook.models.rss import RssModel
    >>> from locbook.user_methods import check_output
    >>> anchors_m = np.array([[0.0, 0.0], [10.0, 0.0], [0.0, 10.0], [10.0, 10.0]])
    >>> channel = PathLossModel(-40.0, 2.0, 4.0)        # P_0 at 1 m (dBm), exponent n, shadowing sigma (dB)
    >>> inp = MethodInput(rss_dbm=np.array([[-47.0, -59.3, -58.1, -61.6], [-61.6, -58.1, np.nan, -47.0]]),
    ...                   time_s=np.array([0.0, 1.0]), recording="walk", kind="static", tag_height_m=None,
    ...                   anchors_m=anchors_m, channel=channel, model=RssModel(anchors_m, channel),
    ...                   outline_m=np.array([[0.0, 0.0], [10.0, 0.0], [10.0, 10.0], [0.0, 10.0]]))
    >>> def strongest_anchor(inp):
    ...     return inp.anchors_m[np.nanargmax(inp.rss_dbm, axis=1)]     # NaN: an anchor not heard
    >>> positions, covariances = check_output("strongest", strongest_anchor(inp), inp.n_epochs)
    >>> print(positions)
    [[ 0.  0.]
     [10. 10.]]
    >>> print(covariances)
    None
    """

    rss_dbm: np.ndarray
    time_s: np.ndarray
    recording: str
    kind: str
    tag_height_m: float | None
    anchors_m: np.ndarray
    channel: "PathLossModel"
    model: "RssModel"
    outline_m: np.ndarray
    rng: np.random.Generator | None = None
    range_m: np.ndarray | None = None
    range_std_m: np.ndarray | None = None

    @property
    def n_epochs(self) -> int:
        return int(self.rss_dbm.shape[0])


@dataclass(frozen=True)
class MethodFailure:
    """A user method that did not give positions: its name, kind, :attr:`UserMethod.described`, the recording it
    failed on ("" when it failed to import), the one-line ``error`` and the ``traceback`` (its own frames)."""

    name: str
    kind: str
    function: str
    recording: str
    error: str
    traceback: str

    def line(self) -> str:
        where = f" on {self.recording}" if self.recording else ""
        return f"user method {self.name!r} ({self.kind}, {self.function}) failed{where}: {self.error}"


@dataclass(frozen=True)
class UserMethod:
    """One registered method: a function of your own and how the reports name it.

    :meth:`parse` checks a spec; :meth:`load` imports the function; :func:`run_method` calls it on each
    :class:`MethodInput`.

    Attributes
    ----------
    name : str
        Its rows' and legends' name.
    kind : str
        One of :data:`METHOD_KINDS` (``"static"`` or ``"tracker"``).
    function : str
        The spec as given, ``package.module:function`` or ``path/to/file.py:function``.
    module : str or None
        The importable module of a module spec.
    path : pathlib.Path or None
        The absolute path of a file spec's file.
    attribute : str
        The function's name in it, dotted for an attribute of an attribute.
    source : str
        ``"manifest"`` or ``"command line"``.

    Examples
    --------
    >>> from locbook import UserMethod
    >>> m = UserMethod.parse("strongest", "my_methods:strongest_anchor", "static", base=".")
    >>> m.module, m.attribute, m.path
    ('my_methods', 'strongest_anchor', None)
    >>> m.option()
    'strongest=my_methods:strongest_anchor'
    >>> m.described
    'user method my_methods:strongest_anchor'

    A battery method's name is refused, in one line:

    >>> UserMethod.parse("lls", "my_methods:strongest_anchor", "static", base=".")  # doctest: +ELLIPSIS
    Traceback (most recent call last):
    ...
    locbook.errors.ParameterError: method name 'lls' is a battery method's (...): give yours another name
    """

    name: str
    kind: str
    function: str
    module: str | None
    path: Path | None
    attribute: str
    source: str = "command line"

    @classmethod
    def parse(cls, name, spec, kind, *, base, source: str = "command line", where: str = "") -> "UserMethod":
        """A method from its name, spec and kind, or one ParameterError line (``where`` opens it) naming what is
        wrong. A file spec is taken relative to ``base`` (a folder) and must name an existing ``.py`` file."""
        problem = method_name_problem(name)
        if problem:
            raise ParameterError(f"{where}{problem}")
        if kind not in METHOD_KINDS:
            raise ParameterError(f"{where}method {name!r}: kind must be one of {METHOD_KINDS}, got {_shown(kind)}")
        if not isinstance(spec, str) or ":" not in spec.strip():
            raise ParameterError(f"{where}method {name!r}: function must be {_SPEC_HELP}, got {_shown(spec)}")
        spec = spec.strip()
        target, _, attribute = spec.rpartition(":")
        if not _DOTTED.fullmatch(attribute):
            raise ParameterError(f"{where}method {name!r}: {_shown(attribute)} after the last ':' of {spec!r} is no "
                                 f"Python name; function must be {_SPEC_HELP}")
        if target.endswith(".py"):
            try:
                path = Path(target).expanduser()
                path = path if path.is_absolute() else Path(base) / path
                found = path.is_file()
                missing = not path.exists()
            except (OSError, ValueError, RuntimeError) as exc:      # a NUL byte, a name too long, no home folder
                raise ParameterError(f"{where}method {name!r}: {_shown(target)} is not a usable file name "
                                     f"({type(exc).__name__}: {' '.join(str(exc).split())})") from None
            if not found:
                raise ParameterError(f"{where}method {name!r}: no file {target!r} "
                                     f"({'not found' if missing else 'not a regular file'} at {path}); "
                                     f"function must be {_SPEC_HELP}")
            return cls(name, kind, spec, None, Path(os.path.realpath(path)), attribute, source)
        if not _DOTTED.fullmatch(target):
            raise ParameterError(f"{where}method {name!r}: {_shown(target)} is neither a .py file nor a dotted "
                                 f"module name; function must be {_SPEC_HELP}")
        return cls(name, kind, spec, target, None, attribute, source)

    @property
    def described(self) -> str:
        """How the reports name it: ``user method <spec>``, with the file's content hash (its first 12 digits) for a
        file spec, the file absolute for a command line's (a manifest's relative to the data set's folder)."""
        if self.path is None:
            return f"user method {self.function}"
        shown = self.function if self.source == "manifest" else f"{self.path}:{self.attribute}"
        digest = self.sha256()
        return f"user method {shown}" + (f" (sha256 {digest[:12]})" if digest else "")

    def sha256(self) -> str:
        """The content hash of a file spec's file now ('' for a module spec, or a file that cannot be read)."""
        if self.path is None:
            return ""
        try:
            return hashlib.sha256(self.path.read_bytes()).hexdigest()
        except OSError:
            return ""

    def option(self) -> str:
        """The method as a notebook parameter's entry, ``NAME=SPEC`` with a file absolute (the kernel runs in the
        notebook's folder)."""
        return f"{self.name}={self.function if self.path is None else f'{self.path}:{self.attribute}'}"

    def load(self):
        """The function: its module imported (a file spec: the file's bytes executed as a module of their own, its
        folder on ``sys.path`` while they run, so it may import modules beside it), and what ran recorded for the
        report's cache record (:func:`locbook._datalog.record_read`). Raises what the import raises, or a TypeError
        line when the name is not a function."""
        from ._datalog import record_read
        if self.path is not None:
            source = self.path.read_bytes()
            digest = hashlib.sha256(source).hexdigest()
            record_read(str(self.path), digest)
            stem = re.sub(r"\W", "_", self.path.stem)
            module_name = f"locbook_user_method_{digest[:16]}_{stem}"
            module = sys.modules.get(module_name)
            if module is None:
                module = types.ModuleType(module_name)
                module.__file__ = str(self.path)
                code = compile(source, str(self.path), "exec")
                sys.modules[module_name] = module
                folder = str(self.path.parent)
                sys.path.insert(0, folder)
                try:
                    exec(code, module.__dict__)
                except BaseException:
                    sys.modules.pop(module_name, None)
                    raise
                finally:
                    try:
                        sys.path.remove(folder)
                    except ValueError:
                        pass
        else:
            module = importlib.import_module(self.module)
            file = getattr(module, "__file__", None)
            if file and os.path.isfile(file):
                real = os.path.realpath(file)
                try:
                    with open(real, "rb") as fh:
                        record_read(real, hashlib.sha256(fh.read()).hexdigest())
                except OSError:
                    pass
        obj: Any = module
        for part in self.attribute.split("."):
            if not hasattr(obj, part):
                where = self.path.name if self.path is not None else self.module
                raise AttributeError(f"{where} has no {part!r} (method {self.name!r}, {self.function})")
            obj = getattr(obj, part)
        if not callable(obj):
            raise TypeError(f"{self.function} is not a function: {self.attribute} is of type {type(obj).__name__} "
                            f"(method {self.name!r})")
        return obj


def _shown(value) -> str:
    text = repr(value)
    return text if len(text) <= 80 else text[:77] + "..."


def method_name_problem(name) -> str:
    """``""`` if ``name`` may name a user method, else why not (one line): letters, digits, ``_`` and ``-``, starting
    with a letter, at most :data:`MAX_METHOD_NAME_CHARS` characters, and no battery method's name nor one of
    :data:`RESERVED_METHOD_NAMES` (compared without case)."""
    if not isinstance(name, str) or not _NAME.fullmatch(name) or len(name) > MAX_METHOD_NAME_CHARS:
        return (f"method name {_shown(name)} must be letters, digits, '_' and '-', starting with a letter, at most "
                f"{MAX_METHOD_NAME_CHARS} characters")
    # lazy for start-up time, not for a circle: the battery's modules take seconds to import (numba), and a data
    # set's manifest is checked without running any method
    from .battery import STATIC_METHODS, TRACKERS
    from .inertial_trackers import FUSION_TRACKERS
    from .scenarios.measured_ranges import RANGE_METHOD_NAMES
    battery = (*STATIC_METHODS, *TRACKERS, *RANGE_METHOD_NAMES, *FUSION_TRACKERS)
    if name.lower() in battery:
        return (f"method name {name!r} is a battery method's ({', '.join(battery)}): give yours another name")
    if name.lower() in RESERVED_METHOD_NAMES:
        return (f"method name {name!r} is reserved (the reports use {', '.join(RESERVED_METHOD_NAMES)}): give yours "
                "another")
    return ""


def parse_method_option(text: str, kind: str, *, base=None) -> UserMethod:
    """A command line's ``NAME=SPEC`` (``--method`` for a static method, ``--tracker`` for a tracker; a file
    relative to ``base``, default the current folder), or one ParameterError line."""
    flag = "--method" if kind == "static" else "--tracker"
    name, sep, spec = str(text).partition("=")
    if not sep or not name.strip():
        raise ParameterError(f"{flag} expects NAME=SPEC with SPEC {_SPEC_HELP}, got {text!r}")
    return UserMethod.parse(name.strip(), spec, kind, base=Path.cwd() if base is None else base,
                            where=f"{flag} {text}: ")


def registered_methods(data=None, *, methods=(), trackers=(), base=None) -> tuple[UserMethod, ...]:
    """Every user method of a run: the data set's manifest ones (``data.methods``), then the command line's
    ``methods`` (static) and ``trackers`` (``NAME=SPEC`` texts or :class:`UserMethod`), in that order. A name given
    twice is one ParameterError line."""
    out = list(getattr(data, "methods", ()) or ())
    for kind, given in (("static", methods), ("tracker", trackers)):
        for item in given or ():
            out.append(item if isinstance(item, UserMethod) else parse_method_option(item, kind, base=base))
    seen: dict[str, UserMethod] = {}
    for m in out:
        other = next((o for o in seen.values() if o.name.lower() == m.name.lower()), None)
        if other is not None:
            raise ParameterError(f"method name {m.name!r} is given twice ({other.kind}, {other.source}: "
                                 f"{other.function}; {m.kind}, {m.source}: {m.function}): give each its own name")
        seen[m.name] = m
    return tuple(out)


# -- the output rule ---------------------------------------------------------------------------------------------

class MethodOutputError(ValueError):
    """A user method's output that breaks the rule of :func:`check_output`."""


def _what(value) -> str:
    if value is None:
        return "None"
    if isinstance(value, (str, bytes)):
        return f"a {type(value).__name__} ({_shown(value)})"
    shape = getattr(value, "shape", None)
    if shape is not None:
        return f"a {type(value).__name__} of shape {tuple(shape)}"
    return f"a {type(value).__name__}"


def _ndim(value) -> int:
    try:
        return int(np.ndim(value))
    except (ValueError, TypeError):      # a ragged sequence
        return -1


def _array(value, what: str):
    """``value`` as a real float array, or the reason it is none."""
    if value is None or isinstance(value, (str, bytes, dict, set, frozenset)) or callable(value):
        raise MethodOutputError(f"{what} {_what(value)}")
    try:
        a = np.asarray(value)
    except (ValueError, TypeError) as exc:
        raise MethodOutputError(f"{what} {_what(value)} that is no array ({' '.join(str(exc).split())})") from None
    if a.dtype.kind == "c":
        raise MethodOutputError(f"{what} complex values (dtype {a.dtype})")
    if a.dtype.kind not in "fiu":
        kind = "bool" if a.dtype.kind == "b" else f"dtype {a.dtype}"
        raise MethodOutputError(f"{what} {_what(value)} of {kind} (ragged, or not numbers)" if a.dtype.kind == "O"
                                else f"{what} {_what(value)} of {kind}")
    return a.astype(float)


def check_output(name: str, output, n_epochs: int) -> tuple[np.ndarray, np.ndarray | None]:
    """``(positions (E, 2), covariances (E, 2, 2) or None)`` from what user method ``name`` returned for ``E =
    n_epochs`` epochs, or a :class:`MethodOutputError` line naming it and what it returned. The rule: positions
    ``(E, 2)`` (any array-like of real numbers; a row of NaN is no fix; inf, or one coordinate without the other, is
    refused), or the tuple ``(positions, covariances)`` with covariances ``(E, 2, 2)``, finite, symmetric and
    positive semi-definite at every fix (NaN allowed where there is no fix)."""
    head = f"user method {name!r} returned"
    want = (f"; it returns positions ({n_epochs}, 2) (E = {n_epochs} epochs, NaN rows = no fix), or (positions, "
            f"covariances ({n_epochs}, 2, 2)) (locbook.MethodInput)")
    cov = None
    try:
        if isinstance(output, tuple) and len(output) == 2 and _ndim(output[0]) == 2 and output[1] is not None \
                and _ndim(output[1]) != 1:
            positions, cov = output
        else:
            positions = output
        p = _array(positions, head + (" positions as" if cov is not None else ""))
        if p.shape != (n_epochs, 2):
            raise MethodOutputError(f"{head} positions of shape {p.shape}")
        if np.isinf(p).any():
            i = int(np.flatnonzero(np.isinf(p).any(axis=1))[0])
            raise MethodOutputError(f"{head} inf at epoch {i} ({p[i].tolist()})")
        half = np.isnan(p).any(axis=1) & ~np.isnan(p).all(axis=1)
        if half.any():
            i = int(np.flatnonzero(half)[0])
            raise MethodOutputError(f"{head} half a position at epoch {i} ({p[i].tolist()}): NaN in one coordinate "
                                    "only (a NaN row is no fix)")
        if cov is None:
            return p, None
        c = _array(cov, head + " covariances as")
        if c.shape != (n_epochs, 2, 2):
            raise MethodOutputError(f"{head} covariances of shape {c.shape}")
        fixed = np.isfinite(p).all(axis=1)
        bad = fixed & ~np.isfinite(c).all(axis=(1, 2))
        if bad.any():
            i = int(np.flatnonzero(bad)[0])
            raise MethodOutputError(f"{head} a non-finite covariance at epoch {i} ({c[i].tolist()}), where it "
                                    "gives a fix")
        if fixed.any():
            cf = c[fixed]
            scale = np.maximum(np.abs(cf).max(axis=(1, 2)), 1e-300)
            asym = np.abs(cf - np.swapaxes(cf, 1, 2)).max(axis=(1, 2)) > 1e-9 * scale
            if asym.any():
                i = int(np.flatnonzero(fixed)[np.flatnonzero(asym)[0]])
                raise MethodOutputError(f"{head} a covariance that is not symmetric at epoch {i} ({c[i].tolist()})")
            low = np.linalg.eigvalsh(0.5 * (cf + np.swapaxes(cf, 1, 2)))[:, 0] < -1e-9 * scale
            if low.any():
                i = int(np.flatnonzero(fixed)[np.flatnonzero(low)[0]])
                raise MethodOutputError(f"{head} a covariance that is not positive semi-definite at epoch {i} "
                                        f"({c[i].tolist()})")
        return p, c
    except MethodOutputError as exc:
        raise MethodOutputError(str(exc) + want) from None


# -- running one -------------------------------------------------------------------------------------------------

def _locbook_frame(filename: str) -> bool:
    package = os.path.dirname(os.path.abspath(__file__)) + os.sep
    return filename.startswith(package) or filename.startswith("<frozen importlib")


def user_traceback(exc: BaseException) -> str:
    """The traceback of ``exc`` from the first frame outside locbook (and outside the import machinery): the user's
    own frames and what they called, without locbook's frames that called the user's code."""
    frames = traceback.extract_tb(exc.__traceback__)
    first = next((i for i, f in enumerate(frames) if not _locbook_frame(f.filename)), len(frames))
    lines = traceback.format_exception_only(type(exc), exc)
    kept = frames[first:]
    if not kept:
        return "".join(lines).rstrip("\n")
    return ("Traceback (most recent call last):\n" + "".join(traceback.StackSummary.from_list(kept).format())
            + "".join(lines)).rstrip("\n")


def _one_line(exc: BaseException) -> str:
    text = " ".join(str(exc).split())
    return f"{type(exc).__name__}: {text}" if text else type(exc).__name__


def _failure(method: UserMethod, recording: str, exc: BaseException) -> MethodFailure:
    # an output refused: its message without the method's name, which the failure's line names once
    error = " ".join(str(exc).split()).removeprefix(f"user method {method.name!r} ") \
        if isinstance(exc, MethodOutputError) else _one_line(exc)
    trace = "" if isinstance(exc, MethodOutputError) else user_traceback(exc)
    return MethodFailure(method.name, method.kind, method.described, recording, error, trace)


def check_import(method: UserMethod) -> str:
    """``""`` if the method's function imports, else the one-line reason (``locbook data check``)."""
    try:
        method.load()
    except (Exception, SystemExit) as exc:
        return _one_line(exc)
    return ""


def run_method(method: UserMethod, inputs: dict) -> dict | MethodFailure:
    """Run ``method`` on each :class:`MethodInput` of ``inputs`` (``{recording: input}``, in order): ``{recording:
    (positions (E, 2), covariances or None)}``, or the :class:`MethodFailure` of the first recording it raised on
    or returned what :func:`check_output` refuses (an import that fails is a failure too, on no recording)."""
    try:
        fn = method.load()
    except (Exception, SystemExit) as exc:
        return _failure(method, "", exc)
    out = {}
    for recording, inp in inputs.items():
        try:
            out[recording] = check_output(method.name, fn(inp), inp.n_epochs)
        except (Exception, SystemExit) as exc:
            return _failure(method, recording, exc)
    return out


def frozen(a, dtype=float) -> np.ndarray:
    """A read-only copy of ``a`` (what a :class:`MethodInput` holds)."""
    out = np.array(a, dtype=dtype, copy=True)
    out.setflags(write=False)
    return out
