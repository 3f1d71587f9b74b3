"""Linear Kalman filter, vectorized over leading Monte-Carlo axes.

Standard recursion (filterpy / Dogan 2015, Table 3.1 notation):

    x_{k|k-1} = F x_{k-1|k-1}                      P_{k|k-1} = F P_{k-1|k-1} F^T + Q
    S_k = H P_{k|k-1} H^T + R                      K_k = P_{k|k-1} H^T S_k^{-1}
    x_{k|k} = x_{k|k-1} + K_k (z_k - H x_{k|k-1})
    P_{k|k} = (I - K_k H) P_{k|k-1} (I - K_k H)^T + K_k R K_k^T     (Joseph form)

Document 003 (George and Vadivukkarasi, Eqs. (9)-(13)) prints the update with ``X_{k-1}`` and
``P_{k-1}`` in place of the predicted quantities, so the prediction of Eqs. (9)-(10) is computed and
then discarded. That literal form is available as ``variant="literal_003"`` (flagged; note 003,
section 2.6 point 1): it reduces to a running average of the measurements.
"""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from .._validate import as_array, check_choice, check_scalar
from ..models.channel import PathLossModel, log_distance_gradient, log_distance_mean_dbm
from ..errors import SingularCovarianceError

__all__ = ["KalmanResult", "kalman_filter", "KF_VARIANTS", "LinearMeasurement", "RssMeasurement", "NonlinearMeasurement",
           "TrackResult", "run_recursive_filter",
           "extended_kalman_filter", "rss_measurement_jacobian", "RSS_UPDATE_MODES", "SERIAL_ORDERS"]

KF_VARIANTS = ("standard", "literal_003")


@dataclass(frozen=True)
class KalmanResult:
    """Filter output; shapes ``batch + (T, n)`` and ``batch + (T, n, n)``.

    ``x_pred``/``P_pred`` are the one-step predictions used at each update (for ``literal_003`` the
    quantities that the printed update actually uses, i.e. the previous posterior).
    """

    x: np.ndarray
    P: np.ndarray
    x_pred: np.ndarray
    P_pred: np.ndarray
    innovation: np.ndarray
    variant: str


def _mT(a):
    return np.swapaxes(a, -1, -2)


def _matrix(name: str, value, rows: int, cols: int) -> np.ndarray:
    """A finite ``(rows, cols)`` matrix, possibly with leading batch axes; never a silently broadcast vector."""
    value = as_array(name, value)
    if value.ndim < 2 or value.shape[-2:] != (rows, cols):
        raise ValueError(f"{name} must have shape ({rows}, {cols}) or batch + ({rows}, {cols}), got {value.shape}")
    return value


def _first_bad(bad) -> str:
    """'run (i, j)' of the first True entry of a batch mask ('' for an unbatched filter)."""
    bad = np.asarray(bad)
    return f" (run index {tuple(int(i) for i in np.argwhere(bad)[0])})" if bad.ndim and bad.any() else ""


def _singular_runs(S, active):
    """After LAPACK found a singular matrix in the batch ``S``: the ``active`` entries whose smallest
    eigenvalue is not clearly positive (all ``active`` ones if round-off hides it). Error path only."""
    eig = np.linalg.eigvalsh(np.where(np.isfinite(S), S, 0.0))
    tol = S.shape[-1] * np.finfo(float).eps * np.abs(eig).max(axis=-1)
    bad = active & ~(eig[..., 0] > tol) | active & ~np.all(np.isfinite(S), axis=(-2, -1))
    return bad if bad.any() else np.asarray(active)


def _solve_active(S, B, active):
    """``S^{-1} B`` for the batch entries that update; the others get an identity S (their result is not
    used), so a singular S of a missing row cannot stop the batch. With every entry active, ``S`` is used
    unchanged (bit-identical to a plain solve)."""
    if not np.all(active):
        S = np.where(np.asarray(active)[..., None, None], S, np.eye(S.shape[-1]))
    try:
        return np.linalg.solve(S, B)
    except np.linalg.LinAlgError:
        raise _Singular(_singular_runs(S, active)) from None


def _not_positive_definite(S):
    """Batch mask of innovation covariances that are not positive definite (closed form for 1 x 1 and 2 x 2;
    larger ones are caught by the finiteness check of the updated state)."""
    if S.shape[-1] == 1:
        return ~(S[..., 0, 0] > 0)
    if S.shape[-1] == 2:
        det = S[..., 0, 0] * S[..., 1, 1] - S[..., 0, 1] * S[..., 1, 0]
        return ~((S[..., 0, 0] > 0) & (det > 0))
    return np.zeros(S.shape[:-2], bool)


class _Singular(Exception):
    """Raised inside an update; the time loop turns it into a SingularCovarianceError naming the step."""

    def __init__(self, bad, message: str = ""):
        super().__init__()
        self.bad = bad
        self.message = message      # "": the innovation covariance; else the text of the failure ({step} filled in)


def _raise_singular(step: int, bad, what: str = "innovation covariance", message: str = ""):
    if message:
        raise SingularCovarianceError(message.format(step=step) + _first_bad(bad))
    raise SingularCovarianceError(
        f"the {what} S = H P H^T + R is singular, not positive definite or not finite at step {step}{_first_bad(bad)}; "
        "the measurement noise (R, sigma_db) must be positive where the prior covariance gives no spread, and "
        "measurements and covariances finite (an overflow, e.g. fixes of 1e120 m, ends here too)")


def kalman_filter(z, F, H, Q, R, x0, P0, *, predict_first: bool = True,
                  variant: str = "standard", joseph: bool = True) -> KalmanResult:
    """Run a linear Kalman filter over measurements ``z`` of shape ``batch + (T, m)``.

    Parameters
    ----------
    z : measurements; a NaN entry is a missing component: the update uses the components present (the
        missing rows are left out of H and R) and a step whose entries are all NaN is prediction only.
    F, H, Q : model matrices ``(n, n)``, ``(m, n)``, ``(n, n)``; may carry batch axes.
    R : measurement covariance ``(m, m)`` or ``batch + (m, m)`` (e.g. an empirical R per run).
    x0, P0 : initial state ``batch + (n,)`` and covariance.
        With ``predict_first=True`` they are the posterior one step *before* ``z[..., 0, :]``
        (filterpy's convention: predict, then update, at every step). With ``predict_first=False``
        they are the prior at the time of ``z[..., 0, :]``, which is used without a prediction.
    variant : ``"standard"`` or ``"literal_003"`` (Eqs. (11)-(13) of document 003 as printed).
    joseph : use the Joseph-form covariance update (keeps P symmetric positive definite).
    """
    check_choice("variant", variant, KF_VARIANTS)
    z = as_array("z", z, min_ndim=2, nan_ok=True)
    F = as_array("F", F)
    if F.ndim < 2 or F.shape[-1] != F.shape[-2]:
        raise ValueError(f"F must be square (n, n) or batch + (n, n), got {F.shape}")
    n = F.shape[-1]
    H = as_array("H", H)
    if H.ndim < 2 or H.shape[-1] != n:
        raise ValueError(f"H must have shape (m, {n}) or batch + (m, {n}), got {H.shape}")
    m = H.shape[-2]
    Q, R = _matrix("Q", Q, n, n), _matrix("R", R, m, m)
    if z.shape[-1] != m:
        raise ValueError(f"measurements have dimension {z.shape[-1]} but H has {m} rows")
    x, P = as_array("x0", x0), as_array("P0", P0)
    if x.ndim < 1 or x.shape[-1] != n or P.ndim < 2 or P.shape[-2:] != (n, n):
        raise ValueError(f"x0 must end in ({n},) and P0 in ({n}, {n}); got {x.shape} and {P.shape}")
    batch = np.broadcast_shapes(z.shape[:-2], x.shape[:-1], P.shape[:-2], F.shape[:-2], H.shape[:-2],
                                Q.shape[:-2], R.shape[:-2])
    T = z.shape[-2]
    x = np.broadcast_to(x, batch + (n,)).copy()
    P = np.broadcast_to(P, batch + (n, n)).copy()
    z = np.broadcast_to(z, batch + (T, m))
    eye = np.eye(n)
    out_x = np.empty(batch + (T, n))
    out_P = np.empty(batch + (T, n, n))
    out_xp = np.empty(batch + (T, n))
    out_Pp = np.empty(batch + (T, n, n))
    out_nu = np.full(batch + (T, m), np.nan)
    for k in range(T):
        if predict_first or k > 0:
            x_pred = x @ _mT(F)                      # x- = F x
            P_pred = F @ P @ _mT(F) + Q              # P- = F P F' + Q
        else:
            x_pred, P_pred = x, P
        # the printed update of document 003 uses the previous posterior, not the prediction
        x_use, P_use = (x, P) if variant == "literal_003" else (x_pred, P_pred)
        z_raw = z[..., k, :]
        finite = np.isfinite(z_raw)
        valid = np.all(finite, axis=-1)
        partial = np.any(finite, axis=-1) & ~valid
        zk = np.where(valid[..., None], z_raw, 0.0)
        S = H @ P_use @ _mT(H) + R                   # S = H P H' + R
        singular = valid & _not_positive_definite(S)
        if singular.any():
            _raise_singular(k, singular)
        try:
            K = _solve_active(S, H @ P_use, valid)   # K' = S^{-1} H P  (S, P symmetric)
        except _Singular as exc:
            _raise_singular(k, exc.bad)
        K = _mT(K)
        nu = zk - x_use @ _mT(H)                     # innovation z - H x
        x_new = x_use + (K @ nu[..., None])[..., 0]
        IKH = eye - K @ H
        if joseph:
            P_new = IKH @ P_use @ _mT(IKH) + K @ R @ _mT(K)   # P = (I-KH)P(I-KH)' + KRK'
        else:
            P_new = IKH @ P_use                                # P = (I-KH)P
        P_new = 0.5 * (P_new + _mT(P_new))
        if partial.any():
            # missing components: the EKF's masked update (their gain columns are exactly zero), so the present
            # components update as they would alone
            try:
                xp_new, Pp_new = _linear_update(x_use, P_use, np.where(partial[..., None], z_raw, np.nan), H, R,
                                                joseph=joseph)
            except _Singular as exc:
                _raise_singular(k, exc.bad)
            x_new = np.where(partial[..., None], xp_new, x_new)
            P_new = np.where(partial[..., None, None], Pp_new, P_new)
            nu = np.where(partial[..., None], np.where(finite, z_raw - x_use @ _mT(H), np.nan), nu)
            valid = valid | partial
        x = np.where(valid[..., None], x_new, x_pred)
        P = np.where(valid[..., None, None], P_new, P_pred)
        bad = valid & ~np.all(np.isfinite(x), axis=-1)
        if bad.any():
            _raise_singular(k, bad)
        out_x[..., k, :], out_P[..., k, :, :] = x, P
        out_xp[..., k, :], out_Pp[..., k, :, :] = x_use, P_use
        out_nu[..., k, :] = np.where(valid[..., None], nu, np.nan)
    return KalmanResult(out_x, out_P, out_xp, out_Pp, out_nu, variant)


# --------------------------------------------------------------------------------------------------
# Extended Kalman filter with RSS measurements and multi-rate sequential updates (Dogan 2015, Ch. 3)
# --------------------------------------------------------------------------------------------------

RSS_UPDATE_MODES = ("parallel", "serial")
SERIAL_ORDERS = ("descending", "given")


@dataclass(frozen=True)
class LinearMeasurement:
    """A linear-Gaussian measurement stream ``z_k = H x_k + v_k``, ``v_k ~ N(0, R)``.

    ``z``: ``batch + (T, m)``; a NaN entry is a missing component (that row is left out of the
    update, the others are used), so streams at different rates share one time grid.
    ``R``: ``(m, m)`` or with batch axes ``batch + (m, m)``.
    ``mode``: ``"parallel"`` (one stacked update) or ``"serial"`` (one scalar update per row in the given order;
    needs a diagonal R, and then equals the parallel update exactly, note 000 s.2.6).
    """

    z: np.ndarray
    H: np.ndarray
    R: np.ndarray
    mode: str = "parallel"

    def __post_init__(self):
        check_choice("mode", self.mode, RSS_UPDATE_MODES)
        z = as_array("LinearMeasurement.z", self.z, min_ndim=2, nan_ok=True)
        H = as_array("LinearMeasurement.H", self.H)
        m = z.shape[-1]
        if H.ndim < 2 or H.shape[-2] != m:
            raise ValueError(f"LinearMeasurement.H must have {m} rows (one per component of z), got shape {H.shape}")
        R = _matrix("LinearMeasurement.R", self.R, m, m)
        if self.mode == "serial" and np.any(R - R * np.eye(R.shape[-1])):
            raise ValueError("serial linear updates need a diagonal R (independent measurement components)")


@dataclass(frozen=True)
class RssMeasurement:
    """Received powers from fixed anchors, ``z_kj = P_0 - 10 alpha log10 |p_k - a_j| + e_kj``
    (Dogan Eq. (2.2)), ``e ~ N(0, sigma_db^2)`` i.i.d., for the EKF.

    ``power_dbm``: ``batch + (T, m)``, NaN where an anchor gave no reading (a step without any reading is
    prediction only). ``channel``: its ``ref_power_dbm``, ``path_loss_exp`` and ``sigma_db`` may be scalars,
    per-anchor ``(m,)`` arrays, or carry batch axes ``batch + (1,)`` (several settings run as one batch).
    ``mode``: ``"parallel"`` (one stacked update, Table 3.4) or ``"serial"`` (scalar updates, each
    re-linearised at the state updated so far, Table 3.3, in ``order`` ``"descending"`` RSS as printed or
    the ``"given"`` anchor order). ``min_distance_m`` keeps the Jacobian finite at an anchor.

    ``anchors_m``: fixed anchors ``(m, dim)``, or receiver positions per step ``batch + (T, m, dim)`` (a moving
    receiver, or measurement locations drawn per Monte-Carlo run: Palvai 2008, Eq. (4.28)). ``anchor_sigma_m``:
    the anchors' positions are known only to this standard deviation (e.g. GPS, Palvai's sigma_3); the
    measurement variance is then inflated to ``sigma^2 + (10 n / ln 10)^2 anchor_sigma^2 / d^2`` at the
    linearisation point (first-order propagation of the position error; note 002 A8).

    ``tag_height_m``: the anchors are ``(m, 3)`` (x, y, height), the tag moves in the plane ``z = tag_height_m``
    and ``position_index`` names the state's x and y only; the distances are 3-D.
    """

    power_dbm: np.ndarray
    anchors_m: np.ndarray
    channel: PathLossModel
    position_index: np.ndarray
    mode: str = "parallel"
    order: str = "descending"
    min_distance_m: float = 1e-3
    anchor_sigma_m: float = 0.0
    tag_height_m: float | None = None

    def lift(self, positions_m):
        """Positions ``(..., k)`` from the state, with the known tag height appended when there is one."""
        if self.tag_height_m is None:
            return positions_m
        return np.concatenate([positions_m, np.full(positions_m.shape[:-1] + (1,), float(self.tag_height_m))], -1)

    def anchors_at(self, step: int) -> np.ndarray:
        """Anchor positions at ``step``: ``(m, dim)`` or ``batch + (m, dim)``."""
        a = np.asarray(self.anchors_m, dtype=float)
        return a if a.ndim == 2 else a[..., min(step, a.shape[-3] - 1), :, :]

    def variance_db2(self, distance_m, path_loss_exp, sigma_db):
        """Measurement variance per reading: ``sigma^2``, inflated for ``anchor_sigma_m`` (class docstring)."""
        var = np.asarray(sigma_db, dtype=float) ** 2
        if self.anchor_sigma_m > 0:
            slope = 10.0 * np.asarray(path_loss_exp, dtype=float) / np.log(10.0)
            var = var + (slope * self.anchor_sigma_m / np.maximum(distance_m, self.min_distance_m)) ** 2
        return var

    def __post_init__(self):
        check_choice("mode", self.mode, RSS_UPDATE_MODES)
        check_choice("order", self.order, SERIAL_ORDERS)
        power = as_array("RssMeasurement.power_dbm", self.power_dbm, min_ndim=2, nan_ok=True)
        anchors = as_array("RssMeasurement.anchors_m", self.anchors_m, min_ndim=2)
        m, dim = anchors.shape[-2], anchors.shape[-1]
        if power.shape[-1] != m:
            raise ValueError(f"RssMeasurement.power_dbm has {power.shape[-1]} anchors on its last axis, "
                             f"anchors_m has {m}")
        if anchors.ndim > 2 and anchors.shape[-3] not in (1, power.shape[-2]):
            raise ValueError(f"RssMeasurement.anchors_m per step must have shape batch + (T, m, dim) with T = "
                             f"{power.shape[-2]} steps (or 1), got {anchors.shape}")
        idx = np.asarray(self.position_index)
        if self.tag_height_m is not None:
            check_scalar("tag_height_m", self.tag_height_m)
            if dim != 3:
                raise ValueError(f"RssMeasurement with tag_height_m needs anchors (m, 3) (x, y, height), got {anchors.shape}")
        n_free = dim - (self.tag_height_m is not None)
        if idx.shape != (n_free,):
            raise ValueError(f"RssMeasurement.position_index must hold {n_free} state indices (one per "
                             f"axis of the anchors{', the height known' if n_free < dim else ''}), got "
                             f"{self.position_index!r}")
        check_scalar("anchor_sigma_m", self.anchor_sigma_m, ge=0)
        for name in ("ref_power_dbm", "path_loss_exp", "sigma_db"):
            value = as_array(f"RssMeasurement.channel.{name}", getattr(self.channel, name))
            if value.ndim and value.shape[-1] not in (1, m):
                raise ValueError(f"RssMeasurement.channel.{name} must be a scalar or end in (1,) or ({m},) "
                                 f"(one per anchor), got shape {value.shape}")
        check_scalar("min_distance_m", self.min_distance_m, gt=0)


@dataclass(frozen=True)
class NonlinearMeasurement:
    """A nonlinear measurement stream ``z_k = h(x_k) + v_k``, ``v_k ~ N(0, R)`` (e.g. a body-frame accelerometer,
    whose reading depends on the heading state; Gudipati 2017, Eqs. (3.9), (3.11)).

    ``z``: ``batch + (T, m)``, NaN = a missing component (left out of the update). ``h``: maps states
    ``(..., n)`` to ``(..., m)`` over any leading axes: the EKF calls it with ``batch + (n,)``, the UKF with the
    sigma points ``batch + (2n + 1, n)``. ``jacobian``: states ``(..., n)`` to ``(..., m, n)``; the EKF needs it,
    the UKF does not. ``R``: ``(m, m)`` or ``batch + (m, m)``. ``name`` names the stream in error messages.
    """

    z: np.ndarray
    h: object
    R: np.ndarray
    jacobian: object = None
    name: str = "nonlinear measurement"

    def __post_init__(self):
        z = as_array(f"{self.name}: z", self.z, min_ndim=2, nan_ok=True)
        if not callable(self.h):
            raise ValueError(f"{self.name}: h must be a function of the state, got {type(self.h).__name__}")
        if self.jacobian is not None and not callable(self.jacobian):
            raise ValueError(f"{self.name}: jacobian must be a function of the state or None, got "
                             f"{type(self.jacobian).__name__}")
        _matrix(f"{self.name}: R", self.R, z.shape[-1], z.shape[-1])


MEASUREMENT_TYPES = (LinearMeasurement, RssMeasurement, NonlinearMeasurement)


@dataclass(frozen=True)
class TrackResult:
    """Posterior means ``batch + (S, n)`` and covariances ``batch + (S, n, n)`` at the recorded ``steps`` (S,)."""

    x: np.ndarray
    P: np.ndarray
    steps: np.ndarray


def rss_measurement_jacobian(positions_m, anchors_m, path_loss_exp, *, min_distance_m: float = 1e-3):
    """Predicted-power gradient w.r.t. position, ``(..., m, dim)``:
    ``dh_j/dp = -(10 alpha / ln 10) (p - a_j) / d_j^2`` (note 000, section 2.6; not printed in the thesis).
    Also returns the distances ``(..., m)`` (at least ``min_distance_m``).

    ``positions_m (..., dim)``, ``anchors_m (m, dim)``, ``path_loss_exp`` a scalar, ``(m,)`` or broadcastable
    to ``(..., m)``; all finite, ``min_distance_m > 0``."""
    anchors = as_array("anchors_m", anchors_m, ndim=2)
    as_array("positions_m", positions_m, min_ndim=1, trailing=(anchors.shape[1],))
    ple = as_array("path_loss_exp", path_loss_exp)
    if ple.ndim and ple.shape[-1] not in (1, anchors.shape[0]):
        raise ValueError(f"path_loss_exp must be a scalar or end in ({anchors.shape[0]},) (one per anchor), "
                         f"got shape {ple.shape}")
    check_scalar("min_distance_m", min_distance_m, gt=0)
    return _rss_jacobian(positions_m, anchors_m, path_loss_exp, min_distance_m)


def _rss_jacobian(positions_m, anchors_m, path_loss_exp, min_distance_m):
    """:func:`rss_measurement_jacobian` without the input checks (the EKF's inner loop)."""
    diff = np.asarray(positions_m, dtype=float)[..., None, :] - np.asarray(anchors_m, dtype=float)
    grad, d2 = log_distance_gradient(diff, path_loss_exp, min_distance_m=min_distance_m)
    return grad, np.sqrt(d2)


def _joseph(P, K, H, R):
    """(I - K H) P (I - K H)^T + K R K^T, symmetrised."""
    ikh = np.eye(P.shape[-1]) - K @ H
    out = ikh @ P @ _mT(ikh) + K @ R @ _mT(K)
    return 0.5 * (out + _mT(out))


def _inv_small(S):
    """Inverse of symmetric 1 x 1 or 2 x 2 matrices in closed form (batched LAPACK is slow on tiny matrices)."""
    if S.shape[-1] == 1:
        return 1.0 / S
    det = S[..., 0, 0] * S[..., 1, 1] - S[..., 0, 1] * S[..., 1, 0]
    inv = np.stack([np.stack([S[..., 1, 1], -S[..., 0, 1]], -1), np.stack([-S[..., 1, 0], S[..., 0, 0]], -1)], -2)
    return inv / det[..., None, None]


def _linear_update(x, P, z, H, R, *, joseph: bool = True):
    """Kalman update with missing rows: a NaN component gets a zero row in H, a zero innovation and a unit
    decoupled noise, so its gain column is exactly zero and the other rows update as usual. ``joseph=False``:
    the short covariance form ``(I - K H) P`` (symmetrised)."""
    valid = np.isfinite(z)
    if not valid.any():
        return x, P
    if not valid.all():
        H = np.where(valid[..., :, None], H, 0.0)
        pair = valid[..., :, None] & valid[..., None, :]
        R = np.where(pair, R, np.eye(z.shape[-1]))
    nu = np.where(valid, z, 0.0) - (H @ x[..., None])[..., 0]
    nu = np.where(valid, nu, 0.0)
    HP = H @ P
    S = HP @ _mT(H) + R
    bad = valid.any(axis=-1) & _not_positive_definite(S)
    if bad.any():
        raise _Singular(bad)
    if S.shape[-1] <= 2:                                      # K = P H^T S^{-1}, closed-form inverse
        K = _mT(HP) @ _inv_small(S)
    else:
        K = _mT(_solve_active(S, HP, valid.any(axis=-1)))
    x_new = x + (K @ nu[..., None])[..., 0]
    bad = ~np.all(np.isfinite(x_new), axis=-1)
    if bad.any():                                             # a larger S that is not positive definite
        raise _Singular(bad)
    if joseph:
        return x_new, _joseph(P, K, H, R)
    short = (np.eye(P.shape[-1]) - K @ H) @ P
    return x_new, 0.5 * (short + _mT(short))


def _rss_parallel_update(x, P, z, meas: RssMeasurement, step: int = 0):
    """Table 3.4: one update with the stacked Jacobian at the predicted state, R = sigma^2 I (inflated for
    uncertain anchor positions, :class:`RssMeasurement`)."""
    idx = np.asarray(meas.position_index)
    ch = meas.channel
    grad, d = _rss_jacobian(meas.lift(x[..., idx]), meas.anchors_at(step), ch.path_loss_exp, meas.min_distance_m)
    m = z.shape[-1]
    H = np.zeros(grad.shape[:-1] + (x.shape[-1],))
    H[..., idx] = grad[..., :idx.size]
    h = ch.mean_power_dbm(d)
    sigma2 = np.broadcast_to(meas.variance_db2(d, ch.path_loss_exp, ch.sigma_db), z.shape)
    R = sigma2[..., :, None] * np.eye(m)
    valid = np.isfinite(z)
    # the linear update on the innovation's linearisation: z - h(x) = H (x_true - x) + e
    return _linear_update(x, P, np.where(valid, z - h + (H @ x[..., None])[..., 0], np.nan), H, R)


def _serial_order(z, order: str):
    """Anchor order of serial updates per run ``batch + (m,)``: strongest reading first (missing last) or as given."""
    if order == "descending":
        return np.argsort(-np.where(np.isfinite(z), z, -np.inf), axis=-1, kind="stable")
    return np.broadcast_to(np.arange(z.shape[-1]), z.shape)


def _pick_anchor(anchors, a):
    """The anchor ``a`` (batch indices) of fixed ``(m, dim)`` or per-run ``batch + (m, dim)`` anchors."""
    if anchors.ndim == 2:
        return anchors[a]
    anchors = np.broadcast_to(anchors, a.shape + anchors.shape[-2:])
    return np.take_along_axis(anchors, a[..., None, None], -2)[..., 0, :]


def _rss_serial_update(x, P, z, meas: RssMeasurement, step: int = 0):
    """Table 3.3: scalar updates in descending RSS order (strongest anchor first), each re-linearised at the
    state updated so far; loop bound j <= N (the print's j < N is corrected, note 000 A11)."""
    idx = np.asarray(meas.position_index)
    ch = meas.channel
    m = z.shape[-1]
    anchors = meas.anchors_at(step)
    p0 = np.broadcast_to(np.asarray(ch.ref_power_dbm, dtype=float), z.shape)
    ple = np.broadcast_to(np.asarray(ch.path_loss_exp, dtype=float), z.shape)
    sigma2 = np.broadcast_to(np.asarray(ch.sigma_db, dtype=float) ** 2, z.shape)
    order = _serial_order(z, meas.order)
    for j in range(m):
        a = order[..., j]
        zj = np.take_along_axis(z, a[..., None], -1)[..., 0]
        valid = np.isfinite(zj)
        if not valid.any():
            continue
        pick = lambda arr: np.take_along_axis(arr, a[..., None], -1)[..., 0]
        diff = meas.lift(x[..., idx]) - _pick_anchor(anchors, a)
        grad, d2 = log_distance_gradient(diff, pick(ple), min_distance_m=meas.min_distance_m)
        h_row = np.zeros(x.shape)
        h_row[..., idx] = grad[..., :idx.size]
        hx = log_distance_mean_dbm(np.sqrt(d2), pick(p0), pick(ple), ref_distance_m=ch.ref_distance_m)
        var = meas.variance_db2(np.sqrt(d2), pick(ple), np.sqrt(pick(sigma2)))
        nu = np.where(valid, zj - hx, 0.0)
        ph = (P @ h_row[..., None])[..., 0]                   # P H^T
        s = np.einsum("...i,...i->...", h_row, ph) + var
        if (valid & ~(s > 0)).any():
            raise _Singular(valid & ~(s > 0))
        K = np.where(valid[..., None], ph / s[..., None], 0.0)
        x = x + K * nu[..., None]
        P = _joseph(P, K[..., :, None], h_row[..., None, :], var[..., None, None])
    return x, P


def _nonlinear_ekf_update(x, P, z, meas: NonlinearMeasurement):
    """EKF update of a :class:`NonlinearMeasurement`: linearised at the predicted state."""
    if meas.jacobian is None:
        raise ValueError(f"{meas.name}: the EKF needs its jacobian (the UKF does not)")
    H = np.asarray(meas.jacobian(x), dtype=float)
    if H.shape != x.shape[:-1] + (z.shape[-1], x.shape[-1]):
        raise ValueError(f"{meas.name}: jacobian returned shape {H.shape}, expected "
                         f"{x.shape[:-1] + (z.shape[-1], x.shape[-1])}")
    h = np.asarray(meas.h(x), dtype=float)
    valid = np.isfinite(z)
    return _linear_update(x, P, np.where(valid, z - h + (H @ x[..., None])[..., 0], np.nan), H,
                          np.asarray(meas.R, dtype=float))


def _linear_stream_update(x, P, z, meas: LinearMeasurement):
    H, R = np.asarray(meas.H, float), np.asarray(meas.R, float)
    if meas.mode == "parallel":
        return _linear_update(x, P, z, H, R)
    for j in range(z.shape[-1]):
        x, P = _linear_update(x, P, z[..., j:j + 1], H[..., j:j + 1, :], R[..., j:j + 1, j:j + 1])
    return x, P


def _ekf_update(x, P, z, meas, step):
    if isinstance(meas, LinearMeasurement):
        return _linear_stream_update(x, P, z, meas)
    if isinstance(meas, NonlinearMeasurement):
        return _nonlinear_ekf_update(x, P, z, meas)
    if meas.mode == "parallel":
        return _rss_parallel_update(x, P, z, meas, step)
    return _rss_serial_update(x, P, z, meas, step)


def _stream_name(meas) -> str:
    return meas.name if isinstance(meas, NonlinearMeasurement) else type(meas).__name__


def run_recursive_filter(F, Q, x0, P0, measurements, update, *, record=None, predict_first: bool = True,
                         filter_name: str = "filter") -> TrackResult:
    """The time loop shared by the EKF and the UKF: at every step predict with the linear motion
    ``x = F x``, ``P = F P F^T + Q``, then apply the ``measurements`` present at that step in the given order with
    ``update(x, P, z_k, stream, k)`` (each starts from the previous update's posterior). Checks the inputs; see
    :func:`extended_kalman_filter` for the arguments."""
    F = as_array("F", F)
    if F.ndim < 2 or F.shape[-1] != F.shape[-2]:
        raise ValueError(f"F must be square (n, n) or batch + (n, n), got {F.shape}")
    Q = _matrix("Q", Q, F.shape[-1], F.shape[-1])
    if not all(isinstance(m, MEASUREMENT_TYPES) for m in measurements):
        raise ValueError("measurements must be LinearMeasurement, RssMeasurement or NonlinearMeasurement streams, got "
                         f"{[type(m).__name__ for m in measurements]}")
    for meas in measurements:
        if isinstance(meas, LinearMeasurement) and np.shape(meas.H)[-1] != F.shape[-1]:
            raise ValueError(f"a LinearMeasurement's H has {np.shape(meas.H)[-1]} columns, the state has {F.shape[-1]}")
        if isinstance(meas, RssMeasurement) and np.max(meas.position_index) >= F.shape[-1]:
            raise ValueError(f"RssMeasurement.position_index {meas.position_index} is outside the {F.shape[-1]}-state")
    streams = [m.power_dbm if isinstance(m, RssMeasurement) else m.z for m in measurements]
    if not streams:
        raise ValueError(f"{filter_name} needs at least one measurement stream")
    T = {np.shape(s)[-2] for s in streams}
    if len(T) != 1:
        raise ValueError(f"measurement streams must share one time grid, got lengths {sorted(T)}")
    T = T.pop()
    x = as_array("x0", x0)
    P = as_array("P0", P0)
    n = F.shape[-1]
    if x.ndim < 1 or x.shape[-1] != n or P.ndim < 2 or P.shape[-2:] != (n, n):
        raise ValueError(f"x0 must end in ({n},) and P0 in ({n}, {n}); got {x.shape} and {P.shape}")
    batch = np.broadcast_shapes(x.shape[:-1], P.shape[:-2], *(np.shape(s)[:-2] for s in streams))
    x = np.broadcast_to(x, batch + (n,)).copy()
    P = np.broadcast_to(P, batch + (n, n)).copy()
    steps = np.arange(T) if record is None else np.asarray(record)
    if record is not None and (steps.ndim != 1 or not np.issubdtype(steps.dtype, np.integer)
                               or np.any(steps < 0) or np.any(steps >= T) or np.unique(steps).size != steps.size):
        raise ValueError(f"record must be distinct integer step indices in [0, {T}), got {record!r}")
    slot = np.full(T, -1)
    slot[steps] = np.arange(steps.size)
    out_x = np.empty(batch + (steps.size, n))
    out_P = np.empty(batch + (steps.size, n, n))
    zs = [np.broadcast_to(np.asarray(s, dtype=float), batch + np.shape(s)[-2:]) for s in streams]
    active = [np.isfinite(z).any(axis=tuple(i for i in range(z.ndim) if i != z.ndim - 2)) for z in zs]
    Ft = _mT(F)
    for k in range(T):
        if predict_first or k > 0:
            x = x @ Ft
            P = F @ P @ Ft + Q
        for meas, z, act in zip(measurements, zs, active):
            if not act[k]:
                continue
            try:
                x, P = update(x, P, z[..., k, :], meas, k)
            except _Singular as exc:
                _raise_singular(k, exc.bad, f"innovation covariance of the {_stream_name(meas)} update", exc.message)
        if slot[k] >= 0:
            out_x[..., slot[k], :] = x
            out_P[..., slot[k], :, :] = P
    return TrackResult(out_x, out_P, steps)


def extended_kalman_filter(F, Q, x0, P0, measurements, *, record=None,
                           predict_first: bool = True) -> TrackResult:
    """Multi-rate (extended) Kalman filter on one time grid, vectorized over leading Monte-Carlo axes.

    At every step: predict with ``x = F x``, ``P = F P F^T + Q`` (linear motion, so the EKF's F is F), then apply
    the ``measurements`` in the given order, each update starting from the previous one's posterior (Dogan
    Table 3.5: acceleration first, then RSS at RSS epochs). Each entry is a :class:`LinearMeasurement` (KF,
    e.g. accelerometer or MLE position fixes), a :class:`RssMeasurement` (parallel or serial EKF) or a
    :class:`NonlinearMeasurement` with its Jacobian. Covariance updates use the Joseph form (Tables 3.1-3.4
    print ``P - K S K^T``; equal in exact arithmetic).

    ``x0``, ``P0``: ``batch + (n,)``, ``batch + (n, n)``; with ``predict_first`` (filterpy's convention) they
    are the posterior one step before step 0, else the prior at step 0. ``record``: step indices to return
    (default all).
    """
    return run_recursive_filter(F, Q, x0, P0, measurements, _ekf_update, record=record, predict_first=predict_first,
                                filter_name="extended_kalman_filter")
