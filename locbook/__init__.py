"""locbook: rerun, check and extend published RSSI indoor localization and tracking experiments.

The public API is the table ``_API`` below (role, home module, names), listed in docs/architecture.md under
"Public API": the channel and the one RSS measurement model; calibration and static localization; motion models,
trajectories and inertial sensors; the Kalman family, particle and grid filters; bounds, metrics and Monte-Carlo
helpers; measured data, methods of your own beside the battery (:class:`MethodInput`) and floor geometry; errors;
and the reproduction layer (:class:`Report`, :func:`printed`, :class:`Ambiguity`).
"""
__version__ = "0.1.0"

from ._datalog import install_from_environment as _install_data_log
from ._lazy import lazy_exports

# (role, home module, names): the names a user calls, each imported on first use from its one home (PEP 562), so
# that `import locbook` loads no submodule. Constants (variant lists, defaults, limits) stay in their modules.
# docs/architecture.md's "Public API" table lists exactly this (tests/project/test_public_api.py).
_API = (
    ("channel", "models.channel", ("PathLossModel", "register_to_dbm", "dbm_to_register", "quantize_db",
        "pairwise_distance_m", "correlated_shadowing_db", "wall_crossings", "small_scale_fading_db",
        "log_normal_range_moments", "correct_range_bias")),
    ("measurement and motion models", "models.base", ("MeasurementModel", "LinearGaussian", "FunctionMeasurement",
        "MotionModel", "LinearMotion", "per_state")),
    ("RSS measurement model", "models.rss", ("RssModel", "RssMeasurementModel")),
    ("range measurement model", "models.range", ("RangeModel",)),
    ("calibration", "static.calibration", ("PathLossFit", "fit_path_loss", "fit_path_loss_closed_form",
        "calibrate_path_loss", "calibrate_path_loss_devices", "fix_error_covariance", "path_loss_exp_ratio_estimate",
        "path_loss_exp_given_ref_power")),
    ("reference tags", "static.reference_tags", ("OnlineCalibration", "calibrate_from_reference_tags",
        "pooled_sigma_db", "smooth_rssi")),
    ("static localization", "static.result", ("LocalizationResult",)),
    ("static localization", "static.checks", ("check_anchor_geometry", "implausible_powers")),
    ("static localization", "static.lateration", ("lateration_system", "lateration_ls", "lateration_wls")),
    ("static localization", "static.box_ls", ("lateration_box_ls",)),
    ("static localization", "static.rss_ml", ("rss_ml_position",)),
    ("static localization", "static.grid_ml", ("grid_ml_position",)),
    ("static localization", "static.least_squares", ("recursive_least_squares", "RlsResult")),
    ("range lateration", "static.ranging", ("range_nls_position",)),
    ("fingerprinting", "static.fingerprint", ("knn_position", "model_fingerprints", "pattern_fingerprints")),
    ("motion", "models.motion", ("KinematicModel", "HeadingKinematicModel", "constant_velocity",
        "constant_acceleration", "reflect_into_box", "simulate_states")),
    ("motion", "models.trajectory", ("Trajectory", "waypoint_trajectory", "polyline_trajectory")),
    ("inertial sensors", "models.imu", ("accelerometer_readings", "gyroscope_readings", "stationary_bias",
        "rotation_2d", "world_to_body", "body_to_world", "integrate", "dead_reckon",
        "inertial_measurement_function", "inertial_measurement_jacobian", "InertialMeasurement")),
    ("Kalman family", "tracking.kalman", ("kalman_filter", "extended_kalman_filter")),
    ("Kalman family", "tracking.unscented", ("unscented_kalman_filter", "unscented_weights", "UnscentedWeights",
        "sigma_points", "unscented_transform")),
    ("Kalman family", "tracking.streams", ("Stream", "LinearMeasurement", "RssMeasurement", "NonlinearMeasurement")),
    ("Kalman family", "tracking.results", ("FilterResult", "KalmanResult", "nis_divergence", "nees")),
    ("Kalman family", "tracking.functional", ("predict", "update", "KalmanUpdate")),
    ("Kalman family", "models.base", ("per_step", "PerStep")),
    ("Kalman family", "tracking.transition", ("NonlinearMotion",)),
    ("Kalman family", "tracking.smoother", ("rts_smoother", "SmoothedResult")),
    ("Kalman family", "tracking.fixed_lag", ("fixed_lag_smoother", "FixedLagResult", "OnlineFixedLagSmoother")),
    ("Kalman family", "tracking.square_root", ("square_root_kalman_filter", "SquareRootKalmanResult")),
    ("Kalman family", "tracking.imm", ("imm_filter", "ImmResult", "embed")),
    ("Kalman family", "tracking.online", ("OnlineFilter",)),
    ("Kalman family", "tracking.noise", ("fit_noise_ml", "fit_noise_em", "NoiseFit")),
    ("fusion", "tracking.fusion", ("fuse_estimates",)),
    ("particle and grid filters", "tracking.particle", ("particle_filter", "ParticleFilterResult",
        "kernel_map_estimate")),
    ("particle and grid filters", "tracking.bayes", ("BayesFilterResult", "grid_bayes_filter",
        "grid_transition_matrix")),
    ("particle and grid filters", "tracking.resampling", ("resample", "resample_where", "systematic_resample",
        "effective_sample_size", "counts_to_indices")),
    ("bounds", "bounds.crlb", ("rss_fisher_information", "rss_position_information", "rss_crlb_m",
        "crlb_rms_over_area_m", "range_position_information", "range_crlb_m")),
    ("bounds", "bounds.pcrlb", ("posterior_crlb", "position_bound_m", "rss_state_information",
        "linear_measurement_information")),
    ("metrics", "metrics", ("position_error_m", "mean_error_m", "rmse_m", "median_error_m", "percentile_error_m",
        "error_std_m", "empirical_cdf", "reduction_pct", "error_summary", "rmse_standard_error_m",
        "accuracy_metrics")),
    ("Monte Carlo", "montecarlo", ("spawn_generators", "streams", "seed_from_values", "canonical_encoding",
        "mc_standard_error", "bootstrap_standard_error", "jackknife_standard_error", "replicate_standard_error",
        "moving_block_indices", "circular_block_indices",
        "single_run_interval")),
    ("measured data", "data.csvfile", ("DataFormatError",)),
    ("measured data", "data.long_format", ("MeasuredDataWarning", "validate_readings")),
    ("measured data", "data.readings_file", ("read_readings",)),
    ("measured data", "data.measured", ("read_anchors", "read_outline", "read_path_segments")),
    ("measured data", "data.epoching", ("Epochs", "epochs", "regular_epochs", "scan_interval_s")),
    ("measured data", "data.dataset", ("Dataset", "Recording", "load_dataset")),
    ("measured data", "data.manifest", ("shipped_datasets",)),
    ("measured data", "data.summary", ("dataset_summary",)),
    ("measured data", "data.ranges", ("read_ranges", "align_ranges")),
    ("methods of your own", "user_methods", ("MethodInput", "UserMethod")),
    ("floor geometry", "geometry", ("inside_outline", "grid_in_outline", "outline_box", "box_outline",
        "distance_to_segments", "nearest_on_outline")),
    ("errors", "errors", ("LocbookError", "ParameterError", "DegenerateGeometryError", "ConvergenceError",
        "SingularCovarianceError")),
    ("reproduction", "reproduce.report", ("Report",)),
    ("reproduction", "reproduce.scoring", ("Ambiguity",)),
    ("reproduction", "reproduce.printed_values", ("Printed", "PrintedValues", "printed")),
)
_HOME = {name: module for _, module, names in _API for name in names}
__all__ = ["__version__", *_HOME]
__getattr__, __dir__ = lazy_exports(__name__, _HOME)

_install_data_log()   # records the data files read under `locbook run` (no-op otherwise)
