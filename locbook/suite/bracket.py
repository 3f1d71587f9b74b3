"""Interpretation brackets: does ANY plausible interpretation of what a source left unprinted reproduce a printed
number?

``locbook bracket EXPERIMENT`` runs the experiment under its declared interpretations
(:mod:`locbook.reproduce.interpretations`,
``locbook/data/interpretations/<document>.csv``) and gives every scored row a bracket verdict beside its verdict.

Points (each one task of :func:`locbook.suite.runner.run_tasks`, so lock, staging, validation, retries, interrupts,
Dask and the cache per point are the runner's): the ``default`` point (the profile's own parameters), then, one
interpretation at a time, a point per other value of each interpretation that a notebook parameter sets: every
alternative, and for a numeric range both ends ``low`` and ``high`` (rounded for an ``int`` parameter). Values equal to
the profile's value are not run again (except an interpretation's default under the values its ``requires`` column
names, which runs with them); an experiment's ``[experiment.bracket]`` parameters (the experiment list)
are set at every point, the default one included (never an interpretation's parameter; e.g. a notebook's own sweep of
interpretations the bracket runs as points anyway); two interpretations that name the same parameter value share one
point. When two or more interpretations name values fitted to printed output (the ``fitted`` column), one more point
sets them all at once, as they were chosen together (``fitted interpretations together [fitted]: ...``). Every value
is checked against the parameter's type and rule before anything runs (an interpretations file that names a value the
notebook refuses is a :class:`~locbook.suite.spec.SuiteError`). Interpretations act one at a time: a printed number
that only a combination of interpretations reaches is not found (declare the combination as an interpretation of its
own).

The points also include, for the interpretations an experiment's ``[experiment.bracket] factorial`` names, every
combination of their non-fitted values in which two or more differ from the default (``interpretations together: ...``):
interpretations that interact are judged together, not only one at a time.

The bracket verdict of a scored row (kind ``reproduction``, ``calibrated`` or ``claim`` with a within / loose /
miss verdict; arithmetic, shown and linked rows have none), one of the tiers :data:`BRACKETS`, decided in this
order:

``default``
    within under the default interpretation;
``other_interpretation``
    within under another declared interpretation that is not fitted (textual, or assumed where the text is silent):
    ``reached_by`` names each (``interpretation: parameter=value``);
``fitted_only``
    within only under a value fitted to printed output (``[fitted]``: rows under it are calibrations);
``open``
    not reached, and an interpretation that could matter was not swept: a gap (an interpretation no notebook parameter
    sets yet, with alternatives or a range), a point that failed, a range whose runs straddle the printed value
    (``open_interpretations`` names them), or a printed value beyond every run but within the Monte-Carlo margin of the
    nearest (below);
``loose``
    under at least one interpretation the printed value lies inside a window wider than +-25 % (``loose_under``): the
    comparison cannot decide;
``between``
    no run within, but the printed value lies inside the band of our values: ``between`` names the two runs on
    either side (an interpretation in between, not declared, might reach it);
``outside``
    beyond the band, and beyond the nearest run by more than its margin (``outside_margin``): the rounding, the
    ambiguity and two standard errors of the difference between two runs of that error, ours and the source's
    (:data:`SOURCE_SE_FACTOR`): the printed number disagrees with every plausible interpretation of its description.

A run whose error exceeds the experiment's ``largest_error_m`` (``[experiment.bracket]``, the diagonal of the area
the source prints) is implausible: it is named in ``implausible`` and counts for nothing (neither band nor
verdict). "Within" is the point's own verdict, i.e. under that run's window (rounding, 2 Monte-Carlo standard errors
at the bracket's profile, the named ambiguity). ``band_low`` / ``band_high`` are the smallest and largest of our
plausible values over every point, ``closest`` the value nearest the printed one and ``closest_interpretation`` its
point.

Outputs in ``<reports>/brackets/<experiment>/``: ``bracket.csv`` (:data:`BRACKET_COLUMNS`, one row per scored
row of the default point), ``values.csv`` (:data:`VALUE_COLUMNS`: every scored row under every point, with the
point's basis, for the conclusions pages), ``points.csv`` (:data:`POINT_COLUMNS`: what each point changed and how it
ended) and one report folder per point. The site (index, pages, ``numbers.csv``, and each document's findings and
conclusions pages: :mod:`locbook.suite.findings`, :mod:`locbook.suite.conclusions`) shows the bracket of each row
(:func:`bracket_of_rows`) in the folders of a profile (``reports/quick``, ``reports/full``; not a ``-p`` run's
folder), rebuilt by the next ``locbook run`` (a cached run costs nothing): ``default`` when the row is within in
that report, else what the bracket's other interpretations gave, named with the bracket's profile; where no bracket.csv
exists at all, a row keeps the bracket columns the folder's numbers.csv gave it while its value and verdict are
unchanged. After every bracket run, also an interrupted or failed one, bracket.csv, values.csv and points.csv are
rebuilt from every point with an up-to-date report, this run's and earlier ones
(:func:`~locbook.suite.sweep.current_points`); a bracket whose default point has none writes nothing (an earlier
one is kept).
"""
from __future__ import annotations

import csv
import io
import json
import math
import os
import re
from dataclasses import dataclass, field
from pathlib import Path

from .._deprecation import renamed_keyword, renamed_names, warn_deprecated
from ..errors import ParameterError
from ..reproduce.interpretations import Interpretation, interpretations_for, load_interpretation_file
from ..reproduce.printed_values import printed_number
from ..reproduce.scoring import BRACKETS
from .bracket_table import (
    BRACKET_COLUMNS,
    BRACKET_ROW_COLUMNS,
    DEFAULT_POINT,
    POINT_COLUMNS,
    SITE_NUMBER_COLUMNS,
    VALUE_COLUMNS,
    NoBracket,
    bracket_of_rows,
    brackets_root,
    counts,
    find_row,
    index_rows,
    is_scored,
    load_bracket,
    load_values,
)
from .files import point_key, point_text, read_csv, value_text, write_text_atomic
from .params import check_value
from .runner import Task
from .spec import Experiment, Suite, SuiteError, finite_float
from .sweep import Aggregate, current_points, run_sweep
from .sweep_pages import write_bracket_page

__all__ = ["BracketPoint", "find_experiment", "brackets_root", "SITE_NUMBER_COLUMNS", "BRACKET_ROW_COLUMNS",
           "experiment_interpretations", "bracket_settings", "counts", "VALUE_COLUMNS", "load_values",
           "read_interpretations_option", "bracket_points", "bracket_gaps", "run_bracket", "bracket_folder",
           "bracket_rows", "bracket_of_rows", "load_bracket", "NoBracket", "BRACKETS", "BRACKET_COLUMNS",
           "POINT_COLUMNS"]


@dataclass(frozen=True)
class BracketPoint:
    """One run of a bracket: ``parameter`` set to ``value`` (``None`` for the default point) for ``interpretations``
    (the declared interpretations that name this value); ``parameters`` every value the notebook gets."""

    key: str
    experiment: Experiment
    interpretations: tuple[Interpretation, ...]
    parameter: str
    value: object
    parameters: dict = field(hash=False)
    #: the joint point of the fitted values: parameter -> value (``parameter`` is then empty)
    together: dict = field(default_factory=dict, hash=False)
    #: other parameters set with ``value`` because the interpretation acts only together with them (its ``requires``)
    requires: dict = field(default_factory=dict, hash=False)
    #: each interpretation's own value at this point (interpretation name -> value; a shared point holds several)
    interpretation_values: dict = field(default_factory=dict, hash=False)
    #: a joint point of the ``factorial`` interpretations (``together`` then holds its values; not fitted)
    combined: bool = False

    @property
    def readings(self) -> tuple[Interpretation, ...]:
        """Deprecated name of :attr:`interpretations`."""
        warn_deprecated("BracketPoint.readings", "BracketPoint.interpretations", skip=(__name__,))
        return self.interpretations

    @property
    def reading_values(self) -> dict:
        """Deprecated name of :attr:`interpretation_values`."""
        warn_deprecated("BracketPoint.reading_values", "BracketPoint.interpretation_values", skip=(__name__,))
        return self.interpretation_values

    @property
    def fitted(self) -> bool:
        """True when a value of this point was fitted to printed results (rows under it are calibrations)."""
        if self.together and not self.combined:
            return True
        return any(r.is_fitted(self.interpretation_values.get(r.name, self.value)) for r in self.interpretations)

    @property
    def basis(self) -> str:
        """``default``, ``fitted`` (a fitted value), ``assumed`` (every value an interpretation the text is silent on),
        or
        ``textual`` (:meth:`~locbook.reproduce.interpretations.Interpretation.alternative_basis` of its values)."""
        if not self.interpretations:
            return DEFAULT_POINT
        if self.fitted:
            return "fitted"
        bases = {r.alternative_basis(self.interpretation_values.get(r.name, self.value)) for r in self.interpretations}
        return "assumed" if bases == {"assumed"} else "textual"

    @property
    def label(self) -> str:
        """``interpretation: parameter=value`` (``[fitted]`` after an interpretation whose value was fitted to printed
        results),
        ``fitted interpretations together [fitted]: p=v, q=w``, or ``default``."""
        if not self.interpretations:
            return DEFAULT_POINT
        if self.together and self.combined:
            return "interpretations together: " + ", ".join(f"{k}={_text(v)}" for k, v in self.together.items())
        if self.together:
            return "fitted interpretations together [fitted]: " + ", ".join(f"{k}={_text(v)}"
                                                                    for k, v in self.together.items())
        values = self.interpretation_values
        names = ", ".join(r.name + (" [fitted]" if r.is_fitted(values.get(r.name, self.value)) else "")
                          for r in self.interpretations)
        extra = "".join(f" with {k}={_text(v)}" for k, v in self.requires.items())
        return f"{names}: {self.parameter}={_text(self.value)}{extra}"


_text = value_text


def _sweep_values(interp: Interpretation, annotation: str) -> list:
    values = list(interp.alternatives)
    if interp.low is not None:
        if annotation.replace(" ", "").split("|")[0] == "int":   # int, int | None: the whole numbers inside
            values += [math.ceil(interp.low), math.floor(interp.high)]
        else:
            values += [interp.low, interp.high]
    return values


def _point_key(exp: Experiment, values: dict, taken: dict[str, str] | None = None) -> str:
    """The folder of a bracket point: the experiment id and the first 10 hex digits of the SHA-256 of its values (as
    committed in points.csv), or all 64 when those 10 are already ``taken`` (key -> values) by other values: a
    bracket has a few dozen points, and two of them never share a folder."""
    return point_key(exp.id, values, 10, taken)


def _same(a, b) -> bool:
    if isinstance(a, bool) or isinstance(b, bool):
        return a is b
    if isinstance(a, (int, float)) and isinstance(b, (int, float)):
        return float(a) == float(b)
    return a == b


def find_experiment(suite: Suite, experiment_id: str) -> Experiment:
    """The experiment of ``experiment_id`` (exactly: a bracket is per experiment)."""
    for exp in suite.experiments:
        if exp.id == experiment_id:
            return exp
    raise SuiteError(f"unknown experiment {experiment_id!r}; a bracket takes one experiment id (`locbook list`)")


def experiment_interpretations(exp: Experiment, interpretations: tuple[Interpretation, ...] | None = None
                               ) -> tuple[Interpretation, ...]:
    """The interpretations of ``exp``: those given (any that list it), else the declared ones of the package."""
    found = interpretations_for(exp.id) if interpretations is None else \
        tuple(r for r in interpretations if exp.id in r.experiments)
    if not found:
        raise SuiteError(f"no interpretations are declared for experiment {exp.id!r}, so there is nothing to bracket "
                         "(locbook/data/interpretations/<document>.csv, or give an interpretations file with "
                         "--interpretations)")
    return found


def bracket_gaps(interpretations: tuple[Interpretation, ...]) -> list[Interpretation]:
    """The interpretations that could move a row but cannot be swept: no notebook parameter sets them, and they name
    alternatives or a range."""
    return [r for r in interpretations if r.is_gap and (r.alternatives or r.low is not None)]


def _declared(exp: Experiment, declared: dict, name: str, who: str) -> None:
    """``who`` (e.g. ``interpretation george/x names parameter``) names a parameter the notebook must declare."""
    if name not in declared:
        raise SuiteError(f"{who} {name!r}, which {exp.id!r} does not declare (known: {', '.join(sorted(declared))})")


def _checked(exp: Experiment, declared: dict, name: str, value, who: str):
    """``value`` checked against the type and rule of ``name`` (declared); a refusal is a :class:`SuiteError`
    that starts with ``who``."""
    try:
        return check_value(declared[name], value, exp.rules.get(name))
    except ParameterError as exc:
        raise SuiteError(f"{who}: {exc}") from None


def bracket_settings(exp: Experiment, interpretations: tuple[Interpretation, ...]) -> dict:
    """The experiment's ``[experiment.bracket]`` parameters, checked: declared by the notebook, valid, and none
    of them an interpretation's parameter (they must not change what the bracket sweeps)."""
    declared = exp.declared_parameters()
    swept = {r.parameter for r in interpretations if not r.is_gap} | {k for r in interpretations for k in r.requires}
    profiled = {k for values in exp.profiles.values() for k in values}
    settings = {}
    who = f"[experiment.bracket] of {exp.id!r}"
    for name, value in exp.bracket_parameters.items():
        _declared(exp, declared, name, f"{who} sets")
        if name in swept:
            raise SuiteError(f"[experiment.bracket] of {exp.id!r} sets {name!r}, a parameter its interpretations sweep")
        if name in profiled:     # the default point must stay the profile's run (the site compares the two)
            raise SuiteError(f"[experiment.bracket] of {exp.id!r} sets {name!r}, which a profile sets")
        settings[name] = _checked(exp, declared, name, value, who)
    return settings


def _required(exp: Experiment, interp: Interpretation, declared: dict, base: dict) -> dict:
    """The values of ``interp.requires`` that differ from ``base``, checked (an interpretation of the packaged
    files or of ``--interpretations``: an unknown parameter or a refused value is a :class:`SuiteError`)."""
    out = {}
    for name, value in interp.requires.items():
        _declared(exp, declared, name, f"interpretation {interp.document}/{interp.name} requires parameter")
        checked = _checked(exp, declared, name, value, f"interpretation {interp.document}/{interp.name} of {exp.id!r} "
                                                       "(requires)")
        if not _same(checked, base.get(name, declared[name].default)):
            out[name] = checked
    return out


def bracket_points(exp: Experiment, profile: str, interpretations: tuple[Interpretation, ...]) -> list[BracketPoint]:
    """The default point, then one point per other value of each sweepable interpretation (module docstring), every
    value checked against the parameter's type and rule."""
    declared = exp.declared_parameters()
    base = {**exp.parameters(profile), **bracket_settings(exp, interpretations)}
    points = [BracketPoint(f"{exp.id}-{DEFAULT_POINT}", exp, (), "", None, base)]
    by_value: dict[str, int] = {}       # the values a point changes (canonical text) -> its index
    taken: dict[str, str] = {}          # folder key -> the values it holds
    for interp in interpretations:
        if interp.is_gap:
            continue
        _declared(exp, declared, interp.parameter, f"interpretation {interp.document}/{interp.name} names parameter")
        param = declared[interp.parameter]
        profiled = base.get(interp.parameter, param.default)
        if interp.default is not None and not _same(profiled, interp.default):
            raise SuiteError(f"interpretation {interp.document}/{interp.name}: the {profile} profile of {exp.id!r} "
                             f"sets {interp.parameter} = {profiled!r}, not the declared default {interp.default!r}; "
                             "the bracket's default point would not be the default interpretation")
        requires = _required(exp, interp, declared, base)
        values = _sweep_values(interp, param.annotation)
        if requires and interp.default is not None:
            values = [interp.default, *values]     # the default too acts differently under what it requires
        for value in values:
            checked = _checked(exp, declared, interp.parameter, value,
                               f"interpretation {interp.document}/{interp.name} of {exp.id!r}")
            change = {**requires}
            if not _same(checked, base.get(interp.parameter, param.default)):
                change[interp.parameter] = checked
            if not change:
                continue       # the profile's own value: the default point
            text = point_text(change)
            if text in by_value:   # another interpretation names the same values: one run serves both
                i = by_value[text]
                if interp not in points[i].interpretations:
                    points[i] = BracketPoint(points[i].key, exp, (*points[i].interpretations, interp),
                                             points[i].parameter,
                                             points[i].value, points[i].parameters, requires=points[i].requires,
                                             interpretation_values={**points[i].interpretation_values,
                                                                    interp.name: checked})
                continue
            key = _point_key(exp, change, taken)
            taken[key] = text
            by_value[text] = len(points)
            points.append(BracketPoint(key, exp, (interp,), interp.parameter, checked, {**base, **change},
                                       requires=requires, interpretation_values={interp.name: checked}))
    # values fitted to printed output were chosen together: one more run sets them all at once
    fitted: dict[str, tuple[Interpretation, object]] = {}
    for interp in interpretations:
        if not interp.is_gap and interp.fitted:
            fitted.setdefault(interp.parameter, (interp, interp.fitted[0]))
    if len(fitted) >= 2:
        together = {p: check_value(declared[p], v, exp.rules.get(p)) for p, (_r, v) in fitted.items()}
        key = _point_key(exp, together, taken)
        taken[key] = point_text(together)
        by_value[point_text(together)] = len(points)
        points.append(BracketPoint(key, exp, tuple(r for r, _v in fitted.values()), "", None,
                                   {**base, **together}, together))
    points += _factorial_points(exp, interpretations, declared, base, by_value, taken)
    return points


def _factorial_points(exp: Experiment, interpretations: tuple[Interpretation, ...], declared: dict, base: dict,
                      by_value: dict, taken: dict) -> list[BracketPoint]:
    """The joint points of ``[experiment.bracket] factorial``: every combination of the named interpretations' values
    that are not fitted (the default, the textual or assumed alternatives, a range's ends) in which two or more differ
    from the default (one alone is a single interpretation's point); combinations that repeat a point are not run
    twice."""
    import itertools
    if not exp.bracket_factorial:
        return []
    by_name = {r.name: r for r in interpretations}
    chosen = []
    for name in exp.bracket_factorial:
        interp = by_name.get(name)
        if interp is None or interp.is_gap:
            raise SuiteError(f"[experiment.bracket] factorial of {exp.id!r} names {name!r}, which is not an "
                             f"interpretation of it that a notebook parameter sets (its interpretations: "
                             f"{', '.join(sorted(by_name))})")
        param = declared[interp.parameter]
        profiled = base.get(interp.parameter, param.default)
        values = [v for v in _sweep_values(interp, param.annotation) if not interp.is_fitted(v)]
        checked = [_checked(exp, declared, interp.parameter, v, f"interpretation {interp.document}/{interp.name} of "
                            f"{exp.id!r}") for v in values]
        chosen.append((interp, [profiled] + [v for v in checked if not _same(v, profiled)]))
    out = []
    for combo in itertools.product(*(values for _r, values in chosen)):
        change = {r.parameter: v for (r, values), v in zip(chosen, combo) if not _same(v, values[0])}
        if len(change) < 2:
            continue
        text = point_text(change)
        if text in by_value:
            continue
        key = _point_key(exp, change, taken)
        taken[key] = text
        by_value[text] = -1          # run once (a joint point is never shared by a later interpretation)
        values = {r.name: v for (r, _values), v in zip(chosen, combo) if r.parameter in change}
        out.append(BracketPoint(key, exp, tuple(r for r, _v in chosen if r.parameter in change), "", None,
                                {**base, **change}, dict(change), interpretation_values=values, combined=True))
    return out


# ---------------------------------------------------------------------------------------------------
# verdicts


def _crossings(printed: float | None, points: list[BracketPoint], values: dict[str, tuple]) -> list[str]:
    """The range interpretations with two neighbouring runs (the default and the range ends, in parameter order) that
    miss the printed value on opposite sides: in between it may be reached, and nothing ran there. (A run inside its
    window, loose, already puts the printed value inside: the interpretation is judged by those runs.) ``values``: point
    key -> (our value, verdict)."""
    if printed is None:
        return []
    out = []
    by_interpretation: dict[str, list[tuple[float, float, str]]] = {}
    for p in points[1:]:
        if p.together:          # other interpretations changed too: not a run of one interpretation
            continue
        v, verdict = values.get(p.key, (None, ""))
        for interp in p.interpretations:
            x = p.interpretation_values.get(interp.name)       # its value at the point (shared points too)
            if interp.low is not None and v is not None and isinstance(x, (int, float)) and not isinstance(x, bool):
                by_interpretation.setdefault(interp.name, []).append((float(x), v, verdict))
    default_v, default_verdict = values.get(points[0].key, (None, ""))
    for interp in {r.name: r for p in points[1:] for r in p.interpretations}.values():
        runs = by_interpretation.get(interp.name, [])
        if interp.low is None or not runs:
            continue
        base = points[0].parameters.get(interp.parameter, interp.default)
        # an interpretation whose required values the default point lacks has its own run at its default instead
        satisfied = all(_same(points[0].parameters.get(k), v) for k, v in interp.requires.items())
        if default_v is not None and isinstance(base, (int, float)) and satisfied:
            runs = [*runs, (float(base), default_v, default_verdict)]
        runs.sort()
        for (x0, y0, v0), (x1, y1, v1) in zip(runs, runs[1:]):
            if v0 == v1 == "miss" and (y0 - printed) * (y1 - printed) < 0:
                out.append(f"{interp.name} between {interp.parameter}={x0:g} and {x1:g} (ours {y0:.4g} .. "
                           f"{y1:.4g} straddles the printed value; not run in between)")
                break
    return out


#: The source's own Monte-Carlo error of a printed number, taken equal to ours where a row does not already hold it
#: in its ambiguity: the full profile runs the source's run count where it is printed (Ozkaya's 1000 runs), so an
#: ``outside`` verdict needs the printed value beyond our nearest value by more than the rounding, the ambiguity and
#: 2 standard errors of the difference of two such runs.
SOURCE_SE_FACTOR = 1.0
#: an ambiguity that already is the source's own Monte-Carlo error (Ozkaya's and Dogan's simulation rows)
_SOURCE_MC = re.compile(r"(thesis|source|paper)'s own[^;]*Monte-Carlo|Monte-Carlo error of the (thesis|source|paper)",
                        re.IGNORECASE)


def _printed_number(text: str) -> float | None:
    """The number in a printed text ('3.83m', 'reach accuracy 1 m'), None if it holds none or several."""
    try:
        value = printed_number(text)
    except ValueError:
        return None
    return value if math.isfinite(value) else None


def _margin(row: dict) -> float:
    """The half-width an ``outside`` verdict must clear around our value of ``row`` (a numbers row): rounding +
    ambiguity + 2 standard errors of (ours - printed), ours and the source's (:data:`SOURCE_SE_FACTOR`), the
    source's counted once: not again where the row's ambiguity already is it."""
    def num(column):
        v = finite_float(row.get(column, ""))
        return 0.0 if v is None else abs(v)
    se = num("mc_std_error")
    source = 0.0 if _SOURCE_MC.search(row.get("ambiguity_basis", "") or "") else SOURCE_SE_FACTOR
    return num("rounding") + num("ambiguity") + 2.0 * se * math.sqrt(1.0 + source ** 2)


_EXTREME = re.compile(r"\b(worst|max|maximum|largest)\b", re.IGNORECASE)


def _implausible(exp: Experiment, row: dict, value: float | None) -> bool:
    """A value no plausible interpretation gives: a typical error in metres (not a worst case or maximum, which may
    leave the area) over the experiment's ``largest_error_m`` (the area's diagonal, ``[experiment.bracket]``)."""
    return (exp.largest_error_m is not None and value is not None and row.get("unit") == "m"
            and not _EXTREME.search(f"{row.get('quantity', '')} {row.get('printed_id', '')}")
            and value > exp.largest_error_m)


def bracket_rows(exp: Experiment, points: list[BracketPoint], folder: Path, status: dict[str, str],
                 gaps: list[Interpretation], profile: str, values_out: list | None = None) -> list[dict]:
    """The bracket.csv rows: one per scored row of the default point (none if the default point did not run).

    ``status``: each point's outcome (``ok``, ``cached``, ``failed``, ``interrupted``, ``not run``). A point that did
    not finish, or finished without producing the row (renamed, linked, damaged numbers.csv), leaves the row
    ``open``, as does a range interpretation whose runs straddle the printed value (:func:`_crossings`). The verdict, in
    :data:`BRACKETS` order: ``default``; ``other_interpretation`` (within under a point with no fitted value);
    ``fitted_only``; then, reached by none: ``open``; ``loose``; ``between`` (the printed value inside the band of
    our plausible values: ``between`` names the two points either side); ``outside`` when the printed value
    also clears the band's nearest edge by :func:`_margin` (else ``open``: Monte-Carlo error could close the gap).
    A point whose value is implausible (:func:`_implausible`) is named in ``implausible`` and counts for nothing.
    ``values_out``: filled with the :data:`VALUE_COLUMNS` rows (every scored row under every point)."""
    done = {k for k, st in status.items() if st in ("ok", "cached")}
    if points[0].key not in done:
        return []
    default = read_csv(folder / points[0].key / "numbers.csv")
    others = [(p, index_rows(read_csv(folder / p.key / "numbers.csv"))) for p in points[1:] if p.key in done]
    unfinished = [f"{p.label} ({status.get(p.key, 'not run')})" for p in points[1:] if p.key not in done]
    gap_names = [f"{r.name} (gap: {r.where})" for r in gaps]
    rows = []
    for r in default:
        if not is_scored(r):
            continue
        printed = _printed_number(r["printed"])
        ours = finite_float(r["reproduced"])
        # (label, value, numbers row, point) of every point that produced the row
        runs = [(DEFAULT_POINT, ours, r, points[0])]
        by_key = {points[0].key: (ours, r["verdict"])}
        missing = []
        for p, indexed in others:
            alt = find_row(indexed, r)
            if alt is None or alt.get("verdict") not in ("within", "loose", "miss"):
                missing.append(f"{p.label} (row not produced)")
                continue
            value = finite_float(alt.get("reproduced", ""))
            runs.append((p.label, value, alt, p))
            by_key[p.key] = (value, alt["verdict"])
        if values_out is not None:
            values_out += [{"experiment": exp.id, "printed_id": r["printed_id"], "quantity": r["quantity"],
                            "where": r["where"], "point": p.key, "interpretation": label, "basis": p.basis,
                            "ours": row.get("reproduced", ""), "mc_std_error": row.get("mc_std_error", ""),
                            "verdict": row.get("verdict", "")} for label, _v, row, p in runs]
        implausible = [f"{label} gave {v:.4g} m, over the largest plausible error {exp.largest_error_m:g} m "
                       f"({exp.largest_error_reason})" for label, v, row, _p in runs if _implausible(exp, row, v)]
        plausible = [(label, v, row, p) for label, v, row, p in runs if not _implausible(exp, row, v)]
        others_ok = [(label, v, row, p) for label, v, row, p in runs[1:] if not _implausible(exp, row, v)]
        reached = [label for label, _v, row, p in others_ok if row["verdict"] == "within"]
        reached_textual = [label for label, _v, row, p in others_ok if row["verdict"] == "within" and not p.fitted]
        inside = [label for label, _v, row, _p in plausible if row["verdict"] == "loose"]
        # an implausible run counts for no verdict: not for a crossing either
        kept = {p.key for _l, _v, _r, p in plausible}
        open_names = gap_names + unfinished + missing + _crossings(
            printed, points, {k: v for k, v in by_key.items() if k in kept})
        finite = [(label, v, row) for label, v, row, _p in plausible if v is not None]
        low = min(finite, key=lambda x: x[1], default=None)
        high = max(finite, key=lambda x: x[1], default=None)
        between, margin_note = "", ""
        if printed is not None and low is not None:
            below = max((x for x in finite if x[1] <= printed), key=lambda x: x[1], default=None)
            above = min((x for x in finite if x[1] >= printed), key=lambda x: x[1], default=None)
            if below is not None and above is not None:
                between = f"{below[0]} ({below[1]:.4g}) and {above[0]} ({above[1]:.4g})"
            edge = low if printed < low[1] else high if printed > high[1] else None
            if edge is not None:
                margin = _margin(edge[2])
                gap = abs(printed - edge[1])
                margin_note = (f"{gap:.4g} from {edge[0]} ({edge[1]:.4g}), "
                               f"{'within' if gap <= margin else 'beyond'} its margin {margin:.4g} (rounding, "
                               "ambiguity, 2 SE of ours and the source's)")
        if r["verdict"] == "within" and not _implausible(exp, r, ours):
            verdict = "default"
        elif reached_textual:
            verdict = "other_interpretation"
        elif reached:
            verdict = "fitted_only"
        elif not finite:
            verdict = "open"
            open_names = ["no plausible run produced a value"]
        elif open_names:
            verdict = "open"
        elif inside:
            verdict = "loose"
        elif between:
            verdict = "between"
        elif margin_note and "within its margin" in margin_note:
            verdict = "open"
            open_names = [f"Monte-Carlo error: the printed value is {margin_note}; more runs would decide"]
        else:
            verdict = "outside"
        closest = (min(finite, key=lambda x: abs(x[1] - printed)) if finite and printed is not None
                   else ("", None, None))
        rows.append({"experiment": exp.id, "printed_id": r["printed_id"], "quantity": r["quantity"],
                     "where": r["where"], "unit": r["unit"], "kind": r["kind"], "printed": r["printed"],
                     "ours": r["reproduced"], "verdict": r["verdict"], "bracket": verdict,
                     "reached_by": "; ".join(reached),
                     "open_interpretations": "; ".join(open_names) if verdict == "open" else "",
                     "loose_under": "; ".join(inside) if not reached else "",
                     "between": between if verdict == "between" else "",
                     "band_low": _fmt(low[1] if low else None), "band_high": _fmt(high[1] if high else None),
                     "outside_margin": margin_note if verdict in ("outside", "open") else "",
                     "implausible": "; ".join(implausible),
                     "closest": _fmt(closest[1]), "closest_interpretation": closest[0], "points": len(finite),
                     "profile": profile})
    return rows


def _fmt(value: float | None) -> str:
    return "" if value is None else f"{value:.10g}"


# ---------------------------------------------------------------------------------------------------
# outputs

def bracket_folder(suite: Suite, exp: Experiment, report_root: Path | None = None) -> Path:
    root = Path(os.path.abspath(Path(report_root).expanduser())) if report_root else suite.default_reports()
    return root / "brackets" / exp.id


def _write_table(path: Path, columns, rows) -> None:
    out = io.StringIO()
    writer = csv.DictWriter(out, fieldnames=columns, lineterminator="\n")
    writer.writeheader()
    writer.writerows(rows)
    write_text_atomic(path, out.getvalue())


def write_bracket_outputs(exp: Experiment, points: list[BracketPoint], folder: Path, outcomes,
                          gaps: list[Interpretation], profile: str, suite: Suite, interpretations_file: str = "",
                          wrote: list | None = None) -> Aggregate:
    """bracket.csv, values.csv and points.csv, from every point with an up-to-date report (this
    run's and earlier ones: :func:`~locbook.suite.sweep.current_points`), so an interrupted or failed run never
    drops a point that still holds; a row is ``open`` while a point it needs has none. Without an up-to-date default
    point nothing is written (an earlier bracket is kept as it was). Each file is replaced atomically. ``wrote``: the
    :class:`~locbook.suite.sweep.Aggregate` is appended as soon as bracket.csv is in place (or known unwritten)."""
    status = current_points(folder, profile, [(p.key, exp, p.parameters, False) for p in points], outcomes)
    done = sum(st in ("ok", "cached") for st in status.values())
    path = folder / "bracket.csv"
    if status.get(points[0].key) not in ("ok", "cached"):
        aggregate = Aggregate(path, done, len(points), written=False)
        if wrote is not None:
            wrote.append(aggregate)
        return aggregate
    values: list[dict] = []
    rows = bracket_rows(exp, points, folder, status, gaps, profile, values)
    _write_table(folder / "values.csv", VALUE_COLUMNS, values)
    _write_table(path, BRACKET_COLUMNS, rows)
    aggregate = Aggregate(path, done, len(points))
    if wrote is not None:
        wrote.append(aggregate)
    _write_table(folder / "points.csv", POINT_COLUMNS, [
        {"point": i, "interpretations": ", ".join(r.name for r in p.interpretations),
         "parameter": ", ".join(p.together) if p.together else p.parameter,
         "value": ", ".join(_text(v) for v in p.together.values()) if p.together
         else "" if not p.parameter else _text(p.value), "status": status.get(p.key, "not run"),
         "folder": p.key, "generated_by": _stamp(folder / p.key), "interpretations_file": interpretations_file,
         # [experiment.bracket] as this bracket ran it (the findings page names it from here, not from today's file)
         "settings": "" if not exp.bracket_parameters else
         ", ".join(f"{k}={_text(v)}" for k, v in exp.bracket_parameters.items()) + f" ({exp.bracket_reason})"}
        for i, p in enumerate(points)])
    write_bracket_page(exp, rows, values, folder, profile)
    return aggregate


def _stamp(folder: Path) -> str:
    """The locbook version and commit a point's report was made by (its report.json), '' if it has none."""
    try:
        return str(json.loads((folder / "report.json").read_text(encoding="utf-8")).get("locbook", ""))
    except (OSError, ValueError, AttributeError):
        return ""


@renamed_keyword("readings", "interpretations")
def run_bracket(suite: Suite, exp: Experiment, *, profile: str = "quick",
                interpretations: tuple[Interpretation, ...] | None = None, report_root: Path | None = None,
                jobs: int = 1, force: bool = False, timeout_s: float = 1800, retries: int = 1, progress="plain",
                executor: str = "local", scheduler: str | None = None, kernel_name: str | None = None):
    """Run the bracket of ``exp`` (module docstring) into ``<report_root>/brackets/<experiment>/``.
    ``interpretations``: the interpretations to sweep (default: those the package declares for ``exp``). Returns the
    runner's :class:`~locbook.suite.runner.SuiteRun` (one outcome per point, by folder key)."""
    found = experiment_interpretations(exp, interpretations)
    # an interpretations file of one's own is named in points.csv (the packaged ones: empty)
    interpretations_file = "" if interpretations is None else \
        "; ".join(sorted({r.document for r in found})) + " (--interpretations)"
    points = bracket_points(exp, profile, found)      # every value checked before anything runs
    gaps = bracket_gaps(found)
    folder = bracket_folder(suite, exp, report_root)
    # numbers only; the point of the default interpretations is the profile's own report: reused when up to date
    tasks = [Task(p.key, exp, p.parameters, figures=False, label=p.label,
                  reuse=folder.parent.parent / profile / exp.id) for p in points]
    # run.aggregate: what bracket.csv holds now, for the CLI to say (not rewritten: no up-to-date default point, or a
    # failed write)
    return run_sweep(suite, tasks, profile, folder,
                     lambda where, outcomes, wrote: write_bracket_outputs(exp, points, where, outcomes, gaps, profile,
                                                                          suite, interpretations_file, wrote),
                     folder / "bracket.csv", jobs=jobs, force=force, timeout_s=timeout_s, retries=retries,
                     kernel_name=kernel_name, progress=progress, executor=executor, scheduler=scheduler)


def read_interpretations_option(path: Path | None) -> tuple[Interpretation, ...] | None:
    """``--interpretations FILE``: an interpretations CSV of one's own (the columns of locbook/data/interpretations),
    else None."""
    return None if path is None else load_interpretation_file(path)


# the names before "reading" meant only a sensor measurement (deprecated for one release)
__getattr__ = renamed_names(__name__, {"experiment_readings": "experiment_interpretations",
                                       "read_readings_option": "read_interpretations_option"})
