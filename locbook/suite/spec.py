"""The declarative experiment list (``notebooks/experiments.toml``).

Schema::

    [documents.<key>]            # key: dogan2015, gudipati2017, palvai2008, george, ozkaya2011, measured
    title, authors, year, source  # source: where it was published (thesis, university, date), or for a data
                                  # set or our own benchmark the file in the repository that describes it

    [[experiment]]
    id = "<key>-<name>"           # prefixed by its document key
    document = "<key>"
    title, section                # section: which table/figure/section of the source
    notebook = "<path relative to the TOML file>"
    [experiment.profiles.quick]   # parameters per profile (every profile must be present)
    [experiment.profiles.full]
    [experiment.parameter_rules]  # optional: rules for this experiment's parameters (override the suite's)
    [experiment.bracket]          # optional: parameters every point of ``locbook bracket`` sets (never a scored
    parameters = { ... }          # quantity's input, never a declared interpretation), and the reason, shown with the
    reason = "..."                # bracket's findings (e.g. a notebook's own sweep of interpretations the bracket runs)
    factorial = ["a", "b"]        # optional: interpretations that interact; the bracket also runs their combinations
    largest_error_m = 9.43        # optional: the largest plausible error in metres (the area's diagonal) and
    largest_error_reason = "..."  # where the area is printed: a point whose error exceeds it is implausible
    [experiment.data_run]         # an experiment that takes a data set (a ``data`` parameter; ``locbook run --data``)
    needs = ["track"]             # the data set holds at least one of these kinds (DATA_KINDS), else the experiment
                                  # is left out of a data run (and asking for it by id is an error); without the
                                  # table it runs on every data set
    parameters = { ... }          # optional: parameters a data run sets (before -p), e.g. the benchmark's
                                  # { synthetic = false }: a data run holds the data set's scenarios only

    [parameter_rules]             # allowed values by parameter name, for every experiment declaring it
    n_runs = { ge = 2 }           # keys: ge, gt, le, lt, allow_inf, min_items, max_items (ParameterRule)

    [[study]]                     # optional: parameter studies, read by locbook.suite.study (its docstring)

Experiment ids are ``[a-z0-9-]`` only (they name folders under ``reports/``). The file is checked by its schema,
the pydantic models of :mod:`locbook.suite.spec_schema` (keys, types and the rules between them); the first broken
rule is a :class:`SuiteError` of one line naming the file, the table or experiment, the key and the value.
"""
from __future__ import annotations

import math
import tomllib
from dataclasses import dataclass, field
from pathlib import Path

from pydantic import ValidationError

from ..errors import ParameterError
from .params import NotebookParameter, ParameterRule, is_numeric_annotation, read_parameters, resolve_parameters
from .spec_schema import DATA_KINDS, DOCUMENT_KEYS, PROFILES, SuiteFile, one_line
from .spec_schema import SAFE_NAME as SAFE_NAME  # re-exported: study, bracket and the tests import it from here

__all__ = ["Suite", "Experiment", "Document", "DataRun", "PROFILES", "DOCUMENT_KEYS", "DATA_KINDS", "load_suite",
           "find_suite_file", "packaged_suite_file"]

SUITE_FILE = Path("notebooks") / "experiments.toml"

class SuiteError(ParameterError):
    """The experiment list (or a study, a bracket) is malformed; the message is one line (a value's line breaks
    are shown as ``\\n``)."""

    def __init__(self, message: str):
        super().__init__(str(message).replace("\r\n", "\\n").replace("\n", "\\n").replace("\r", "\\r"))


@dataclass(frozen=True)
class Document:
    key: str
    title: str
    authors: str
    year: str
    source: str


@dataclass(frozen=True)
class DataRun:
    """``[experiment.data_run]``: how an experiment runs on a data set. ``needs``: the kinds (:data:`DATA_KINDS`) of
    which the data set must hold at least one; ``parameters``: values a data run sets (after the profile's, before
    ``-p``)."""

    needs: tuple[str, ...]
    parameters: dict = field(default_factory=dict, hash=False)

    def missing(self, kinds) -> str:
        """'' when a data set holding ``kinds`` meets :attr:`needs`, else why not, in words ("the data set has no
        track recording")."""
        if set(self.needs) & set(kinds):
            return ""
        return "the data set has no " + " and no ".join(DATA_KINDS[k] for k in self.needs)


@dataclass(frozen=True)
class Experiment:
    id: str
    document: Document
    title: str
    section: str
    notebook: Path
    profiles: dict[str, dict] = field(hash=False)
    rules: dict[str, ParameterRule] = field(default_factory=dict, hash=False)
    #: ``[experiment.bracket]``: parameter -> value set at every bracket point, and why (empty: none)
    bracket_parameters: dict = field(default_factory=dict, hash=False)
    bracket_reason: str = ""
    #: ``[experiment.bracket] factorial``: the interpretations whose textual values the bracket also runs in combination
    bracket_factorial: tuple = ()
    #: ``[experiment.bracket] largest_error_m``: the largest plausible error (m; None: not declared), and its source
    largest_error_m: float | None = None
    largest_error_reason: str = ""
    #: ``[experiment.data_run]``: what it needs of a data set and what a data run sets (None: not declared)
    data_run: DataRun | None = None

    def declared_parameters(self) -> dict[str, NotebookParameter]:
        return read_parameters(self.notebook)

    def parameters(self, profile: str, overrides: dict[str, str] | None = None, *, data_run: bool = False) -> dict:
        """Checked parameters for a profile with ``-p`` overrides (text) applied. ``data_run``: the run has a data
        set, so the values of ``[experiment.data_run] parameters`` apply too (over the profile's, under ``-p``); a
        name the notebook does not declare fails here, as any unknown parameter does."""
        if profile not in self.profiles:
            raise SuiteError(f"experiment {self.id!r} has no profile {profile!r}")
        declared = self.declared_parameters()
        values = dict(self.profiles[profile])
        if data_run and self.data_run is not None and self.data_run.parameters:
            resolve_parameters(self.notebook, declared, self.data_run.parameters, {},
                               f"experiment {self.id!r}, [experiment.data_run] parameters", self.rules)
            values.update(self.data_run.parameters)
        return resolve_parameters(self.notebook, declared, values, overrides or {},
                                  f"experiment {self.id!r}, profile {profile!r}", self.rules)

    def unruled_numeric_parameters(self) -> list[str]:
        """Numeric parameters without a range rule (the suite's test requires none)."""
        return [p.name for p in self.declared_parameters().values()
                if is_numeric_annotation(p.annotation) and p.name not in self.rules]


@dataclass(frozen=True)
class Suite:
    path: Path
    documents: dict[str, Document]
    experiments: list[Experiment]

    @property
    def root(self) -> Path:
        """The folder holding ``notebooks/`` (the repository root in a clone)."""
        return self.path.parent.parent

    @property
    def repository(self) -> Path | None:
        """The locbook source tree the suite belongs to (a clone: ``notebooks/`` beside ``locbook/``), or None for
        the suite shipped inside an installed package or a copy made by ``locbook notebooks``."""
        root = self.root
        return root if (self.path.parent.name == "notebooks" and (root / "locbook" / "__init__.py").is_file()) else None

    def default_reports(self) -> Path:
        """Where reports go without ``--reports``: ``<repository>/reports`` in a clone, else ``./reports``."""
        return (self.repository or Path.cwd()) / "reports"

    def select(self, ids: list[str]) -> list[Experiment]:
        """Experiments by exact id or by document key / id prefix (``george`` selects all of its experiments)."""
        if not ids:
            return list(self.experiments)
        chosen, unknown = [], []
        for wanted in ids:
            hits = [e for e in self.experiments if e.id == wanted or e.id.startswith(wanted + "-")]
            if not hits:
                unknown.append(wanted)
            chosen += [e for e in hits if e not in chosen]
        if unknown:
            raise SuiteError(f"unknown experiment(s) {', '.join(unknown)}; `locbook list` shows the ids")
        return chosen


def packaged_suite_file() -> Path:
    """The experiment list locbook ships with: the source tree's ``notebooks/`` (a clone or an editable install),
    else the copy inside the installed package (``locbook/notebooks/``, put there by the wheel)."""
    package = Path(__file__).resolve().parents[1]
    for candidate in (package.parent / SUITE_FILE, package / "notebooks" / SUITE_FILE.name):
        if candidate.is_file():
            return candidate
    raise SuiteError(f"the installed locbook has no experiment list (looked for {package.parent / SUITE_FILE} and "
                     f"{package / 'notebooks' / SUITE_FILE.name}); reinstall locbook or pass --suite")


def find_suite_file(start: Path | None = None) -> Path:
    """``notebooks/experiments.toml`` in the current folder or a parent (a clone, or notebooks copied out with
    ``locbook notebooks``), else the one locbook ships with (:func:`packaged_suite_file`)."""
    here = (start or Path.cwd()).resolve()
    for folder in (here, *here.parents):
        if (folder / SUITE_FILE).is_file():
            return folder / SUITE_FILE
    return packaged_suite_file()


def read_toml(path: Path, what: str) -> dict:
    """The TOML file ``path`` (``what`` names it in the error: unreadable, or not TOML with its line)."""
    from ..reproduce.interpretations import read_declaration
    try:    # decoded here: tomllib's own UnicodeDecodeError names no file or line; and read only up to a limit
        text = read_declaration(path, SuiteError, what)
    except OSError as exc:
        raise SuiteError(f"cannot read {what} {path}: {exc.strerror}") from None
    try:
        return tomllib.loads(text)
    except tomllib.TOMLDecodeError as exc:
        raise SuiteError(f"{path}: {exc}") from None
    except RecursionError:      # arrays or tables nested thousands deep
        raise SuiteError(f"{path}: values are nested too deeply to read as TOML") from None


def finite_float(value) -> float | None:
    """``value`` as a finite float, else None (records and CSV cells may be empty or damaged)."""
    try:
        x = float(value)
    except (TypeError, ValueError):
        return None
    return x if math.isfinite(x) else None


def load_suite(path: Path | None = None) -> Suite:
    """The experiment list at ``path`` (default: :func:`find_suite_file`), checked by its schema
    (:mod:`locbook.suite.spec_schema`): a :class:`SuiteError` of one line naming the file, the table or experiment,
    the key and the value."""
    path = Path(path) if path else find_suite_file()
    data = read_toml(path, "the experiment list")
    try:
        spec = SuiteFile.read(data, path.parent)
    except ValidationError as exc:
        raise SuiteError(one_line(exc, data, path)) from None
    documents = {key: Document(key, d.title, d.authors, d.year, d.source) for key, d in spec.documents.items()}
    suite_rules = {name: rule.rule() for name, rule in spec.parameter_rules.items()}
    experiments = []
    for e in spec.experiment:
        bracket, run = e.bracket, e.data_run
        experiments.append(Experiment(
            e.id, documents[e.document], e.title, e.section, e.notebook, e.profiles,
            {**suite_rules, **{name: rule.rule() for name, rule in e.parameter_rules.items()}},
            dict(bracket.parameters), bracket.reason.strip(), tuple(bracket.factorial), bracket.largest_error_m,
            bracket.largest_error_reason.strip(), None if run is None else DataRun(run.needs, run.parameters)))
    return Suite(path.resolve(), documents, experiments)
