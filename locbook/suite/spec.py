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

Experiment ids are ``[a-z0-9-]`` only (they name folders under ``reports/``).
"""
from __future__ import annotations

import math
import re
import tomllib
from dataclasses import dataclass, field
from pathlib import Path

from ..errors import ParameterError
from .params import NotebookParameter, ParameterRule, is_numeric_annotation, read_parameters, resolve_parameters

__all__ = ["Suite", "Experiment", "Document", "DataRun", "PROFILES", "DOCUMENT_KEYS", "DATA_KINDS", "load_suite",
           "find_suite_file", "packaged_suite_file"]

PROFILES = ("quick", "full")
#: the five source documents, the measured data sets (any data set: ``locbook run --data``), and the cross-document
#: benchmark (issue 16)
DOCUMENT_KEYS = ("dogan2015", "gudipati2017", "palvai2008", "george", "ozkaya2011", "measured", "benchmark")
SUITE_FILE = Path("notebooks") / "experiments.toml"
#: experiment ids and report folder names: lower-case letters, digits and single hyphens
SAFE_NAME = re.compile(r"^[a-z0-9]+(-[a-z0-9]+)*$")
#: what a data set can hold, as ``[experiment.data_run] needs`` names it: a recording of each role of
#: :data:`locbook.data.dataset.ROLES`, and "scored": a recording the static methods are scored on (a static one, or a
#: track with a true position per epoch: :func:`locbook.scenarios.measured.scored_recordings`)
DATA_KINDS = {"calibration": "calibration recording", "static": "static recording", "track": "track recording",
              "scored": "scored recording (a static recording, or a track with a true position per epoch)"}
_DATA_RUN_KEYS = ("needs", "parameters")


class SuiteError(ParameterError):
    """The experiment list (or a study, a bracket) is malformed; the message is one line (a value's line breaks
    are shown as ``\\n``)."""

    def __init__(self, message: str):
        super().__init__(str(message).replace("\r\n", "\\n").replace("\n", "\\n").replace("\r", "\\r"))


_DOCUMENT_FIELDS = {"title", "authors", "year", "source"}


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


def _rules(raw: dict, where: str) -> dict[str, ParameterRule]:
    if not isinstance(raw, dict):
        raise SuiteError(f"{where} must be a table of rules by parameter name")
    return {name: ParameterRule.from_toml(name, rule, where) for name, rule in raw.items()}


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


def _data_run(raw, where: str) -> DataRun | None:
    """``[experiment.data_run]`` checked (one line naming the file, the experiment and the key), or None."""
    if raw is None:
        return None
    if not isinstance(raw, dict):
        raise SuiteError(f"{where}: [experiment.data_run] must be a table with the keys {', '.join(_DATA_RUN_KEYS)}")
    unknown = sorted(set(raw) - set(_DATA_RUN_KEYS))
    if unknown:
        raise SuiteError(f"{where}: [experiment.data_run] has unknown key {unknown[0]!r}; expected "
                         f"{', '.join(_DATA_RUN_KEYS)}")
    needs = raw.get("needs")
    if not isinstance(needs, list) or not needs or not all(isinstance(k, str) for k in needs) \
            or len(set(needs)) != len(needs):
        raise SuiteError(f"{where}: [experiment.data_run] needs must list one or more distinct kinds of "
                         f"{', '.join(DATA_KINDS)}, got {needs!r}")
    bad = [k for k in needs if k not in DATA_KINDS]
    if bad:
        raise SuiteError(f"{where}: [experiment.data_run] needs: unknown kind {bad[0]!r}; expected one of "
                         f"{', '.join(DATA_KINDS)}")
    parameters = raw.get("parameters", {})
    if not isinstance(parameters, dict):
        raise SuiteError(f"{where}: [experiment.data_run] parameters must be a table of parameter values")
    if "data" in parameters:
        raise SuiteError(f"{where}: [experiment.data_run] parameters cannot set 'data' (the run's data set sets it)")
    return DataRun(tuple(needs), dict(parameters))


def load_suite(path: Path | None = None) -> Suite:
    path = Path(path) if path else find_suite_file()
    data = read_toml(path, "the experiment list")
    documents = {}
    for key, doc in data.get("documents", {}).items():
        if key not in DOCUMENT_KEYS:
            raise SuiteError(f"{path}: unknown document key {key!r}; expected one of {DOCUMENT_KEYS}")
        missing, unknown = _DOCUMENT_FIELDS - set(doc), set(doc) - _DOCUMENT_FIELDS
        if missing:
            raise SuiteError(f"{path}: document {key!r} lacks {sorted(missing)}")
        if unknown:
            raise SuiteError(f"{path}: document {key!r} has unknown fields {sorted(unknown)}; "
                             f"expected {sorted(_DOCUMENT_FIELDS)}")
        documents[key] = Document(key, doc["title"], doc["authors"], str(doc["year"]), doc["source"])
    suite_rules = _rules(data.get("parameter_rules", {}), f"{path}: [parameter_rules]")
    experiments, seen = [], set()
    for raw in data.get("experiment", []):
        missing = {"id", "document", "title", "section", "notebook", "profiles"} - set(raw)
        if missing:
            raise SuiteError(f"{path}: experiment {raw.get('id', '?')!r} lacks {sorted(missing)}")
        eid, dkey = raw["id"], raw["document"]
        if not isinstance(eid, str) or not SAFE_NAME.match(eid):
            raise SuiteError(f"{path}: experiment id {eid!r} must be lower-case letters, digits and hyphens "
                             "([a-z0-9-], e.g. 'george-tracking'); it names a folder under reports/")
        if dkey not in documents:
            raise SuiteError(f"{path}: experiment {eid!r} names undeclared document {dkey!r}")
        if not eid.startswith(dkey + "-"):
            raise SuiteError(f"{path}: experiment id {eid!r} must start with its document key '{dkey}-'")
        if eid in seen:
            raise SuiteError(f"{path}: duplicate experiment id {eid!r}")
        seen.add(eid)
        if set(raw["profiles"]) != set(PROFILES):
            raise SuiteError(f"{path}: experiment {eid!r} must define exactly the profiles {PROFILES}")
        notebook = (path.parent / raw["notebook"]).resolve()
        if not notebook.is_file():
            raise SuiteError(f"{path}: experiment {eid!r}: notebook {raw['notebook']} does not exist")
        rules = {**suite_rules, **_rules(raw.get("parameter_rules", {}), f"{path}: experiment {eid!r}")}
        bracket = raw.get("bracket", {})
        if not isinstance(bracket, dict) or set(bracket) - {"parameters", "reason", "factorial", "largest_error_m",
                                                             "largest_error_reason"} \
                or not isinstance(bracket.get("parameters", {}), dict):
            raise SuiteError(f"{path}: experiment {eid!r}: [experiment.bracket] takes a table 'parameters', a "
                             "string 'reason', a list 'factorial' of interpretation names, and 'largest_error_m' (a "
                             "positive number) with 'largest_error_reason'")
        factorial = bracket.get("factorial", [])
        if not isinstance(factorial, list) or not all(isinstance(n, str) and n for n in factorial) \
                or len(set(factorial)) != len(factorial) or len(factorial) == 1:
            raise SuiteError(f"{path}: experiment {eid!r}: [experiment.bracket] factorial must list two or more "
                             f"distinct interpretation names, got {factorial!r}")
        largest = bracket.get("largest_error_m")
        if largest is not None and (isinstance(largest, bool) or not isinstance(largest, (int, float))
                                    or not math.isfinite(largest) or largest <= 0):
            raise SuiteError(f"{path}: experiment {eid!r}: [experiment.bracket] largest_error_m must be a positive "
                             f"number of metres, got {largest!r}")
        if (largest is None) != (not str(bracket.get("largest_error_reason", "")).strip()):
            raise SuiteError(f"{path}: experiment {eid!r}: [experiment.bracket] largest_error_m and "
                             "largest_error_reason go together (the reason says where the area is printed)")
        if not isinstance(bracket.get("reason", ""), str):
            raise SuiteError(f"{path}: experiment {eid!r}: [experiment.bracket] reason must be a string")
        if bracket.get("parameters") and not bracket.get("reason", "").strip():
            raise SuiteError(f"{path}: experiment {eid!r}: [experiment.bracket] sets parameters without a 'reason'")
        experiments.append(Experiment(eid, documents[dkey], raw["title"], raw["section"], notebook,
                                      {p: dict(raw["profiles"][p]) for p in PROFILES}, rules,
                                      dict(bracket.get("parameters", {})), str(bracket.get("reason", "")).strip(),
                                      tuple(factorial), None if largest is None else float(largest),
                                      str(bracket.get("largest_error_reason", "")).strip(),
                                      _data_run(raw.get("data_run"), f"{path}: experiment {eid!r}")))
    return Suite(path.resolve(), documents, experiments)
