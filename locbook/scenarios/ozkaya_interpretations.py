"""Ozkaya (2011)'s contested simulation interpretations (locbook/data/interpretations/ozkaya2011.csv): which are fitted
to printed output, how a miss note names them, a case under chosen interpretations (:func:`with_interpretations`,
:func:`run_summary`) and how they are recorded as assumptions.
"""
from __future__ import annotations

from dataclasses import replace

import numpy as np

from .._deprecation import renamed_keyword, renamed_names
from ..errors import ParameterError
from ..reproduce.interpretations import interpretations as declared_interpretations
from .ozkaya_simulation import (
    HALF_SEPARATION_LAYOUTS,
    LAYOUTS,
    PATH_LOSS_EXP,
    ROOM_M,
    SIM_INTERPRETATIONS,
    SimCase,
    check_interpretation,
    run_case,
    summarize,
)

#: The values that nothing in the text supports and that were chosen because they fit printed output (basis
#: ``fitted`` in the interpretations CSV): interpretation name -> the fitted value. Rows computed under one are
#: calibrations. The simulation interpretations are not here: each of their values is supported by the text
#: (interpretations CSV, ``quotes``).
FITTED_VALUES = {"crlb_average": "cells_mean", "crlb_exponent": 2.0}


def _can_move(name: str, case: SimCase | None) -> bool:
    """Whether interpretation ``name`` can change the errors of ``case`` (noise interpretations need noise; the fixed
    target's noise needs recursions; the mobile protocol a mobile target); None: any case."""
    if case is None:
        return True
    if name == "reader_noise":
        return case.sigma0_db > 0
    if name == "fixed_target_noise":
        return case.sigma0_db > 0 and case.target == "fixed" and case.method != "nn"
    if name == "mobile_protocol":
        return case.target == "mobile"
    return True


def fitted_interpretations(chosen: dict, case: SimCase | None = None) -> tuple[str, ...]:
    """The names of the ``chosen`` interpretations (name -> value) set to a value fitted to the printed output
    (:data:`FITTED_VALUES`); with ``case``, only those that can move that case's numbers. A row computed under any of
    them is ``calibrated`` and names them (:func:`fitted_calibrated_from`)."""
    return tuple(n for n, v in chosen.items() if n in FITTED_VALUES and v == FITTED_VALUES[n] and _can_move(n, case))


def fitted_calibrated_from(chosen: dict, case: SimCase | None = None) -> str:
    """The ``calibrated_from`` text of a row computed under ``chosen`` (empty when no fitted interpretation
    moves it)."""
    names = fitted_interpretations(chosen, case)
    if not names:
        return ""
    return ("; ".join(f"{n} = {chosen[n]!r}" for n in names) + " chosen because they reproduce the printed output "
            "(interpretations no text supports, locbook/data/interpretations/ozkaya2011.csv)")


#: How each contested interpretation reads in a miss note: interpretation name -> value -> words. The first value of
#: each is the declared default.
_INTERPRETATION_WORDS = {
    "reader_noise": {"independent_per_reader": "noise independent per reader",
                     "common_mode": "common-mode noise on the transmit power"},
    "fixed_target_noise": {"frozen_per_run": "a fixed target's noise frozen over the run",
                           "fresh_per_step": "a fixed target's noise drawn afresh at every recursion"},
    "mobile_protocol": {"reflect_error_at_rt": "a mobile run's error at recursion rt",
                        "mean_over_recursions": "a mobile run's statistics over every recursion"},
    "crlb_exponent": {PATH_LOSS_EXP: f"n = {PATH_LOSS_EXP:g}", 2.0: "n = 2"},
    "crlb_average": {"area_rms": "the RMS over the room", "cells_mean": "the mean over the 1 m cells"},
}


def unfitted_interpretations(chosen: dict, case: SimCase | None = None) -> tuple[str, ...]:
    """The names of the contested interpretations (:data:`_INTERPRETATION_WORDS`) that ``chosen`` sets and that can move
    ``case`` (any case when None), other than those set to a value fitted to the output: the interpretations a miss
    note names."""
    return tuple(n for n, v in chosen.items() if n in _INTERPRETATION_WORDS and _can_move(n, case)
                 and not (n in FITTED_VALUES and v == FITTED_VALUES[n]))


def _other_values(name: str, value) -> list:
    return [v for v in _INTERPRETATION_WORDS[name] if v != value]


def text_interpretation_note(chosen: dict, case: SimCase | None, experiment: str, reproduced: float,
                             printed_value: float, *, fitted_to: str = "the printed tables") -> str:
    """One line saying which contested interpretations a missed row was computed under
    (:func:`unfitted_interpretations`: those that can move ``case``), where our value falls, and which other
    interpretations ``locbook bracket <experiment>`` runs: each named ``textual`` (another interpretation the text
    supports) or as fitted to ``fitted_to`` (no text supports it). Empty when no such interpretation moves the case."""
    names = unfitted_interpretations(chosen, case)
    if not names:
        return ""
    ours = " and ".join(_INTERPRETATION_WORDS[n].get(chosen[n], f"{n} = {chosen[n]!r}") for n in names)
    others = [(n, v) for n in names for v in _other_values(n, chosen[n])]
    textual = [_INTERPRETATION_WORDS[n][v] for n, v in others if not (n in FITTED_VALUES and v == FITTED_VALUES[n])]
    fitted = [_INTERPRETATION_WORDS[n][v] for n, v in others if n in FITTED_VALUES and v == FITTED_VALUES[n]]
    side = "below" if reproduced < printed_value else "above"
    parts = []
    if textual:
        parts.append(f"the other textual interpretation{'s' if len(textual) > 1 else ''} ({' and '.join(textual)})")
    if fitted:
        parts.append(f"the interpretation{'s' if len(fitted) > 1 else ''} fitted to {fitted_to}, which no text "
                     f"supports ({' and '.join(fitted)})")
    many = len(textual) + len(fitted) > 1
    return (f"under the interpretations run ({ours}) ours is {side} the printed value; " + " and ".join(parts)
            + (" are alternatives" if many else " is an alternative")
            + f": locbook bracket {experiment} runs {'them' if many else 'it'}")


def sim_interpretations(**chosen) -> dict:
    """Every simulation interpretation (:data:`SIM_INTERPRETATIONS`), the ``chosen`` values over the defaults; an
    unknown interpretation or value raises :class:`~locbook.errors.ParameterError` naming it."""
    for name, value in chosen.items():
        if name not in SIM_INTERPRETATIONS:
            raise ParameterError(f"unknown simulation interpretation {name!r}; known: {sorted(SIM_INTERPRETATIONS)}")
        check_interpretation(name, value)
    return {name: chosen.get(name, values[0]) for name, values in SIM_INTERPRETATIONS.items()}


@renamed_keyword("readings", "interpretations")
def with_interpretations(case: SimCase, interpretations: dict | None = None) -> SimCase:
    """``case`` under the simulation ``interpretations`` (:func:`sim_interpretations`): a target the thesis places 'at
    random in the room' (``target_region="room"``) is drawn per ``target_sampling``; a region the thesis prints (Table
    7.22's 1 m from the walls) is kept. The noise, weight, threshold, wall and known-start interpretations set their
    fields, and
    ``half_separation_layout`` the readers of a half-separation case (Table 7.5)."""
    r = sim_interpretations(**(interpretations or {}))
    layout = HALF_SEPARATION_LAYOUTS[r["half_separation_layout"]] if case.layout in LAYOUTS_OF_HALF else case.layout
    return replace(case, target_region=r["target_sampling"] if case.target_region == "room" else case.target_region,
                   nn_weights=r["nn_weights"], reader_noise=r["reader_noise"],
                   fixed_target_noise=r["fixed_target_noise"], resample_threshold_unit=r["resample_threshold"],
                   wall_handling=r["wall_handling"], initial_location=r["known_initial_location"], layout=layout)


#: The layouts a half-separation case may hold (:data:`HALF_SEPARATION_LAYOUTS`).
LAYOUTS_OF_HALF = frozenset(HALF_SEPARATION_LAYOUTS.values())


@renamed_keyword("readings", "interpretations")
def run_summary(case: SimCase, n_runs: int, seed: int, interpretations: dict | None = None,
                rng: np.random.Generator | None = None) -> dict:
    """:func:`summarize` of ``case`` run under ``interpretations`` (:func:`with_interpretations`): the percentile
    convention, and the mobile protocol for a mobile target."""
    r = sim_interpretations(**(interpretations or {}))
    case = with_interpretations(case, r)
    _, per_step, _, _ = run_case(case, n_runs, seed, return_all=True)
    return summarize(per_step, rng, percentile_convention=r["percentile_convention"],
                     over_recursions=case.target == "mobile" and r["mobile_protocol"] == "mean_over_recursions")

def record_interpretations(report, chosen: dict) -> None:
    """Record each chosen interpretation (name -> value, names of locbook/data/interpretations/ozkaya2011.csv) as an
    assumption, with its source, the reason of the declaration and the other values it could take."""
    declared = {r.name: r for r in declared_interpretations("ozkaya2011")}
    for name, value in chosen.items():
        if name not in declared:
            raise ParameterError(f"unknown interpretation {name!r}; declared: {sorted(declared)}")
        r = declared[name]
        others = [v for v in r.values if v != value]
        report.assumption(name, value, f"{r.source}: {r.reason} (basis of the declared default: {r.basis}; other "
                          f"interpretations: {', '.join(map(str, others)) or 'none'})")


@renamed_keyword("readings", "interpretations")
def record_simulation_assumptions(report, interpretations: dict | None = None) -> None:
    """Record the assumptions shared by the Sec. 7.2 simulation notebooks (NN, grid, SIR and their comparison): the
    single 5 m x 8 m room with three corner readers, the cells, the averaging of the thesis's CRLB column, and the
    notebook's simulation ``interpretations`` (:func:`record_interpretations`: the noise and motion protocols, the
    percentiles)."""
    for name, value, reason in [
        ("room_m", ROOM_M, "Sec. 7.2.1: single 5 m x 8 m room, no walls"),
        ("anchors_m", LAYOUTS["corners3"], "three corners (separations 5 m and 8 m, Sec. 7.2.1); which three is not "
         "printed and is equivalent by symmetry"),
        ("target_protocol", "mobile: uniform start, Gaussian steps kept in the room per wall_handling, fresh noise "
         "each step; fixed: uniform position", "not fully printed (Sec. 7.2.1); the contested parts are the "
         "interpretations below"),
        ("cells", "nx x ny partition of the room shrunk by 0.5 m", "gives the printed 28 cells at x 1..4, y 1..7 and "
         "the 0.5 m and 2 m grids; the 6/16/56/98 patterns are not printed"),
        ("min_distance_m", 0.1, "avoids log10(0) at a reader (ours)"),
        ("thesis_crlb_average", f"RMS over the room, printed form (1/d^2), n = {PATH_LOSS_EXP:g}",
         "the CRLB column shown beside the tables (compared in ozkaya2011-crlb): the text's exponent and the RMS "
         "over positions; n = 2 with the mean over the 1 m cells, fitted to the printed columns, is the alternative"),
    ]:
        report.assumption(name, value, reason)
    record_interpretations(report, interpretations or {})


# the names before "reading" meant only a sensor measurement (deprecated for one release)
__getattr__ = renamed_names(__name__, {
    "fitted_readings": "fitted_interpretations",
    "unfitted_readings": "unfitted_interpretations",
    "text_reading_note": "text_interpretation_note",
    "sim_readings": "sim_interpretations",
    "with_readings": "with_interpretations",
    "record_readings": "record_interpretations",
})
