"""locbook: rerun, check and extend published RSSI indoor localization and tracking experiments.

The public API, by role:

- channel: :class:`PathLossModel`, register conversions, quantisation, correlated shadowing
- calibration: :func:`fit_path_loss`, :func:`calibrate_path_loss` (cvxpy and closed form)
- localization: linearized / weighted / box-constrained lateration, RSS maximum likelihood, grid ML
- motion and filters: :class:`KinematicModel`, :func:`kalman_filter`, :func:`extended_kalman_filter` (parallel and
  serial RSS EKF, multi-rate fusion), :func:`unscented_kalman_filter`
- inertial sensors: accelerometer and gyroscope models, stationary bias calibration, dead reckoning; waypoint
  trajectories; covariance-weighted fusion of two estimates
- fingerprinting: weighted k-NN over pattern or model RSSI maps
- Bayes filters: grid-based Bayes and (improved) SIR particle filters, systematic resampling
- reference tags: online bounded calibration, pooled sigma, RSSI smoothing
- bounds: static RSS CRLB (correct and Ozkaya's printed form); posterior CRLB for filtering (Tichavsky)
- metrics (with the ISO/IEC 18305 accuracy table) and Monte-Carlo helpers
- measured data: the long format and its validation, the Kolakowski (2021) BLE data set; floor outlines
- report: :class:`Report`, what a notebook records; :func:`printed` (the numbers each source printed,
  from package data) and :class:`Ambiguity` (a named protocol ambiguity that widens a window)
"""
__version__ = "0.1.0"

from importlib import import_module

# Names are imported on first use (PEP 562): `import locbook` loads no submodule, so a kernel or a CLI call pays
# only for what it uses (pandas, matplotlib and cvxpy load with the first name that needs them).
_API = (
    # channel
    ("models.channel", ("PathLossModel", "CC2420_RSSI_OFFSET_DB", "AT86RF230_ED_OFFSET_DB", "register_to_dbm",
        "dbm_to_register", "quantize_db", "pairwise_distance_m", "correlated_shadowing_db", "wall_crossings",
        "small_scale_fading_db",)),
    # calibration
    ("static.calibration", ("PathLossFit", "FIT_PROBLEM_STATUSES", "fit_path_loss", "fit_path_loss_closed_form",
        "calibrate_path_loss", "CALIBRATION_MODES", "fix_error_covariance", "path_loss_exp_ratio_estimate",
        "path_loss_exp_given_ref_power",)),
    # static localization
    ("static.localization", ("LocalizationResult", "LOCALIZATION_STATUSES", "ANCHOR_CONDITION_RTOL",
        "GOODNESS_OF_FIT_ALPHA", "IMPLAUSIBLE_SIGMAS", "implausible_powers", "check_anchor_geometry",
        "lateration_system", "lateration_ls", "lateration_wls", "lateration_box_ls", "rss_ml_position",
        "grid_ml_position", "LATERATION_PAIRS", "LATERATION_VARIANTS",)),
    ("static.least_squares", ("recursive_least_squares", "RlsResult",)),
    ("models.channel", ("log_normal_range_moments", "correct_range_bias", "RANGE_BIAS_TARGETS",)),
    # fingerprinting
    ("static.fingerprint", ("knn_position", "model_fingerprints", "pattern_fingerprints", "KNN_WEIGHTINGS",)),
    # motion and filters
    ("models.motion", ("KinematicModel", "constant_velocity", "constant_acceleration", "reflect_into_box",
        "simulate_states", "HeadingKinematicModel", "HEADING_MODELS",)),
    ("tracking.results", ("KalmanResult",)),
    ("models.trajectory", ("Trajectory", "waypoint_trajectory", "polyline_trajectory",)),
    # inertial sensors and fusion
    ("models.imu", ("accelerometer_readings", "gyroscope_readings", "stationary_bias", "rotation_2d",
        "world_to_body", "body_to_world", "integrate", "dead_reckon", "inertial_measurement_function",
        "inertial_measurement_jacobian", "IMU_FRAMES", "INTEGRATION_RULES",)),
    ("tracking.fusion", ("fuse_estimates", "FUSION_READINGS",)),
    ("tracking.kalman", ("kalman_filter", "KF_VARIANTS", "extended_kalman_filter",)),
    ("tracking.results", ("nis_divergence", "DIVERGENCE_WINDOW", "DIVERGENCE_PROBABILITY", "KALMAN_OUTPUTS",)),
    ("tracking.streams", ("LinearMeasurement", "RssMeasurement", "NonlinearMeasurement",
        "RSS_UPDATE_MODES", "SERIAL_ORDERS",)),
    ("tracking.functional", ("KalmanUpdate",)),
    ("models.motion", ("NOISE_MODELS", "STATE_LAYOUTS",)),
    ("tracking.unscented", ("unscented_kalman_filter", "unscented_weights", "UnscentedWeights",
        "sigma_points", "unscented_transform", "UKF_WEIGHTS",)),
    # Bayes filters
    ("models.rss", ("RssModel",)),
    ("tracking.bayes", ("BayesFilterResult", "grid_bayes_filter", "grid_transition_matrix",)),
    ("tracking.resampling", ("resample", "systematic_resample", "resample_where", "effective_sample_size",
        "counts_to_indices", "RESAMPLING_METHODS", "RESAMPLING_CDFS",)),
    ("tracking.particle", ("particle_filter", "kernel_map_estimate", "WEIGHT_SMOOTHINGS",)),
    # reference tags
    ("static.reference_tags", ("OnlineCalibration", "calibrate_from_reference_tags", "pooled_sigma_db",
        "smooth_rssi", "OZKAYA_REF_POWER_BOUNDS_DBM", "OZKAYA_PATH_LOSS_EXP_BOUNDS",)),
    # bounds
    ("bounds.pcrlb", ("posterior_crlb", "position_bound_m", "rss_state_information",
        "linear_measurement_information", "PCRLB_FORMS",)),
    ("bounds.crlb", ("rss_fisher_information", "rss_position_information", "rss_crlb_m", "crlb_rms_over_area_m",
        "CRLB_FORMS",)),
    # metrics and Monte Carlo
    ("metrics", ("position_error_m", "mean_error_m", "rmse_m", "median_error_m", "percentile_error_m",
        "error_std_m", "empirical_cdf", "reduction_pct", "error_summary", "rmse_standard_error_m",
        "accuracy_metrics", "ACCURACY_STATISTICS",)),
    ("montecarlo", ("spawn_generators", "streams", "mc_standard_error", "bootstrap_standard_error",
        "jackknife_standard_error", "replicate_standard_error", "single_run_interval", "seed_from_values",
        "canonical_encoding",)),
    # measured data and floor geometry
    ("data.measured", ("MeasuredData", "Epochs", "DataFormatError", "read_readings", "read_anchors", "read_outline",
        "read_path_segments", "validate_readings", "epochs", "regular_epochs", "kolakowski2021",
        "KOLAKOWSKI2021_ATTRIBUTION", "MeasuredDataWarning", "MAX_TIME_S", "ANCHOR_MIN_SEPARATION_M",
        "MAX_REGULAR_EPOCHS",)),
    ("geometry", ("inside_outline", "grid_in_outline", "outline_box", "box_outline", "distance_to_segments",)),
    ("tracking.bayes", ("GRID_TRANSITIONS",)),
    ("static.fingerprint", ("KNN_BLOCK_BYTES",)),
    # errors and reports
    ("errors", ("LocbookError", "DegenerateGeometryError", "ConvergenceError", "ParameterError",
        "SingularCovarianceError",)),
    ("reproduce.report", ("Report",)),
    ("reproduce.scoring", ("Ambiguity",)),
    ("reproduce.printed_values", ("Printed", "PrintedValues", "printed",)),
)
_HOME = {name: module for module, names in _API for name in names}
__all__ = ["__version__", *_HOME]


def __getattr__(name):
    module = _HOME.get(name)
    if module is None:
        raise AttributeError(f"module {__name__!r} has no attribute {name!r}")
    value = getattr(import_module(f".{module}", __name__), name)
    globals()[name] = value
    return value


def __dir__():
    return sorted(__all__)


from ._datalog import install_from_environment as _install_data_log  # noqa: E402

_install_data_log()   # records the data files read under `locbook run` (no-op otherwise)
