"""Calibration of the log-distance path-loss model by least squares (closed forms, and cvxpy).

For measurements ``(d_i, P_i)`` the model ``P_i = P_0 - 10 n log10(d_i/d0) + e_i`` is linear in
``T = [P_0, n]``; the least-squares fit is ``T = (M^T M)^{-1} M^T P`` with rows
``M_i = [1, -10 log10(d_i/d0)]``.

This is Eq. (6) of George and Vadivukkarasi with the sign of the second column
corrected: the paper prints ``+10 log d_i``, which, read literally, returns ``-n``
where the paper reports n = +2.1843. The literal form is kept as ``sign_convention="literal_george"``.
It is also Eq. (5.1) of Dogan (2015) and the per-reader fit of Ozkaya (2011), Eq. (6.4)-(6.6),
whose bounded variant (alpha in [-55, -40] dBm, n in [1.5, 3]) is the ``*_bounds_*`` arguments.

Problems carry leading batch axes: ``distance_m`` and ``rss_dbm`` of shape ``(..., N)`` are
``prod(...)`` independent fits. NaN powers are missing samples (a reading not heard); a NaN distance pads a
ragged problem and must pair with a NaN power.

A batch is isolated: the distances are the design (chosen by the experimenter), so a problem whose given
distances are all equal cannot identify the exponent whatever was heard, and raises
:class:`DegenerateGeometryError`; the powers are data, so a problem that heard too little (fewer than two
distinct distances among its heard samples) or whose arithmetic overflows (powers of 1e300 dBm) gets NaN
parameters and its own ``PathLossFit.problem_status``, and every other problem of the batch is what fitting it
alone gives.

Solvers (:func:`fit_path_loss`, ``solver``): the closed form (normal equations from running sums: time and memory
linear in the samples), the exact bounded fit (KKT enumeration over the running sums) and cvxpy (the robust Huber
variant, and the oracle). A cvxpy fit that does not reach an optimum returns NaN parameters with the solver's
status in ``PathLossFit.status``; it never raises.
"""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np
import scipy.sparse as sp

from .._cvx import cp, solve
from .._validate import as_array, check_choice, check_scalar
from ..errors import ConvergenceError, DegenerateGeometryError, ParameterError
from ..models.channel import PathLossModel, log_distance_regressor_db

__all__ = [
    "PathLossFit",
    "path_loss_design_matrix",
    "fit_path_loss",
    "fix_error_covariance",
    "fit_path_loss_closed_form",
    "calibrate_path_loss",
    "calibrate_path_loss_devices",
    "CALIBRATION_MODES",
    "CALIBRATION_SOLVERS",
    "CALIBRATION_LOSSES",
    "FIT_PROBLEM_STATUSES",
    "path_loss_exp_ratio_estimate",
    "path_loss_exp_given_ref_power",
]

CALIBRATION_MODES = ("per_location_mean", "pooled", "per_anchor")
CALIBRATION_SOLVERS = ("auto", "closed_form", "exact", "cvxpy")
CALIBRATION_LOSSES = ("squared", "huber")
#: values of :attr:`PathLossFit.problem_status`
FIT_PROBLEM_STATUSES = ("ok", "too_few_distances", "not_finite", "solver_failed")
#: statuses of a fit whose parameters can be used
USABLE_STATUSES = ("closed_form", "optimal")


@dataclass(frozen=True)
class PathLossFit:
    """Result of a path-loss fit; arrays carry the batch shape of the problems.

    ``covariance`` is the least-squares parameter covariance ``s^2 (M^T M)^{-1}`` (ordering
    ``[ref_power_dbm, path_loss_exp]``) estimated from the residuals, for standard errors (NaN for the Huber
    fit, whose covariance this formula does not give).

    ``status``: ``"closed_form"`` (the unconstrained normal equations), ``"optimal"`` (a bounded or robust fit at
    its optimum: the exact bounded fit, or cvxpy's status of the stacked solve); any other cvxpy status
    (``"optimal_inaccurate"``, ``"infeasible"``, ``"solver_error"``...) comes with NaN parameters, so a failed
    fit is never mistaken for a result.

    ``problem_status`` (the batch shape; one of :data:`FIT_PROBLEM_STATUSES`) says per problem whether its
    parameters can be used: ``"ok"``; ``"too_few_distances"`` (fewer than two distinct distances among the samples
    it heard); ``"not_finite"`` (the arithmetic overflowed, e.g. powers of 1e300 dBm); ``"solver_failed"`` (cvxpy
    did not reach an optimum for it: a failed stacked solve is halved until the failing problems are alone, and
    ``status`` is then the first failure's). Every problem not ``"ok"`` has NaN
    parameters, residual sigma and covariance. :attr:`problem_ok` is that per problem, :attr:`ok` whether the
    whole batch can be used (the solver's status is usable and every problem is ``"ok"``).
    """

    ref_power_dbm: np.ndarray
    path_loss_exp: np.ndarray
    residual_sigma_db: np.ndarray
    covariance: np.ndarray
    n_samples: np.ndarray
    status: str
    per_location: "PathLossFit | None" = None
    problem_status: np.ndarray | None = None

    def __post_init__(self):
        if self.problem_status is None:      # derived: a usable status and finite parameters
            finite = np.isfinite(self.ref_power_dbm) & np.isfinite(self.path_loss_exp)
            derived = np.where(finite, "ok", "not_finite") if self.status in USABLE_STATUSES else \
                np.full(np.shape(finite), "solver_failed")
            object.__setattr__(self, "problem_status", np.asarray(derived).astype("<U17"))

    @property
    def problem_ok(self) -> np.ndarray:
        """Per problem (the batch shape): whether its parameters can be used."""
        return np.asarray(self.problem_status) == "ok"

    @property
    def ok(self) -> bool:
        """Whether every problem's parameters can be used (:attr:`problem_ok` for each problem)."""
        return self.status in USABLE_STATUSES and bool(np.all(self.problem_status == "ok"))

    @property
    def std_error(self) -> np.ndarray:
        """Standard errors of ``[ref_power_dbm, path_loss_exp]``, shape ``batch + (2,)``."""
        return np.sqrt(np.diagonal(self.covariance, axis1=-2, axis2=-1))

    def model(self, sigma_db=None, *, ref_distance_m: float = 1.0, **options) -> PathLossModel:
        """The fitted channel as a :class:`~locbook.PathLossModel`, for the estimators and filters.

        ``sigma_db``: the shadowing of the model (default: the fit's residual sigma). ``ref_distance_m`` must be
        the reference distance the fit used (1 m unless given to the fit); ``options`` are the model's other
        fields (``min_distance_m``, ``wall_attenuation_db``). A scalar fit gives one shared channel; a 1-D fit
        (``calibrate_path_loss(..., "per_anchor")``) one channel per anchor, in anchor order. A fit with more
        axes (independent problems) has no single model; a fit with a problem that is not ``"ok"`` is refused.
        """
        if not self.ok:
            bad = sorted(set(np.atleast_1d(np.asarray(self.problem_status)).tolist()) - {"ok"}) or [self.status]
            raise ValueError(f"this path-loss fit cannot become a model: status {self.status!r}, problems {bad}")
        if np.ndim(self.ref_power_dbm) > 1:
            raise ValueError(f"a fit of shape {np.shape(self.ref_power_dbm)} holds independent problems; a model "
                             "takes one shared fit or one per anchor (shape (m,)): select one problem first")
        sigma = self.residual_sigma_db if sigma_db is None else sigma_db
        return PathLossModel(self.ref_power_dbm, self.path_loss_exp, sigma, ref_distance_m=ref_distance_m,
                             **options)


def path_loss_design_matrix(distance_m, ref_distance_m: float = 1.0,
                            sign_convention: str = "corrected"):
    """Rows ``[1, -10 log10(d/d0)]`` (corrected) or ``[1, +10 log10 d]`` as printed in Eq. (6)
    of George and Vadivukkarasi (``"literal_george"``; its second unknown is then ``-n``)."""
    check_choice("sign_convention", sign_convention, ("corrected", "literal_george"))
    check_scalar("ref_distance_m", ref_distance_m, gt=0)
    distance_m = as_array("distance_m", distance_m)
    _positive_distances(distance_m)
    log_term = log_distance_regressor_db(distance_m, ref_distance_m)
    second = -log_term if sign_convention == "corrected" else log_term
    return np.stack([np.ones_like(log_term), second], axis=-1)


def _prepare(distance_m, rss_dbm, ref_distance_m):
    # NaN distances pad ragged problems (rows of unequal length) and must pair with a NaN power
    distance_m = as_array("distance_m", distance_m, nan_ok=True)
    rss_dbm = as_array("rss_dbm", rss_dbm, nan_ok=True)
    check_scalar("ref_distance_m", ref_distance_m, gt=0)
    if distance_m.shape != rss_dbm.shape:
        # the one broadcast allowed: distances shared by all problems, powers with the full shape (..., N)
        try:
            shared = np.broadcast_shapes(distance_m.shape, rss_dbm.shape) == rss_dbm.shape
        except ValueError:
            shared = False
        if not shared:
            raise ValueError(f"distance_m {distance_m.shape} must have the shape of rss_dbm {rss_dbm.shape} "
                             "(..., N), or be shared by all its problems")
        distance_m = np.broadcast_to(distance_m, rss_dbm.shape)
    if distance_m.ndim == 0 or distance_m.shape[-1] < 2:
        raise DegenerateGeometryError("distance_m and rss_dbm must hold at least two measurements per problem "
                                      f"(on the last axis) for a path-loss fit, got shape {rss_dbm.shape}")
    orphan = np.isnan(distance_m) & np.isfinite(rss_dbm)
    if orphan.any():
        at = tuple(int(i) for i in np.argwhere(orphan)[0])
        raise ValueError(f"distance_m is NaN where rss_dbm holds a reading ({int(orphan.sum())} such sample(s), the "
                         f"first at index {at}): a NaN distance pads a problem and must pair with a NaN power")
    mask = np.isfinite(rss_dbm) & np.isfinite(distance_m)
    _positive_distances(distance_m[mask])
    # the design (every given distance, heard or not): all equal is an error whatever was heard
    given = distance_m > 0
    # log10 d here only tests that the distances differ (not the law)
    _check_distinct_distances(np.where(given, np.log10(np.where(given, distance_m, 1.0)), 0.0), given)
    log_d = np.where(mask, log_distance_regressor_db(np.where(mask, distance_m, 1.0), ref_distance_m), 0.0)
    return log_d, np.where(mask, rss_dbm, 0.0), mask, _distinct(log_d, mask)


def _positive_distances(distance_m):
    if np.any(distance_m <= 0):
        raise ValueError(f"distance_m must be positive (calibration distances), got a minimum of {distance_m.min()}")


def _distinct(log_d, mask) -> np.ndarray:
    """Per problem: whether the samples of ``mask`` span at least two distinct (log-)distances."""
    big, small = np.where(mask, log_d, -np.inf), np.where(mask, log_d, np.inf)
    low = small.min(axis=-1)
    with np.errstate(invalid="ignore"):          # no sample: -inf - inf
        return (big.max(axis=-1) - low) > 1e-9 * np.maximum(1.0, np.abs(low))


def _check_distinct_distances(log_d, mask):
    """Two unknowns need at least two distinct distances in every problem."""
    bad = ~_distinct(log_d, mask)
    if np.any(bad):
        where = np.argwhere(np.atleast_1d(bad))[:5].tolist()
        raise DegenerateGeometryError(
            "path-loss calibration needs at least two distinct distances per problem; "
            f"problem(s) {where} have all distances equal (e.g. a point at the same distance from "
            "every anchor, like the centre of a rectangle of anchors), so the exponent is not identifiable"
        )


def _finish(log_d, power, mask, ref, exp, status, usable, *, covariance: bool = True, solved=None):
    """Residual sigma and the LS covariance ``s^2 (M^T M)^{-1}`` from running sums (memory linear in N); the
    problems that are not ``usable`` (too few distinct distances heard), whose numbers are not finite, or that the
    solver did not solve (``solved`` False; by default every problem if ``status`` is not usable) get NaN and
    their status (:attr:`PathLossFit.problem_status`)."""
    with np.errstate(over="ignore", invalid="ignore"):     # overflow is caught below, per problem
        resid = np.where(mask, power - (ref[..., None] - exp[..., None] * log_d), 0.0)
        n = mask.sum(axis=-1)
        dof = np.maximum(n - 2, 1)
        s2 = (resid**2).sum(axis=-1) / dof
    del resid
    sum_l, sum_l2 = log_d.sum(-1), (log_d**2).sum(-1)          # M^T M = [[n, -sum L], [-sum L, sum L^2]]
    mtm = np.stack([np.stack([n.astype(float), -sum_l], -1), np.stack([-sum_l, sum_l2], -1)], -2)
    if solved is None:
        solved = np.full(np.shape(usable), status in USABLE_STATUSES)
    finite = np.isfinite(ref) & np.isfinite(exp) & np.isfinite(s2)
    problem_status = np.where(~usable, "too_few_distances", np.where(~solved, "solver_failed",
                                                                     np.where(finite, "ok", "not_finite")))
    problem_status = np.asarray(problem_status).astype("<U17")
    ok = problem_status == "ok"
    if not ok.all():       # a singular M^T M (too few distances heard) must not reach inv; the others are untouched
        mtm = np.where(ok[..., None, None], mtm, np.eye(2))
        ref, exp, s2 = (np.where(ok, v, np.nan) for v in (ref, exp, s2))
    with np.errstate(over="ignore", invalid="ignore"):
        cov = s2[..., None, None] * np.linalg.inv(mtm) if covariance else np.full(mtm.shape, np.nan)
    return PathLossFit(ref, exp, np.sqrt(s2), cov, n, status, problem_status=problem_status)


def fit_path_loss_closed_form(distance_m, rss_dbm, ref_distance_m: float = 1.0) -> PathLossFit:
    """Unconstrained least squares by the normal equations ``(M^T M)^{-1} M^T P`` (Eq. (6),
    George and Vadivukkarasi, sign corrected), batched over leading axes. Missing powers are NaN."""
    log_d, power, mask, usable = _prepare(distance_m, rss_dbm, ref_distance_m)
    # normal equations of P = a - n L:  [[N, -sum L], [-sum L, sum L^2]] [a, n] = [sum P, -sum L P];
    # log_d and power are 0 at missing samples, so the plain sums run over the observed ones
    with np.errstate(over="ignore", invalid="ignore", divide="ignore"):   # per problem: _finish marks them
        s0, s1, s2 = mask.sum(-1).astype(float), log_d.sum(-1), (log_d**2).sum(-1)
        p0, p1 = power.sum(-1), (log_d * power).sum(-1)
        det = s0 * s2 - s1 * s1
        ref = (s2 * p0 - s1 * p1) / det
        exp = (s1 * p0 - s0 * p1) / det
    return _finish(log_d, power, mask, ref, exp, "closed_form", usable)


def _bounded_closed_form(log_d, power, mask, ref_bounds, exp_bounds):
    """Exact bounded least squares of ``P = a - n L``, ``a`` in ``ref_bounds``, ``n`` in ``exp_bounds`` (either
    may be None: unbounded), batched, from the running sums.

    KKT enumeration of the two-parameter box QP (strictly convex: two distinct distances per problem). If the
    unconstrained minimiser is inside the box it is the answer. Otherwise the minimum lies on the boundary, i.e.
    on one of the four edges; on the edge ``n = c`` the objective is a convex parabola in ``a`` whose minimiser
    ``a = (sum P + c sum L) / N`` is clipped to the bounds of ``a`` (the corners are those clips), and on
    ``a = c`` likewise ``n = (c sum L - sum L P) / sum L^2``. The answer is the candidate of least objective,
    compared as the exact excess over the unconstrained minimum ``|M (t - t*)|^2 = N (da - dn Lbar)^2 + S_LL dn^2``
    (``Lbar`` the mean log-distance, ``S_LL`` the centred sum of squares), which has no cancellation.
    Returns ``(ref, exp)`` with the batch shape.
    """
    lo = np.array([-np.inf if b is None else b[0] for b in (ref_bounds, exp_bounds)])
    hi = np.array([np.inf if b is None else b[1] for b in (ref_bounds, exp_bounds)])
    # the unconstrained fit, the arithmetic of fit_path_loss_closed_form (so inactive bounds give its answer)
    s0, s1, s2 = mask.sum(-1).astype(float), log_d.sum(-1), (log_d**2).sum(-1)
    p0, p1 = power.sum(-1), (log_d * power).sum(-1)
    det = s0 * s2 - s1 * s1
    ref = (s2 * p0 - s1 * p1) / det
    exp = (s1 * p0 - s0 * p1) / det
    mean_l = s1 / s0
    s_ll = (np.where(mask, log_d - mean_l[..., None], 0.0) ** 2).sum(-1)
    cand_ref, cand_exp = [ref], [exp]
    for c in (lo[1], hi[1]):                 # edges n = c: the best intercept, clipped (an infinite bound: none)
        if np.isfinite(c):
            cand_exp.append(np.full_like(ref, c))
            cand_ref.append(np.clip((p0 + c * s1) / s0, lo[0], hi[0]))
    for c in (lo[0], hi[0]):                 # edges a = c: the best exponent, clipped
        if np.isfinite(c):
            cand_ref.append(np.full_like(ref, c))
            cand_exp.append(np.clip((c * s1 - p1) / s2, lo[1], hi[1]))
    cand_ref, cand_exp = np.stack(cand_ref), np.stack(cand_exp)          # (candidates, ...)
    feasible = (cand_ref >= lo[0]) & (cand_ref <= hi[0]) & (cand_exp >= lo[1]) & (cand_exp <= hi[1])
    da, dn = cand_ref - ref, cand_exp - exp
    excess = np.where(feasible, s0 * (da - dn * mean_l) ** 2 + s_ll * dn**2, np.inf)
    best = np.argmin(excess, axis=0)[None]
    return np.take_along_axis(cand_ref, best, 0)[0], np.take_along_axis(cand_exp, best, 0)[0]


def _stacked_problem(log_d, power, mask, ref_bounds, exp_bounds, loss="squared", huber_delta_db=None):
    """One cvxpy problem for all ``k`` fits: ``min sum_i ||P_i - P0_i + n_i L_i||^2`` over the observed samples.

    The data enter as constants of one sparse matrix, so building it costs time and memory linear in ``k``
    (not a parameterized DPP form: docs/speed.md).
    """
    k = log_d.shape[0]
    problem_of, _ = np.nonzero(mask)                                  # sample -> problem, row-major
    rows = np.arange(problem_of.size)
    pick = sp.csr_matrix((np.ones(rows.size), (rows, problem_of)), shape=(rows.size, k))
    design = sp.hstack([pick, sp.diags(-log_d[mask]) @ pick], format="csr")   # rows [1, -L] per sample
    ref, exp = cp.Variable(k, name="ref_power_dbm"), cp.Variable(k, name="path_loss_exp")
    constraints = []
    if ref_bounds is not None:
        constraints += [ref >= ref_bounds[0], ref <= ref_bounds[1]]
    if exp_bounds is not None:
        constraints += [exp >= exp_bounds[0], exp <= exp_bounds[1]]
    resid = design @ cp.hstack([ref, exp]) - power[mask]
    # Huber: quadratic within delta of the model, linear beyond, so a gross outlier pulls with bounded force
    objective = cp.sum_squares(resid) if loss == "squared" else cp.sum(cp.huber(resid, huber_delta_db))
    problem = cp.Problem(cp.Minimize(objective), constraints)
    return problem, (ref, exp)


def fit_path_loss(distance_m, rss_dbm, *, ref_distance_m: float = 1.0,
                  ref_power_bounds_dbm: tuple[float, float] | None = None,
                  path_loss_exp_bounds: tuple[float, float] | None = None,
                  solver: str = "auto", loss: str = "squared", huber_delta_db: float = 6.0) -> PathLossFit:
    """Least-squares fit of the log-distance model's ``(ref_power_dbm, path_loss_exp)`` for every problem.

    The model ``P_i = P_0 - 10 n log10(d_i/d0) + e_i`` is linear in ``[P_0, n]``; the fit is
    ``(M^T M)^{-1} M^T P`` with rows ``M_i = [1, -10 log10(d_i/d0)]`` (module docstring), bounded or robust on
    request.

    Parameters
    ----------
    distance_m : array_like, shape (..., N)
        Distances (m), one problem per leading index (may be shared by all problems). A NaN distance pads a
        ragged problem and must pair with a NaN power.
    rss_dbm : array_like, shape (..., N)
        Received powers (dBm); NaN is a sample not heard.
    ref_distance_m : float, default 1.0
        The reference distance ``d0`` (m).
    ref_power_bounds_dbm, path_loss_exp_bounds : (lower, upper), optional
        Bounds on ``P_0`` and ``n`` for every problem (Ozkaya 2011, Sec. 6.2: alpha in [-55, -40] dBm, n in
        [1.5, 3]).
    solver : {"auto", "closed_form", "exact", "cvxpy"}, default "auto"
        :data:`CALIBRATION_SOLVERS`. ``"auto"``: the closed form unbounded, ``"exact"`` bounded, cvxpy for
        ``loss="huber"``. ``"closed_form"``: the normal equations (unconstrained squared loss only). ``"exact"``:
        the bounded fit with the box handled exactly (KKT enumeration: the unconstrained fit if inside the bounds,
        else the best edge, one parameter at a bound and the other in closed form, clipped; no iterations), status
        ``"optimal"``; squared loss only (the Huber fit has no closed form). ``"cvxpy"``: all problems as one
        stacked convex problem (the oracle, Clarabel at tight tolerances).
    loss : {"squared", "huber"}, default "squared"
        ``"huber"`` is the robust variant: residuals beyond ``huber_delta_db`` count linearly (cvxpy's
        ``huber``), so a few gross outliers (a blocked link) do not drag the fit.
    huber_delta_db : float, default 6.0
        The Huber threshold (dB).

    Returns
    -------
    PathLossFit
        The parameters, residual sigma and covariance with the problems' batch shape. A cvxpy solve that does not
        reach an optimum gives NaN parameters and its status (``PathLossFit.status``, ``PathLossFit.ok``). A
        problem that heard fewer than two distinct distances, or whose arithmetic overflows, gets NaN parameters
        and its ``problem_status``, alone. An empty batch gives an empty fit in every mode (status
        ``"closed_form"`` or ``"optimal"``).

    Raises
    ------
    DegenerateGeometryError
        A problem's given distances (heard or not) are all equal: the design cannot identify the exponent.
    ValueError
        Bounds that are not ``(lower, upper)``, a solver that cannot do what is asked (the closed form with bounds
        or the Huber loss; ``"exact"`` with the Huber loss).

    References
    ----------
    George and Vadivukkarasi, Eq. (6) (the sign of the second column corrected); Dogan (2015), Eq. (5.1); Ozkaya
    (2011), Eqs. (6.4)-(6.6) and their bounded variant.

    Examples
    --------
    Noise-free powers give the channel back:

    >>> import numpy as np
    >>> import locbook as lb
    >>> distance = np.array([1.0, 2.0, 4.0, 8.0])
    >>> power = -40.0 - 10 * 2.5 * np.log10(distance)
    >>> fit = lb.fit_path_loss(distance, power)
    >>> print(np.round(fit.ref_power_dbm, 2), np.round(fit.path_loss_exp, 2), fit.status)
    -40.0 2.5 closed_form
    """
    check_choice("solver", solver, CALIBRATION_SOLVERS)
    check_choice("loss", loss, CALIBRATION_LOSSES)
    bounded = ref_power_bounds_dbm is not None or path_loss_exp_bounds is not None
    bounds: list[tuple[float, ...] | None] = []
    for name, given in (("ref_power_bounds_dbm", ref_power_bounds_dbm), ("path_loss_exp_bounds", path_loss_exp_bounds)):
        if given is None:
            bounds.append(None)
            continue
        pair = as_array(name, given)
        if pair.shape != (2,) or not pair[0] <= pair[1]:
            raise ValueError(f"{name} must be (lower, upper) with lower <= upper, got {pair.tolist()}")
        bounds.append(tuple(map(float, pair)))
    if loss == "huber":
        check_scalar("huber_delta_db", huber_delta_db, gt=0)
    if solver == "auto":
        solver = "cvxpy" if loss != "squared" else "exact" if bounded else "closed_form"
    if solver == "closed_form":
        if bounded or loss != "squared":
            raise ValueError("the closed form is the unconstrained least-squares fit; bounds and loss='huber' "
                             "need solver='cvxpy' (or 'auto'; bounds alone also solver='exact')")
        return fit_path_loss_closed_form(distance_m, rss_dbm, ref_distance_m)
    if solver == "exact":
        if loss != "squared":
            raise ValueError("solver='exact' is the (bounded) least-squares fit; loss='huber' has no closed form "
                             "and needs solver='cvxpy' (or 'auto')")
        if not bounded:
            return fit_path_loss_closed_form(distance_m, rss_dbm, ref_distance_m)
    log_d, power, mask, usable = _prepare(distance_m, rss_dbm, ref_distance_m)
    if solver == "exact":
        with np.errstate(over="ignore", invalid="ignore", divide="ignore"):   # per problem: _finish marks them
            ref, exp = _bounded_closed_form(log_d, power, mask, bounds[0], bounds[1])
        return _finish(log_d, power, mask, ref, exp, "optimal", usable)     # the optimum, as cvxpy would report it
    batch, n = log_d.shape[:-1], log_d.shape[-1]
    k = int(np.prod(batch))
    with np.errstate(over="ignore"):    # data whose squares overflow: no solver can use them (not_finite)
        finite = np.isfinite(np.sum(power.reshape(k, n) ** 2, axis=-1))
    use = usable.reshape(k) & finite
    ref, exp, solved = np.full(k, np.nan), np.full(k, np.nan), np.zeros(k, bool)
    status = "optimal"             # nothing to solve (an empty batch, or no problem heard enough): nothing failed
    if use.any():                  # only the problems that can be fitted enter the stacked problem
        pick = (lambda a: a.reshape(k, n)) if use.all() else (lambda a: a.reshape(k, n)[use])
        ref[use], exp[use], solved[use], status = _solve_stacked(pick(log_d), pick(power), pick(mask), bounds, loss,
                                                                 huber_delta_db)
    return _finish(log_d, power, mask, ref.reshape(batch), exp.reshape(batch), status, usable,
                   covariance=loss == "squared", solved=(solved | ~use).reshape(batch))


def _solve_stacked(log_d, power, mask, bounds, loss, huber_delta_db):
    """The problems ``(k, N)`` as one stacked cvxpy problem; if that solve fails the batch is halved and each half
    solved again, so a problem the solver cannot handle fails alone (as in the box-constrained lateration).
    Returns ``(ref, exp, solved, status)``: NaN where not solved, and cvxpy's status (the first failure's if some
    part of the batch failed)."""
    k = log_d.shape[0]
    problem, (v_ref, v_exp) = _stacked_problem(log_d, power, mask, bounds[0], bounds[1], loss, huber_delta_db)
    try:
        solve(problem, "path-loss calibration")
        status = problem.status
    except ConvergenceError:
        status = str(problem.status)
    except cp.error.SolverError:
        status = "solver_error"
    if status == cp.OPTIMAL:
        return v_ref.value, v_exp.value, np.ones(k, bool), status
    if k == 1:
        return np.full(1, np.nan), np.full(1, np.nan), np.zeros(1, bool), status
    half = k // 2
    parts = [_solve_stacked(log_d[sl], power[sl], mask[sl], bounds, loss, huber_delta_db)
             for sl in (slice(0, half), slice(half, k))]
    failed = [p[3] for p in parts if p[3] != cp.OPTIMAL]
    return (np.concatenate([p[0] for p in parts]), np.concatenate([p[1] for p in parts]),
            np.concatenate([p[2] for p in parts]), failed[0] if failed else cp.OPTIMAL)


def calibrate_path_loss(distance_m, rss_dbm, mode: str = "per_location_mean", **fit_kwargs) -> PathLossFit:
    """Calibrate one shared ``(P_0, n)`` from measurements at known locations.

    Parameters
    ----------
    distance_m : array_like, shape (..., L, m)
        Distance ``d_lj`` (m) of location ``l`` from anchor ``j``; leading axes are independent calibrations (e.g.
        Monte-Carlo runs).
    rss_dbm : array_like, shape (..., L, m)
        The mean received power of each link (dBm); NaN is a link not heard.
    mode : {"per_location_mean", "pooled", "per_anchor"}, default "per_location_mean"
        :data:`CALIBRATION_MODES`. ``"per_location_mean"`` (George and Vadivukkarasi, Simulation Results): fit
        each location's m links, then average the L estimates; ``per_location`` holds the L fits and the
        covariance is that of the mean of L independent fits. ``"pooled"``: one fit over all ``L*m`` pairs.
        ``"per_anchor"``: one fit per anchor over its L links (column-wise), giving arrays of length m.
    **fit_kwargs
        Passed to :func:`fit_path_loss` (bounds, solver, loss).

    Returns
    -------
    PathLossFit
        The calibration (batch shape ``(...)``, or ``(..., m)`` per anchor).

    Raises
    ------
    ValueError
        Shapes that differ or hold no location or no anchor, an unknown ``mode``.
    DegenerateGeometryError
        As :func:`fit_path_loss`: a location (or anchor, or the pool) whose distances are all equal.

    References
    ----------
    George and Vadivukkarasi, Eq. (6) and the Simulation Results' per-location average.

    Examples
    --------
    Noise-free powers at three locations give the channel back:

    >>> import numpy as np
    >>> import locbook as lb
    >>> anchors = np.array([[0.0, 0.0], [10.0, 0.0], [0.0, 10.0], [10.0, 10.0]])
    >>> locations = np.array([[2.0, 3.0], [6.0, 5.0], [8.0, 1.0]])
    >>> distance = lb.pairwise_distance_m(locations, anchors)
    >>> power = lb.PathLossModel(-40.0, 2.5).mean_rss_dbm(distance)
    >>> fit = lb.calibrate_path_loss(distance, power)
    >>> print(np.round(fit.ref_power_dbm, 2), np.round(fit.path_loss_exp, 2))
    -40.0 2.5
    >>> print(np.round(lb.calibrate_path_loss(distance, power, mode="per_anchor").path_loss_exp, 2))
    [2.5 2.5 2.5 2.5]
    """
    check_choice("mode", mode, CALIBRATION_MODES)
    distance_m = as_array("distance_m", distance_m)
    rss_dbm = as_array("rss_dbm", rss_dbm, nan_ok=True)
    if distance_m.ndim < 2 or distance_m.shape != rss_dbm.shape:
        raise ValueError(
            f"distance_m and rss_dbm must both have shape (..., locations, anchors); got "
            f"{distance_m.shape} and {rss_dbm.shape}"
        )
    if distance_m.shape[-2] < 1 or distance_m.shape[-1] < 1:
        raise ValueError(f"distance_m and rss_dbm must hold at least one location and one anchor, got shape "
                         f"{distance_m.shape}")
    if mode == "per_location_mean":
        per = fit_path_loss(distance_m, rss_dbm, **fit_kwargs)
        n_loc = distance_m.shape[-2]
        cov = per.covariance.sum(axis=-3) / n_loc**2
        # a calibration is the mean of all its locations' fits: a failed location fails it (NaN already propagates)
        worst = np.take_along_axis(per.problem_status, np.argmin(per.problem_status == "ok", axis=-1)[..., None],
                                   -1)[..., 0]
        return PathLossFit(
            per.ref_power_dbm.mean(axis=-1), per.path_loss_exp.mean(axis=-1),
            np.sqrt(np.mean(per.residual_sigma_db**2, axis=-1)), cov, per.n_samples.sum(axis=-1),
            per.status, per, worst,
        )
    if mode == "pooled":
        pooled = distance_m.shape[:-2] + (distance_m.shape[-2] * distance_m.shape[-1],)   # not -1: empty batches
        return fit_path_loss(distance_m.reshape(pooled), rss_dbm.reshape(pooled), **fit_kwargs)
    if mode == "per_anchor":
        return fit_path_loss(np.swapaxes(distance_m, -1, -2), np.swapaxes(rss_dbm, -1, -2), **fit_kwargs)
    raise ValueError(f"calibration mode must be one of {CALIBRATION_MODES}, got {mode!r}")


def calibrate_path_loss_devices(distance_m, rss_dbm, device, *, reference=None,
                                ref_distance_m: float = 1.0) -> tuple[PathLossFit, dict[str, float]]:
    """Per-anchor log-distance fit jointly with one receiver offset per device:
    ``rss_la = P0_a - 10 n_a log10(d_la / d0) + o_d(l) + e_la``, one linear least-squares problem over the finite
    readings (NaN = not heard, left out), the reference device's offset fixed at 0 dB.

    ``distance_m, rss_dbm``: ``(L, m)``, location (epoch) ``l`` at distance ``d_la`` from anchor ``a``;
    ``device``: ``(L,)``, the device of each location (text). ``reference``: the device whose offset is 0 (default:
    the one with most finite readings; ties: the first in sorted order). Returns the fit, a :class:`PathLossFit`
    of the kind ``calibrate_path_loss(distance_m, rss_dbm, "per_anchor", solver="closed_form")`` returns (arrays
    of length m), and ``{device: o_d}`` in dB (a device that reads 3 dB strong has +3).

    Solved by the Frisch-Waugh-Lovell theorem: the offsets are the least-squares solution of the readings and the
    device indicators each residualised on its anchor's ``[1, L]`` (``L = 10 log10(d/d0)``), then each anchor's
    ``(P0_a, n_a)`` is the closed form (:func:`fit_path_loss_closed_form`) on the readings with the offsets
    removed; with one device that is exactly the per-anchor closed form. With several, the residuals (offsets
    removed) give ``residual_sigma_db_a = sqrt(SSR_a / (N_a - 2 - K N_a / N))``, the K = D - 1 offsets' degrees of
    freedom shared in proportion to the readings, and ``covariance_a`` the OLS covariance of ``(P0_a, n_a)``
    under per-anchor noise ``sigma_a``: ``s_a^2 (M_a^T M_a)^{-1} + G_a Cov(o) G_a^T``, ``G_a`` the regression of
    the device indicators on ``M_a`` and ``Cov(o)`` the sandwich ``A^{-1} Z~^T S Z~ A^{-1}``, ``A = Z~^T Z~``.

    Raises :class:`DegenerateGeometryError` for a device with no finite reading, an anchor whose finite readings
    span fewer than two distinct distances, or offsets the readings cannot separate from the anchors' ``P0``
    (devices that share no anchor, through other devices, with the reference).
    """
    distance_m = as_array("distance_m", distance_m, ndim=2)
    rss_dbm = as_array("rss_dbm", rss_dbm, ndim=2, nan_ok=True)
    check_scalar("ref_distance_m", ref_distance_m, gt=0)
    if distance_m.shape != rss_dbm.shape or 0 in distance_m.shape:
        raise ParameterError(f"distance_m {distance_m.shape} and rss_dbm {rss_dbm.shape} must both have the shape "
                             "(locations, anchors), at least one of each")
    _positive_distances(distance_m)
    n_loc, m = rss_dbm.shape
    device = np.asarray(device, dtype=object)
    if device.shape != (n_loc,):
        raise ParameterError(f"device must give one device per location, shape ({n_loc},), got {device.shape}")
    if any(d is None or (isinstance(d, float) and not np.isfinite(d)) or not str(d).strip() for d in device.tolist()):
        raise ParameterError("device holds an empty or missing device name; every location names its device")
    names, code = np.unique(device.astype(str), return_inverse=True)
    heard = np.isfinite(rss_dbm)
    per_device = np.bincount(code, weights=heard.sum(axis=1), minlength=len(names))
    if (per_device == 0).any():
        d = str(names[int(np.flatnonzero(per_device == 0)[0])])
        raise DegenerateGeometryError(f"device {d!r} has no finite reading (all not heard): its offset cannot be "
                                      "fitted; leave its locations out")
    if reference is None:
        ref_index = int(np.argmax(per_device))                 # the first of the largest, in sorted order
    elif str(reference) in names:
        ref_index = int(np.flatnonzero(names == str(reference))[0])
    else:
        raise ParameterError(f"reference {reference!r} is not one of the devices {names.tolist()}")
    log_d = log_distance_regressor_db(distance_m, ref_distance_m)      # L = 10 log10(d/d0), (L, m)
    lw = np.where(heard, log_d, 0.0)
    s0, s1, s2 = heard.sum(0).astype(float), lw.sum(0), (lw**2).sum(0)   # per anchor: N_a, sum L, sum L^2
    few = ~_distinct(np.where(heard, log_d, 0.0).T, heard.T)
    if few.any():
        raise DegenerateGeometryError(
            f"anchor(s) {np.flatnonzero(few)[:5].tolist()} (columns) have fewer than two distinct distances among "
            "their finite readings: their exponent, and so the device offsets, cannot be fitted")
    others = np.delete(np.arange(len(names)), ref_index)
    k = len(others)
    offsets = np.zeros(len(names))
    if k:
        from scipy.sparse.csgraph import connected_components
        hears = np.zeros((len(names), m))                     # device x anchor: readings shared
        np.add.at(hears, code, heard.astype(float))
        graph = sp.bmat([[None, sp.csr_matrix(hears)], [sp.csr_matrix(hears.T), None]])
        _, label = connected_components(graph, directed=False)
        apart = [str(names[i]) for i in range(len(names)) if label[i] != label[ref_index]]
        if apart:
            raise DegenerateGeometryError(
                f"device(s) {apart} share no anchor, directly or through other devices, with the reference device "
                f"{str(names[ref_index])!r}: their offsets cannot be told from the anchors' reference powers")
        det = s0 * s2 - s1 * s1

        def sol(a, b):
            """Per anchor, [[N_a, S1_a], [S1_a, S2_a]]^-1 [a, b]: the regression on [1, L] (a, b: (m, ...))."""
            col = (slice(None),) + (None,) * (np.ndim(a) - 1)
            return ((s2[col] * a - s1[col] * b) / det[col], (s0[col] * b - s1[col] * a) / det[col])
        # the readings, residualised on each anchor's [1, L]
        y = np.where(heard, rss_dbm, 0.0)
        b0, b1 = sol(y.sum(0), (lw * y).sum(0))
        y_res = (rss_dbm - b0 - b1 * log_d)[heard]
        # each non-reference device's indicator, residualised likewise: (locations, anchors, k)
        z = (code[:, None] == others[None, :]).astype(float)                       # (L, k)
        zh = heard[:, :, None] * z[:, None, :]
        c0, c1 = sol(zh.sum(0), (lw[:, :, None] * zh).sum(0))                      # (m, k)
        z_res = (z[:, None, :] - c0 - c1 * log_d[:, :, None])[heard]               # (N, k)
        o, _, rank, _ = np.linalg.lstsq(z_res, y_res, rcond=None)
        if rank < k:
            raise DegenerateGeometryError("the device offsets are not identifiable from these readings (the device "
                                          "indicators are collinear with the anchors' [1, log-distance] terms)")
        offsets[others] = o
    fit = calibrate_path_loss(distance_m, rss_dbm - offsets[code][:, None], "per_anchor", solver="closed_form",
                              ref_distance_m=ref_distance_m)
    if k:
        n_all = s0.sum()
        resid = np.where(heard, rss_dbm - offsets[code][:, None]
                         - (fit.ref_power_dbm - fit.path_loss_exp * log_d), 0.0)
        dof = s0 - 2.0 - k * s0 / n_all                  # the offsets' k degrees of freedom, shared by readings
        sigma2 = (resid**2).sum(0) / np.where(dof > 0, dof, 1.0)
        weight = np.broadcast_to(sigma2, heard.shape)[heard]                       # S = diag(sigma_a(i)^2)
        a_inv = np.linalg.inv(z_res.T @ z_res)
        cov_o = a_inv @ (z_res.T @ (weight[:, None] * z_res)) @ a_inv              # (k, k)
        g = np.stack([c0, -c1], axis=1)                  # (m, 2, k): indicators on [1, -L], the (P0, n) columns
        inv_mtm = np.stack([np.stack([s2, s1], -1), np.stack([s1, s0], -1)], -2) / det[:, None, None]
        cov = sigma2[:, None, None] * inv_mtm + g @ cov_o @ np.swapaxes(g, 1, 2)
        fit = PathLossFit(fit.ref_power_dbm, fit.path_loss_exp, np.sqrt(sigma2), cov, fit.n_samples, fit.status,
                          problem_status=fit.problem_status)
    return fit, {str(d): float(o) for d, o in zip(names, offsets)}


def _exponent_inputs(distance_m, rss_dbm, ref_power_dbm, ref_distance_m):
    distance_m = as_array("distance_m", distance_m)
    rss_dbm = as_array("rss_dbm", rss_dbm, nan_ok=True)
    try:
        shape = np.broadcast_shapes(distance_m.shape, rss_dbm.shape)
    except ValueError:
        raise ValueError(f"distance_m {distance_m.shape} and rss_dbm {rss_dbm.shape} do not broadcast") from None
    if not shape:
        raise ValueError("distance_m and rss_dbm need a sample axis (the last one)")
    if np.any(distance_m <= 0):
        raise ValueError("distances must be positive")
    ref = as_array("ref_power_dbm", ref_power_dbm)
    check_scalar("ref_distance_m", ref_distance_m, gt=0)
    # L = log10(D/d0) of Eq. (3.8) and its LS form, as those estimators print it (the law's regressor is 10 L;
    # the factor 10 stays where they write it, so their rounding is the printed algebra's)
    log_d = np.broadcast_to(np.log10(distance_m / ref_distance_m), shape)
    excess = np.broadcast_to(rss_dbm - ref[..., None], shape)
    return log_d, excess


def path_loss_exp_ratio_estimate(distance_m, rss_dbm, ref_power_dbm, *, ref_distance_m: float = 1.0):
    """The thesis-literal exponent estimator, Eq. (3.8) in Gudipati 2017 (flagged: an average of ratios):
    ``C = -(1/N) sum_s (M_s - S) / (10 log10(D_s / d0))`` with ``S = ref_power_dbm`` measured at ``d0``.

    The term at ``D = d0`` is 0/0 and is left out (the print does not say so), as are missing (NaN) powers; near
    ``d0`` the ratio's denominator is small, so those points dominate its variance (compare
    :func:`path_loss_exp_given_ref_power`). ``(..., N)`` -> ``(...)``."""
    log_d, excess = _exponent_inputs(distance_m, rss_dbm, ref_power_dbm, ref_distance_m)
    use = np.isfinite(excess) & (np.abs(log_d) > 1e-12)
    if np.any(use.sum(axis=-1) == 0):
        raise DegenerateGeometryError("the ratio estimator needs at least one heard point away from the reference "
                                      "distance (D = d0 is 0/0)")
    ratio = np.where(use, -excess / (10.0 * np.where(use, log_d, 1.0)), 0.0)
    return ratio.sum(axis=-1) / use.sum(axis=-1)


def path_loss_exp_given_ref_power(distance_m, rss_dbm, ref_power_dbm, *, ref_distance_m: float = 1.0):
    """Least-squares exponent with the reference power fixed at its measured value: minimises
    ``sum_s (M_s - S + 10 C log10(D_s/d0))^2``, so ``C = -sum L (M - S) / (10 sum L^2)``, ``L = log10(D/d0)``.
    The convex reformulation of Eq. (3.8) (ours, not the thesis's; the full two-parameter fit is
    :func:`fit_path_loss`).
    Missing (NaN) powers are left out. ``(..., N)`` -> ``(...)``."""
    log_d, excess = _exponent_inputs(distance_m, rss_dbm, ref_power_dbm, ref_distance_m)
    use = np.isfinite(excess)
    l2 = np.where(use, log_d**2, 0.0).sum(axis=-1)
    if np.any(l2 <= 0):
        raise DegenerateGeometryError("the exponent needs at least one heard point away from the reference distance")
    return -np.where(use, log_d * excess, 0.0).sum(axis=-1) / (10.0 * l2)


def fix_error_covariance(fixes_m, truth_m) -> np.ndarray:
    """Measurement-noise covariance of position fixes calibrated against ground truth: the sample covariance
    of ``fix - truth`` over the points of each run, ``fixes_m (..., T, dim)``, ``truth_m (T, dim)`` ->
    ``(..., dim, dim)``. This is how a test bed obtains a tracker's R "from experiments" (George and
    Vadivukkarasi, Conclusion); it needs the truth, so it is a calibration, not an online estimate."""
    fixes_m = as_array("fixes_m", fixes_m, min_ndim=2, nan_ok=True)
    truth_m = as_array("truth_m", truth_m, ndim=2, trailing=(fixes_m.shape[-2], fixes_m.shape[-1]))
    if fixes_m.shape[-2] < 2:
        raise ValueError(f"a covariance needs at least 2 points per run, got {fixes_m.shape[-2]}")
    err = fixes_m - truth_m
    err = err - err.mean(axis=-2, keepdims=True)
    return np.einsum("...ti,...tj->...ij", err, err) / (err.shape[-2] - 1)
