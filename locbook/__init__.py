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

from .tracking.bayes import (RESAMPLING_CDFS, WEIGHT_SMOOTHINGS, GridFilterResult, ParticleFilterResult,
                            RssMeasurementModel, effective_sample_size, grid_bayes_filter, grid_transition_matrix,
                            particle_filter, systematic_resample)
from .bounds.crlb import CRLB_FORMS, crlb_rms_over_area_m, rss_crlb_m, rss_fisher_information, rss_position_information
from .static.calibration import (CALIBRATION_MODES, FIT_PROBLEM_STATUSES, PathLossFit, calibrate_path_loss, fit_path_loss, fit_path_loss_closed_form,
                                 fix_error_covariance, path_loss_exp_given_ref_power, path_loss_exp_ratio_estimate)
from .models.imu import (IMU_FRAMES, INTEGRATION_RULES, accelerometer_readings, body_to_world, dead_reckon,
                         gyroscope_readings, inertial_measurement_function, inertial_measurement_jacobian, integrate,
                         rotation_2d, stationary_bias, world_to_body)
from .models.trajectory import Trajectory, waypoint_trajectory
from .tracking.fusion import FUSION_READINGS, fuse_estimates
from .static.least_squares import (LATERATION_REFERENCES, LATERATION_VARIANTS, RlsResult, lateration_rows,
                                   least_squares_position, recursive_least_squares)
from .models.channel import RANGE_BIAS_TARGETS, correct_range_bias, log_normal_range_moments
from .tracking.particle import SirResult, kernel_map_estimate, rss_log_likelihood, sir_particle_filter
from .tracking.resampling import RESAMPLING_METHODS, counts_to_indices, resample, resample_where
from .models.channel import (AT86RF230_ED_OFFSET_DB, CC2420_RSSI_OFFSET_DB, PathLossModel, correlated_shadowing_db,
                      dbm_to_register, pairwise_distance_m, quantize_db, register_to_dbm, small_scale_fading_db, wall_crossings)
from .errors import ConvergenceError, DegenerateGeometryError, LocbookError, ParameterError, SingularCovarianceError
from .static.fingerprint import KNN_WEIGHTINGS, knn_position, model_fingerprints, pattern_fingerprints
from .tracking.kalman import (DIVERGENCE_PROBABILITY, DIVERGENCE_WINDOW, KF_VARIANTS, nis_divergence, RSS_UPDATE_MODES, SERIAL_ORDERS, KalmanResult, LinearMeasurement,
                              NonlinearMeasurement, RssMeasurement, TrackResult, extended_kalman_filter, kalman_filter,
                              rss_measurement_jacobian)
from .tracking.unscented import (UKF_WEIGHTS, UkfResult, UnscentedWeights, sigma_points, unscented_kalman_filter,
                                 unscented_transform, unscented_weights)
from .static.localization import (ANCHOR_CONDITION_RTOL, GOODNESS_OF_FIT_ALPHA, IMPLAUSIBLE_SIGMAS, LOCALIZATION_STATUSES, LocalizationResult,
                                  implausible_powers, check_anchor_geometry, grid_ml_position, lateration_box_ls,
                           lateration_ls, lateration_system, lateration_wls, rss_ml_position)
from .metrics import (empirical_cdf, error_std_m, error_summary, mean_error_m, median_error_m, percentile_error_m,
                      position_error_m, reduction_pct, rmse_m, rmse_standard_error_m)
from .bounds.pcrlb import (PCRLB_FORMS, linear_measurement_information, position_bound_m, posterior_crlb,
                    rss_state_information)
from .montecarlo import (bootstrap_standard_error, canonical_encoding, mc_standard_error, seed_from_values,
                         spawn_generators, streams)
from .models.motion import (HEADING_MODELS, NOISE_MODELS, STATE_LAYOUTS, HeadingKinematicModel, KinematicModel,
                            constant_acceleration, constant_velocity, reflect_into_box, simulate_states)
from .static.reference_tags import (OZKAYA_PATH_LOSS_EXP_BOUNDS, OZKAYA_REF_POWER_BOUNDS_DBM, OnlineCalibration,
                             calibrate_from_reference_tags, pooled_sigma_db, smooth_rssi)
from .data.printed_values import Printed, PrintedValues, printed
from .data.measured import (ANCHOR_MIN_SEPARATION_M, KOLAKOWSKI2021_ATTRIBUTION, MAX_REGULAR_EPOCHS, MAX_TIME_S,
                            DataFormatError, MeasuredDataWarning, Epochs, MeasuredData, epochs,
                            kolakowski2021, read_anchors, read_outline, read_path_segments, read_readings,
                            regular_epochs, validate_readings)
from .geometry import distance_to_segments, grid_in_outline, inside_outline, outline_box
from .metrics import ACCURACY_STATISTICS, accuracy_metrics
from .tracking.bayes import GRID_TRANSITIONS
from .static.fingerprint import KNN_BLOCK_BYTES
from .suite.report import Report
from .suite.scoring import Ambiguity

__all__ = [
    "__version__",
    # channel
    "PathLossModel", "CC2420_RSSI_OFFSET_DB", "AT86RF230_ED_OFFSET_DB", "register_to_dbm", "dbm_to_register",
    "quantize_db", "pairwise_distance_m", "correlated_shadowing_db", "wall_crossings", "small_scale_fading_db",
    # calibration
    "PathLossFit", "FIT_PROBLEM_STATUSES", "fit_path_loss", "fit_path_loss_closed_form", "calibrate_path_loss", "CALIBRATION_MODES", "fix_error_covariance",
    "path_loss_exp_ratio_estimate", "path_loss_exp_given_ref_power",
    # static localization
    "LocalizationResult", "LOCALIZATION_STATUSES", "ANCHOR_CONDITION_RTOL", "GOODNESS_OF_FIT_ALPHA", "IMPLAUSIBLE_SIGMAS", "implausible_powers", "check_anchor_geometry", "lateration_system", "lateration_ls", "lateration_wls",
    "lateration_box_ls", "rss_ml_position", "grid_ml_position", "lateration_rows", "least_squares_position",
    "recursive_least_squares", "RlsResult", "LATERATION_REFERENCES", "LATERATION_VARIANTS",
    "log_normal_range_moments", "correct_range_bias", "RANGE_BIAS_TARGETS",
    # fingerprinting
    "knn_position", "model_fingerprints", "pattern_fingerprints", "KNN_WEIGHTINGS",
    # motion and filters
    "KinematicModel", "constant_velocity", "constant_acceleration", "reflect_into_box", "simulate_states", "KalmanResult",
    "HeadingKinematicModel", "HEADING_MODELS", "Trajectory", "waypoint_trajectory",
    # inertial sensors and fusion
    "accelerometer_readings", "gyroscope_readings", "stationary_bias", "rotation_2d", "world_to_body", "body_to_world",
    "integrate", "dead_reckon", "inertial_measurement_function", "inertial_measurement_jacobian", "IMU_FRAMES",
    "INTEGRATION_RULES", "fuse_estimates", "FUSION_READINGS",
    "kalman_filter", "KF_VARIANTS", "nis_divergence", "DIVERGENCE_WINDOW", "DIVERGENCE_PROBABILITY", "NOISE_MODELS", "STATE_LAYOUTS", "extended_kalman_filter", "LinearMeasurement",
    "RssMeasurement", "NonlinearMeasurement", "TrackResult", "rss_measurement_jacobian", "RSS_UPDATE_MODES",
    "SERIAL_ORDERS", "unscented_kalman_filter", "UkfResult", "unscented_weights", "UnscentedWeights", "sigma_points",
    "unscented_transform", "UKF_WEIGHTS",
    # Bayes filters
    "RssMeasurementModel", "GridFilterResult", "grid_bayes_filter", "grid_transition_matrix",
    "ParticleFilterResult", "particle_filter", "systematic_resample", "effective_sample_size",
    "RESAMPLING_CDFS", "WEIGHT_SMOOTHINGS", "resample", "resample_where", "counts_to_indices", "RESAMPLING_METHODS",
    "sir_particle_filter", "SirResult", "rss_log_likelihood", "kernel_map_estimate",
    # reference tags
    "OnlineCalibration", "calibrate_from_reference_tags", "pooled_sigma_db", "smooth_rssi",
    "OZKAYA_REF_POWER_BOUNDS_DBM", "OZKAYA_PATH_LOSS_EXP_BOUNDS",
    # bounds
    "posterior_crlb", "position_bound_m", "rss_state_information", "linear_measurement_information", "PCRLB_FORMS",
    "rss_fisher_information", "rss_position_information", "rss_crlb_m", "crlb_rms_over_area_m", "CRLB_FORMS",
    # metrics and Monte Carlo
    "position_error_m", "mean_error_m", "rmse_m", "median_error_m", "percentile_error_m", "error_std_m",
    "empirical_cdf", "reduction_pct", "error_summary", "rmse_standard_error_m", "spawn_generators", "streams", "mc_standard_error", "bootstrap_standard_error", "seed_from_values", "canonical_encoding",
    "accuracy_metrics", "ACCURACY_STATISTICS",
    # measured data and floor geometry
    "MeasuredData", "Epochs", "DataFormatError", "read_readings", "read_anchors", "read_outline", "read_path_segments",
    "validate_readings", "epochs", "regular_epochs", "kolakowski2021", "KOLAKOWSKI2021_ATTRIBUTION",
    "MeasuredDataWarning", "MAX_TIME_S", "ANCHOR_MIN_SEPARATION_M", "MAX_REGULAR_EPOCHS",
    "inside_outline", "grid_in_outline", "outline_box", "distance_to_segments", "GRID_TRANSITIONS", "KNN_BLOCK_BYTES",
    # errors and reports
    "LocbookError", "DegenerateGeometryError", "ConvergenceError", "ParameterError", "SingularCovarianceError",
    "Report", "Ambiguity", "Printed", "PrintedValues", "printed",
]

from ._datalog import install_from_environment as _install_data_log

_install_data_log()   # records the data files read under `locbook run` (no-op otherwise)
