"""B. Ozkaya, "Application, comparison, and improvement of known received signal strength
indication (RSSI) based indoor localization and tracking methods using active RFID devices", M.Sc. thesis,
METU, 2011. Chapter 7 simulations.

The simulation protocol is the one stated in Sec. 7.2.1, each unprinted part read as the text supports best (issue
45: argued from quotes in locbook/data/interpretations/ozkaya2011.csv, never from a fit to the printed numbers): a 5 m x
8 m room without walls, readers at three (or four) corners, alpha = -52 dBm, n = 2.3 for every reader, zero-mean
Gaussian noise independent per reader (the product of one Gaussian per reader of Eq. (A.6), the model the filters and
the CRLB use), 1000 runs per setting. A *mobile* target starts uniformly in the room and takes one Gaussian step of std
D_0 per recursion (reflected at the walls, an assumption), with fresh noise at every step, and its error is taken at
recursion rt, after the wait "for a sufficient recursion time for the filter to settle" (Sec. 7.2.2.2); a *fixed*
target is uniform in the room and its noise is drawn once per run (one erroneous measurement at a location, the
thesis's "worst case scenario"). NN methods take one shot.

The other interpretations the text supports (common-mode noise "added on the transmit power", fresh noise at every
recursion of a fixed target, a mobile run's statistics over every recursion) are named alternatives
(:data:`SIM_INTERPRETATIONS`); rows computed under them are reproductions too. Only the values that no text supports and
that were chosen because they fit printed output (:data:`FITTED_VALUES`: the CRLB columns' n = 2 and the mean over the
cells) make a row ``calibrated``.

Every printed simulation result (Tables 7.1-7.25, 7.45, 7.46) is mapped to a :class:`SimCase` by
:func:`simulation_cases`; settings the thesis does not print are the documented defaults of the fields.

The code lives along the thesis's seams: :mod:`locbook.scenarios.ozkaya_simulation` (the Sec. 7.2 protocol and the
CRLB of a layout), :mod:`locbook.scenarios.ozkaya_interpretations` (the contested interpretations),
:mod:`locbook.scenarios.ozkaya_tables` (the printed simulation tables and their scoring) and
:mod:`locbook.scenarios.ozkaya_propagation` (Chs. 5-6); the test bed of Sec. 7.3 is
:mod:`locbook.scenarios.ozkaya_testbed`. This module gathers their public names, the namespace the notebooks use.
"""
from __future__ import annotations

from .._deprecation import renamed_names
from .ozkaya_interpretations import (
    FITTED_VALUES,
    LAYOUTS_OF_HALF,
    fitted_calibrated_from,
    fitted_interpretations,
    record_interpretations,
    record_simulation_assumptions,
    run_summary,
    sim_interpretations,
    text_interpretation_note,
    unfitted_interpretations,
    with_interpretations,
)
from .ozkaya_propagation import (
    AUTO_PARAMETERS,
    OFFLINE_PARAMETERS,
    R3_CALIBRATION_DISTANCES_M,
    READER_SENSITIVITY_DBM,
    REFERENCE_TAGS_M,
    TESTBED_READERS_M,
    TESTBED_SIZE_M,
    TESTBED_WALLS_M,
    WAF_DB,
    literature_table,
    synthetic_campaign,
)
from .ozkaya_simulation import (
    ALPHA_DBM,
    CELL_MARGIN_M,
    CELL_PATTERNS,
    HALF_SEPARATION_LAYOUTS,
    LARGE_ROOM_M,
    LAYOUTS,
    PATH_LOSS_EXP,
    PRINTED,
    ROOM_M,
    SIGMA_DB,
    SIM_INTERPRETATIONS,
    STATISTICS,
    WALL_HANDLINGS,
    SimCase,
    case_seed_sequence,
    cell_centres,
    check_interpretation,
    correct_crlb_m,
    printed_cell,
    printed_tables,
    printed_value,
    readers_for,
    resample_fraction,
    room_for,
    run_case,
    simulate_truth_and_rss,
    summarize,
    thesis_crlb_m,
)
from .ozkaya_tables import (
    CRLB_NOT_FROM_FORMULA,
    GRID_RT_BY_SIGMA,
    KNOWN_MISSES,
    SIR_RT_BY_SIGMA,
    TEXT_CRLB,
    THESIS_RUNS,
    crlb_rows,
    is_crlb_row,
    record_crlb,
    record_tables,
    run_tables,
    settling_interpretation,
    settling_step,
    simulation_cases,
    table_view,
    thesis_monte_carlo_ambiguity,
)

__all__ = ["PRINTED", "ROOM_M", "LARGE_ROOM_M", "ALPHA_DBM", "PATH_LOSS_EXP", "SIGMA_DB", "STATISTICS", "LAYOUTS",
    "CELL_PATTERNS", "CELL_MARGIN_M", "HALF_SEPARATION_LAYOUTS", "WALL_HANDLINGS", "SIM_INTERPRETATIONS", "room_for",
    "readers_for", "cell_centres", "printed_tables", "printed_cell", "printed_value", "SimCase", "case_seed_sequence",
    "simulate_truth_and_rss", "resample_fraction", "run_case", "summarize", "thesis_crlb_m", "correct_crlb_m",
    "check_interpretation", "FITTED_VALUES", "fitted_interpretations", "fitted_calibrated_from",
    "unfitted_interpretations", "text_interpretation_note", "sim_interpretations", "with_interpretations",
    "LAYOUTS_OF_HALF", "run_summary", "record_interpretations",
    "record_simulation_assumptions", "GRID_RT_BY_SIGMA", "SIR_RT_BY_SIGMA", "simulation_cases", "THESIS_RUNS",
    "thesis_monte_carlo_ambiguity", "KNOWN_MISSES", "run_tables", "is_crlb_row", "record_tables",
    "CRLB_NOT_FROM_FORMULA", "TEXT_CRLB", "crlb_rows", "record_crlb", "table_view", "settling_step",
    "settling_interpretation", "literature_table", "OFFLINE_PARAMETERS", "AUTO_PARAMETERS",
    "R3_CALIBRATION_DISTANCES_M",
    "READER_SENSITIVITY_DBM", "WAF_DB", "synthetic_campaign", "TESTBED_SIZE_M", "TESTBED_WALLS_M",
    "TESTBED_READERS_M", "REFERENCE_TAGS_M"]


# the names before "reading" meant only a sensor measurement (deprecated for one release)
__getattr__ = renamed_names(__name__, {
    "SIM_READINGS": "SIM_INTERPRETATIONS",
    "check_reading": "check_interpretation",
    "fitted_readings": "fitted_interpretations",
    "unfitted_readings": "unfitted_interpretations",
    "text_reading_note": "text_interpretation_note",
    "sim_readings": "sim_interpretations",
    "with_readings": "with_interpretations",
    "record_readings": "record_interpretations",
    "settling_reading": "settling_interpretation",
})
