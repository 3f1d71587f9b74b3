"""Dogan (2015), "Indoor Localization and Tracking Based on RSSI and Accelerometer
Measurements", M.Sc. thesis, METU.

One blindfolded node tracked from RSS at four corner anchors with a nearly-constant-acceleration model:
static MLE, a KF on the MLE fixes ("KF (MLE)"), parallel and serial EKFs on the raw RSS, each fused with a
20 Hz accelerometer used as a linear measurement of the acceleration states (Table 3.5), and the posterior
CRLB (Ch. 4).

Every printed value used here is read from ``locbook/data/printed/dogan2015.csv`` (Table 3.6, Eqs. (3.20) and
(3.24), the Sec. 3.5 rates, the Sec. 5.4 area). The thesis prints neither the room of Ch. 3, nor the trajectory,
nor the time step. Every such value is a named default here, with its reason beside it: the room is the test-bed room
7.6 m x 9.2 m (inferred), the trajectory a 24 m polyline walked at 0.3 m/s in 80 s (our choice), a 20 Hz grid
for the fused filters with RSS at every 10th step (Table 3.5), the ONLY-RSS filters stepping once per RSS epoch
(:data:`RSS_ONLY_STEPS`; the 20 Hz grid is the declared alternative), and the MLE an unconstrained grid +
Levenberg-Marquardt search (the thesis names no solver).

The fusion interpretation (how the filter's Q and P_0 relate to sigma_ACC, and how the node starts) is a named option,
:data:`NOISE_INTERPRETATIONS` and :data:`START_MODES`. The defaults follow the printed text: Q and
P_0,acc as the constants of Eqs. (3.20), (3.24) and a node starting from rest, as the thesis's own x_0. An
interpretation chosen because it fits printed output (Q scaled with sigma_ACC, fitted to Table 3.9; the moving start
with its walking speed, fitted to Fig. 3.2) is a named alternative, and every row computed under it is ``calibrated``
and names it (:func:`calibrated_from_text`).

The code lives along the protocol's seams: :mod:`locbook.scenarios.dogan_protocol` (the printed constants, the walk,
the draws, the MLE and the filters of Table 3.5, the noise fit), :mod:`locbook.scenarios.dogan_tables` (Tables
3.7-3.12 and their scoring) and :mod:`locbook.scenarios.dogan_bounds` (the Ch. 4 bounds). This module gathers their
public names, the namespace the notebooks and :mod:`locbook.scenarios.dogan_testbed` use.
"""
from __future__ import annotations

from .._deprecation import renamed_names
from .dogan_bounds import (
    BOUND_KINDS,
    HORIZON_SOURCE,
    BoundStudy,
    bound_rows,
    horizon_ambiguity,
    pcrlb_m,
    smc_trajectories,
    smc_trajectory,
)
from .dogan_protocol import (
    ANCHORS_M,
    DEFAULT_NOISE_INTERPRETATION,
    DEFAULT_RSS_ONLY_STEP,
    DEFAULT_START,
    DT_S,
    FILTERS,
    MC_RUNS,
    MLE_BOUNDS,
    MLE_GRID_MARGIN_M,
    MLE_GRID_STEP_M,
    MLE_R_INTERPRETATIONS,
    MLE_ROOM_INSET_M,
    MOVING_START_FITTED,
    NOISE_CALIBRATED_FROM,
    NOISE_INTERPRETATIONS,
    P00_ACC_VAR,
    P00_VEL_VAR,
    PATH_LOSS_EXP,
    PCRLB_MSE_MLE,
    PRINTED,
    Q_PER_ACC_VARIANCE,
    Q_PER_STEP,
    REF_POWER_DBM,
    RMSE_EPOCHS,
    ROOM_M,
    RSS_EVERY,
    RSS_ONLY_STEPS,
    SIGMA_ACC_MPS2,
    SIGMA_RSS_DB,
    SPEED_ASSUMED,
    SPEED_CALIBRATED_FROM,
    SPEED_MPS,
    START_MODES,
    STATE_LAYOUT,
    WAYPOINTS_M,
    ChannelRun,
    calibrated_from_text,
    corner_anchors,
    filter_grid,
    filter_inputs,
    filter_noise,
    initial_state,
    mle_cost_eq24,
    mle_positions,
    motion_model,
    noise_fit,
    only_acc_errors,
    printed_number,
    room_sides_m,
    room_waypoints,
    rss_grid,
    run_channel,
    run_filter,
    scored_errors,
    simulate_acceleration,
    simulate_rss,
    speed_reason,
    trajectory_step_s,
    walk_trajectory,
)
from .dogan_tables import (
    CHANNELS,
    REPEATED_ROWS,
    RMSE_TABLES,
    SIGMA_ACC_SWEEP_CHANNELS,
    TABLE_36_CHANNEL,
    TABLE_SETTINGS,
    TABLE_SIGMA_ACC_MPS2,
    TableSetting,
    divergence_table,
    fusion_gain_pct,
    fusion_reduction_rows,
    interpretations_summary,
    mean_rmse_m,
    ordering_rows,
    printed_fusion_gains_pct,
    printed_tables,
    record_tables,
    run_channels,
    table_channels,
    table_rows,
    table_view,
    tail_rows,
    thesis_repeat_error,
)

__all__ = ["PRINTED", "printed_number", "ROOM_M", "room_sides_m", "corner_anchors", "ANCHORS_M", "STATE_LAYOUT",
    "REF_POWER_DBM", "PATH_LOSS_EXP", "SIGMA_RSS_DB", "SIGMA_ACC_MPS2", "Q_PER_STEP", "DT_S", "RSS_EVERY",
    "P00_VEL_VAR", "P00_ACC_VAR", "WAYPOINTS_M", "SPEED_MPS", "SPEED_CALIBRATED_FROM", "SPEED_ASSUMED", "MC_RUNS",
    "START_MODES", "DEFAULT_START", "MOVING_START_FITTED", "NOISE_INTERPRETATIONS", "DEFAULT_NOISE_INTERPRETATION",
    "NOISE_CALIBRATED_FROM", "Q_PER_ACC_VARIANCE", "MLE_R_INTERPRETATIONS", "FILTERS", "MLE_GRID_STEP_M",
    "MLE_GRID_MARGIN_M", "MLE_BOUNDS", "MLE_ROOM_INSET_M", "RMSE_EPOCHS", "PCRLB_MSE_MLE", "RSS_ONLY_STEPS",
    "DEFAULT_RSS_ONLY_STEP", "filter_noise", "calibrated_from_text", "speed_reason", "room_waypoints",
    "walk_trajectory", "rss_grid", "filter_grid", "trajectory_step_s", "motion_model", "simulate_rss",
    "simulate_acceleration", "mle_positions", "mle_cost_eq24", "initial_state", "filter_inputs", "run_filter",
    "ChannelRun", "scored_errors", "run_channel", "noise_fit", "only_acc_errors", "TableSetting", "RMSE_TABLES",
    "TABLE_SETTINGS", "TABLE_36_CHANNEL", "SIGMA_ACC_SWEEP_CHANNELS", "TABLE_SIGMA_ACC_MPS2", "printed_tables",
    "table_channels", "CHANNELS", "run_channels", "table_rows", "REPEATED_ROWS", "thesis_repeat_error",
    "record_tables", "interpretations_summary", "fusion_reduction_rows", "fusion_gain_pct", "mean_rmse_m",
    "printed_fusion_gains_pct", "ordering_rows", "tail_rows", "divergence_table", "table_view", "BOUND_KINDS",
    "smc_trajectories", "smc_trajectory", "pcrlb_m", "bound_rows", "HORIZON_SOURCE", "BoundStudy",
    "horizon_ambiguity"]


# the names before "reading" meant only a sensor measurement (deprecated for one release)
__getattr__ = renamed_names(__name__, {
    "NOISE_READINGS": "NOISE_INTERPRETATIONS",
    "DEFAULT_NOISE_READING": "DEFAULT_NOISE_INTERPRETATION",
    "MLE_R_READINGS": "MLE_R_INTERPRETATIONS",
    "readings_summary": "interpretations_summary",
})
