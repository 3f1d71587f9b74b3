"""Reference tags at known positions: online path-loss calibration and RSSI smoothing (Ozkaya 2011).

Online calibration (Secs. 6.2, 7.1.5.1-2). At every observation step and for every
reader j, fit ``(alpha_j, n_j)`` to the instantaneous RSSI of the K reference tags,

    min  sum_i (RSSI_ij - (alpha_j - 10 n_j log10 d_ij - nW_ij WAF))^2     (Eqs. (6.5)-(6.6))
    s.t. -55 <= alpha_j <= -40 dBm,  1.5 <= n_j <= 3,

which the thesis solves by exhaustive search over that box; here it is the equivalent bounded least-squares
problem (a convex QP), all readers and steps stacked into one cvxpy solve (:func:`locbook.fit_path_loss`).
The pooled measurement noise is Eq. (6.7): ``sigma = sqrt(sum_ij resid_ij^2 / (K m))`` (no degrees-of-freedom
correction, one value shared by all readers).

RSSI smoothing (Sec. 7.1.5.3, the thesis's own contribution): the reference tags'
errors ``e_k = r_k - r_hat_k`` (observed minus expected) are assumed to be spatially correlated; when the
target's RSSI vector is close (in RSSI space) to tag k's, the target's RSSI is corrected by that error.
"""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from .._validate import as_array, check_scalar
from ..errors import ConvergenceError, DegenerateGeometryError
from ..models.channel import PathLossModel, pairwise_distance_m, wall_crossings
from .calibration import PathLossFit, fit_path_loss
from .fingerprint import _fingerprints

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
    Gaussian residuals; ``ddof = 2 m`` (the fitted parameters) gives the degrees-of-freedom-corrected variant.

    A NaN residual is a reading not heard: it is left out, and ``K m`` becomes the number of heard readings of
    that group (a group with no more than ``ddof`` heard readings gets NaN)."""
    check_scalar("ddof", ddof, ge=0, integer=True)
    sq = np.square(as_array("residual_db", residual_db, nan_ok=True))
    count = np.prod([sq.shape[a] for a in np.atleast_1d(axis)])
    if count - ddof <= 0:
        raise ValueError(f"ddof = {ddof} leaves no degrees of freedom for {count} residuals")
    heard = ~np.isnan(sq)
    if heard.all():
        return np.sqrt(np.sum(sq, axis=axis) / (count - ddof))
    # missing readings (separate branch: the complete-data arithmetic above stays as it was)
    dof = np.sum(heard, axis=axis) - ddof
    total = np.sum(np.where(heard, sq, 0.0), axis=axis)
    return np.sqrt(np.where(dof > 0, total / np.where(dof > 0, dof, 1), np.nan))


def calibrate_from_reference_tags(ref_rss_dbm, ref_positions_m, anchors_m, *, walls_m=None,
                                  wall_attenuation_db: float = 0.0,
                                  ref_power_bounds_dbm=OZKAYA_REF_POWER_BOUNDS_DBM,
                                  path_loss_exp_bounds=OZKAYA_PATH_LOSS_EXP_BOUNDS,
                                  sigma_ddof: int = 0) -> OnlineCalibration:
    """Fit every reader at every step from the reference tags' RSSI ``(..., K, m)`` (K tags, m readers).

    WAF stays at its a-priori value (Sec. 6.2); the known wall loss ``nW_ij WAF`` is added back to the
    observations before the fit. Pass ``None`` bounds for the unconstrained fit (then the closed form, see
    :func:`locbook.fit_path_loss`). ``sigma_ddof``: see :func:`pooled_sigma_db` (0 = Eq. (6.7) as printed).

    A NaN tag reading is one not heard: the reader's fit at that step uses the tags it heard (at least two at
    distinct distances, else :class:`DegenerateGeometryError` naming the step and the reader), and the pooled sigma
    the heard residuals. Readings whose fit overflows (e.g. 1e300 dBm) raise ``ValueError`` naming them.
    The bounded fit is the exact closed form with the box handled by its KKT cases (:func:`locbook.fit_path_loss`);
    raises :class:`ConvergenceError` if a fit does not reach an optimum.
    """
    check_scalar("wall_attenuation_db", wall_attenuation_db)
    anchors_m = as_array("anchors_m", anchors_m, ndim=2, trailing=(None, 2))
    ref_positions_m = as_array("ref_positions_m", ref_positions_m, ndim=2, trailing=(None, 2))
    ref_rss_dbm = as_array("ref_rss_dbm", ref_rss_dbm, min_ndim=2, nan_ok=True,
                           trailing=(ref_positions_m.shape[0], anchors_m.shape[0]))
    distance = pairwise_distance_m(ref_positions_m, anchors_m, names=("ref_positions_m", "anchors_m"))  # (K, m)
    wall_loss = (0.0 if walls_m is None
                 else wall_attenuation_db * wall_crossings(ref_positions_m, anchors_m, walls_m))
    compensated = ref_rss_dbm + wall_loss                                           # (..., K, m)
    fit = fit_path_loss(np.broadcast_to(distance.T, compensated.shape[:-2] + distance.T.shape),
                        np.swapaxes(compensated, -1, -2),
                        ref_power_bounds_dbm=ref_power_bounds_dbm, path_loss_exp_bounds=path_loss_exp_bounds)
    for bad, error, why in (("too_few_distances", DegenerateGeometryError,
                             "heard fewer than two reference tags at distinct distances"),
                            ("not_finite", ValueError, "has a fit that is not finite (readings too large to fit)")):
        hit = np.argwhere(np.atleast_1d(fit.problem_status == bad))
        if hit.size:
            step, reader = tuple(int(i) for i in hit[0][:-1]), int(hit[0][-1])
            raise error(f"ref_rss_dbm: at step {step} reader {reader} {why} ({len(hit)} reader-step(s) in all); "
                        "no calibration is returned")
    if not fit.ok:
        raise ConvergenceError(f"reference-tag calibration: the path-loss fit ended with status "
                               f"{fit.status!r}; no calibration is returned")
    ref, exp = fit.ref_power_dbm, fit.path_loss_exp                                 # (..., m)
    # the model's map at the tags (model_fingerprints' arithmetic; the per-step fits carry any batch axes (..., m))
    expected = _fingerprints(ref_positions_m, anchors_m,
                             PathLossModel(ref, exp, wall_attenuation_db=wall_attenuation_db), walls_m)
    sigma = pooled_sigma_db(ref_rss_dbm - expected, ddof=sigma_ddof)
    return OnlineCalibration(ref, exp, sigma, expected, fit)


def smooth_rssi(rss_dbm, ref_rss_dbm, ref_expected_dbm, threshold: float = 0.4):
    """RSSI smoothing with reference tags, Ozkaya (2011) Sec. 7.1.5.3.

    ``rss_dbm (..., m)`` target RSSI; ``ref_rss_dbm``, ``ref_expected_dbm`` ``(..., K, m)`` the tags'
    observed and model-expected RSSI at the same step. Weights ``w_k = (1/E_k^2) / sum (1/E^2)`` from the
    RSSI-space distances ``E_k = ||s - r_k||``; if the largest exceeds ``threshold`` the target counts as
    close to that tag and ``s' = s - w_k* e_k*``, otherwise ``s`` is returned unchanged.
    Returns ``(smoothed (..., m), nearest tag index (...), applied (...) bool)``.

    Missing readings (NaN = not heard, in ``rss_dbm`` or ``ref_rss_dbm``): ``E_k^2`` is summed over the readers
    both the target and tag k heard and rescaled by ``m / (their number)`` (so complete data give the formula
    above); a tag sharing no heard reader with the target gets no weight; only heard target components are
    corrected, by the tag's error where the tag heard that reader (else left as they are); NaN stays NaN. If no
    tag shares a reader with the target, nothing is applied.
    """
    rss_dbm = as_array("rss_dbm", rss_dbm, min_ndim=1, nan_ok=True)
    ref_rss_dbm = as_array("ref_rss_dbm", ref_rss_dbm, min_ndim=2, nan_ok=True, trailing=(None, rss_dbm.shape[-1]))
    as_array("ref_expected_dbm", ref_expected_dbm, trailing=ref_rss_dbm.shape[-2:])
    check_scalar("threshold", threshold, ge=0, le=1)
    if np.isnan(rss_dbm).any() or np.isnan(ref_rss_dbm).any():
        return _smooth_rssi_missing(rss_dbm, ref_rss_dbm, np.asarray(ref_expected_dbm, float), threshold)
    diff = ref_rss_dbm - rss_dbm[..., None, :]
    inv = 1.0 / np.maximum(np.einsum("...ki,...ki->...k", diff, diff), 1e-300)
    w = inv / inv.sum(axis=-1, keepdims=True)
    nearest = np.argmax(w, axis=-1)
    w_max = np.take_along_axis(w, nearest[..., None], -1)[..., 0]
    error = np.take_along_axis(ref_rss_dbm - np.asarray(ref_expected_dbm, float), nearest[..., None, None],
                               -2)[..., 0, :]
    applied = w_max > threshold
    smoothed = np.where(applied[..., None], rss_dbm - w_max[..., None] * error, rss_dbm)
    return smoothed, nearest, applied


def _smooth_rssi_missing(rss_dbm, ref_rss_dbm, ref_expected_dbm, threshold):
    """:func:`smooth_rssi` when some reading is NaN (not heard); see its docstring."""
    m = rss_dbm.shape[-1]
    diff = ref_rss_dbm - rss_dbm[..., None, :]                                     # (..., K, m)
    common = np.isfinite(diff)
    n_common = common.sum(axis=-1)
    e2 = np.where(common, diff, 0.0)
    e2 = np.einsum("...ki,...ki->...k", e2, e2) * m / np.maximum(n_common, 1)
    inv = np.where(n_common > 0, 1.0 / np.maximum(e2, 1e-300), 0.0)
    total = inv.sum(axis=-1, keepdims=True)
    w = inv / np.where(total > 0, total, 1.0)
    nearest = np.argmax(w, axis=-1)
    w_max = np.take_along_axis(w, nearest[..., None], -1)[..., 0]
    error = np.take_along_axis(ref_rss_dbm - ref_expected_dbm, nearest[..., None, None], -2)[..., 0, :]
    error = np.where(np.isnan(error), 0.0, error)                                 # the tag did not hear that reader
    applied = (w_max > threshold) & (total[..., 0] > 0)
    smoothed = np.where(applied[..., None], rss_dbm - w_max[..., None] * error, rss_dbm)
    return smoothed, nearest, applied
