"""Declared parameter studies: many points of one or more experiments, run by the suite's runner, one tidy table.

A study is a ``[[study]]`` table in ``notebooks/experiments.toml`` or in a TOML file of its own (given by path;
such a file holds one ``[[study]]``)::

    [[study]]
    name = "george-sigma"               # [a-z0-9-]: names reports/studies/<name>/
    experiments = ["george-tracking"]   # experiment ids; every swept parameter must be declared by each
    profile = "quick"                   # default "quick": the values of every parameter the study does not set
    replicates = 2                      # default 1: replicate r = 0, 1, ... sets seed_parameter = base + r,
    seed_parameter = "seed"             #   base = the profile's seed (else the notebook's default), so
                                        #   replicate 0 is the profile's own run ("consecutive seeds")
    samples = 4                         # draws of the random / lhs parameters (needed iff there are any)
    sample_seed = 0                     # default 0: numpy.random.default_rng(sample_seed) draws them
    collect = ["mean error C without filter"]   # optional: keep rows whose quantity or printed_id is listed
    [study.parameters]
    sigma_db = { grid = [1.5, 2.0, 2.5] }                     # an axis crossed with every other block
    ref_power_dbm = { list = [-45.0, -50.0] }                 # lists are paired element-wise (equal lengths)
    dt_s = { random = { low = 0.5, high = 2.0 } }             # uniform draws, i.i.d.
    r_iso_m2 = { lhs = { low = 1e-1, high = 10.0, log = true } }   # Latin hypercube (stratified) draws

The points are the Cartesian product of the blocks, in the order the parameters are declared: each ``grid``
parameter is a block, all ``list`` parameters together one block (row i pairs their i-th values), all ``random``
and ``lhs`` parameters together one block of ``samples`` rows. A ``random`` value is ``low + u (high - low)``
with ``u ~ U[0, 1)``; a ``lhs`` column is ``(permutation(samples) + U[0, 1)) / samples`` mapped the same way
(McKay, Beckman and Conover 1979, one stratum per sample in each dimension); ``log = true`` maps ``u`` on
``log(low) .. log(high)`` instead. Draws are taken parameter by parameter in declared order, so the same study
gives the same points. Only ``float`` parameters can be drawn.

Everything is checked before anything runs (:class:`~locbook.suite.spec.SuiteError`, naming the study and what is
wrong; the keys and values by the schema, the pydantic models ``_StudyTable``, ``_Sampler`` and ``_Range``, then the
rules against each experiment's notebook): unknown keys, experiments and samplers, parameters an experiment does
not declare, the number of runs (experiments x the product of the block sizes x replicates, at most
:data:`MAX_STUDY_RUNS`, counted before anything is drawn), two points with the same checked values, and every
value of every point against the parameter's type
and declared rule (``[parameter_rules]``).

Each point (experiment x parameter point x replicate) is one task of :func:`locbook.suite.runner.run_tasks`, all
in one runner session (``--jobs`` runs points in parallel; lock, staging, validation, retries, interrupts and the
cache per point are the runner's). A point's folder is ``<experiment>-<SHA-256 of its values>`` (all 64 hex
digits), so a finished point is cached across reruns and edits of the study that keep it; a point that is the same
run as the profile's own report (``<reports>/<profile>/<experiment>``, up to date) is copied from there, not executed
(:attr:`~locbook.suite.runner.Task.reuse`). ``study.json`` in the
folder records the file that declared the study and its declaration's fingerprint: another declaration of the same
name from another file is refused (:func:`check_claim`). After every run, also an interrupted or failed one, the
aggregates are rebuilt from every point with an up-to-date report, this run's and earlier ones
(:func:`current_points`). Outputs in ``<reports>/studies/<name>/``:

- ``study.csv`` (:data:`STUDY_COLUMNS` with one column per swept parameter after ``replicate_seed``): one row per
  point and collected ``numbers.csv`` row, values copied as the notebook wrote them;
- ``plots/<experiment>-<printed quantity>-<parameter>.png``: each printed quantity's ``ours`` (2 standard errors
  as bars) against each swept parameter, the printed value as a line and its rounding (printed +- rounding) as
  a band;
- one report folder per point (the executed notebook, numbers.csv), as ``locbook run`` writes.
"""
from __future__ import annotations

import csv
import hashlib
import io
import itertools
import json
import math
import os
import re
from dataclasses import dataclass, field
from pathlib import Path
from typing import Annotated, Any

import numpy as np
from pydantic import AfterValidator, BaseModel, ConfigDict, Field, ValidationError, ValidationInfo, model_validator
from pydantic_core import PydanticCustomError

from ..errors import ParameterError
from .files import atomic_write, point_key, point_text, read_csv, read_json, value_text
from .params import check_value
from .runner import Task
from .spec import SAFE_NAME, Experiment, Suite, SuiteError, finite_float, read_toml
from .sweep import Aggregate, current_points, run_sweep
from .sweep_pages import replicate_mean_se, write_study_page

__all__ = ["Study", "StudyPoint", "Aggregate", "load_study", "load_studies", "expand_study", "run_study",
           "study_size", "current_points", "check_claim", "STUDY_COLUMNS", "MAX_STUDY_RUNS"]

_SAMPLERS = ("grid", "list", "random", "lhs")
#: study.csv columns before the swept parameters, then after them
_LEAD = ("study", "experiment", "point", "replicate", "replicate_seed")
_TAIL = ("printed_id", "quantity", "where", "unit", "kind", "printed", "ours", "mc_std_error", "rounding",
         "verdict", "folder")
STUDY_COLUMNS = (*_LEAD, *_TAIL)
#: The most runs (experiments x parameter points x replicates) a study may declare: each is one notebook execution
#: of seconds to minutes with its own report folder, so more is a typo (``samples = 1000000000``) or a study to split.
#: Counted from the declaration before anything is drawn or expanded.
MAX_STUDY_RUNS = 10_000


@dataclass(frozen=True)
class Study:
    """A checked study declaration (module docstring)."""

    name: str
    experiments: tuple[Experiment, ...]
    profile: str
    replicates: int
    seed_parameter: str
    samples: int
    sample_seed: int
    collect: tuple[str, ...]
    parameters: dict[str, tuple[str, object]] = field(hash=False)   # name -> (sampler, values or range)
    source: Path = field(default=Path(), hash=False)


@dataclass(frozen=True)
class StudyPoint:
    """One task of a study: ``values`` (the swept parameters) of parameter point ``point`` (1-based),
    replicate ``replicate`` of ``experiment``; ``parameters``: every checked value the notebook gets."""

    key: str
    experiment: Experiment
    point: int
    replicate: int
    replicate_seed: int | None
    values: dict = field(hash=False)
    parameters: dict = field(hash=False)


def _err(study: str, where: Path, text: str) -> SuiteError:
    return SuiteError(f"{where}: study {study!r}: {text}")


# -- the schema: pydantic models of a [[study]] table ------------------------------------------------------------
def _refuse(kind: str, text: str = ""):
    """A rule's refusal inside a model; :func:`_one_line` puts the file, the study and the place in front."""
    raise PydanticCustomError(kind, "{text}", {"text": text})


def _whole(key: str, least: int):
    """A validator: a whole number >= ``least`` (not a boolean)."""
    def check(value):
        if not isinstance(value, int) or isinstance(value, bool) or value < least:
            _refuse("study", f"{key} must be a whole number >= {least}, got {value!r}")
        return value
    return AfterValidator(check)


def _name(value):
    if not isinstance(value, str) or not SAFE_NAME.match(value):
        _refuse("study_name")
    return value


def _experiments(ids, info: ValidationInfo):
    """The experiment ids, as the suite's experiments (``info.context["suite"]``)."""
    if not isinstance(ids, list) or not ids or not all(isinstance(i, str) for i in ids):
        _refuse("study", "experiments must be a non-empty list of experiment ids")
    by_id = {e.id: e for e in info.context["suite"].experiments}
    missing = [i for i in ids if i not in by_id]
    if missing:
        _refuse("study", f"unknown experiment(s) {', '.join(missing)}; `locbook list` shows the ids")
    if len(set(ids)) != len(ids):
        _refuse("study", "an experiment is listed twice")
    return tuple(by_id[i] for i in ids)


def _profile(profile, info: ValidationInfo):
    experiments = info.data.get("experiments", ())     # absent: their own error comes first
    if not isinstance(profile, str) or any(profile not in e.profiles for e in experiments):
        _refuse("study", f"profile {profile!r} is not a profile of every experiment (quick, full)")
    return profile


def _seed_parameter(value):
    if not isinstance(value, str):
        _refuse("study", f"seed_parameter must be a parameter name, got {value!r}")
    return value


def _collect(value):
    if not isinstance(value, list) or not all(isinstance(c, str) for c in value):
        _refuse("study", "collect must be a list of quantities or printed ids (numbers.csv columns)")
    return tuple(value)


def _finite(value):
    if isinstance(value, bool) or not isinstance(value, (int, float)) or not math.isfinite(value):
        _refuse("range_finite")
    return value


def _log(value):
    if not isinstance(value, bool):
        _refuse("range_log", f"log must be true or false, got {value!r}")
    return value


class _Table(BaseModel):
    """A table of the declaration: no key but its fields (extra="forbid"); values as TOML gives them."""
    model_config = ConfigDict(extra="forbid")


class _Range(_Table):
    """``{ low = ..., high = ..., log = false }`` of a ``random`` or ``lhs`` sampler (module docstring)."""
    low: Annotated[Any, AfterValidator(_finite)]
    high: Annotated[Any, AfterValidator(_finite)]
    log: Annotated[Any, AfterValidator(_log)] = False

    @model_validator(mode="after")
    def _ordered(self):
        if not self.low < self.high:
            _refuse("range_order", f"needs low < high, got {self.low} and {self.high}")
        if self.log and not self.low > 0:
            _refuse("range_log", f"log = true needs low > 0, got {self.low}")
        return self

    def spec(self) -> dict:
        return {"low": float(self.low), "high": float(self.high), "log": self.log}


#: the field of a sampler whose name is a Python builtin's
_FIELD = {"list": "list_"}


class _Sampler(_Table):
    """``{ grid = [...] }``, ``{ list = [...] }``, ``{ random = {...} }`` or ``{ lhs = {...} }``: exactly one."""
    grid: Annotated[list, Field(min_length=1, strict=True)] = None      # type: ignore[assignment]
    list_: Annotated[list, Field(min_length=1, strict=True, alias="list")] = None    # type: ignore[assignment]
    random: _Range = None           # type: ignore[assignment]
    lhs: _Range = None              # type: ignore[assignment]

    @model_validator(mode="before")
    @classmethod
    def _one(cls, spec):
        # one of four keys: the one rule here that field types cannot say (checked first, as it names the sampler)
        if not isinstance(spec, dict) or len(spec) != 1 or next(iter(spec)) not in _SAMPLERS:
            _refuse("sampler")
        return spec

    def declared(self) -> tuple[str, object]:
        """(sampler, values) or (sampler, range as :meth:`_Range.spec`)."""
        sampler = next(k for k in _SAMPLERS if _FIELD.get(k, k) in self.model_fields_set)
        value = getattr(self, _FIELD.get(sampler, sampler))
        return sampler, value.spec() if isinstance(value, _Range) else value


class _StudyTable(_Table):
    """One ``[[study]]`` (module docstring); the field order is the order its rules are checked in."""
    model_config = ConfigDict(extra="forbid", validate_default=True)    # the default profile is checked too
    name: Annotated[Any, AfterValidator(_name)]
    experiments: Annotated[Any, AfterValidator(_experiments)]
    profile: Annotated[Any, AfterValidator(_profile)] = "quick"
    replicates: Annotated[Any, _whole("replicates", 1)] = 1
    samples: Annotated[Any, _whole("samples", 0)] = 0
    sample_seed: Annotated[Any, _whole("sample_seed", 0)] = 0
    seed_parameter: Annotated[Any, AfterValidator(_seed_parameter)] = "seed"
    collect: Annotated[Any, AfterValidator(_collect)] = []
    parameters: dict[str, _Sampler] = {}

    @model_validator(mode="after")
    def _together(self):
        """The rules between keys: paired lists, draws and samples, seeds, the number of runs."""
        parameters = self.declared_parameters()
        lists = {p: len(v) for p, (s, v) in parameters.items() if s == "list"}
        if len(set(lists.values())) > 1:
            _refuse("study", f"list parameters are paired element-wise and need equal lengths, got {lists}")
        drawn = [p for p, (s, _v) in parameters.items() if s in ("random", "lhs")]
        if drawn and self.samples < 1:
            _refuse("study", f"random / lhs parameters ({', '.join(drawn)}) need samples >= 1")
        if self.samples and not drawn:
            _refuse("study", "samples is set but no parameter is random or lhs")
        if self.replicates > 1 and self.seed_parameter in parameters:
            _refuse("study", f"{self.seed_parameter!r} is swept and also set by the replicates; do one of them")
        factors = _factors(len(self.experiments), parameters, self.samples, self.replicates)
        if math.prod(n for _key, n in factors) > MAX_STUDY_RUNS:
            _refuse("study", _too_many(factors))
        return self

    def declared_parameters(self) -> dict[str, tuple[str, object]]:
        return {p: s.declared() for p, s in self.parameters.items()}


_SHAPE = {"model_type", "missing", "extra_forbidden", "dict_type"}


def _rank(error: dict, index: int, table: dict) -> tuple:
    """The order the rules are checked in (the first broken one is reported): the name, unknown keys, then the
    keys in field order (pydantic's), a sampler's shape before its values."""
    loc, kind = error["loc"], error["type"]
    if loc[:1] == ("name",):
        return (0, index)
    if kind == "extra_forbidden" and len(loc) == 1:
        return (1, index)
    if loc[:1] == ("parameters",) and len(loc) > 1:
        names = list(table.get("parameters", {}))
        return (2, 1, names.index(loc[1]) if loc[1] in names else -1, 0 if kind in _SHAPE else 1, index)
    return (2, 0, index)


def _one_line(exc: ValidationError, table: dict, where: Path) -> str:
    """The first broken rule of a ``[[study]]`` (:func:`_rank`), in the house words: the file, the study, what."""
    errors = exc.errors()
    error = min(enumerate(errors), key=lambda e: _rank(e[1], e[0], table))[1]
    loc, kind = error["loc"], error["type"]
    name = table.get("name")
    if loc[:1] == ("name",):      # a name that breaks its rule, or none
        return (f"{where}: study name {name!r} must be lower-case letters, digits and hyphens ([a-z0-9-]); it names "
                "reports/studies/<name>/")
    if kind == "extra_forbidden" and len(loc) == 1:
        unknown = sorted(e["loc"][0] for e in errors if e["type"] == kind and len(e["loc"]) == 1)
        text = f"unknown key(s) {unknown}; allowed: {', '.join(sorted(_StudyTable.model_fields))}"
    elif kind == "missing" and len(loc) == 1:      # experiments (the name's own rule names a missing name)
        text = "experiments must be a non-empty list of experiment ids"
    elif loc == ("parameters",):
        text = "[study.parameters] must be a table of parameter = { sampler = ... }"
    elif loc[:1] == ("parameters",):
        pname, spec = loc[1], table["parameters"][loc[1]]
        sampler = "list" if loc[2:3] == ("list",) else loc[2] if len(loc) > 2 else ""
        if kind == "sampler" or len(loc) == 2:
            text = (f"parameter {pname!r} needs exactly one sampler of {', '.join(_SAMPLERS)} (e.g. {{ grid = "
                    f"[1.0, 2.0] }}), got {spec!r}")
        elif sampler in ("grid", "list"):
            text = f"parameter {pname!r}: {sampler} needs a non-empty list of values"
        elif kind in _SHAPE:
            text = (f"parameter {pname!r}: {sampler} needs a table {{ low = ..., high = ..., log = false }}, got "
                    f"{spec[sampler]!r}")
        elif kind == "range_finite":
            text = f"parameter {pname!r}: {sampler} low and high must be finite numbers"
        elif kind == "range_order":
            text = f"parameter {pname!r}: {sampler} {error['ctx']['text']}"
        else:                                       # range_log
            text = f"parameter {pname!r}: {error['ctx']['text']}"
    else:
        text = error.get("ctx", {}).get("text") or error["msg"]
    return f"{where}: study {name!r}: {text}"


def _parse(raw: dict, suite: Suite, where: Path) -> Study:
    if not isinstance(raw, dict):
        raise SuiteError(f"{where}: a [[study]] must be a table")
    try:
        table = _StudyTable.model_validate(raw, context={"suite": suite})
    except ValidationError as exc:
        raise SuiteError(_one_line(exc, raw, where)) from None
    name, experiments, parameters = table.name, table.experiments, table.declared_parameters()
    drawn = [p for p, (s, _v) in parameters.items() if s in ("random", "lhs")]
    for exp in experiments:        # the rules against each experiment's notebook (its declared parameters)
        declared = exp.declared_parameters()
        for pname in parameters:
            if pname not in declared:
                raise _err(name, where, f"experiment {exp.id!r} has no parameter {pname!r} (known: "
                                        f"{', '.join(sorted(declared))})")
        for pname in drawn:
            if declared[pname].annotation != "float":
                raise _err(name, where, f"parameter {pname!r} of {exp.id!r} is {declared[pname].annotation}; "
                                        "only float parameters can be drawn (use grid or list)")
        if table.replicates > 1 and (table.seed_parameter not in declared
                                     or declared[table.seed_parameter].annotation != "int"):
            raise _err(name, where, f"replicates need an int parameter {table.seed_parameter!r} in {exp.id!r} "
                                    "(set seed_parameter)")
    return Study(name, experiments, table.profile, table.replicates, table.seed_parameter, table.samples,
                 table.sample_seed, tuple(table.collect), parameters, where)


def _factors(n_experiments: int, parameters: dict, samples: int, replicates: int) -> list[tuple[str, int]]:
    """The factors of a study's number of runs (module docstring: the product of the blocks), each with the key
    that sets it: ``experiments``, each ``grid`` parameter, the ``list`` block, ``samples``, ``replicates``."""
    factors = [("experiments", n_experiments)]
    factors += [(f"{p} (grid)", len(v)) for p, (sampler, v) in parameters.items() if sampler == "grid"]
    lists = [len(v) for sampler, v in parameters.values() if sampler == "list"]
    if lists:
        factors.append(("the list parameters", lists[0]))
    if any(sampler in ("random", "lhs") for sampler, _v in parameters.values()):
        factors.append(("samples", samples))
    return [*factors, ("replicates", replicates)]


def study_size(study: Study) -> int:
    """The number of runs of ``study`` (experiments x parameter points x replicates), without expanding it."""
    return math.prod(n for _key, n in _factors(len(study.experiments), study.parameters, study.samples,
                                               study.replicates))


def _too_many(factors: list[tuple[str, int]]) -> str:
    """Why a study of more than :data:`MAX_STUDY_RUNS` runs is refused, naming its factors."""
    runs = math.prod(n for _key, n in factors)
    largest = max(factors, key=lambda f: f[1])[0]
    return (f"{' x '.join(f'{n} {key}' for key, n in factors)} = {runs} runs, more than the limit of "
            f"{MAX_STUDY_RUNS} (each run is one notebook execution); reduce {largest} or split the study")


def _check_size(name: str, where: Path, n_experiments: int, parameters: dict, samples: int, replicates: int) -> None:
    """Refuse a study of more than :data:`MAX_STUDY_RUNS` runs, naming its factors (before anything is drawn)."""
    factors = _factors(n_experiments, parameters, samples, replicates)
    if math.prod(n for _key, n in factors) > MAX_STUDY_RUNS:
        raise _err(name, where, _too_many(factors))


def load_studies(suite: Suite, path: Path | None = None) -> dict[str, Study]:
    """Every study declared in ``path`` (default: the suite's experiments.toml), checked, by name."""
    path = Path(path) if path else suite.path
    data = read_toml(path, "the study file")
    raw = data.get("study", [])
    if not isinstance(raw, list):
        raise SuiteError(f"{path}: studies are [[study]] tables (an array of tables)")
    studies = {}
    for table in raw:
        study = _parse(table, suite, path)
        if study.name in studies:
            raise SuiteError(f"{path}: duplicate study name {study.name!r}")
        studies[study.name] = study
    return studies


def load_study(suite: Suite, name_or_path: str | Path) -> Study:
    """A study by name (declared in the suite's experiments.toml) or the one study of a TOML file."""
    studies = load_studies(suite)
    if str(name_or_path) in studies:
        return studies[str(name_or_path)]
    path = Path(name_or_path).expanduser()
    if not path.is_file():
        known = ", ".join(studies) or "none"
        raise SuiteError(f"no study {str(name_or_path)!r}: neither a study of {suite.path} (declared: {known}) nor "
                         "a TOML file")
    found = load_studies(suite, path)
    if len(found) != 1:
        raise SuiteError(f"{path}: a study file holds exactly one [[study]], found {len(found)} "
                         f"({', '.join(found) or 'none'})")
    return next(iter(found.values()))


def _draw(study: Study) -> dict[str, list[float]]:
    """The ``samples`` values of each random / lhs parameter (module docstring), in declared order."""
    rng = np.random.default_rng(study.sample_seed)
    n, out = study.samples, {}
    for pname, (sampler, spec) in study.parameters.items():
        if sampler == "random":
            u = rng.random(n)
        elif sampler == "lhs":
            u = (rng.permutation(n) + rng.random(n)) / n
        else:
            continue
        lo, hi = (math.log(spec["low"]), math.log(spec["high"])) if spec["log"] else (spec["low"], spec["high"])
        x = lo + u * (hi - lo)
        out[pname] = [float(v) for v in (np.exp(x) if spec["log"] else x)]
    return out


def _parameter_points(study: Study) -> list[dict]:
    """The parameter points (without replicates): the product of the blocks (module docstring)."""
    drawn = _draw(study)
    lists = {p: v for p, (s, v) in study.parameters.items() if s == "list"}
    blocks, placed = [], set()     # placed: the list and drawn blocks, at their first parameter
    for pname, (sampler, values) in study.parameters.items():
        block = "list" if sampler == "list" else "drawn" if sampler in ("random", "lhs") else pname
        if block in placed:
            continue
        placed.add(block)
        columns = {pname: values} if sampler == "grid" else lists if block == "list" else drawn
        blocks.append([dict(zip(columns, row)) for row in zip(*columns.values())])
    return [{k: v for part in combo for k, v in part.items()} for combo in itertools.product(*blocks)]


def point_labels(points: list[StudyPoint]) -> dict[str, str]:
    """What a person reads for each point of a study (key -> label): the swept values that differ between its
    points (all of them where none differ), the replicate, and the experiment where the study runs several:
    ``sigma_db=1.5 rep 0``. The folder keeps the hash key; the live view, the scoreboard and the pages show this."""
    seen: dict[str, set] = {}
    for p in points:
        for name, value in p.values.items():
            seen.setdefault(name, set()).add(point_text({"v": value}))
    varying = [name for name, texts in seen.items() if len(texts) > 1] or list(seen)
    several = len({p.experiment.id for p in points}) > 1
    return {p.key: " ".join(part for part in (
        p.experiment.id if several else "",
        ", ".join(f"{name}={value_text(p.values[name])}" for name in varying if name in p.values),
        f"rep {p.replicate}") if part) for p in points}


def expand_study(study: Study) -> list[StudyPoint]:
    """Every task of the study (experiment x parameter point x replicate), each value checked against the
    parameter's type and rule; raises a SuiteError naming the point and the value otherwise."""
    _check_size(study.name, study.source, len(study.experiments), study.parameters, study.samples,
                study.replicates)      # also for a Study built by hand, before anything is drawn
    points = _parameter_points(study)
    tasks, seen, keys = [], {}, {}
    for exp in study.experiments:
        declared = exp.declared_parameters()
        base = exp.parameters(study.profile)
        for i, values in enumerate(points, start=1):
            checked = {}
            for pname, value in values.items():
                try:
                    checked[pname] = check_value(declared[pname], value, exp.rules.get(pname))
                except ParameterError as exc:    # say which study and point
                    raise _err(study.name, study.source, f"point {i} of {exp.id!r}: {exc}") from None
            seeded = (study.seed_parameter in declared and study.seed_parameter not in checked
                      and declared[study.seed_parameter].annotation == "int")
            base_seed = base.get(study.seed_parameter, declared[study.seed_parameter].default) if seeded else None
            for r in range(study.replicates):
                # the seed is always explicit (also with one replicate), so adding replicates keeps replicate 0
                seed = base_seed + r if seeded else None
                run_values = dict(checked)
                if seeded:
                    try:
                        run_values[study.seed_parameter] = check_value(declared[study.seed_parameter], seed,
                                                                       exp.rules.get(study.seed_parameter))
                    except ParameterError as exc:
                        raise _err(study.name, study.source, f"replicate {r} of {exp.id!r}: {exc}") from None
                text = (exp.id, point_text(run_values))
                if text in seen:       # the same values (after checking: 1 and 1.0 of a float are one value)
                    raise _err(study.name, study.source, f"point {i} of {exp.id!r} repeats point {seen[text]} "
                                                         f"({values}); every point must differ")
                seen[text] = i
                key = point_key(exp.id, run_values)
                if keys.setdefault(key, text) != text:    # a SHA-256 collision: refused, never merged
                    raise _err(study.name, study.source, f"point {i} of {exp.id!r}: its folder key {key} is "
                                                         "that of another point")
                tasks.append(StudyPoint(key, exp, i, r, seed, checked, {**base, **run_values}))
    return tasks


# ---------------------------------------------------------------------------------------------------
# outputs

def study_rows(study: Study, points: list[StudyPoint], folder: Path, done: set[str]) -> list[dict]:
    """The study.csv rows of the points in ``done`` (keys whose report is up to date), in point order."""
    rows = []
    for p in points:
        if p.key not in done:
            continue
        for r in read_csv(folder / p.key / "numbers.csv"):
            if study.collect and r["quantity"] not in study.collect and r["printed_id"] not in study.collect:
                continue
            seed = "" if p.replicate_seed is None else p.replicate_seed
            rows.append({"study": study.name, "experiment": p.experiment.id, "point": p.point,
                         "replicate": p.replicate, "replicate_seed": seed,
                         **{k: json.dumps(v) if isinstance(v, (list, dict)) else v for k, v in p.values.items()},
                         **{c: r.get(c, "") for c in _TAIL if c not in ("ours", "folder")},
                         "ours": r.get("reproduced", ""), "folder": p.key})
    return rows


def _write_csv(study: Study, rows: list[dict], path: Path) -> None:
    out = io.StringIO()
    writer = csv.DictWriter(out, fieldnames=[*_LEAD, *study.parameters, *_TAIL], lineterminator="\n")
    writer.writeheader()
    writer.writerows(rows)
    atomic_write(path, lambda tmp: tmp.write_text(out.getvalue(), encoding="utf-8"))


def _slug(text: str, limit: int = 50) -> str:
    return re.sub(r"[^a-z0-9]+", "-", text.lower()).strip("-")[:limit].strip("-")


def _write_plots(study: Study, rows: list[dict], plots: Path) -> list[tuple[Path, str]]:
    """One PNG per (experiment, printed quantity with a numeric printed value, numeric swept parameter); returns
    each file with its caption."""
    import matplotlib
    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    groups: dict[tuple, list[dict]] = {}
    for r in rows:
        if finite_float(r["printed"]) is not None and finite_float(r["ours"]) is not None:
            groups.setdefault((r["experiment"], r["printed_id"]), []).append(r)
    written = []
    plots.mkdir(exist_ok=True)
    for (eid, printed_id), group in groups.items():
        printed = finite_float(group[0]["printed"])
        rounding = finite_float(group[0]["rounding"]) or 0.0
        for pname in study.parameters:
            xs = [finite_float(r[pname]) for r in group]
            if any(x is None for x in xs):
                continue    # a list- or text-valued parameter has no axis
            ys = np.array([finite_float(r["ours"]) for r in group])
            fig, ax = plt.subplots(figsize=(6, 4))
            ax.axhspan(printed - rounding, printed + rounding, color="#E69F00", alpha=0.25,
                       label=f"printed {group[0]['printed']} +- rounding {rounding:g}")
            ax.axhline(printed, color="#E69F00", lw=1)
            # each point's replicates joined by their mean and its standard error (the study page's rule)
            joined = {}
            for r, x_value, y_value in zip(group, xs, ys):
                joined.setdefault(r["point"], (x_value, [], r))[1].append(y_value)
            means = sorted((x_value, float(np.mean(v)), replicate_mean_se(v, r["mc_std_error"]))
                           for x_value, v, r in joined.values())
            mx, my, mse = (np.array(c) for c in zip(*means))
            if len(joined) < len(group):
                ax.plot(xs, ys, "o", ms=3, color="#0072B2", alpha=0.35, label="each replicate")
            if len(set(mx.tolist())) == len(mx):      # one point per value: a line with its band
                ax.plot(mx, my, "o-", ms=4, color="#0072B2", label="mean of the replicates")
                ax.fill_between(mx, my - 2 * mse, my + 2 * mse, color="#0072B2", alpha=0.2,
                                label="+- 2 standard errors of the mean")
            else:                                      # other parameters vary too: one error bar per point
                ax.errorbar(mx, my, yerr=2 * mse, fmt="o", ms=4, capsize=2, color="#0072B2",
                            label="mean of the replicates (+- 2 standard errors)")
            sampler, spec = study.parameters[pname]
            if sampler in ("random", "lhs") and spec["log"]:
                ax.set_xscale("log")
            ax.set_xlabel(pname)
            ax.set_ylabel(f"{group[0]['quantity']}" + (f" ({group[0]['unit']})" if group[0]["unit"] else ""))
            ax.set_title(f"{eid}: {printed_id}"[:90], fontsize=9)
            ax.legend(fontsize=8)
            fig.tight_layout()
            digest = hashlib.sha256(printed_id.encode()).hexdigest()[:6]
            path = plots / f"{eid}-{_slug(printed_id)}-{digest}-{_slug(pname)}.png"
            atomic_write(path, lambda tmp: fig.savefig(tmp, format="png", dpi=100))
            plt.close(fig)
            written.append((path, f"{eid}: {group[0]['quantity']} ({group[0]['where']}) against {pname}"))
    for old in plots.glob("*.png"):    # plots of quantities or parameters the study no longer has
        if old not in {p for p, _caption in written}:
            old.unlink(missing_ok=True)
    return written


def write_study_outputs(study: Study, points: list[StudyPoint], folder: Path, outcomes,
                        wrote: list | None = None) -> Aggregate:
    """study.csv and the plots from every point with an up-to-date report (:func:`current_points`: this run's and
    earlier ones), so an interrupted or failed run never drops a good row. study.csv is replaced atomically, then
    the plots; a write that fails leaves the earlier files (old plots are removed only once every new one is
    written). With no up-to-date point at all, nothing is rewritten. ``wrote``: the :class:`Aggregate` is appended
    as soon as study.csv is in place (a caller learns it also when the plots then fail)."""
    status = current_points(folder, study.profile, [(p.key, p.experiment, p.parameters, True) for p in points],
                            outcomes)
    done = {k for k, st in status.items() if st in ("ok", "cached")}
    csv_path = folder / "study.csv"
    if not done and csv_path.is_file():
        aggregate = Aggregate(csv_path, 0, len(points), written=False)
        if wrote is not None:
            wrote.append(aggregate)
        return aggregate
    _claim(study, folder)
    rows = study_rows(study, points, folder, done)
    _write_csv(study, rows, csv_path)
    aggregate = Aggregate(csv_path, len(done), len(points))
    if wrote is not None:
        wrote.append(aggregate)
    plots = _write_plots(study, rows, folder / "plots")
    write_study_page(study, rows, folder, point_labels(points), plots)
    return aggregate


def _fingerprint(study: Study) -> str:
    """The declaration of ``study`` as a hash (everything that decides its points)."""
    declared = {"name": study.name, "experiments": [e.id for e in study.experiments], "profile": study.profile,
                "replicates": study.replicates, "seed_parameter": study.seed_parameter, "samples": study.samples,
                "sample_seed": study.sample_seed, "collect": list(study.collect),
                "parameters": {p: [sampler, v] for p, (sampler, v) in study.parameters.items()}}
    return hashlib.sha256(json.dumps(declared, sort_keys=True).encode()).hexdigest()


def _record(study: Study) -> dict:
    return {"study": study.name, "declared_in": str(Path(study.source).resolve()),
            "fingerprint": _fingerprint(study)}


def check_claim(study: Study, folder: Path) -> None:
    """Refuse to run ``study`` into ``folder`` when the folder holds another study of the same name: one declared in
    another file with a different declaration (``study.json`` records the file and the declaration's fingerprint).
    The same file edited is the same study (its points are cached by their values); an identical declaration in
    another file (a copy) shares the folder too."""
    held = read_json(folder / "study.json", {})
    mine = _record(study)
    if held.get("declared_in") and held.get("declared_in") != mine["declared_in"] \
            and held.get("fingerprint") != mine["fingerprint"]:
        raise SuiteError(f"{folder} holds the study {study.name!r} declared in {held['declared_in']}; this "
                         f"{study.name!r} of {mine['declared_in']} is declared differently: give it another name, "
                         "write it to another reports folder (--reports), or remove that folder")


def _claim(study: Study, folder: Path) -> None:
    """Record which declaration ``folder`` holds (``study.json``, :func:`check_claim`)."""
    text = json.dumps(_record(study), indent=1) + "\n"
    path = folder / "study.json"
    if not path.is_file() or path.read_text(encoding="utf-8", errors="replace") != text:
        atomic_write(path, lambda tmp: tmp.write_text(text, encoding="utf-8"))


def study_folder(suite: Suite, study: Study, report_root: Path | None = None) -> Path:
    root = Path(os.path.abspath(Path(report_root).expanduser())) if report_root else suite.default_reports()
    return root / "studies" / study.name


def run_study(suite: Suite, study: Study, *, report_root: Path | None = None, jobs: int = 1, force: bool = False,
              timeout_s: float = 1800, retries: int = 1, progress="plain", executor: str = "local",
              scheduler: str | None = None, kernel_name: str | None = None):
    """Run every point of ``study`` in one runner session into ``<report_root>/studies/<name>/`` and write its
    study.csv and plots (also after an interrupt: the points finished so far). Returns the
    :class:`~locbook.suite.runner.SuiteRun` (one outcome per point, by folder key)."""

    points = expand_study(study)     # every value checked before anything runs
    folder = study_folder(suite, study, report_root)
    check_claim(study, folder)       # another study of this name: refused before anything runs
    labels = point_labels(points)
    # a point with the profile's own values (replicate 0 of an unswept default) is that report: reused, not rerun
    profile_folder = folder.parent.parent / study.profile
    tasks = [Task(p.key, p.experiment, p.parameters, label=labels[p.key], reuse=profile_folder / p.experiment.id)
             for p in points]
    # run.aggregate: what study.csv holds now, for the CLI to say (not rewritten: none up to date, or its write failed)
    return run_sweep(suite, tasks, study.profile, folder,
                     lambda where, outcomes, wrote: write_study_outputs(study, points, where, outcomes, wrote),
                     folder / "study.csv", jobs=jobs, force=force, timeout_s=timeout_s, retries=retries,
                     kernel_name=kernel_name, progress=progress, executor=executor, scheduler=scheduler)
