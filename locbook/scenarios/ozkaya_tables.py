"""Ozkaya (2011)'s printed simulation tables (Tables 7.1-7.25, 7.45, 7.46): each printed row as a case
(:func:`simulation_cases`), the runs behind them (:func:`run_tables`), their scoring (:func:`record_tables`) with the
known misses, the printed CRLB values beside the bound (:func:`crlb_rows`, :func:`record_crlb`), and the views and
settling rules the notebooks show.
"""
from __future__ import annotations

from dataclasses import replace
from functools import lru_cache

import numpy as np

from .._deprecation import renamed_keyword, renamed_names
from ..reproduce.scoring import Ambiguity, score
from .ozkaya_interpretations import (
    LAYOUTS_OF_HALF,
    fitted_calibrated_from,
    fitted_interpretations,
    run_summary,
    sim_interpretations,
    text_interpretation_note,
    with_interpretations,
)
from .ozkaya_simulation import (
    HALF_SEPARATION_LAYOUTS,
    PATH_LOSS_EXP,
    PRINTED,
    SIM_INTERPRETATIONS,
    STATISTICS,
    SimCase,
    case_seed_sequence,
    check_interpretation,
    printed_cell,
    thesis_crlb_m,
)

# -- the printed simulation tables as cases -----------------------------------------------------------
_NN, _GRID, _SIR = SimCase("nn"), SimCase("grid", "mobile"), SimCase("sir", "mobile")
_IMPROVED = dict(resample_threshold=0.5, weight_smoothing="sqrt")
#: rt per sigma (dB): grid Tables 7.10/7.11, SIR Tables 7.15/7.16.
GRID_RT_BY_SIGMA = {1.0: 8, 3.0: 8, 5.2: 10, 7.0: 12, 9.0: 16}
SIR_RT_BY_SIGMA = {1.0: 6, 3.0: 8, 5.2: 10, 7.0: 16, 9.0: 20}


def simulation_cases() -> list[tuple[str, str, str | None, SimCase]]:
    """``(table, row, column, case)`` for every printed simulation result. ``column`` None means every
    statistic of the row; ``"rmse_m@sigma=..."`` names one cell of Tables 7.7 / 7.14."""
    cases = []
    add = cases.append
    for k_cell, k_nn in zip((6, 8, 16, 28, 56, 98, 112), (3, 4, 8, 14, 28, 49, 56)):
        add(("7.1", str(k_cell), None, replace(_NN, k_cell=k_cell, k_nn=k_nn)))
    for m in (3, 4):
        add(("7.2", str(m), None, replace(_NN, layout=f"corners{m}")))
    for s in (3, 5.2, 7, 9):
        add(("7.3", f"{s:g}", None, replace(_NN, sigma0_db=s, sigma_db=s)))
    for k in (1, 2, 3, 4, 5, 6, 7, 10, 15, 20, 23, 25, 28):
        add(("7.4", str(k), None, replace(_NN, k_nn=k)))
    add(("7.5", "Half of default (2.5 m, 4 m)", None, replace(_NN, layout="half3", k_nn=14)))
    add(("7.5", "Default (5 m, 8 m)", None, replace(_NN, k_nn=14)))
    for m in (3, 4):
        add(("7.6", f"160 / {m}", None, replace(_NN, layout=f"large{m}", k_cell=135, k_nn=68)))
        add(("7.6", f"40 / {m}", None, replace(_NN, layout=f"corners{m}")))
    for s in (1.0, 3.0, 5.2):
        for est in ("map", "mmse"):
            add(("7.7", est.upper(), f"rmse_m@sigma={s:g}",
                 replace(_GRID, sigma0_db=s, sigma_db=s, rt=GRID_RT_BY_SIGMA[s], estimator=est)))
    for k_cell in (8, 28, 112):
        add(("7.8", str(k_cell), None, replace(_GRID, k_cell=k_cell)))
    for m in (3, 4):
        add(("7.9", str(m), None, replace(_GRID, layout=f"corners{m}")))
    for s, rt in GRID_RT_BY_SIGMA.items():
        add(("7.10", f"{s:g}", None, replace(_GRID, sigma0_db=s, sigma_db=s, rt=rt)))
        add(("7.11", f"{s:g}", None, replace(_GRID, target="fixed", sigma0_db=s, sigma_db=s, rt=rt)))
    for d, rt in ((0.1, 16), (0.5, 12), (1.0, 10)):
        add(("7.12", f"{d:g}", None, replace(_GRID, spread_m=d, motion_m=d, rt=rt)))
    for d, rt, label in ((0.1, 16, "0.1"), (0.5, 12, "0.5"), (1.0, 10, "1"), (np.inf, 8, "infinity")):
        add(("7.13", label, None, replace(_GRID, target="fixed", spread_m=d, rt=rt)))
    for s in (1.0, 3.0, 5.2):
        for est in ("map", "mmse"):
            add(("7.14", est.upper(), f"rmse_m@sigma={s:g}",
                 replace(_SIR, sigma0_db=s, sigma_db=s, rt=SIR_RT_BY_SIGMA[s], estimator=est)))
    for s, rt in SIR_RT_BY_SIGMA.items():
        add(("7.15", f"{s:g}", None, replace(_SIR, target="fixed", sigma0_db=s, sigma_db=s, rt=rt)))
        add(("7.16", f"{s:g}", None, replace(_SIR, sigma0_db=s, sigma_db=s, rt=rt)))
    for d in (0.1, 0.5, 1.0, 2.0, 4.0):
        add(("7.17", f"{d:g}", None, replace(_SIR, spread_m=d, motion_m=d)))
    for d, label in ((0.1, "0.1"), (0.5, "0.5"), (1.0, "1"), (2.0, "2"), (np.inf, "infinity")):
        add(("7.18", label, None, replace(_SIR, target="fixed", spread_m=d)))
    add(("7.19", "Gaussian, D = 0.5", None, _SIR))
    add(("7.19", "Uniform over the area", None, replace(_SIR, spread_m=np.inf)))
    cv = replace(_SIR, target="const_velocity")
    add(("7.20", "Gaussian, mean = known velocity, D = 0.5 / const. vel.", None, replace(cv, known_velocity=True)))
    add(("7.20", "Gaussian, zero mean, D = 0.5 / const. vel.", None, cv))
    add(("7.21", "Gaussian zero-mean, D = 0.5 / Gaussian, D_0 = 0.5", None, _SIR))
    add(("7.21", "same + initial location known / Gaussian, D_0 = 0.5", None, replace(_SIR, known_initial=True)))
    add(("7.21", "Gaussian, mean = known velocity, D = 0.5 / const. vel.", None, replace(cv, known_velocity=True)))
    add(("7.21", "same + initial location known / const. vel.", None,
         replace(cv, known_velocity=True, known_initial=True)))
    add(("7.22", "Up to walls / 1 m from walls", None, replace(_SIR, target_region="inner")))
    add(("7.22", "1 m from walls / 1 m from walls", None,
         replace(_SIR, target_region="inner", filter_region="inner")))
    for target, tlabel, t725 in (("mobile", "Gaussian D_0 = 0.5", "Gaussian D_0 = 0.5"), ("fixed", "Fixed", "fixed")):
        base = replace(_SIR, target=target)
        add(("7.23", f"Gaussian D = 0.5 / {tlabel}", None, base))
        add(("7.23", f"Gaussian D = 0.5, smoothed w / {tlabel}", None, replace(base, weight_smoothing="sqrt")))
        add(("7.24", f"Gaussian D = 0.5 / {tlabel}", None, base))
        for thr in (0.5, 0.3):
            add(("7.24", f"+ resample if N_eff < {thr:g} / {tlabel}", None, replace(base, resample_threshold=thr)))
        add(("7.25", f"Gaussian D = 0.5 / {t725}", None, base))
        add(("7.25", f"+ N_eff < 0.5 + w smoothing / {t725}", None, replace(base, **_IMPROVED)))
    add(("7.45", "Parameter-based offline NN", None, replace(_NN, k_nn=14)))
    add(("7.45", "Grid-based Bayesian", None, replace(_GRID, target="fixed")))
    add(("7.45", "Basic SIR", None, replace(_SIR, target="fixed")))
    add(("7.45", "Improved SIR", None, replace(_SIR, target="fixed", **_IMPROVED)))
    add(("7.46", "Grid-based Bayesian", None, _GRID))
    add(("7.46", "Basic SIR", None, _SIR))
    add(("7.46", "Improved SIR", None, replace(_SIR, **_IMPROVED)))
    return cases


# -- running and recording tables -------------------------------------------------------------------
#: Sec. 7.2.1: every simulated setting is run this many times; the printed statistics are Monte-Carlo
#: estimates themselves.
THESIS_RUNS = int(PRINTED.get("Sec. 7.2.1 text", "simulation", "runs_per_setting").value)


def thesis_monte_carlo_ambiguity(standard_error: float, n_runs: int) -> Ambiguity:
    """The Monte-Carlo error of the thesis's own estimate: 2 standard errors of a THESIS_RUNS-run statistic,
    measured from our ``n_runs`` runs (SE scaled by sqrt(n_runs / THESIS_RUNS))."""
    size = 2.0 * standard_error * float(np.sqrt(n_runs / THESIS_RUNS))
    return Ambiguity(size, f"Monte-Carlo error of the thesis's own {THESIS_RUNS}-run statistic (2 standard errors, "
                     "measured here)", "Ozkaya 2011 Sec. 7.2.1")


#: Why a printed simulation cell is expected to be missed.
KNOWN_MISSES = {
    ("7.5", "Half of default (2.5 m, 4 m)"): (
        "reader positions of Fig. 7.6 are not printed: the interpretation half_separation_layout declares two assumed "
        "placements (the corner triangle halved about the room's centre, or with its centroid there); the thesis's "
        "may be neither"),
    ("7.19", "Uniform over the area"): (
        "the thesis's 'uniform proposal' is not a memoryless uniform draw (which ignores all motion and gives about "
        "1.75 m); its exact form is not stated"),
    ("7.20", "Gaussian, zero mean, D = 0.5 / const. vel."): (
        "constant-velocity protocol not fully stated (start x range, whether particles start uniform, step count); "
        "a separate pilot simulation of ours gets the same 1.6 m"),
    ("7.20", "Gaussian, mean = known velocity, D = 0.5 / const. vel."): (
        "constant-velocity protocol not fully stated (a separate pilot simulation: about 0.97 m with the same "
        "interpretation)"),
    ("7.21", "Gaussian, mean = known velocity, D = 0.5 / const. vel."): (
        "same case as Table 7.20 row 1 (constant-velocity protocol not fully stated)"),
    ("7.21", "same + initial location known / const. vel."): (
        "constant-velocity protocol not fully stated; with a known start this interpretation beats the thesis"),
}
_NN_LARGE_K = ("weighted-centroid NN with many neighbours: our error rises with k faster than the thesis's (the "
               "thesis's curve is flat beyond k = 10). Target sampling (whole room; the cell core gives the opposite "
               "trend) and weights (normalised 1/E^2, validated at k = 4 and k = 68) do not explain it")
for _k in ("15", "20", "23", "25", "28"):
    KNOWN_MISSES[("7.4", _k)] = _NN_LARGE_K
for _s in ("3", "5.2", "7", "9"):
    KNOWN_MISSES[("7.3", _s)] = ("parameter-based NN errors come out 0.05-0.15 m below the thesis's at every sigma_0 "
                                 "(a separate pilot simulation found the same: 1.36/1.87/2.19/2.49 vs "
                                 "1.38/1.95/2.29/2.57); the thesis's NN has some extra error source that is not "
                                 "described")
for _k in ("1", "2", "3", "4", "5", "6", "7"):
    KNOWN_MISSES[("7.4", _k)] = ("few-neighbour NN errors come out 0.1-0.2 m below the thesis's (a separate pilot "
                                  "simulation: k = 1 gives 1.97 vs 2.17); the cause is not known")
_SHAPE = ("the row's RMSE agrees; the shape of the error distribution differs (here typically a higher median and a "
          "lower 90th percentile than printed, i.e. fewer large errors); the thesis does not say how it computed "
          "percentiles")
_UNEXPLAINED = ("not explained: the simulation protocol is a reconstruction (it matches most tables to "
                "about 0.1 m) and the thesis does not print every setting of this case")


def _statistic(column: str) -> str:
    return "rmse_m" if column.startswith("rmse_m") else column


@lru_cache(maxsize=None)
def _first_printings() -> dict:
    """(case, statistic) -> the first printed cell of that setting and statistic, in the thesis's table order."""
    first: dict = {}
    for table, row, column, case in simulation_cases():
        columns = [column] if column else [c for c in STATISTICS if printed_cell(table, row, c) is not None]
        for col in columns:
            first.setdefault((case, _statistic(col)), printed_cell(table, row, col))
    return first


@renamed_keyword("readings", "interpretations")
def run_tables(tables, n_runs: int, seed: int, *, interpretations: dict | None = None, **overrides) -> list[dict]:
    """Run every case of the given tables (e.g. ``["7.1", "7.2"]``) and return long-form rows ``table, row,
    column, printed`` (the :class:`~locbook.reproduce.Printed`), ``reproduced, se_m, case, first_printed`` for every
    printed statistic; CRLB cells carry ``reproduced`` = the thesis-form bound and ``se_m`` None. Identical
    settings are simulated once. ``first_printed`` is the first printing of the same setting and statistic
    in the thesis (the row itself if it is the first). ``overrides`` replace :class:`SimCase` fields in every
    case (e.g. ``n_particles=500``); fields a case does not use are ignored by it. ``interpretations``: the simulation
    interpretations (:func:`sim_interpretations`; omitted ones at their defaults), applied by
    :func:`with_interpretations` and
    :func:`run_summary`."""
    interpretations = sim_interpretations(**(interpretations or {}))
    wanted = {str(t) for t in tables}
    first = _first_printings()
    cache: dict = {}
    rows = []
    for table, row, column, base_case in simulation_cases():
        if table not in wanted:
            continue
        case = replace(with_interpretations(base_case, interpretations), **overrides)
        if case not in cache:
            bootstrap_rng = np.random.default_rng(case_seed_sequence(seed, case).spawn(1)[0])
            cache[case] = run_summary(case, n_runs, seed, interpretations, bootstrap_rng)
        res = cache[case]
        columns = [column] if column else [c for c in STATISTICS if printed_cell(table, row, c) is not None]
        for col in columns:
            stat = _statistic(col)
            rows.append({"table": table, "row": row, "column": col, "printed": printed_cell(table, row, col),
                         "reproduced": res[stat], "se_m": res[stat + "_se"], "case": case,
                         "first_printed": first[(base_case, stat)], "interpretations": interpretations})
        crlb = printed_cell(table, row, "crlb_m")
        if crlb is not None:
            rows.append({"table": table, "row": row, "column": "crlb_m", "printed": crlb,
                         "reproduced": thesis_crlb_m(case.layout, case.sigma0_db), "se_m": None, "case": case,
                         "first_printed": None})
    for table in ("7.7", "7.14"):
        if table in wanted:
            for s in (1.0, 3.0, 5.2):
                col = f"rmse_m@sigma={s:g}"
                rows.append({"table": table, "row": "CRLB", "column": col, "printed": printed_cell(table, "CRLB", col),
                             "reproduced": thesis_crlb_m("corners3", s), "se_m": None, "case": None,
                             "first_printed": None})
    return rows


def is_crlb_row(row: dict) -> bool:
    return row["column"] == "crlb_m" or row["row"] == "CRLB"


def record_tables(report, rows, n_runs: int) -> None:
    """Record every printed error statistic of ``rows`` (from :func:`run_tables`) as a ``reproduction``, or as
    ``calibrated`` when an interpretation fitted to the printed tables moves it (:func:`fitted_calibrated_from`; no
    simulation interpretation is: each value of theirs is textual). A miss or loose row names the contested
    interpretations it was computed under and the other interpretations the bracket runs
    (:func:`text_interpretation_note`), then the known cause (:data:`KNOWN_MISSES`) or a generic one.

    Window: the printed rounding, 2 of our standard errors and the thesis's own Monte-Carlo error
    (:func:`thesis_monte_carlo_ambiguity`). A setting the thesis prints again with the same value is compared
    at its first printing and linked there (``same_as``); a repeat printed with another value is compared as
    well, with a note. CRLB cells are not recorded here: they are compared once, in ``ozkaya2011-crlb``.
    """
    for r in rows:
        if is_crlb_row(r):
            continue
        p, first = r["printed"], r["first_printed"]
        same_as = first if first.id != p.id and first.value == p.value else None
        ambiguity = thesis_monte_carlo_ambiguity(r["se_m"], n_runs)
        calibrated_from = fitted_calibrated_from(r.get("interpretations") or sim_interpretations(), r["case"])
        kind = "calibrated" if calibrated_from else "reproduction"
        judged = score(kind, p.text, r["reproduced"], mc_std_error=r["se_m"], ambiguity=ambiguity,
                       linked=same_as is not None)
        note = ""
        text_note = (text_interpretation_note(r.get("interpretations") or sim_interpretations(), r["case"],
                                              report.experiment, r["reproduced"], p.value)
                     if judged.verdict in ("miss", "loose") else "")
        if text_note:
            # the interpretations are the first suspect; a known cause is named after them
            known = KNOWN_MISSES.get((r["table"], r["row"]), "")
            note = f"{text_note}. Also: {known}" if known else text_note
        elif judged.verdict in ("miss", "loose"):
            note = KNOWN_MISSES.get((r["table"], r["row"]), "")
            if not note and judged.verdict == "miss":
                rmse = next((q for q in rows if q["table"] == r["table"] and q["row"] == r["row"]
                             and q["column"] == "rmse_m"), None)
                rmse_ok = rmse is not None and r["column"] != "rmse_m" and score(
                    "reproduction", rmse["printed"].text, rmse["reproduced"], mc_std_error=rmse["se_m"],
                    ambiguity=thesis_monte_carlo_ambiguity(rmse["se_m"], n_runs)).verdict == "within"
                note = _SHAPE if rmse_ok else _UNEXPLAINED
        if first.id != p.id and first.value != p.value:
            note = (f"the thesis prints this setting again at {first.where} as {first.text}; both printed values "
                    "are compared. " + note).strip()
        report.number(r["column"], p, r["reproduced"], kind=kind, mc_std_error=r["se_m"],
                      ambiguity=ambiguity, same_as=same_as, note=note, calibrated_from=calibrated_from)


#: Note of a printed CRLB of a layout whose bound the printed formula cannot give (half-separation and large room).
CRLB_NOT_FROM_FORMULA = ("not reproducible: the printed CRLB formula is scale-invariant (doubling the room and the "
                         "reader separations leaves it unchanged), so this value cannot come from it; the layout or "
                         "the formula behind it is not printed")


#: The CRLB as the text states it outside the tables' columns: (location, item, sigma_0 in dB) of
#: locbook/data/printed/ozkaya2011.csv; the default 3-reader layout of Fig. 7.2 in each.
TEXT_CRLB = (("Sec. 7.2.2.1 text (Fig. 7.5)", "k_NN sweep, sigma_0 = 11 dB", 11.0),
             ("Sec. 7.2.2.1 text (Table 7.1)", "changing number of grid cells", 5.2),
             ("Fig. 7.4 caption", "k_NN sweep, sigma_0 = 5.2 dB", 5.2),
             ("Table 7.8 caption", "changing number of grid cells", 5.2),
             ("Table 7.12 caption", "different D = D_0", 5.2),
             ("Table 7.13 caption", "changing filter D", 5.2),
             ("Table 7.17 caption", "SIR with changing D = D_0", 5.2),
             ("Table 7.18 caption", "SIR with changing D, fixed target", 5.2),
             ("Table 7.45 caption", "all simulated methods, fixed target", 5.2),
             ("Table 7.46 caption", "probabilistic methods, mobile target", 5.2))


def crlb_rows() -> list[dict]:
    """Every printed CRLB cell of the simulation tables with its layout and sigma (from the table's case), the first
    printing of the same (layout, sigma) (``first_printed``), and how to record it: ``same_as`` is that first
    printing when this cell prints the same value again (a repeat, linked), else None; ``note`` says when the thesis
    prints the bound again with a different value (both are compared) and, for the layouts the scale-invariant
    printed formula cannot give (:data:`CRLB_NOT_FROM_FORMULA`), why it is not reproducible."""
    rows, first = [], {}
    seen = set()
    for table, row, column, case in simulation_cases():
        p = printed_cell(table, row, "crlb_m")
        if p is None or p.id in seen:
            continue
        seen.add(p.id)
        key = (case.layout, case.sigma0_db)
        first.setdefault(key, p)
        rows.append({"printed": p, "layout": case.layout, "sigma_db": case.sigma0_db, "first_printed": first[key]})
    for table in ("7.7", "7.14"):
        for s in (1.0, 3.0, 5.2):
            p = printed_cell(table, "CRLB", f"rmse_m@sigma={s:g}")
            first.setdefault(("corners3", s), p)
            rows.append({"printed": p, "layout": "corners3", "sigma_db": s, "first_printed": first[("corners3", s)]})
    # the bound the text states outside the tables' CRLB columns: Fig. 7.5's 1.70 m at sigma_0 = 11 dB (printed
    # nowhere else) and the captions' restatements of the default 0.80 m (linked to its first printing)
    for location, item, sigma in TEXT_CRLB:
        p = PRINTED.get(location, item, "crlb_m")
        first.setdefault(("corners3", sigma), p)
        rows.append({"printed": p, "layout": "corners3", "sigma_db": sigma,
                     "first_printed": first[("corners3", sigma)]})
    for r in rows:
        p, again = r["printed"], r["first_printed"]
        r["same_as"] = again if again.id != p.id and again.value == p.value else None
        note = CRLB_NOT_FROM_FORMULA if r["layout"] in ("half3", "large3", "large4") else ""
        if again.id != p.id and again.value != p.value:
            note = f"the thesis prints this bound again at {again.where} as {again.text}; both are compared. " + note
        r["note"] = note.strip()
    return rows


def record_crlb(report, path_loss_exp: float = PATH_LOSS_EXP, average: str = "area_rms",
                half_separation_layout: str = SIM_INTERPRETATIONS["half_separation_layout"][0]) -> None:
    """Record every printed CRLB cell (:func:`crlb_rows`, each compared once) against :func:`thesis_crlb_m` under
    the interpretations ``crlb_exponent`` = ``path_loss_exp`` and ``crlb_average`` = ``average``: ``calibrated`` when
    either is the value fitted to the printed columns (:data:`FITTED_VALUES`), naming it; else a ``reproduction`` whose
    miss says the fitted interpretations are the alternatives the bracket runs (:func:`text_interpretation_note`). Table
    7.5's half-separation bound is taken with the readers the interpretation ``half_separation_layout`` places
    (:data:`HALF_SEPARATION_LAYOUTS`). The layouts the scale-invariant printed formula cannot give keep their own note
    (:data:`CRLB_NOT_FROM_FORMULA`)."""
    check_interpretation("half_separation_layout", half_separation_layout)
    chosen = {"crlb_exponent": path_loss_exp, "crlb_average": average}
    fitted = fitted_interpretations(chosen)
    what = {"crlb_exponent": f"n = {path_loss_exp:g} (not the simulations' {PATH_LOSS_EXP:g})",
            "crlb_average": "the mean over the 1 m cells"}
    chosen_because = ", both chosen because they reproduce" if len(fitted) == 2 else ", chosen because it reproduces"
    calibrated_from = ("printed-form bound (Eqs. A.10-A.12, 1/d^2) with " + " and ".join(what[n] for n in fitted)
                       + chosen_because + " the printed CRLB columns (Fig. 7.1, Tables 7.1-7.6)") if fitted else ""
    for r in crlb_rows():
        p = r["printed"]
        layout = HALF_SEPARATION_LAYOUTS[half_separation_layout] if r["layout"] in LAYOUTS_OF_HALF else r["layout"]
        ours = thesis_crlb_m(layout, r["sigma_db"], path_loss_exp, average=average)
        miss_note = "" if r["layout"] in ("half3", "large3", "large4") else text_interpretation_note(
            chosen, None, report.experiment, ours, p.value, fitted_to="the printed CRLB columns")
        report.number("CRLB (thesis form)", p, ours, kind="calibrated" if fitted else "reproduction",
                      calibrated_from=calibrated_from, same_as=r["same_as"], note=r["note"], miss_note=miss_note,
                      loose_note=miss_note)


def table_view(rows, table: str) -> list[dict]:
    """One display row per printed row: printed (as printed) and ours side by side for each column."""
    out: dict = {}
    for r in rows:
        if r["table"] != table:
            continue
        d = out.setdefault(r["row"], {"row": r["row"]})
        d[r["column"] + " printed"] = r["printed"].text
        d[r["column"] + " ours"] = round(r["reproduced"], 2)
    return list(out.values())


def settling_step(mean_error_m, tolerance_m: float = 0.1) -> int:
    """First recursion (1-based) from which the mean error stays within ``tolerance_m`` of its final value:
    the thesis reads settling times off Figs. 7.7-7.9 and 7.12-7.14 without defining them."""
    e = np.asarray(mean_error_m, float)
    inside = np.abs(e - e[-1]) <= tolerance_m
    outside = np.flatnonzero(~inside)
    return int(outside[-1] + 2) if outside.size else 1


def settling_interpretation(mean_error_m, tolerance_m: float, source: str) -> tuple[int, Ambiguity]:
    """Our settling recursion (:func:`settling_step` at ``tolerance_m``) and the ambiguity of the undefined
    "settles": how far it moves when the tolerance is halved or doubled (:meth:`Ambiguity.spread`); ``source`` the
    thesis passage that reads the settling off its figure."""
    settled = settling_step(mean_error_m, tolerance_m)
    moved = [settling_step(mean_error_m, t) for t in (tolerance_m / 2, 2 * tolerance_m)]
    return settled, Ambiguity.spread(moved, settled, "settling is not defined; ours is the first recursion within "
                                     f"{tolerance_m} m of the final mean error, and the ambiguity is how far it moves "
                                     "when that tolerance is halved or doubled", source)


# the names before "reading" meant only a sensor measurement (deprecated for one release)
__getattr__ = renamed_names(__name__, {
    "settling_reading": "settling_interpretation",
})
