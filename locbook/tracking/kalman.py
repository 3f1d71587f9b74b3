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

Speed (issue 18). The filters are vectorized over leading Monte-Carlo axes. When the covariance recursion is the same
in every run (a linear filter whose P0, F, Q, H and R have no batch axes, with the same components missing in every
run) it is computed once per step and only the states are batched. Otherwise the EKF runs, when numba is installed,
in compiled loops over blocks of runs (``_nb_ekf``; ``LOCBOOK_NUMBA=0`` turns them off); without numba, or for
streams the kernel does not cover (NonlinearMeasurement, batched F or Q), the numpy loop runs. All paths give the same
numbers to round-off (tests/test_filter_speed_equality.py), and every error is raised by the numpy loop.

Consistency guard (issue 26). Every Kalman-family filter (this module's :func:`kalman_filter` and
:func:`extended_kalman_filter`, numpy and compiled paths, and :func:`locbook.unscented_kalman_filter`) returns the
normalised innovation squared of each run and step,

    NIS_k = sum over the updates u of step k of  nu_u^T S_u^{-1} nu_u,      dof_k = sum of their dimensions,

(``nu`` the innovation, ``S`` its covariance, the components present only; NaN where step k has no update). It is a
by-product of the update (the solve or Cholesky of S that gives the gain also gives ``S^{-1} nu``). Under the filter's
own model the innovations of one step are independent Gaussians (the sequential updates of one step, e.g. the serial
EKF's scalar updates or several streams, are each conditioned on the previous ones, so their innovations are
independent), so ``NIS_k ~ chi^2(dof_k)``, and the NIS of different steps are independent. That is exact for linear
streams (the KF; LinearMeasurement streams in the EKF and UKF) and holds to first order for RSS and other nonlinear
streams (their innovation is Gaussian only as far as h is linear over the state's spread). A run is flagged
``diverged`` when its NIS exceeds ``chi2.ppf(divergence_probability, dof_k)`` at ``divergence_window`` consecutive
updates (steps without an update, or whose NIS is NaN, neither count nor break the streak); ``diverged_step`` is the
first step of the first such window (-1 where not diverged). On a consistent filter each update exceeds the bound with
probability 1 - p, so a run of T updates is flagged with the probability of a streak of w among T Bernoulli(1 - p)
trials, at most ``(T - w + 1) (1 - p)^w`` (``(1 - p)^w = 1e-60`` at the defaults w = 20, p = 0.999).

What the guard flags: runs whose innovations stay inconsistent with the filter's own S. A filter that has lost track
(an error far beyond its reported covariance) exceeds the bound at every update; but so, at many readings per step,
does a filter whose noise level is badly mis-specified. With sigma underestimated by half and R dominating S the NIS
is 4 chi^2(dof), each update exceeds the bound with probability q = chi2.sf(chi2.ppf(p, dof) / 4, dof), and the exact
probability that a run of T updates is flagged at the defaults (a streak of 20 exceedances) is

    dof                1        2        4        6        8        9        10       12
    q per update:      0.1      0.18     0.33     0.47     0.59     0.64     0.69     0.77
    flagged, T = 1e3:  8.7e-18  8.1e-13  1.4e-07  0.00013  0.0098   0.046    0.16     0.69
    flagged, T = 1e4:  8.8e-17  8.2e-12  1.5e-06  0.0013   0.095    0.38     0.82     1

(dof: the readings of one update, e.g. 2 for a position fix, one per anchor heard for RSS). Up to about 6 readings per
step such a filter is practically never flagged; from 8 a growing share of long runs is, from 12 nearly every run. A
flag says "this run's innovations contradict its covariance" (lost, or a noise level far off), not "this run lost
track". ``divergence_window=0`` (or None) turns the guard off (nothing is flagged; NIS is still returned). The flags
never change the estimates; a diverged run is the caller's to count and show, not to average silently.

Batch isolation: the one exception. Elsewhere in locbook a bad problem of a batch gets NaN and a status while the others
go on. Here a run whose state or covariance overflows (a reading of 1.5e308 dBm, fixes of 1e300 m, a huge F, Q or P0)
or whose innovation covariance is singular raises a SingularCovarianceError for the whole batch, naming the step and
the first such run. Why: on the shared-covariance paths (above) one P, S and K serve every run, so there is no per-run
covariance to set aside; on the batched and compiled paths a failed run would have to be carried to the end as a dead
lane (left out of every update and check, NaN in the output) so that the others go on untouched. That dead-lane mask
is planned for every path; until then such a run is an error, never a NaN or a confident answer.
"""
from __future__ import annotations

import os
import warnings
from dataclasses import dataclass, replace

import numpy as np

from .._validate import as_array, check_choice, check_scalar
from ..models.channel import PathLossModel, log_distance_gradient, log_distance_mean_dbm
from ..errors import SingularCovarianceError

__all__ = ["KalmanResult", "kalman_filter", "nis_divergence", "DIVERGENCE_WINDOW", "DIVERGENCE_PROBABILITY",
           "KF_VARIANTS", "LinearMeasurement", "RssMeasurement", "NonlinearMeasurement",
           "TrackResult", "run_recursive_filter",
           "extended_kalman_filter", "rss_measurement_jacobian", "RSS_UPDATE_MODES", "SERIAL_ORDERS"]

KF_VARIANTS = ("standard", "literal_003")

#: defaults of the consistency guard (module docstring): consecutive updates, and the chi-square probability
DIVERGENCE_WINDOW = 20
DIVERGENCE_PROBABILITY = 0.999


class _Divergence:
    """The consistency guard's fields, shared by every Kalman-family result (module docstring): ``nis``
    ``batch + (T,)`` over every step (NaN where no update), ``nis_dof`` ``batch + (T,)`` (0 there), ``diverged``
    ``batch`` and ``diverged_step`` ``batch`` (-1 where not diverged). None when the result was built by hand."""

    @property
    def n_diverged(self) -> int:
        """The number of runs flagged ``diverged``."""
        return 0 if self.diverged is None else int(np.count_nonzero(self.diverged))


@dataclass(frozen=True)
class KalmanResult(_Divergence):
    """Filter output; shapes ``batch + (T, n)`` and ``batch + (T, n, n)``.

    ``x_pred``/``P_pred`` are the one-step predictions used at each update (for ``literal_003`` the
    quantities that the printed update actually uses, i.e. the previous posterior). ``nis``, ``nis_dof``,
    ``diverged``, ``diverged_step``: the consistency guard (module docstring).
    """

    x: np.ndarray
    P: np.ndarray
    x_pred: np.ndarray
    P_pred: np.ndarray
    innovation: np.ndarray
    variant: str
    nis: np.ndarray = None
    nis_dof: np.ndarray = None
    diverged: np.ndarray = None
    diverged_step: np.ndarray = None


def _check_guard(window, probability):
    """The guard's arguments: ``window`` a non-negative integer (0 or None: off), ``probability`` in (0, 1)."""
    if window is not None:
        check_scalar("divergence_window", window, ge=0, integer=True)
    check_scalar("divergence_probability", probability, gt=0, lt=1)
    return 0 if window is None else int(window), float(probability)


def nis_divergence(nis, nis_dof, window: int | None = DIVERGENCE_WINDOW,
                   probability: float = DIVERGENCE_PROBABILITY):
    """The consistency guard of the module docstring: ``(diverged batch, diverged_step batch)`` from the normalised
    innovation squared ``nis`` ``batch + (T,)`` (NaN: no update) and its degrees of freedom ``nis_dof``.

    A run diverged when ``nis > chi2.ppf(probability, dof)`` at ``window`` consecutive updates (steps with
    ``dof == 0`` are skipped, and so are steps whose NIS is NaN: they carry no evidence either way, e.g. a foreign
    update function that returns no NIS); ``diverged_step`` is the first step of the first such window, -1 where
    none. ``nis_dof``: non-negative integers (an integer or float array with integral values).
    Vectorized over runs (no loop over runs or steps)."""
    window, probability = _check_guard(window, probability)
    nis = np.asarray(nis, dtype=float)
    dof = np.asarray(nis_dof)
    if not np.issubdtype(dof.dtype, np.integer):        # float (or bool) dof: integral values only
        try:
            as_float = dof.astype(float)
        except (TypeError, ValueError):
            raise ValueError(f"nis_dof must hold non-negative integers (degrees of freedom), got dtype {dof.dtype}") \
                from None
        fractional = ~np.isfinite(as_float) | (as_float != np.round(as_float))
        if fractional.any():
            raise ValueError(f"nis_dof must hold non-negative integers (degrees of freedom); got "
                             f"{as_float[fractional].flat[0]!r} at index "
                             f"{tuple(int(i) for i in np.argwhere(fractional)[0])}")
        dof = as_float.astype(np.int64)
    if dof.size and dof.min() < 0:
        raise ValueError(f"nis_dof must hold non-negative integers (degrees of freedom); got {int(dof.min())} at index "
                         f"{tuple(int(i) for i in np.argwhere(dof < 0)[0])}")
    try:
        dof = np.broadcast_to(dof, nis.shape)
    except ValueError:
        raise ValueError(f"nis_dof {dof.shape} must broadcast to the shape of nis {nis.shape}") from None
    batch = nis.shape[:-1]
    if window == 0 or nis.shape[-1] < window or nis.size == 0:
        return np.zeros(batch, bool), np.full(batch, -1, np.int64)
    from scipy.special import chdtri            # lazy: keeps `import locbook` fast
    updated = (dof > 0) & ~np.isnan(nis)        # a NaN NIS (no evidence) is skipped: neither counts nor breaks
    # the dimensions are small integers: one quantile each, looked up (inf for dof 0: never exceeded)
    table = np.concatenate([[np.inf], chdtri(np.arange(1, max(int(dof.max()), 1) + 1, dtype=float), 1.0 - probability)])
    exceed = nis > table[dof]                   # NaN > bound is False: a skipped step never counts
    # the length of the current streak of exceedances among the updates: count minus the count at the last update
    # that stayed within the bound
    count = np.cumsum(exceed, axis=-1)
    reset = np.maximum.accumulate(np.where(updated & ~exceed, count, 0), axis=-1)
    hit = (count - reset) >= window
    diverged = hit.any(axis=-1)
    end = np.argmax(hit, axis=-1)               # the update that completes the first window
    first = np.take_along_axis(count, end[..., None], -1) - window + 1
    start = np.argmax(count >= first, axis=-1)  # the first exceedance of that window
    return diverged, np.where(diverged, start, -1).astype(np.int64)


#: asymmetry and negative eigenvalues a covariance may have, as a fraction of its entries' scale (the round-off of
#: products such as F P F^T is some 1e-16; a matrix typed or built wrong is off by far more); inputs of lower precision
#: get ``_EPS_FACTOR`` of their own epsilon (float32: 7.6e-6) when that is larger
_SYM_RTOL = 1e-8
_EPS_FACTOR = 64


def _covariance_rtol(dtype) -> float:
    """The round-off allowed in a covariance given with ``dtype`` (its precision before conversion to float64)."""
    try:
        dtype = np.dtype(dtype)
    except TypeError:
        return _SYM_RTOL
    if np.issubdtype(dtype, np.floating):
        return max(_SYM_RTOL, _EPS_FACTOR * float(np.finfo(dtype).eps))
    return _SYM_RTOL                                # integers are exact


def _covariance(name: str, value, rows: int) -> np.ndarray:
    """A finite, symmetric, positive semi-definite ``(rows, rows)`` matrix (possibly with batch axes), checked up
    front with an error naming ``name``.

    Round-off is allowed relative to the input's precision (``rtol``: 1e-8, or 64 epsilons of a float32 input) and to
    each entry's own scale, so that a diffuse prior cannot hide a small block that is not a covariance:

    - asymmetry up to ``rtol`` times the largest |entry|;
    - no negative variance beyond ``rtol`` times the largest |entry| of its own row (a sign typo is refused at any
      scale: ``diag(1e8, 1e8, -0.1, -0.1)``);
    - the correlation-scaled matrix ``C = D^-1/2 A D^-1/2``, ``D = diag(A)`` (a variance below ``rtol^2`` times the
      largest entry counts as that floor, so a zero variance admits only a round-off covariance), has no eigenvalue
      below ``-rtol``. ``A`` is positive semi-definite exactly when ``C`` is (a congruence), and on ``C`` the round-off
      of a product such as ``B B^T`` is a few epsilons whatever the scales of the variances."""
    dtype = getattr(value, "dtype", None)            # before the conversion to float64: its precision sets rtol
    A = _matrix(name, value, rows, rows)
    if A.size == 0:
        return A
    rtol = _covariance_rtol(dtype if dtype is not None else A.dtype)
    scale = np.abs(A).max(axis=(-2, -1))
    tol = rtol * scale
    asym = np.abs(A - _mT(A)).max(axis=(-2, -1))
    if np.any(asym > tol):
        at = _first_bad(asym > tol)
        raise ValueError(f"{name} must be symmetric (a covariance); the largest |{name} - {name}^T| is "
                         f"{float(asym.max()):.3g}{at}")
    sym = 0.5 * (A + _mT(A))
    var = np.diagonal(sym, axis1=-2, axis2=-1)
    negative = var < -rtol * np.abs(sym).max(axis=-1)
    if negative.any():
        where = np.argwhere(negative)[0]
        i = int(where[-1])
        raise ValueError(f"{name} must be positive semi-definite (a covariance); its variance {name}[{i}, {i}] = "
                         f"{float(var[tuple(where)]):.3g} is negative{_first_bad(negative.any(axis=-1))}")
    d = np.maximum(var, (rtol * rtol * scale)[..., None])
    inv_sd = 1.0 / np.sqrt(np.where(d > 0, d, 1.0))  # d = 0 only for an all-zero matrix
    C = sym * inv_sd[..., :, None] * inv_sd[..., None, :]
    diag = np.arange(rows)
    C[..., diag, diag] = np.maximum(var, 0.0) * inv_sd * inv_sd
    try:                                             # the common case: one Cholesky of C + 2 rtol I proves C >= -rtol I
        np.linalg.cholesky(C + 2 * rtol * np.eye(rows))
        return A
    except np.linalg.LinAlgError:
        pass
    low = np.linalg.eigvalsh(C)[..., 0]
    bad = low < -rtol
    if np.any(bad):
        raise ValueError(_not_psd_message(name, sym, C, bad, rtol))
    return A


def _not_psd_message(name: str, sym, C, bad, rtol: float) -> str:
    """The error for a symmetric matrix whose correlation-scaled form ``C`` has an eigenvalue below ``-rtol`` (first
    ``bad`` run): its smallest eigenvalue and, when there is one, the pair of entries that alone breaks it (a
    correlation beyond 1, or a covariance where a variance is 0). Error path only."""
    at = tuple(int(i) for i in np.argwhere(bad)[0]) if np.ndim(bad) else ()
    A, Cb = sym[at], C[at]
    low = float(np.linalg.eigvalsh(A)[0])
    text = f"{name} must be positive semi-definite (a covariance); its smallest eigenvalue is {low:.3g}"
    excess = np.abs(Cb) - np.sqrt(np.outer(np.diag(Cb), np.diag(Cb))) * (1 + rtol)
    np.fill_diagonal(excess, -np.inf)
    if excess.max() > 0:
        i, j = (int(v) for v in np.unravel_index(np.argmax(excess), excess.shape))
        i, j = min(i, j), max(i, j)
        if A[i, i] <= 0 or A[j, j] <= 0 or min(A[i, i], A[j, j]) < rtol * rtol * np.abs(A).max():
            k = i if A[i, i] <= A[j, j] else j
            text += (f": the variance {name}[{k}, {k}] is {A[k, k]:.3g} but its covariance {name}[{i}, {j}] = "
                     f"{A[i, j]:.3g} is not 0")
        else:
            text += (f": |{name}[{i}, {j}]| = {abs(A[i, j]):.3g} exceeds sqrt({name}[{i}, {i}] {name}[{j}, {j}]) = "
                     f"{np.sqrt(A[i, i] * A[j, j]):.3g} (a correlation beyond 1)")
    return text + (f" (run index {at})" if at else "")


def _apply(M, x):
    """``M x`` for matrices ``(r, c)`` or ``batch + (r, c)`` and states ``batch + (c,)``."""
    return x @ _mT(M) if M.ndim == 2 else (M @ x[..., None])[..., 0]


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


_STATE_NOT_FINITE = ("the state is not finite, or so far from the anchors that its distance overflows, at step {step}: "
                     "the filter ran away (an overflow, e.g. after a reading of 1e300 dBm or a huge F or Q)")


_STATE_OVERFLOW = ("the state or its covariance overflowed at step {step} (no longer finite): the filter ran away, "
                   "e.g. after a reading too large for float64 arithmetic (1.5e308 dBm or m) or with a huge F, Q or P0")
_UPDATE_OVERFLOW = ("the state overflowed in the update at step {step}: the updated state is not finite (a reading too "
                    "large for float64 arithmetic, e.g. 1.5e308 dBm or m, or a state already far out after a huge F, Q "
                    "or P0)")


class _Singular(Exception):
    """Raised inside an update; the time loop turns it into a SingularCovarianceError naming the step."""

    def __init__(self, bad, message: str = ""):
        super().__init__()
        self.bad = bad
        self.message = message      # "": the innovation covariance; else the text of the failure ({step} filled in)


def _check_state(step: int, x, P):
    """A SingularCovarianceError naming the step and run when a state or covariance is no longer finite (an overflow:
    huge F, Q, P0 or readings); the filter never returns them."""
    if np.isfinite(x).all() and np.isfinite(P).all():
        return
    bad = ~np.all(np.isfinite(x), axis=-1) | ~np.all(np.isfinite(P), axis=(-2, -1))
    _raise_singular(step, bad, message=_STATE_OVERFLOW)


def _raise_singular(step: int, bad, what: str = "innovation covariance", message: str = ""):
    if message:
        raise SingularCovarianceError(message.format(step=step) + _first_bad(bad))
    raise SingularCovarianceError(
        f"the {what} S = H P H^T + R is singular, not positive definite or not finite at step {step}{_first_bad(bad)}; "
        "the measurement noise (R, sigma_db) must be positive where the prior covariance gives no spread, and "
        "measurements and covariances finite (an overflow, e.g. fixes of 1e120 m, ends here too)")


def kalman_filter(z, F, H, Q, R, x0, P0, *, predict_first: bool = True,
                  variant: str = "standard", joseph: bool = True,
                  divergence_window: int | None = DIVERGENCE_WINDOW,
                  divergence_probability: float = DIVERGENCE_PROBABILITY) -> KalmanResult:
    """Run a linear Kalman filter over measurements ``z`` of shape ``batch + (T, m)``.

    Parameters
    ----------
    z : measurements; a NaN entry is a missing component: the update uses the components present (the
        missing rows are left out of H and R) and a step whose entries are all NaN is prediction only.
        ``T = 0`` steps give an empty result (shapes ``batch + (0, n)``).
    F, H : model matrices ``(n, n)``, ``(m, n)``; may carry batch axes (one per run).
    Q, R : process and measurement covariances ``(n, n)``, ``(m, m)``, or with batch axes (e.g. an empirical R per
        run); symmetric positive semi-definite (checked up front, the error names the argument).
    x0, P0 : initial state ``batch + (n,)`` and covariance (symmetric positive semi-definite).
        With ``predict_first=True`` they are the posterior one step *before* ``z[..., 0, :]``
        (filterpy's convention: predict, then update, at every step). With ``predict_first=False``
        they are the prior at the time of ``z[..., 0, :]``, which is used without a prediction.
    variant : ``"standard"`` or ``"literal_003"`` (Eqs. (11)-(13) of document 003 as printed).
    joseph : use the Joseph-form covariance update (keeps P symmetric positive definite).
    divergence_window, divergence_probability : the consistency guard (module docstring): a run whose NIS exceeds
        ``chi2.ppf(divergence_probability, dof)`` at ``divergence_window`` consecutive updates is flagged in
        ``diverged`` / ``diverged_step``; 0 or None turns it off.
    """
    check_choice("variant", variant, KF_VARIANTS)
    window, probability = _check_guard(divergence_window, divergence_probability)
    z = as_array("z", z, min_ndim=2, nan_ok=True)
    F = as_array("F", F)
    if F.ndim < 2 or F.shape[-1] != F.shape[-2]:
        raise ValueError(f"F must be square (n, n) or batch + (n, n), got {F.shape}")
    n = F.shape[-1]
    H = as_array("H", H)
    if H.ndim < 2 or H.shape[-1] != n:
        raise ValueError(f"H must have shape (m, {n}) or batch + (m, {n}), got {H.shape}")
    m = H.shape[-2]
    Q, R = _covariance("Q", Q, n), _covariance("R", R, m)
    if z.shape[-1] != m:
        raise ValueError(f"measurements have dimension {z.shape[-1]} but H has {m} rows")
    x = as_array("x0", x0)
    if x.ndim < 1 or x.shape[-1] != n:
        raise ValueError(f"x0 must end in ({n},); got {x.shape}")
    P = _covariance("P0", P0, n)
    batch = _batch_shape(("z", z.shape[:-2]), ("x0", x.shape[:-1]), ("P0", P.shape[:-2]), ("F", F.shape[:-2]),
                         ("H", H.shape[:-2]), ("Q", Q.shape[:-2]), ("R", R.shape[:-2]))
    T = z.shape[-2]
    x = np.broadcast_to(x, batch + (n,)).copy()
    z = np.broadcast_to(z, batch + (T, m))
    if T == 0:
        empty = np.empty(batch + (0, n))
        return KalmanResult(empty, np.empty(batch + (0, n, n)), empty.copy(), np.empty(batch + (0, n, n)),
                            np.empty(batch + (0, m)), variant, np.empty(batch + (0,)), np.zeros(batch + (0,), np.int64),
                            np.zeros(batch, bool), np.full(batch, -1, np.int64))
    pattern = _shared_pattern(z)
    if pattern is not None and all(a.ndim == 2 for a in (F, H, Q, R, P)):
        res = _kalman_filter_shared(z, F, H, Q, R, x, P, pattern, predict_first, variant, joseph)
    else:
        res = _kalman_filter_batched(z, F, H, Q, R, x, P, batch, predict_first, variant, joseph)
    diverged, step = nis_divergence(res.nis, res.nis_dof, window, probability)
    return replace(res, diverged=diverged, diverged_step=step)


def _batch_shape(*named):
    """The broadcast batch shape of the arguments' leading axes ``(name, shape)``; an error naming them if none."""
    try:
        return np.broadcast_shapes(*(shape for _, shape in named))
    except ValueError:
        raise ValueError("the run (batch) axes of the arguments do not broadcast: " +
                         ", ".join(f"{name} {shape}" for name, shape in named if shape)) from None


def _kalman_filter_batched(z, F, H, Q, R, x, P, batch, predict_first, variant, joseph) -> KalmanResult:
    """:func:`kalman_filter`'s loop with batched covariances (and possibly batched F, H, Q, R)."""
    n, (T, m) = x.shape[-1], z.shape[-2:]
    P = np.broadcast_to(P, batch + (n, n)).copy()
    eye = np.eye(n)
    out_x = np.empty(batch + (T, n))
    out_P = np.empty(batch + (T, n, n))
    out_xp = np.empty(batch + (T, n))
    out_Pp = np.empty(batch + (T, n, n))
    out_nu = np.full(batch + (T, m), np.nan)
    out_nis = np.full(batch + (T,), np.nan)
    out_dof = np.zeros(batch + (T,), np.int64)
    for k in range(T):
        if predict_first or k > 0:
            x_pred = _apply(F, x)                    # x- = F x
            P_pred = F @ P @ _mT(F) + Q              # P- = F P F' + Q
            _check_state(k, x_pred, P_pred)          # an overflow in the prediction is named as such
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
        nu = zk - _apply(H, x_use)                   # innovation z - H x
        HP = np.broadcast_to(H @ P_use, batch + (m, n))
        try:                                         # K' = S^{-1} H P and S^{-1} nu from one solve (S, P symmetric)
            sol = _solve_active(S, np.concatenate([HP, nu[..., None]], axis=-1), valid)
        except _Singular as exc:
            _raise_singular(k, exc.bad)
        K = _mT(sol[..., :n])
        nis = np.where(valid, np.einsum("...i,...i->...", nu, sol[..., n]), 0.0)
        x_new = x_use + (K @ nu[..., None])[..., 0]
        IKH = eye - K @ H
        if joseph:
            P_new = IKH @ P_use @ _mT(IKH) + K @ R @ _mT(K)   # P = (I-KH)P(I-KH)' + KRK'
        else:
            P_new = IKH @ P_use                                # P = (I-KH)P
        P_new = 0.5 * (P_new + _mT(P_new))
        dof = np.where(valid, m, 0)
        if partial.any():
            # missing components: the EKF's masked update (their gain columns are exactly zero), so the present
            # components update as they would alone
            try:
                xp_new, Pp_new, nis_p, dof_p = _linear_update(x_use, P_use, np.where(partial[..., None], z_raw, np.nan),
                                                              H, R, joseph=joseph)
            except _Singular as exc:
                _raise_singular(k, exc.bad)
            x_new = np.where(partial[..., None], xp_new, x_new)
            P_new = np.where(partial[..., None, None], Pp_new, P_new)
            nu = np.where(partial[..., None], np.where(finite, z_raw - _apply(H, x_use), np.nan), nu)
            nis = np.where(partial, nis_p, nis)
            dof = np.where(partial, dof_p, dof)
            valid = valid | partial
        x = np.where(valid[..., None], x_new, x_pred)
        P = np.where(valid[..., None, None], P_new, P_pred)
        bad = valid & ~np.all(np.isfinite(x), axis=-1)
        if bad.any():
            _raise_singular(k, bad, message=_UPDATE_OVERFLOW)
        _check_state(k, x, P)
        out_x[..., k, :], out_P[..., k, :, :] = x, P
        out_xp[..., k, :], out_Pp[..., k, :, :] = x_use, P_use
        out_nu[..., k, :] = np.where(valid[..., None], nu, np.nan)
        out_nis[..., k] = np.where(valid, nis, np.nan)
        out_dof[..., k] = dof
    return KalmanResult(out_x, out_P, out_xp, out_Pp, out_nu, variant, out_nis, out_dof)


def _shared_pattern(z):
    """The missing-component pattern ``(T, m)`` of measurements ``batch + (T, m)`` when it is the same in every run
    (then a linear filter's covariance recursion is the same in every run too), else None."""
    if z.size == 0:
        return None
    finite = np.isfinite(z)
    flat = finite.reshape((-1,) + finite.shape[-2:])
    if flat.shape[0] == 0 or not (flat == flat[0]).all():
        return None
    return flat[0]


def _kalman_filter_shared(z, F, H, Q, R, x, P, pattern, predict_first, variant, joseph) -> KalmanResult:
    """:func:`kalman_filter` when F, H, Q, R and P0 have no batch axes and the same components are missing in every
    run: P, S and K are computed once per step (unbatched) and only the states are batched. Same recursion and
    formulas as the batched loop (equal to round-off)."""
    batch, n, (T, m) = x.shape[:-1], x.shape[-1], z.shape[-2:]
    Ft, Ht = np.ascontiguousarray(F.T), np.ascontiguousarray(H.T)
    eye = np.eye(n)
    everyone = np.ones(batch, bool)
    out_x = np.empty(batch + (T, n))
    out_P = np.empty(batch + (T, n, n))
    out_xp = np.empty(batch + (T, n))
    out_Pp = np.empty(batch + (T, n, n))
    out_nu = np.full(batch + (T, m), np.nan)
    out_nis = np.full(batch + (T,), np.nan)
    out_dof = np.zeros(batch + (T,), np.int64)
    for k in range(T):
        if predict_first or k > 0:
            x_pred = x @ Ft
            P_pred = F @ P @ Ft + Q
            _check_state(k, x_pred, P_pred)
        else:
            x_pred, P_pred = x, P
        x_use, P_use = (x, P) if variant == "literal_003" else (x_pred, P_pred)
        present = pattern[k]
        if present.all():
            S = H @ P_use @ Ht + R
            if _not_positive_definite(S):
                _raise_singular(k, everyone)
            nu = z[..., k, :] - x_use @ Ht
            flat = nu.reshape(-1, m)
            try:                                             # K' = S^{-1} H P and S^{-1} nu^T in one solve
                sol = np.linalg.solve(S, np.concatenate([H @ P_use, flat.T], axis=-1))
            except np.linalg.LinAlgError:
                _raise_singular(k, everyone)
            K = sol[:, :n].T
            nis = np.einsum("bi,ib->b", flat, sol[:, n:]).reshape(batch)
            dof = m
            x_new = x_use + nu @ K.T
            IKH = eye - K @ H
            P_new = IKH @ P_use @ IKH.T + K @ R @ K.T if joseph else IKH @ P_use
            P_new = 0.5 * (P_new + P_new.T)
        elif present.any():
            try:
                x_new, P_new, nis, dof = _linear_update_shared(x_use, P_use, z[..., k, :], present, H, R,
                                                               joseph=joseph)
            except _Singular as exc:
                _raise_singular(k, exc.bad)
            nu = np.where(present, z[..., k, :] - x_use @ Ht, np.nan)
        else:
            x_new = nu = None
        if x_new is None:
            x, P = x_pred, P_pred
        else:
            x, P = x_new, P_new
            if not np.isfinite(x).all():
                _raise_singular(k, ~np.all(np.isfinite(x), axis=-1), message=_UPDATE_OVERFLOW)
            out_nu[..., k, :] = nu
            out_nis[..., k] = nis
            out_dof[..., k] = dof
        _check_state(k, x, P)
        out_x[..., k, :], out_P[..., k, :, :] = x, P
        out_xp[..., k, :], out_Pp[..., k, :, :] = x_use, P_use
    return KalmanResult(out_x, out_P, out_xp, out_Pp, out_nu, variant, out_nis, out_dof)


def _linear_update_shared(x, P, z, present, H, R, *, joseph: bool = True):
    """:func:`_linear_update` with one covariance ``P (n, n)`` and one ``H``, ``R`` for every run, the components
    ``present (m,)`` the same in every run; ``x`` and ``z`` batched. Also returns the NIS ``batch`` and its dof."""
    if not present.any():
        return x, P, np.zeros(x.shape[:-1]), 0
    m = present.size
    if not present.all():
        H = np.where(present[:, None], H, 0.0)
        R = np.where(present[:, None] & present[None, :], R, np.eye(m))
    nu = z - x @ H.T if present.all() else np.where(present, np.where(present, z, 0.0) - x @ H.T, 0.0)
    HP = H @ P
    S = HP @ H.T + R
    everyone = np.ones(x.shape[:-1], bool)
    if _not_positive_definite(S):
        raise _Singular(everyone)
    flat = nu.reshape(-1, m)
    if m <= 2:
        S_inv = _inv_small(S)
        K = HP.T @ S_inv
        nis = np.einsum("bi,bi->b", flat @ S_inv, flat)
    else:
        try:                                    # K' = S^{-1} H P and S^{-1} nu^T in one solve
            sol = np.linalg.solve(S, np.concatenate([HP, flat.T], axis=-1))
        except np.linalg.LinAlgError:
            raise _Singular(everyone) from None
        K = sol[:, :P.shape[-1]].T
        nis = np.einsum("bi,ib->b", flat, sol[:, P.shape[-1]:])
    nis, dof = nis.reshape(x.shape[:-1]), int(present.sum())
    x_new = x + nu @ K.T
    if not np.isfinite(x_new).all():
        raise _Singular(~np.all(np.isfinite(x_new), axis=-1), _UPDATE_OVERFLOW)
    if joseph:
        return x_new, _joseph(P, K, H, R), nis, dof
    short = (np.eye(P.shape[-1]) - K @ H) @ P
    return x_new, 0.5 * (short + short.T), nis, dof


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
        R = _covariance("LinearMeasurement.R", self.R, m)
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
        _covariance(f"{self.name}: R", self.R, z.shape[-1])


MEASUREMENT_TYPES = (LinearMeasurement, RssMeasurement, NonlinearMeasurement)


@dataclass(frozen=True)
class TrackResult(_Divergence):
    """Posterior means ``batch + (S, n)`` and covariances ``batch + (S, n, n)`` at the recorded ``steps`` (S,);
    the consistency guard's ``nis`` and ``nis_dof`` ``batch + (T,)`` at every step (recorded or not), ``diverged``
    and ``diverged_step`` ``batch`` (module docstring)."""

    x: np.ndarray
    P: np.ndarray
    steps: np.ndarray
    nis: np.ndarray = None
    nis_dof: np.ndarray = None
    diverged: np.ndarray = None
    diverged_step: np.ndarray = None


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
    out += _mT(out)
    out *= 0.5
    return out


def _inv_small(S):
    """Inverse of symmetric 1 x 1 or 2 x 2 matrices in closed form (batched LAPACK is slow on tiny matrices)."""
    if S.shape[-1] == 1:
        return 1.0 / S
    det = S[..., 0, 0] * S[..., 1, 1] - S[..., 0, 1] * S[..., 1, 0]
    inv = np.empty(S.shape)
    inv[..., 0, 0], inv[..., 0, 1] = S[..., 1, 1], -S[..., 0, 1]
    inv[..., 1, 0], inv[..., 1, 1] = -S[..., 1, 0], S[..., 0, 0]
    inv /= det[..., None, None]
    return inv


def _linear_update(x, P, z, H, R, *, joseph: bool = True):
    """Kalman update with missing rows: a NaN component gets a zero row in H, a zero innovation and a unit
    decoupled noise, so its gain column is exactly zero and the other rows update as usual. ``joseph=False``:
    the short covariance form ``(I - K H) P`` (symmetrised). Also returns the NIS ``nu^T S^{-1} nu`` of the rows
    present ``batch`` and their number (the dof) ``batch``."""
    valid = np.isfinite(z)
    dof = valid.sum(axis=-1)
    if not valid.any():
        return x, P, np.zeros(np.broadcast_shapes(x.shape[:-1], z.shape[:-1])), dof
    if not valid.all():
        H = np.where(valid[..., :, None], H, 0.0)
        pair = valid[..., :, None] & valid[..., None, :]
        R = np.where(pair, R, np.eye(z.shape[-1]))
    Ht = np.ascontiguousarray(H.T) if H.ndim == 2 else _mT(H)     # one H for all runs: a contiguous H^T
    if valid.all():
        nu = z - (x @ Ht if H.ndim == 2 else (H @ x[..., None])[..., 0])
    else:
        nu = np.where(valid, np.where(valid, z, 0.0) - (H @ x[..., None])[..., 0], 0.0)
    HP = H @ P
    S = HP @ Ht + R
    bad = valid.any(axis=-1) & _not_positive_definite(S)
    if bad.any():
        raise _Singular(bad)
    if S.shape[-1] <= 2:                                      # K = P H^T S^{-1}, closed-form inverse
        S_inv = _inv_small(S)
        K = _mT(HP) @ S_inv
        nis = np.einsum("...i,...i->...", nu, (S_inv @ nu[..., None])[..., 0])
    else:                                                     # K' = S^{-1} H P and S^{-1} nu from one solve
        n = P.shape[-1]
        both = np.broadcast_shapes(nu.shape[:-1], HP.shape[:-2])
        rhs = np.concatenate([np.broadcast_to(HP, both + HP.shape[-2:]), np.broadcast_to(nu, both + nu.shape[-1:])[..., None]],
                             axis=-1)
        sol = _solve_active(S, rhs, valid.any(axis=-1))
        K = _mT(sol[..., :n])
        nis = np.einsum("...i,...i->...", nu, sol[..., n])
    x_new = x + (K @ nu[..., None])[..., 0]
    if not np.isfinite(x_new).all():                          # a larger S that is not positive definite
        raise _Singular(~np.all(np.isfinite(x_new), axis=-1), _UPDATE_OVERFLOW)
    if joseph:
        return x_new, _joseph(P, K, H, R), nis, dof
    short = (np.eye(P.shape[-1]) - K @ H) @ P
    return x_new, 0.5 * (short + _mT(short)), nis, dof


def _rss_parallel_update(x, P, z, meas: RssMeasurement, step: int = 0):
    """Table 3.4: one update with the stacked Jacobian at the predicted state, R = sigma^2 I (inflated for
    uncertain anchor positions, :class:`RssMeasurement`)."""
    idx = np.asarray(meas.position_index)
    ch = meas.channel
    grad, d = _rss_jacobian(meas.lift(x[..., idx]), meas.anchors_at(step), ch.path_loss_exp, meas.min_distance_m)
    m = z.shape[-1]
    H = np.zeros(grad.shape[:-1] + (x.shape[-1],))
    H[..., idx] = grad[..., :idx.size]
    far = ~np.all(np.isfinite(d), axis=-1)
    if far.any():                   # the state ran away (an overflow, e.g. after a reading of 1e300 dBm)
        raise _Singular(far, _STATE_NOT_FINITE)
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
    # the scalar innovations of one step are independent under the model (each is conditioned on the previous
    # updates), so their NIS add up to a chi-square with one dof per reading (to first order: h is linearised)
    nis, dof = np.zeros(x.shape[:-1]), np.isfinite(z).sum(axis=-1)
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
        nis = nis + np.where(valid, nu * nu / np.where(valid, s, 1.0), 0.0)
        x = x + K * nu[..., None]
        over = ~np.all(np.isfinite(x), axis=-1)
        if over.any():              # named here: the next reading's linearisation would only see NaN
            raise _Singular(over, _UPDATE_OVERFLOW)
        P = _joseph(P, K[..., :, None], h_row[..., None, :], var[..., None, None])
    return x, P, nis, dof


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
    nis, dof = 0.0, 0
    for j in range(z.shape[-1]):
        x, P, nis_j, dof_j = _linear_update(x, P, z[..., j:j + 1], H[..., j:j + 1, :], R[..., j:j + 1, j:j + 1])
        nis, dof = nis + nis_j, dof + dof_j
    return x, P, nis, dof


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


@dataclass
class _Setup:
    """The checked inputs of a recursive filter: ``x`` ``batch + (n,)`` (a copy), ``P`` as given (possibly without
    the batch axes), the streams' measurements ``zs`` broadcast to the batch, the steps with any reading
    ``active`` per stream, and the recorded ``steps`` with their output ``slot`` per step (-1: not recorded)."""

    F: np.ndarray
    Q: np.ndarray
    x: np.ndarray
    P: np.ndarray
    batch: tuple
    T: int
    steps: np.ndarray
    slot: np.ndarray
    zs: list
    active: list


def _setup(F, Q, x0, P0, measurements, record, filter_name) -> _Setup:
    """The input checks of :func:`run_recursive_filter` (once, before the time loop)."""
    F = as_array("F", F)
    if F.ndim < 2 or F.shape[-1] != F.shape[-2]:
        raise ValueError(f"F must be square (n, n) or batch + (n, n), got {F.shape}")
    Q = _covariance("Q", Q, F.shape[-1])
    try:
        measurements = list(measurements)
    except TypeError:
        raise ValueError(f"measurements must be a list of measurement streams, got {type(measurements).__name__}") \
            from None
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
    n = F.shape[-1]
    if x.ndim < 1 or x.shape[-1] != n:
        raise ValueError(f"x0 must end in ({n},); got {x.shape}")
    P = _covariance("P0", P0, n)
    # every argument with run axes sets the batch (a batched Q alone runs one filter per Q)
    batch = _batch_shape(("x0", x.shape[:-1]), ("P0", P.shape[:-2]), ("F", F.shape[:-2]), ("Q", Q.shape[:-2]),
                         *((_stream_name(m), shape) for m, s in zip(measurements, streams)
                           for shape in _stream_batch_shapes(m, s)))
    x = np.broadcast_to(x, batch + (n,)).copy()
    steps = np.arange(T) if record is None else np.asarray(record)
    if record is not None and (steps.ndim != 1 or not np.issubdtype(steps.dtype, np.integer)
                               or np.any(steps < 0) or np.any(steps >= T) or np.unique(steps).size != steps.size):
        raise ValueError(f"record must be distinct integer step indices in [0, {T}), got {record!r}")
    slot = np.full(T, -1)
    slot[steps] = np.arange(steps.size)
    zs = [np.broadcast_to(np.asarray(s, dtype=float), batch + np.shape(s)[-2:]) for s in streams]
    active = [_steps_with_readings(z) for z in zs]
    return _Setup(F, Q, x, P, batch, T, steps, slot, zs, active)


def _stream_batch_shapes(meas, z):
    """The run axes that a stream's arrays carry: its readings ``batch + (T, m)`` and its parameters (H, R, anchors
    per step ``batch + (T, m, dim)``, channel parameters ``batch + (1 or m,)``)."""
    shapes = [np.shape(z)[:-2]]
    if isinstance(meas, (LinearMeasurement, NonlinearMeasurement)):
        shapes.append(np.shape(meas.R)[:-2])
    if isinstance(meas, LinearMeasurement):
        shapes.append(np.shape(meas.H)[:-2])
    if isinstance(meas, RssMeasurement):
        shapes.append(np.shape(meas.anchors_m)[:-3])
        ch = meas.channel
        shapes += [np.shape(v)[:-1] for v in (ch.ref_power_dbm, ch.path_loss_exp, ch.sigma_db)]
    return shapes


def _steps_with_readings(z):
    """``(T,)``: the steps at which ``z`` ``batch + (T, m)`` has a reading in some run (batch axes reduced first:
    one pass over contiguous memory)."""
    if z.size == 0:
        return np.zeros(z.shape[-2], bool)
    finite = np.isfinite(z).reshape(-1, z.shape[-2] * z.shape[-1])
    return finite.any(axis=0).reshape(z.shape[-2:]).any(axis=-1)


def _time_loop(setup: _Setup, measurements, update, predict_first: bool, *, shared: bool = False) -> TrackResult:
    """The time loop of :func:`run_recursive_filter`. ``shared``: while the covariance is the same in every run
    (P0, F and Q without batch axes, linear streams whose H and R have none and whose missing components are the
    same in every run) it is kept unbatched and updated once per step (:func:`_shared_linear_update`); the first
    update that differs between runs broadcasts it and continues batched."""
    F, Q, x, batch, n = setup.F, setup.Q, setup.x, setup.batch, setup.F.shape[-1]
    shared = shared and F.ndim == 2 and Q.ndim == 2 and setup.P.ndim == 2
    P = setup.P.copy() if shared else np.broadcast_to(setup.P, batch + (n, n)).copy()
    steps, slot = setup.steps, setup.slot
    out_x = np.empty(batch + (steps.size, n))
    out_P = np.empty(batch + (steps.size, n, n))
    out_nis = np.full(batch + (setup.T,), np.nan)
    out_dof = np.zeros(batch + (setup.T,), np.int64)
    Ft = np.ascontiguousarray(_mT(F))
    for k in range(setup.T):
        if predict_first or k > 0:
            x = x @ Ft if F.ndim == 2 else _apply(F, x)
            P = F @ P @ Ft + Q
            _check_state(k, x, P)               # an overflow in the prediction is named as such
        nis, dof = 0.0, 0
        for meas, z, act in zip(measurements, setup.zs, setup.active):
            if not act[k]:
                continue
            try:
                out = None
                if shared:
                    out = _shared_linear_update(x, P, z[..., k, :], meas)
                    if out is None:
                        shared = False
                        P = np.broadcast_to(P, batch + (n, n)).copy()
                if out is None:
                    out = update(x, P, z[..., k, :], meas, k)
            except _Singular as exc:
                _raise_singular(k, exc.bad, f"innovation covariance of the {_stream_name(meas)} update", exc.message)
            x, P = out[0], out[1]
            if len(out) == 4:        # the update's NIS and dof (a foreign update function may return x and P only)
                nis, dof = nis + out[2], dof + out[3]
            else:
                nis = nis + np.nan
        _check_state(k, x, P)
        out_nis[..., k] = np.where(np.asarray(dof) > 0, nis, np.nan)
        out_dof[..., k] = dof
        if slot[k] >= 0:
            out_x[..., slot[k], :] = x
            out_P[..., slot[k], :, :] = P
    return TrackResult(out_x, out_P, steps, out_nis, out_dof)


def _shared_linear_update(x, P, z, meas):
    """The update of a :class:`LinearMeasurement` on an unbatched covariance ``P (n, n)`` when H and R have no batch
    axes and the same components are present in every run; else None (the caller goes batched)."""
    if not isinstance(meas, LinearMeasurement):
        return None
    H, R = np.asarray(meas.H, float), np.asarray(meas.R, float)
    if H.ndim != 2 or R.ndim != 2:
        return None
    finite = np.isfinite(z)
    m = finite.shape[-1]
    flat = finite.reshape(-1, m)
    if flat.shape[0] == 0 or not (flat == flat[0]).all():
        return None
    present = flat[0]
    if meas.mode == "parallel":
        return _linear_update_shared(x, P, z, present, H, R)
    nis, dof = 0.0, 0
    for j in range(m):
        x, P, nis_j, dof_j = _linear_update_shared(x, P, z[..., j:j + 1], present[j:j + 1], H[j:j + 1],
                                                   R[j:j + 1, j:j + 1])
        nis, dof = nis + nis_j, dof + dof_j
    return x, P, nis, dof


def run_recursive_filter(F, Q, x0, P0, measurements, update, *, record=None, predict_first: bool = True,
                         filter_name: str = "filter", divergence_window: int | None = DIVERGENCE_WINDOW,
                         divergence_probability: float = DIVERGENCE_PROBABILITY) -> TrackResult:
    """The time loop shared by the EKF and the UKF: at every step predict with the linear motion
    ``x = F x``, ``P = F P F^T + Q``, then apply the ``measurements`` present at that step in the given order with
    ``update(x, P, z_k, stream, k)`` (each starts from the previous update's posterior), which returns ``(x, P)`` or
    ``(x, P, nis, dof)`` (the update's normalised innovation squared and its dimension per run, for the consistency
    guard of the module docstring). Checks the inputs; see :func:`extended_kalman_filter` for the arguments."""
    window, probability = _check_guard(divergence_window, divergence_probability)
    setup = _setup(F, Q, x0, P0, measurements, record, filter_name)
    return _flag(_time_loop(setup, measurements, update, predict_first), window, probability)


def _flag(res: TrackResult, window: int, probability: float) -> TrackResult:
    """``res`` with the guard's ``diverged`` and ``diverged_step`` (module docstring)."""
    diverged, step = nis_divergence(res.nis, res.nis_dof, window, probability)
    return replace(res, diverged=diverged, diverged_step=step)


def extended_kalman_filter(F, Q, x0, P0, measurements, *, record=None, predict_first: bool = True,
                           divergence_window: int | None = DIVERGENCE_WINDOW,
                           divergence_probability: float = DIVERGENCE_PROBABILITY) -> TrackResult:
    """Multi-rate (extended) Kalman filter on one time grid, vectorized over leading Monte-Carlo axes.

    At every step: predict with ``x = F x``, ``P = F P F^T + Q`` (linear motion, so the EKF's F is F), then apply
    the ``measurements`` in the given order, each update starting from the previous one's posterior (Dogan
    Table 3.5: acceleration first, then RSS at RSS epochs). Each entry is a :class:`LinearMeasurement` (KF,
    e.g. accelerometer or MLE position fixes), a :class:`RssMeasurement` (parallel or serial EKF) or a
    :class:`NonlinearMeasurement` with its Jacobian. Covariance updates use the Joseph form (Tables 3.1-3.4
    print ``P - K S K^T``; equal in exact arithmetic).

    ``x0``, ``P0``: ``batch + (n,)``, ``batch + (n, n)``; with ``predict_first`` (filterpy's convention) they
    are the posterior one step before step 0, else the prior at step 0. ``record``: step indices to return
    (default all). ``F``, ``Q``, ``P0`` and the streams' H, R and anchors may carry run axes (the batch is the
    broadcast of all run axes); Q, P0 and R must be symmetric positive semi-definite (checked up front).

    ``divergence_window``, ``divergence_probability``: the consistency guard (module docstring). The result's
    ``nis`` ``batch + (T,)`` sums the NIS of the step's updates (for a serial stream, its scalar updates, whose
    innovations are independent under the model, so the sum is chi-square with one dof per reading: exactly for a
    LinearMeasurement, to first order for an RSS or nonlinear stream, whose h is linearised); a run whose NIS
    exceeds ``chi2.ppf(divergence_probability, dof)`` at ``divergence_window`` consecutive updates is flagged in
    ``diverged`` with its ``diverged_step``; 0 or None turns the flag off. A flag means the run's innovations stay
    inconsistent with its covariance: a lost track, or (at many readings per step) a noise level far off (the module
    docstring gives the probabilities).
    """
    window, probability = _check_guard(divergence_window, divergence_probability)
    setup = _setup(F, Q, x0, P0, measurements, record, "extended_kalman_filter")
    if not _covariance_shared_throughout(setup, measurements):
        compiled = _compiled_ekf(setup, measurements, predict_first)
        if compiled is not None:
            return _flag(compiled, window, probability)
    return _flag(_time_loop(setup, measurements, _ekf_update, predict_first, shared=True), window, probability)


def _covariance_shared_throughout(setup: _Setup, measurements) -> bool:
    """True when the covariance recursion is the same in every run at every step (a linear filter with P0, F, Q, H
    and R without batch axes and the same components missing in every run): the numpy loop then updates one
    covariance per step, which beats running the runs one by one."""
    if setup.F.ndim != 2 or setup.Q.ndim != 2 or setup.P.ndim != 2:
        return False
    return all(isinstance(meas, LinearMeasurement) and np.ndim(meas.H) == 2 and np.ndim(meas.R) == 2
               and _shared_pattern(z) is not None for meas, z in zip(measurements, setup.zs))


# --------------------------------------------------------------------------------------------------
# Optional compiled EKF (numba): the same recursion run by run in compiled loops
# --------------------------------------------------------------------------------------------------
#: The EKF uses compiled loops when numba is installed, this is True (environment variable LOCBOOK_NUMBA=0 turns them
#: off) and the problem has at least ``_NUMBA_MIN_WORK`` run-steps (smaller problems stay in numpy, with no
#: compilation wait). Either way the results are the same to round-off (tests/test_filter_speed_equality.py).
_NUMBA_ENABLED = os.environ.get("LOCBOOK_NUMBA", "1").strip().lower() not in ("0", "false", "no", "off")
_NUMBA_MIN_WORK = int(os.environ.get("LOCBOOK_NUMBA_MIN_WORK", "20000").strip() or 20000)
_NUMBA_STATE = {"ready": None}
_LINEAR_PARALLEL, _LINEAR_SERIAL, _RSS_PARALLEL, _RSS_SERIAL = 0, 1, 2, 3
_KERNELS = ("_nb_predict", "_nb_update", "_nb_rss_row", "_nb_ekf")
_LANES = 64     # runs per block of the compiled EKF: the innermost axis, long enough for LLVM to vectorise it


def _numba_ready() -> bool:
    """Compile (lazily, once; numba caches the machine code on disk) the kernels below, if numba is installed."""
    if _NUMBA_STATE["ready"] is None:
        try:
            import numba
        except ImportError:
            _NUMBA_STATE["ready"] = False
        else:
            space = globals()
            for name in _KERNELS:          # jitted callers bind to the jitted callees through the module globals
                try:
                    space[name] = numba.njit(cache=True, nogil=True, error_model="numpy")(space[name])
                except RuntimeError:       # no writable cache location: compile in memory at each session
                    space[name] = numba.njit(nogil=True, error_model="numpy")(space[name])
            _NUMBA_STATE["ready"] = True
    return _NUMBA_STATE["ready"]


def _nb_predict(Fi, Fj, Fv, Q, x, P, xt, T1):
    """x = F x, P = (F P) F^T + Q in place for the lanes (last axis), F given by its nonzero entries (rows Fi,
    columns Fj, values Fv); P symmetric in, symmetric out (the upper triangle is computed and mirrored)."""
    n = x.shape[0]
    for i in range(n):
        for w in range(_LANES):
            xt[i, w] = 0.0
        for c in range(n):
            for w in range(_LANES):
                T1[i, c, w] = 0.0
    for e in range(Fi.shape[0]):
        i, j, v = Fi[e], Fj[e], Fv[e]
        for w in range(_LANES):
            xt[i, w] += v * x[j, w]
        for c in range(n):
            for w in range(_LANES):
                T1[i, c, w] += v * P[j, c, w]
    for i in range(n):
        for w in range(_LANES):
            x[i, w] = xt[i, w]
        for c in range(i + 1):
            for w in range(_LANES):
                P[c, i, w] = 0.0
    for e in range(Fi.shape[0]):                          # (F P) F^T, upper triangle: P[a, i] for a <= i
        i, j, v = Fi[e], Fj[e], Fv[e]
        for a in range(i + 1):
            for w in range(_LANES):
                P[a, i, w] += v * T1[a, j, w]
    for a in range(n):
        for c in range(a, n):
            for w in range(_LANES):
                P[a, c, w] += Q[a, c]
                P[c, a, w] = P[a, c, w]


def _nb_update(x, P, c, nz, nnz, H, nu, R, HP, HPH, S, L, KT, PH, D, t, u, Y, nis):
    """Kalman update in place, lane by lane (last axis), with the rows ``H[:c]`` (nonzero only in the columns
    ``nz[:nnz]``), innovations ``nu[:c]`` and noise ``R[:c, :c]``; a missing reading is a zero row with zero
    innovation and unit decoupled noise (its gain column is then exactly zero). K = P H^T S^{-1} (Cholesky of
    S = H P H^T + R), x += K nu, and the Joseph form (I - K H) P (I - K H)^T + K R K^T, symmetrised, written as
    P - K (H P) + (K S - P H^T) K^T (equal for any K). Adds each lane's NIS nu^T S^{-1} nu = |L^{-1} nu|^2 to
    ``nis`` (a missing row adds 0). False when some S is not positive definite or some state not finite."""
    n = x.shape[0]
    for r in range(c):                                    # HP = H P, PH = P H^T
        for j in range(n):
            for w in range(_LANES):
                HP[r, j, w] = 0.0
                PH[j, r, w] = 0.0
        for e in range(nnz):
            i = nz[e]
            for j in range(n):
                for w in range(_LANES):
                    HP[r, j, w] += H[r, i, w] * P[i, j, w]
                    PH[j, r, w] += P[j, i, w] * H[r, i, w]
    for r in range(c):                                    # S = H P H^T + R
        for q in range(c):
            for w in range(_LANES):
                HPH[r, q, w] = 0.0
            for e in range(nnz):
                j = nz[e]
                for w in range(_LANES):
                    HPH[r, q, w] += HP[r, j, w] * H[q, j, w]
            for w in range(_LANES):
                S[r, q, w] = HPH[r, q, w] + R[r, q, w]
    for j in range(c):                                    # S = L L^T
        for w in range(_LANES):
            t[w] = S[j, j, w]
        for i in range(j):
            for w in range(_LANES):
                t[w] -= L[j, i, w] * L[j, i, w]
        good = True
        for w in range(_LANES):
            good = good and t[w] > 0.0
        if not good:
            return False
        for w in range(_LANES):
            L[j, j, w] = np.sqrt(t[w])
        for i in range(j + 1, c):
            for w in range(_LANES):
                t[w] = S[i, j, w]
            for q in range(j):
                for w in range(_LANES):
                    t[w] -= L[i, q, w] * L[j, q, w]
            for w in range(_LANES):
                L[i, j, w] = t[w] / L[j, j, w]
    for i in range(c):                                    # NIS = |Y|^2, L Y = nu (forward substitution)
        for w in range(_LANES):
            Y[i, w] = nu[i, w]
        for q in range(i):
            for w in range(_LANES):
                Y[i, w] -= L[i, q, w] * Y[q, w]
        for w in range(_LANES):
            Y[i, w] /= L[i, i, w]
            nis[w] += Y[i, w] * Y[i, w]
    for j in range(n):                                    # K^T = S^{-1} H P
        for i in range(c):
            for w in range(_LANES):
                KT[i, j, w] = HP[i, j, w]
            for q in range(i):
                for w in range(_LANES):
                    KT[i, j, w] -= L[i, q, w] * KT[q, j, w]
            for w in range(_LANES):
                KT[i, j, w] /= L[i, i, w]
        for i in range(c - 1, -1, -1):
            for q in range(i + 1, c):
                for w in range(_LANES):
                    KT[i, j, w] -= L[q, i, w] * KT[q, j, w]
            for w in range(_LANES):
                KT[i, j, w] /= L[i, i, w]
    good = True
    for i in range(n):                                    # x += K nu
        for w in range(_LANES):
            t[w] = 0.0
        for r in range(c):
            for w in range(_LANES):
                t[w] += KT[r, i, w] * nu[r, w]
        for w in range(_LANES):
            x[i, w] += t[w]
            good = good and np.isfinite(x[i, w])
    if not good:
        return False
    for i in range(n):                                    # D = K S - P H^T
        for r in range(c):
            for w in range(_LANES):
                D[i, r, w] = -PH[i, r, w]
            for q in range(c):
                for w in range(_LANES):
                    D[i, r, w] += KT[q, i, w] * S[q, r, w]
    for i in range(n):                                    # P - K (H P) + D K^T, symmetrised
        for j in range(i, n):
            for w in range(_LANES):
                t[w] = P[i, j, w]
                u[w] = P[j, i, w]
            for r in range(c):
                for w in range(_LANES):
                    t[w] += D[i, r, w] * KT[r, j, w] - KT[r, i, w] * HP[r, j, w]
                    u[w] += D[j, r, w] * KT[r, i, w] - KT[r, j, w] * HP[r, i, w]
            for w in range(_LANES):
                P[i, j, w] = 0.5 * (t[w] + u[w])
                P[j, i, w] = P[i, j, w]
    return True


def _nb_rss_row(x, w, pidx, npos, tag_h, anchor, p0, ple, sigma, ref_d, ch_min, meas_min, anchor_sigma, z, parallel):
    """One RSS reading of lane ``w`` linearised at its state: (innovation z - h(x), variance, the Jacobian's entries
    at the ``npos`` position indices), as :func:`_rss_parallel_update` (``parallel``: the channel's near-field
    clamp in h) and :func:`_rss_serial_update`."""
    d2 = 0.0
    for i in range(anchor.shape[0]):
        u = (x[pidx[i], w] if i < npos else tag_h) - anchor[i]
        d2 += u * u
    if d2 < meas_min * meas_min:
        d2 = meas_min * meas_min
    slope = 10.0 * ple / np.log(10.0)
    g0 = -(slope / d2) * (x[pidx[0], w] - anchor[0])
    g1 = -(slope / d2) * (x[pidx[1], w] - anchor[1]) if npos > 1 else 0.0
    g2 = -(slope / d2) * (x[pidx[2], w] - anchor[2]) if npos > 2 else 0.0
    d = np.sqrt(d2)
    dh = d
    if parallel and ch_min > 0.0 and dh < ch_min:
        dh = ch_min
    h = p0 - 10.0 * ple * np.log10(dh / ref_d)
    var = sigma * sigma
    if anchor_sigma > 0.0:
        u = slope * anchor_sigma / (d if d > meas_min else meas_min)
        var += u * u
    return z - h, var, g0, g1, g2


def _nb_ekf(Fi, Fj, Fv, Q, x0, P0, predict_first, slot, active, kind, col, nz, nnz, Z, H, R, A, P0c, PLE, SIG, dims,
            ref_d, ch_min, meas_min, anchor_sigma, tag_h, pidx, npos, descending, out_x, out_P, out_nis, out_dof):
    """The EKF time loop of :func:`_time_loop` with :func:`_ekf_update`, over blocks of ``_LANES`` runs (the last
    block padded with copies of the last run), with each run's NIS and its dof at every step (``out_nis``,
    ``out_dof`` ``(B, T)``; NaN and 0 where no update). Returns 0, or 1 + a run whose update failed (the caller then
    redoes the filter in numpy, which raises the library's error)."""
    T, B, n, ns = Z.shape[0], Z.shape[1], x0.shape[1], kind.shape[0]
    mmax = 1
    for s in range(ns):
        mmax = max(mmax, col[s + 1] - col[s])
    x, xt = np.empty((n, _LANES)), np.empty((n, _LANES))
    P, T1 = np.empty((n, n, _LANES)), np.empty((n, n, _LANES))
    Hr, HP, KT = np.zeros((mmax, n, _LANES)), np.empty((mmax, n, _LANES)), np.empty((mmax, n, _LANES))
    nu, var, key = np.empty((mmax, _LANES)), np.empty((mmax, _LANES)), np.empty((mmax, _LANES))
    Rr, S, L = np.zeros((mmax, mmax, _LANES)), np.empty((mmax, mmax, _LANES)), np.zeros((mmax, mmax, _LANES))
    HPH, PH, D = np.empty((mmax, mmax, _LANES)), np.empty((n, mmax, _LANES)), np.empty((n, mmax, _LANES))
    t, t2 = np.empty(_LANES), np.empty(_LANES)
    Y, nis, dof = np.empty((mmax, _LANES)), np.zeros(_LANES), np.zeros(_LANES, np.int64)
    valid = np.zeros((mmax, _LANES), np.bool_)
    sel = np.empty((mmax, _LANES), np.int64)
    run = np.empty(_LANES, np.int64)
    for b0 in range(0, B, _LANES):
        for w in range(_LANES):
            b = min(b0 + w, B - 1)
            run[w] = b
            for i in range(n):
                x[i, w] = x0[b, i]
                for j in range(n):
                    P[i, j, w] = P0[min(b, P0.shape[0] - 1), i, j]
        for k in range(T):
            if predict_first or k > 0:
                _nb_predict(Fi, Fj, Fv, Q, x, P, xt, T1)
            for w in range(_LANES):
                nis[w] = 0.0
                dof[w] = 0
            ta = min(k, A.shape[1] - 1)
            for s in range(ns):
                if not active[s, k]:                      # no reading of this stream at this step in any run
                    continue
                c0, m, kd = col[s], col[s + 1] - col[s], kind[s]
                serial = kd == 1 or kd == 3
                for w in range(_LANES):                   # the update order: as given, or by descending RSS
                    for j in range(m):
                        sel[j, w] = j
                    if kd == 3 and descending[s]:         # stable: ties (and the missing, last) keep their order
                        for j in range(m):
                            zj = Z[k, run[w], c0 + j]
                            key[j, w] = zj if np.isfinite(zj) else -np.inf
                        for j in range(1, m):
                            i = j
                            while i > 0 and key[sel[i - 1, w], w] < key[sel[i, w], w]:
                                sel[i - 1, w], sel[i, w] = sel[i, w], sel[i - 1, w]
                                i -= 1
                for u in range(m if serial else 1):       # serial: one scalar update per reading
                    rows = 1 if serial else m
                    present = False
                    for r in range(rows):
                        for w in range(_LANES):
                            b = run[w]
                            j = sel[u, w] if serial else r
                            zj = Z[k, b, c0 + j]
                            valid[r, w] = np.isfinite(zj)
                            for e in range(nnz[s]):
                                Hr[r, nz[s, e], w] = 0.0
                            nu[r, w] = 0.0
                            var[r, w] = 1.0
                            if not valid[r, w]:
                                continue
                            present = True
                            dof[w] += 1
                            if kd <= 1:
                                bh = min(b, H.shape[0] - 1)
                                q = 0.0
                                for e in range(nnz[s]):
                                    Hr[r, nz[s, e], w] = H[bh, c0 + j, nz[s, e]]
                                    q += H[bh, c0 + j, nz[s, e]] * x[nz[s, e], w]
                                nu[r, w] = zj - q
                            else:
                                bc = min(b, P0c.shape[0] - 1)
                                nu[r, w], var[r, w], g0, g1, g2 = _nb_rss_row(
                                    x, w, pidx[s], npos[s], tag_h[s], A[min(b, A.shape[0] - 1), ta, c0 + j, :dims[s]],
                                    P0c[bc, c0 + j], PLE[bc, c0 + j], SIG[bc, c0 + j], ref_d[s], ch_min[s], meas_min[s],
                                    anchor_sigma[s], zj, not serial)
                                Hr[r, pidx[s, 0], w] = g0
                                if npos[s] > 1:
                                    Hr[r, pidx[s, 1], w] = g1
                                if npos[s] > 2:
                                    Hr[r, pidx[s, 2], w] = g2
                    if not present:
                        continue
                    for r in range(rows):                 # R of the readings present, unit decoupled noise elsewhere
                        for q in range(rows):
                            for w in range(_LANES):
                                if not (valid[r, w] and valid[q, w]):
                                    Rr[r, q, w] = 1.0 if r == q else 0.0
                                elif kd <= 1:
                                    jr = sel[u, w] if serial else r
                                    jq = sel[u, w] if serial else q
                                    Rr[r, q, w] = R[min(run[w], R.shape[0] - 1), c0 + jr, c0 + jq]
                                else:
                                    Rr[r, q, w] = var[r, w] if r == q else 0.0
                    if not _nb_update(x, P, rows, nz[s], nnz[s], Hr, nu, Rr, HP, HPH, S, L, KT, PH, D, t, t2, Y, nis):
                        return b0 + 1
            for w in range(_LANES):                       # a state or covariance that overflowed: numpy names it
                t[w] = 0.0                                # (v - v is NaN exactly when v is not finite)
            for i in range(n):
                for w in range(_LANES):
                    t[w] += x[i, w] - x[i, w]
                for j in range(i, n):
                    for w in range(_LANES):
                        t[w] += P[i, j, w] - P[i, j, w]
            for w in range(_LANES):
                if not t[w] == 0.0:
                    return b0 + 1
            for w in range(min(_LANES, B - b0)):
                out_nis[b0 + w, k] = nis[w] if dof[w] > 0 else np.nan
                out_dof[b0 + w, k] = dof[w]
            if slot[k] >= 0:
                for w in range(min(_LANES, B - b0)):
                    for i in range(n):
                        out_x[b0 + w, slot[k], i] = x[i, w]
                        for j in range(n):
                            out_P[b0 + w, slot[k], i, j] = P[i, j, w]
    return 0


def _leading(value, batch, B, tail):
    """``value`` (``tail`` or ``batch + tail`` after broadcasting) as ``(1 or B,) + tail``, contiguous."""
    value = np.asarray(value, dtype=float)
    if value.ndim <= len(tail):
        return np.ascontiguousarray(np.broadcast_to(value, tail)[None])
    return np.ascontiguousarray(np.broadcast_to(value, batch + tail).reshape((B,) + tail))


def _pack_streams(setup: _Setup, measurements, B):
    """The streams as the kernel's flat arrays (readings side by side on one axis), or None if one is not supported
    (a NonlinearMeasurement: its h and Jacobian are Python functions)."""
    batch, T, n = setup.batch, setup.T, setup.F.shape[-1]
    kinds, cols, lin, rss, scal = [], [0], [], [], []
    Z = np.empty((T, B, sum(z.shape[-1] for z in setup.zs)))       # time first: a step's readings side by side
    by_time = Z.reshape((T,) + batch + Z.shape[-1:])
    for meas, z in zip(measurements, setup.zs):
        m = z.shape[-1]
        c0 = cols[-1]
        cols.append(c0 + m)
        by_time[..., c0:c0 + m] = np.moveaxis(z, -2, 0)
        if isinstance(meas, LinearMeasurement):
            kinds.append(_LINEAR_PARALLEL if meas.mode == "parallel" else _LINEAR_SERIAL)
            lin.append((c0, m, _leading(meas.H, batch, B, (m, n)), _leading(meas.R, batch, B, (m, m))))
            scal.append((2, 1.0, 0.0, 1.0, 0.0, 0.0, (0, 0, 0), 0, False))
        elif isinstance(meas, RssMeasurement):
            ch = meas.channel
            anchors = np.asarray(meas.anchors_m, dtype=float)
            dim = anchors.shape[-1]
            if dim > 3 or not np.isfinite(ch.wall_attenuation_db):
                return None
            if anchors.ndim == 2:
                a = anchors[None, None]
            elif anchors.ndim == 3:
                a = anchors[None]
            else:
                a = np.broadcast_to(anchors, batch + anchors.shape[-3:]).reshape((B,) + anchors.shape[-3:])
            kinds.append(_RSS_PARALLEL if meas.mode == "parallel" else _RSS_SERIAL)
            rss.append((c0, m, dim, a, *(_leading(v, batch, B, (m,)) for v in (ch.ref_power_dbm, ch.path_loss_exp,
                                                                                ch.sigma_db))))
            idx = np.asarray(meas.position_index, dtype=np.int64)
            tag = np.nan if meas.tag_height_m is None else float(meas.tag_height_m)
            scal.append((dim, float(ch.ref_distance_m), float(ch.min_distance_m), float(meas.min_distance_m),
                         float(meas.anchor_sigma_m), tag, tuple(idx) + (0,) * (3 - idx.size), idx.size,
                         meas.order == "descending"))
        else:
            return None
    M = cols[-1]
    BH = max([h.shape[0] for _, _, h, _ in lin] + [1])
    BR = max([r.shape[0] for _, _, _, r in lin] + [1])
    H, R = np.zeros((BH, M, n)), np.zeros((BR, M, M))
    for c0, m, h, r in lin:
        H[:, c0:c0 + m] = h
        R[:, c0:c0 + m, c0:c0 + m] = r
    BA = max([e[3].shape[0] for e in rss] + [1])
    TA = max([e[3].shape[1] for e in rss] + [1])
    BC = max([max(e[4].shape[0], e[5].shape[0], e[6].shape[0]) for e in rss] + [1])
    A, P0c, PLE, SIG = np.zeros((BA, TA, M, 3)), np.zeros((BC, M)), np.zeros((BC, M)), np.zeros((BC, M))
    for c0, m, dim, a, p0, ple, sigma in rss:
        A[:, :, c0:c0 + m, :dim] = a
        P0c[:, c0:c0 + m], PLE[:, c0:c0 + m], SIG[:, c0:c0 + m] = p0, ple, sigma
    dims, ref_d, ch_min, meas_min, anchor_sigma, tag_h, pidx, npos, desc = (np.array(v) for v in zip(*scal))
    nz, nnz = np.zeros((len(kinds), n), np.int64), np.zeros(len(kinds), np.int64)
    for s, (kind, c0, c1) in enumerate(zip(kinds, cols[:-1], cols[1:])):     # the columns a row can use
        used = np.flatnonzero(np.any(H[:, c0:c1] != 0, axis=(0, 1))) if kind <= _LINEAR_SERIAL else \
            np.asarray(pidx[s][:npos[s]], np.int64)
        nz[s, :used.size], nnz[s] = used, used.size
    return (np.array(kinds, np.int64), np.array(cols, np.int64), nz, nnz, Z, H, R, A, P0c, PLE, SIG, dims.astype(np.int64),
            ref_d.astype(float), ch_min.astype(float), meas_min.astype(float), anchor_sigma.astype(float),
            tag_h.astype(float), pidx.astype(np.int64).reshape(-1, 3), npos.astype(np.int64), desc.astype(np.bool_))


def _compiled_ekf(setup: _Setup, measurements, predict_first: bool):
    """:func:`extended_kalman_filter` by the compiled kernel when it applies (numba installed and enabled, F and Q
    without batch axes, linear and RSS streams, a large enough problem), else None: the numpy loop then runs. It also
    returns None when an update fails (a covariance that is not positive definite, a state that is not finite): the
    numpy loop then redoes the filter and raises the library's error for it."""
    global _NUMBA_ENABLED
    F, Q, batch, T = setup.F, setup.Q, setup.batch, setup.T
    B = int(np.prod(batch, dtype=np.int64))
    if not _NUMBA_ENABLED or F.ndim != 2 or Q.ndim != 2 or B * T < _NUMBA_MIN_WORK or B == 0 or T == 0:
        return None
    if not all(isinstance(m, (LinearMeasurement, RssMeasurement)) for m in measurements):
        return None
    if not (np.array_equal(Q, Q.T) and np.array_equal(setup.P, _mT(setup.P))):
        return None                 # the kernel keeps P exactly symmetric (it computes one triangle of F P F^T + Q)
    packed = _pack_streams(setup, measurements, B)
    if packed is None or not _numba_ready():
        return None
    n, S = F.shape[-1], setup.steps.size
    Fi, Fj = np.nonzero(F)
    P0 = setup.P[None] if setup.P.ndim == 2 else np.broadcast_to(setup.P, batch + (n, n)).reshape(B, n, n)
    out_x, out_P = np.empty((B, S, n)), np.empty((B, S, n, n))
    out_nis, out_dof = np.empty((B, T)), np.empty((B, T), np.int64)
    args = (Fi.astype(np.int64), Fj.astype(np.int64), np.ascontiguousarray(F[Fi, Fj]), np.ascontiguousarray(Q),
            np.ascontiguousarray(setup.x.reshape(B, n)), np.ascontiguousarray(P0), bool(predict_first),
            setup.slot.astype(np.int64), np.array(setup.active, dtype=np.bool_).reshape(-1, T), *packed, out_x, out_P,
            out_nis, out_dof)
    try:                            # only the kernel here: an error of ours must not turn numba off for the session
        status = _nb_ekf(*args)
    except Exception as exc:        # numba could not compile or run the kernel here: numpy from now on
        _NUMBA_ENABLED = False
        warnings.warn(f"locbook: the compiled EKF failed ({type(exc).__name__}: {exc}); using the numpy loop "
                      "(set LOCBOOK_NUMBA=0 to skip the attempt)", RuntimeWarning, stacklevel=3)
        return None
    if status:
        return None
    return TrackResult(out_x.reshape(batch + (S, n)), out_P.reshape(batch + (S, n, n)), setup.steps,
                       out_nis.reshape(batch + (T,)), out_dof.reshape(batch + (T,)))
