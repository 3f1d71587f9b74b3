"""Reference tags at known positions: online path-loss calibration and RSSI smoothing (Ozkaya 2011).

Online calibration (Sec. 6.2, 7.1.5.1-2; note 004, section 3.3). At every observation step and for every
reader j, fit ``(alpha_j, n_j)`` to the instantaneous RSSI of the K reference tags,

    min  sum_i (RSSI_ij - (alpha_j - 10 n_j log10 d_ij - nW_ij WAF))^2     (Eqs. (6.5)-(6.6))
    s.t. -55 <= alpha_j <= -40 dBm,  1.5 <= n_j <= 3,

which the thesis solves by exhaustive search over that box; here it is the equivalent bounded least-squares
problem (a convex QP), all readers and steps stacked into one cvxpy solve (:func:`locbook.fit_path_loss`).
The pooled measurement noise is Eq. (6.7): ``sigma = sqrt(sum_ij resid_ij^2 / (K m))`` (no degrees-of-freedom
correction, one value shared by all readers).

RSSI smoothing (Sec. 7.1.5.3, the thesis's own contribution; note 004, section 3.8): the reference tags'
errors ``e_k = r_k - r_hat_k`` (observed minus expected) are assumed to be spatially correlated; when the
target's RSSI vector is close (in RSSI space) to tag k's, the target's RSSI is corrected by that error.
"""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from ._validate import as_array, check_scalar
from .calibration import PathLossFit, fit_path_loss
from .errors import ConvergenceError
from .channel import PathLossModel, pairwise_distance_m, wall_crossings
from .fingerprint import model_fingerprints

__all__ = ["OnlineCalibration", "calibrate_from_reference_tags", "pooled_sigma_db", "smooth_rssi",
           "OZKAYA_REF_POWER_BOUNDS_DBM", "OZKAYA_PATH_LOSS_EXP_BOUNDS"]

#: The "limiting values" of the exhaustive search, Sec. 6.2 of Ozkaya (2011).
OZKAYA_REF_POWER_BOUNDS_DBM = (-55.0, -40.0)
OZKAYA_PATH_LOSS_EXP_BOUNDS = (1.5, 3.0)


@dataclass(frozen=True)
class OnlineCalibration:
    """Per-step calibration: ``ref_power_dbm``, ``path_loss_exp`` ``(..., m)``; pooled ``sigma_db`` ``(...)``;
    ``expected_dbm`` the fitted mean RSSI of every tag ``(..., K, m)``; ``fit`` the underlying fits."""

    ref_power_dbm: np.ndarray
    path_loss_exp: np.ndarray
    sigma_db: np.ndarray
    expected_dbm: np.ndarray
    fit: PathLossFit


def pooled_sigma_db(residual_db, axis=(-2, -1), ddof: int = 0):
    """Eq. (6.7) of Ozkaya (2011): root mean square of all tag-reader residuals, dividing by ``K m`` as printed
    (``ddof = 0``). With 4 tags and 2 fitted parameters per reader this estimates ``sigma / sqrt(2)`` for
    Gaussian residuals; ``ddof = 2 m`` (the fitted parameters) gives the degrees-of-freedom-corrected variant."""
    sq = np.square(as_array("residual_db", residual_db))
    count = np.prod([sq.shape[a] for a in np.atleast_1d(axis)])
    if count - ddof <= 0:
        raise ValueError(f"ddof = {ddof} leaves no degrees of freedom for {count} residuals")
    return np.sqrt(np.sum(sq, axis=axis) / (count - ddof))


def calibrate_from_reference_tags(ref_rss_dbm, ref_positions_m, readers_m, *, walls_m=None,
                                  wall_attenuation_db: float = 0.0,
                                  ref_power_bounds_dbm=OZKAYA_REF_POWER_BOUNDS_DBM,
                                  path_loss_exp_bounds=OZKAYA_PATH_LOSS_EXP_BOUNDS,
                                  sigma_ddof: int = 0) -> OnlineCalibration:
    """Fit every reader at every step from the reference tags' RSSI ``(..., K, m)`` (K tags, m readers).

    WAF stays at its a-priori value (Sec. 6.2); the known wall loss ``nW_ij WAF`` is added back to the
    observations before the fit. Pass ``None`` bounds for the unconstrained fit. ``sigma_ddof``: see
    :func:`pooled_sigma_db` (0 = Eq. (6.7) as printed).
    """
    readers_m = as_array("readers_m", readers_m, ndim=2, trailing=(None, 2))
    ref_positions_m = as_array("ref_positions_m", ref_positions_m, ndim=2, trailing=(None, 2))
    ref_rss_dbm = as_array("ref_rss_dbm", ref_rss_dbm, min_ndim=2, nan_ok=True,
                           trailing=(ref_positions_m.shape[0], readers_m.shape[0]))
    distance = pairwise_distance_m(ref_positions_m, readers_m)                     # (K, m)
    wall_loss = (0.0 if walls_m is None
                 else wall_attenuation_db * wall_crossings(ref_positions_m, readers_m, walls_m))
    compensated = ref_rss_dbm + wall_loss                                           # (..., K, m)
    fit = fit_path_loss(np.broadcast_to(distance.T, compensated.shape[:-2] + distance.T.shape),
                        np.swapaxes(compensated, -1, -2),
                        ref_power_bounds_dbm=ref_power_bounds_dbm, path_loss_exp_bounds=path_loss_exp_bounds)
    if not fit.ok:
        raise ConvergenceError(f"reference-tag calibration: the stacked path-loss fit ended with status "
                               f"{fit.status!r}; no calibration is returned")
    ref, exp = fit.ref_power_dbm, fit.path_loss_exp                                 # (..., m)
    expected = model_fingerprints(ref_positions_m, readers_m, PathLossModel(ref, exp, wall_attenuation_db=wall_attenuation_db),
                                  walls_m)
    sigma = pooled_sigma_db(ref_rss_dbm - expected, ddof=sigma_ddof)
    return OnlineCalibration(ref, exp, sigma, expected, fit)


def smooth_rssi(rss_dbm, ref_rss_dbm, ref_expected_dbm, threshold: float = 0.4):
    """RSSI smoothing with reference tags, Ozkaya (2011) Sec. 7.1.5.3.

    ``rss_dbm (..., m)`` target RSSI; ``ref_rss_dbm``, ``ref_expected_dbm`` ``(..., K, m)`` the tags'
    observed and model-expected RSSI at the same step. Weights ``w_k = (1/E_k^2) / sum (1/E^2)`` from the
    RSSI-space distances ``E_k = ||s - r_k||``; if the largest exceeds ``threshold`` the target counts as
    close to that tag and ``s' = s - w_k* e_k*``, otherwise ``s`` is returned unchanged.
    Returns ``(smoothed (..., m), nearest tag index (...), applied (...) bool)``.
    """
    rss_dbm = as_array("rss_dbm", rss_dbm, min_ndim=1)
    ref_rss_dbm = as_array("ref_rss_dbm", ref_rss_dbm, min_ndim=2, trailing=(None, rss_dbm.shape[-1]))
    as_array("ref_expected_dbm", ref_expected_dbm, trailing=ref_rss_dbm.shape[-2:])
    check_scalar("threshold", threshold, ge=0, le=1)
    diff = ref_rss_dbm - rss_dbm[..., None, :]
    inv = 1.0 / np.maximum(np.einsum("...ki,...ki->...k", diff, diff), 1e-300)
    w = inv / inv.sum(axis=-1, keepdims=True)
    nearest = np.argmax(w, axis=-1)
    w_max = np.take_along_axis(w, nearest[..., None], -1)[..., 0]
    error = np.take_along_axis(ref_rss_dbm - np.asarray(ref_expected_dbm, float), nearest[..., None, None], -2)[..., 0, :]
    applied = w_max > threshold
    smoothed = np.where(applied[..., None], rss_dbm - w_max[..., None] * error, rss_dbm)
    return smoothed, nearest, applied
