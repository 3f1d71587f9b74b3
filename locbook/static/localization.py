"""Static localization from ranges or received powers, batched over many problems.

Every estimator takes anchors ``(m, 2)`` shared by all problems and measurements with leading batch
axes ``(..., m)``, and returns a :class:`LocalizationResult` whose ``position_m`` has shape ``(..., 2)``. The
distance-based lateration family takes ``(anchors_m, distance_m, ...)``; the RSS estimators take the readings first,
then the one RSS measurement model, :class:`locbook.RssModel` (its anchors, channel and tag height), then keyword-only
options: ``rss_ml_position(rss_dbm, model, initial_m)``, ``grid_ml_position(rss_dbm, model, cells_m)`` (the form
before issue 47, anchors, readings and a :class:`~locbook.PathLossModel`, is deprecated for one release).

- :func:`lateration_ls`: linearized least squares, Eq. (8) of George and Vadivukkarasi:
  subtracting the circle of a reference anchor r from circle i gives the linear system
  ``2 (a_r - a_i)^T p = d_i^2 - d_r^2 - |a_i|^2 + |a_r|^2``. With ``pairs`` (Palvai 2008, Eqs. (2.27)-(2.29)):
  the anchors may differ per problem (receivers ``(..., N, dim)`` at random positions) and the sphere equations
  are differenced in pairs ``(i, j)``, consecutive or against the first or the last anchor,
  ``2 (s_j - s_i)^T X = d_i^2 - d_j^2 - |s_i|^2 + |s_j|^2`` (corrected: the printed rows, Eqs. (2.18), (2.20) and
  (2.27), lack the factor 2 and Eq. (2.18)'s right-hand side the full norms; ``variant="literal_palvai2008"`` keeps the
  printed rows without the 2, flagged: it returns twice the coordinates). :func:`lateration_system` builds either
  system;
  :func:`locbook.static.least_squares.recursive_least_squares` is the recursive form of the same rows.
- :func:`lateration_wls`: the same system with weights.
- :func:`lateration_box_ls`: the same objective with a box constraint, solved exactly by enumerating the
  KKT active sets, vectorized over problems (cvxpy kept as the reference, ``solver="cvxpy"``).
- :func:`rss_ml_position`: maximum likelihood in the RSS domain (Gaussian shadowing), i.e. Eq. (2.4) of
  Dogan (2015), solved by batched Levenberg-Marquardt from a convex (linear LS) initialiser.
- :func:`grid_ml_position`: exhaustive maximum likelihood over candidate points.

Missing readings (the library's one rule): a NaN received power or range means "not heard" (the anchor got
no packet in that epoch). Each problem uses the anchors heard in it; problems are grouped by their pattern of
heard anchors and each group is solved with that subset, so a problem with no NaN goes through exactly the
computation it always did (and a problem with one anchor missing gets exactly what the estimator gives on the
anchors it heard). A problem with fewer than ``min_anchors`` heard anchors (default ``dim + 1``; at most the
number of anchors), or whose heard anchors are collinear or coincide, gets a NaN position, ``converged=False``
and a ``status`` saying why (:class:`LocalizationResult`), alone: its batch is unaffected. If the reference
anchor of the linearized system is not heard, the first heard anchor serves as reference for that problem.

Failures are per problem too: a problem the solver fails on, or whose finite readings overflow the arithmetic
(ranges whose squares are infinite), gets NaN and ``status="solver_failed"``; no estimator raises for its
batch (except :func:`rss_ml_position` when asked to, ``raise_on_failure=True``). Infinite readings, and
non-finite anchors, model parameters, grids, boxes and weights, are rejected with a ``ValueError`` naming the
argument; so are shapes that do not match (nothing is broadcast silently).

Anchor heights (measured data, e.g. anchors near the ceiling and a tag carried at 1.3 m): every estimator takes
``tag_height_m`` (the RSS estimators read it from the model, ``model.tag_height_m``). Then ``anchors_m`` is
``(m, 3)`` (x, y, height), the tag moves in the plane ``z = tag_height_m``, positions are ``(..., 2)`` and every
range and power is that of the 3-D distance ``sqrt(|p - a_xy|^2 + (a_z - tag_height_m)^2)``. The linearized systems
stay exact (the known height moves to the right-hand side: ``|p - a_xy|^2 = d^2 - (a_z - h)^2``); the geometry checks
apply to the anchors' plan positions.
Without ``tag_height_m`` the anchors' dimension is the position's (2-D or 3-D alike).
"""
from __future__ import annotations

import inspect
from dataclasses import dataclass, replace
from functools import lru_cache
from itertools import product

import numpy as np

from .._cvx import cp, solve
from .._validate import as_array, check_choice, check_scalar
from .._deprecation import old_form
from ..models.channel import PathLossModel, log_distance_mean_dbm, pairwise_distance_m, require_path_loss_model
from ..models.rss import RssModel, rss_mean_jacobian
from ..errors import ConvergenceError, DegenerateGeometryError, ParameterError

__all__ = [
    "LocalizationResult",
    "check_anchor_geometry",
    "lateration_system",
    "lateration_ls",
    "lateration_wls",
    "lateration_box_ls",
    "LATERATION_PAIRS",
    "LATERATION_VARIANTS",
    "BOX_LS_SOLVERS",
    "ANCHOR_CONDITION_RTOL",
    "rss_ml_position",
    "grid_ml_position",
    "GRID_ML_BLOCK_BYTES",
    "LOCALIZATION_STATUSES",
    "IMPLAUSIBLE_SIGMAS",
    "implausible_powers",
    "GOODNESS_OF_FIT_ALPHA",
]

#: values of ``solver`` in :func:`lateration_box_ls`
BOX_LS_SOLVERS = ("exact", "cvxpy")

#: values of ``pairs`` in :func:`lateration_system` and :func:`lateration_ls`: which sphere equations are differenced
#: (Palvai 2008): each anchor against the next, or every anchor against the first or the last one
LATERATION_PAIRS = ("consecutive", "first", "last")

#: values of ``variant``: the rows with the factor 2 of the differenced sphere equations, or Palvai's printed rows
#: without it (Palvai 2008, Eqs. (2.20), (2.27); they give twice the coordinates)
LATERATION_VARIANTS = ("corrected", "literal_palvai2008")

#: values of :attr:`LocalizationResult.status`
LOCALIZATION_STATUSES = ("ok", "too_few_anchors", "degenerate_geometry", "solver_failed", "not_converged",
                         "implausible_reading", "poor_fit")

#: A received power more than this many shadowing standard deviations above the model's mean at the estimator's
#: near-field clamp is taken as not a reading of that channel: :func:`rss_ml_position` (clamp
#: ``max(min_distance_m, model.min_distance_m)``, 1 mm by default) and :func:`grid_ml_position` (clamp
#: ``max(model.min_distance_m, 1e-6)``) give its problem ``status="implausible_reading"``. The physical assumption:
#: a reading that implies a tag closer than the clamp (1 mm) to an anchor's antenna is implausible (a unit error, a
#: sentinel, an overflow), not a tag touching the antenna. It is an assumption, not a certainty: a real reading of a
#: tag closer than the clamp can be refused (the model's own ``min_distance_m`` being 0): with ``sigma_db = 0`` (the
#: default) any power above the clamp mean is, e.g. the noise-free reading of a tag 0.5 mm from an anchor. For a tag
#: at least the clamp away, a reading 10 sigma above the clamp mean has probability below 1e-23.
IMPLAUSIBLE_SIGMAS = 10.0

#: False-alarm probability of the ML estimators' goodness-of-fit test (the static analogue of the filters' NIS
#: guard): a converged problem whose minimised cost over the shadowing variance, ``sum_j r_j^2 / sigma^2``, exceeds
#: ``chi2.ppf(1 - GOODNESS_OF_FIT_ALPHA, m_heard - dim)`` gets ``status="poor_fit"``. Under the model the statistic
#: is chi-square with ``m_heard - dim`` degrees of freedom (to first order: the residual sum of squares of a linear
#: Gaussian model fitted by least squares, Cochran's theorem), so a reading set drawn from the model is flagged once
#: in a billion problems, while readings that no single position explains (four corners of a 10 m square all at
#: +100 dBm: about 48 sigma per anchor) are flagged at any sigma. Why so small: the flag must say "these readings
#: are not this channel", not "an unlucky draw"; real mismodelling (walls, a sentinel, a wrong P_0) is many sigma
#: away.
GOODNESS_OF_FIT_ALPHA = 1e-9


@dataclass(frozen=True)
class LocalizationResult:
    """Estimated positions ``(..., dim)`` with per-problem solver information.

    ``converged`` is True only for a problem whose estimate is what the method promises. ``status`` (same
    batch shape) says why not: one of :data:`LOCALIZATION_STATUSES`:

    - ``"ok"``: converged;
    - ``"too_few_anchors"``: fewer than ``min_anchors`` anchors heard (module docstring, "Missing readings");
    - ``"degenerate_geometry"``: the anchors the problem uses are collinear or coincide (for
      :func:`lateration_wls` also: the anchors with a positive weight);
    - ``"solver_failed"``: the solver did not reach an optimum, or the arithmetic did not give a finite
      estimate (e.g. ranges so large that their squares overflow, or no finite start for the iterations);
    - ``"not_converged"``: the iteration limit was reached (the last iterate is returned);
    - ``"implausible_reading"`` (RSS estimators): a heard power more than :data:`IMPLAUSIBLE_SIGMAS` shadowing
      standard deviations above the model's mean at the estimator's near-field clamp, e.g. +500 dBm or 1e300 dBm
      (:func:`implausible_powers`): a reading implying a tag closer than 1 mm (the RSS ML's default clamp) to an
      anchor's antenna is taken as implausible;
    - ``"poor_fit"`` (RSS estimators, model with ``sigma_db > 0``): converged, but the readings do not fit the model
      together: the minimised cost over the shadowing variance exceeds the chi-square bound of
      :data:`GOODNESS_OF_FIT_ALPHA` with ``m_heard - dim`` degrees of freedom (e.g. four equal powers of +100 dBm
      around a 10 m square). The position (the ML answer for those readings) and ``converged=True`` are kept.

    ``converged`` is never True with an infinite or NaN ``cost``.

    Problems with any status but ``"ok"``, ``"not_converged"`` and ``"poor_fit"`` have a NaN position. ``cost`` is
    NaN where no cost was evaluated.
    """

    position_m: np.ndarray
    converged: np.ndarray
    cost: np.ndarray | None
    n_iter: int
    method: str
    status: np.ndarray | None = None

    def __post_init__(self):
        if self.status is None:
            object.__setattr__(self, "status", np.where(self.converged, "ok", "not_converged").astype("<U19"))


#: Anchors whose centred coordinates have a smallest singular value below this fraction of the largest are
#: treated as collinear (coplanar in 3-D): :func:`check_anchor_geometry`. Why 1e-6: the ratio ``r`` is how far
#: the layout is from a line, relative to its size, and a fix across that line moves by about ``1/r`` times the
#: range errors (the linearized system's smallest singular value is ``r`` times its largest); at ``r = 1e-6`` a
#: millimetre of range error is already a kilometre across the line, so no layout below it can give an answer
#: worth reporting. It is scale-invariant, lies well above float64 round-off (the squared ranges' rounding alone
#: moves the fix by about ``eps / r`` of the layout's size, 2e-10 at the bound) and far below every layout the
#: notebooks and the shipped data use (the least full layout, the 2.1 m x 7.8 m corridor, has 0.27 and 0.23 on a
#: subset of three; the least of all, a subset of three of the Kolakowski 2021 anchors, 0.022).
ANCHOR_CONDITION_RTOL = 1e-6


def check_anchor_geometry(anchors_m) -> np.ndarray:
    """Validate anchors ``(m, dim)``: finite, at least ``dim + 1`` anchors, no two at one point (closer than
    1 nm), not on one line (plane), nor nearly so: the smallest singular value of the centred anchor matrix must
    exceed :data:`ANCHOR_CONDITION_RTOL` (1e-6) times the largest (a scale-invariant conditioning criterion; the
    constant's comment says why 1e-6).

    Raises :class:`DegenerateGeometryError` naming the problem (``ValueError`` for a wrong shape or a
    non-finite coordinate).
    """
    anchors_m = as_array("anchors_m", anchors_m, ndim=2)
    m, dim = anchors_m.shape
    if dim < 1:
        raise ValueError(f"anchors_m must have shape (m, dim) with dim >= 1, got {anchors_m.shape}")
    if m < dim + 1:
        raise DegenerateGeometryError(
            f"{dim}-D localization needs at least {dim + 1} anchors, got {m}"
        )
    gaps = np.where(np.eye(m, dtype=bool), np.inf, pairwise_distance_m(anchors_m, anchors_m))
    if np.any(gaps <= 1e-9):
        i, j = np.argwhere(gaps <= 1e-9)[0]
        raise DegenerateGeometryError(f"anchors {i} and {j} coincide at {anchors_m[i].tolist()}: "
                                      "two anchors at one point are one anchor")
    centred = anchors_m - anchors_m.mean(axis=0)
    # the ratio is scale-invariant: normalise first, so coordinates near 1e300 do not overflow inside the SVD
    sv = np.linalg.svd(centred / np.max(np.abs(centred)), compute_uv=False)
    ratio = sv[dim - 1] / sv[0]
    if not ratio > ANCHOR_CONDITION_RTOL:
        rank = int(np.sum(sv > ANCHOR_CONDITION_RTOL * sv[0]))
        flat, across = ("coplanar", "across the plane they lie in") if dim == 3 else \
            ("collinear", "across the line they lie on")
        raise DegenerateGeometryError(
            f"the {m} anchors are {flat} or nearly so: the smallest singular value of the centred anchors is "
            f"{ratio:.3g} of the largest (numerical rank {rank} < {dim}; the bound is {ANCHOR_CONDITION_RTOL:g}), "
            f"so a position {across} cannot be resolved"
        )
    return anchors_m


# -- missing readings ---------------------------------------------------------------------------------
def _readings(name: str, values, m: int) -> np.ndarray:
    """Measurements ``(..., m)``: NaN = not heard; infinities and a wrong anchor axis are errors."""
    values = as_array(name, values, min_ndim=1, nan_ok=True)
    if values.shape[-1] != m:
        raise ValueError(f"{name} must have shape (..., {m}), one value per anchor ({m} anchors), "
                         f"got shape {values.shape}")
    return values


def _given_readings(name: str, values) -> np.ndarray:
    """Readings as the public entry got them, converted once (:func:`locbook._validate.as_array`: a masked entry is
    NaN, not heard), so that every later look at them (which anchors were heard, the per-subset solves) sees the same
    values; the shape is checked where the anchors are known."""
    return as_array(name, values, nan_ok=True)


def _has_missing(values) -> bool:
    """Whether any reading is NaN (not heard). Decided on the readings themselves, never on quantities derived
    from them (a linearized right-hand side can be NaN from overflow with every anchor heard)."""
    return bool(np.isnan(np.asarray(values, dtype=float)).any())


def _status(ok: np.ndarray, failure: str = "solver_failed") -> np.ndarray:
    """Per-problem status: ``"ok"`` where ``ok``, else ``failure``."""
    return np.where(ok, "ok", failure).astype("<U19")


def implausible_powers(rss_dbm, model: PathLossModel, clamp_m: float) -> np.ndarray:
    """Per problem ``(...)``: whether some heard power of ``rss_dbm (..., m)`` exceeds the model's mean at the
    near-field clamp ``clamp_m`` (a positive finite distance), ``P_0 - 10 n log10(clamp_m / d0)`` (walls and
    antenna heights only lower it), by more than :data:`IMPLAUSIBLE_SIGMAS` times the anchor's shadowing sigma.

    The physical assumption: a reading that implies a tag closer than ``clamp_m`` to an anchor's antenna (closer
    than 1 mm at the RSS ML's default clamp) is implausible, a unit error, a sentinel or an overflow rather than a
    tag touching the antenna. A real reading of a tag that close IS refused (with ``sigma_db = 0``, any power above
    the clamp mean); for a tag at least ``clamp_m`` away the model gives such a reading probability below 1e-23.
    NaN (not heard) is never implausible."""
    check_scalar("clamp_m", clamp_m, gt=0)     # 0 would give an infinite bound (nothing refused), NaN no bound
    top = (log_distance_mean_dbm(clamp_m, np.asarray(model.ref_power_dbm, float), np.asarray(model.path_loss_exp, float),
                                 ref_distance_m=model.ref_distance_m)
           + IMPLAUSIBLE_SIGMAS * np.asarray(model.sigma_db, float))
    return np.any(rss_dbm > top, axis=-1)


def _goodness_of_fit(status: np.ndarray, cost: np.ndarray, model: PathLossModel, m: int, dim: int) -> np.ndarray:
    """``status`` with ``"ok"`` turned into ``"poor_fit"`` where ``cost / sigma^2`` exceeds the chi-square
    quantile ``chi2.ppf(1 - GOODNESS_OF_FIT_ALPHA, m - dim)`` (:data:`GOODNESS_OF_FIT_ALPHA`; ``m`` heard anchors).

    ``cost`` is the unweighted ``sum_j r_j^2`` (dB^2) the estimators minimise. With one sigma it is divided by
    ``sigma^2``: the ML residual statistic, chi-square with ``m - dim`` degrees of freedom under the model
    (linearised). With per-anchor sigma it is divided by the largest ``sigma_j^2``: then
    ``min_p sum r_j^2 / max sigma^2 <= min_p sum (r_j / sigma_j)^2``, the weighted ML residual statistic, so the
    test never flags more often than ``alpha`` (it is conservative). No test without shadowing (all sigma 0) or
    without redundancy (``m <= dim``)."""
    sigma_max = float(np.max(np.asarray(model.sigma_db, float)))
    dof = m - dim
    if not sigma_max > 0 or dof <= 0:
        return status
    from scipy.special import chdtri            # lazy: keeps `import locbook` fast
    bound = chdtri(dof, GOODNESS_OF_FIT_ALPHA)  # upper quantile: P(chi2_dof > bound) = alpha
    with np.errstate(over="ignore"):            # a huge finite cost over a tiny sigma is inf: still beyond the bound
        poor = (status == "ok") & (np.asarray(cost) / sigma_max**2 > bound)
    return np.where(poor, "poor_fit", status).astype("<U19")


def _raise_if_failed(res: LocalizationResult, raise_on_failure: bool) -> LocalizationResult:
    if raise_on_failure and not np.all(res.converged):
        raise ConvergenceError(f"RSS maximum likelihood: {int(np.sum(~res.converged))} of {res.converged.size} "
                               f"problems did not converge (statuses: {sorted(set(res.status.ravel().tolist()) - {'ok'})})")
    return res


def _ref_in_subset(ref_index: int, heard: np.ndarray) -> int:
    """Position of the reference anchor among the heard ones; the first heard anchor if it was not heard."""
    hit = np.flatnonzero(heard == ref_index)
    return int(hit[0]) if hit.size else 0


def _model_subset(model: PathLossModel, heard: np.ndarray, m: int) -> PathLossModel:
    """The channel restricted to the heard anchors (per-anchor parameters are subset, scalars kept)."""
    def pick(value):
        value = np.asarray(value)
        return value[..., heard] if value.ndim and value.shape[-1] == m else value
    return replace(model, ref_power_dbm=pick(model.ref_power_dbm), path_loss_exp=pick(model.path_loss_exp),
                   sigma_db=pick(model.sigma_db))


def _planar(anchors_m, tag_height_m):
    """``(anchors the positions live with, vertical offsets a_z - h (m,) or None)``: with a known tag height the
    anchors must be ``(m, 3)`` and the estimators work on their plan positions ``(m, 2)``."""
    if tag_height_m is None:
        return anchors_m, None
    check_scalar("tag_height_m", tag_height_m)
    anchors = as_array("anchors_m", anchors_m, ndim=2)
    if anchors.shape[1] != 3:
        raise ValueError(f"with tag_height_m the anchors must be (m, 3) (x, y, height), got shape {anchors.shape}")
    return anchors[:, :2], anchors[:, 2] - float(tag_height_m)


def _lift(positions_m, vertical_m):
    """Offsets ``p - a`` ``(..., m, 3)`` of plan positions ``(..., 2)`` from anchors at heights ``-vertical``
    (the z component is the constant ``-(a_z - h)``)."""
    return None if vertical_m is None else np.broadcast_to(-vertical_m, positions_m.shape[:-1] + vertical_m.shape)


def _by_heard_anchors(anchors_m, readings, min_anchors, solve_subset, method: str) -> LocalizationResult:
    """Solve every problem with the anchors it heard: group the problems by their pattern of heard anchors,
    call ``solve_subset(heard_indices, problem_indices)`` once per group, and mark the groups that heard too
    few anchors, or collinear ones, as NaN with their status."""
    m, dim = anchors_m.shape
    batch = readings.shape[:-1]
    flat = readings.reshape(-1, m)
    k = flat.shape[0]
    pos = np.full((k, dim), np.nan)
    converged = np.zeros(k, bool)
    cost = np.full(k, np.nan)
    status = np.full(k, "too_few_anchors", dtype="<U19")
    patterns, inverse = np.unique(~np.isnan(flat), axis=0, return_inverse=True)
    inverse = inverse.reshape(-1)
    n_iter = 0
    for g, pattern in enumerate(patterns):
        sel = np.flatnonzero(inverse == g)
        heard = np.flatnonzero(pattern)
        if heard.size < min_anchors:
            continue
        try:
            check_anchor_geometry(anchors_m[heard])
        except DegenerateGeometryError:
            status[sel] = "degenerate_geometry"
            continue
        res = solve_subset(heard, sel)
        pos[sel], converged[sel], status[sel] = res.position_m, res.converged, res.status
        if res.cost is not None:
            cost[sel] = res.cost
        n_iter = max(n_iter, res.n_iter)
    return LocalizationResult(pos.reshape(batch + (dim,)), converged.reshape(batch), cost.reshape(batch), n_iter,
                              method, status.reshape(batch))


def _solve_where(usable, batch, dim: int, solve, method: str, failure: str) -> LocalizationResult:
    """Solve the problems where the flat mask ``usable`` holds with ``solve(indices) -> LocalizationResult`` of
    those problems; the others get NaN, ``converged=False`` and status ``failure``, alone."""
    k = usable.size
    pos, converged, cost = np.full((k, dim), np.nan), np.zeros(k, bool), np.full(k, np.nan)
    status, n_iter = np.full(k, failure, dtype="<U19"), 0
    if usable.any():
        sel = np.flatnonzero(usable)
        res = solve(sel)
        pos[sel], converged[sel], status[sel] = res.position_m.reshape(-1, dim), res.converged.ravel(), res.status.ravel()
        if res.cost is not None:
            cost[sel] = res.cost.ravel()
        n_iter = res.n_iter
    return LocalizationResult(pos.reshape(batch + (dim,)), converged.reshape(batch), cost.reshape(batch), n_iter,
                              method, status.reshape(batch))


def _lateration_by_heard(anchors_m, distance_m, ref_index: int, min_anchors: int, solve, method: str,
                         tag_height_m=None):
    """:func:`_by_heard_anchors` for the linearized systems: ``solve(anchors, distances, ref_index)`` on each
    group's heard anchors, the reference kept if heard (geometry judged on the plan positions with a known
    tag height)."""
    anchors_m, distance_m = np.asarray(anchors_m, float), np.asarray(distance_m, float)
    m = anchors_m.shape[0]
    flat = distance_m.reshape(-1, m)
    return _by_heard_anchors(
        _planar(anchors_m, tag_height_m)[0], distance_m, min_anchors,
        lambda heard, sel: solve(anchors_m[heard], flat[np.ix_(sel, heard)], _ref_in_subset(ref_index % m, heard)),
        method)


def _min_anchors(min_anchors, dim: int, m: int) -> int:
    """``min_anchors`` checked: an integer from ``dim + 1`` (the default) to the number of anchors ``m``."""
    if min_anchors is None:
        return dim + 1
    check_scalar("min_anchors", min_anchors, ge=dim + 1, integer=True)
    if min_anchors > m:
        raise ValueError(f"min_anchors must be <= the number of anchors ({m}), got {min_anchors!r}: "
                         "no problem could ever be solved")
    return int(min_anchors)


def lateration_system(anchors_m, distance_m, ref_index: int = 0, *, pairs: str | None = None,
                      variant: str = "corrected", tag_height_m: float | None = None):
    """Matrices of the linearized lateration system ``A p = b`` (Eq. (8) of George and Vadivukkarasi).

    Returns ``A`` of shape ``(m-1, dim)`` (``2 (a_r - a_i)``, rows for i != r) and ``b`` of shape
    ``(..., m-1)`` (``d_i^2 - d_r^2 - |a_i|^2 + |a_r|^2``). A NaN distance (not heard) gives NaN in the rows
    that use it: its own row, or every row of its problem if it is the reference's.
    With ``tag_height_m`` (anchors ``(m, 3)``) the system is the plan one, exact: ``d^2`` becomes
    ``d^2 - (a_z - h)^2`` and ``a`` the anchors' ``(x, y)`` (module docstring).

    With ``pairs`` (one of :data:`LATERATION_PAIRS`; Palvai 2008, Eqs. (2.27)-(2.28)) the anchors are
    ``(..., N, dim)`` per problem or ``(N, dim)`` shared, and the rows are ``2 (s_j - s_i)`` ``(..., N - 1, dim)``
    and ``d_i^2 - d_j^2 - |s_i|^2 + |s_j|^2`` ``(..., N - 1)`` over the pairs ``(i, j)`` (NaN where a reading is
    missing); no geometry check (the anchors differ per problem: :func:`lateration_ls` judges each system's rank).
    ``variant="literal_palvai2008"`` drops the factor 2 of ``A`` (:data:`LATERATION_VARIANTS`).
    """
    check_choice("variant", variant, LATERATION_VARIANTS)
    factor = 2.0 if variant == "corrected" else 1.0
    if pairs is not None:
        if tag_height_m is not None or ref_index != 0:
            raise ParameterError("pairs: differenced pairs take neither ref_index nor tag_height_m (the pairs name every "
                             "reference; anchor heights are not supported there)")
        return _pair_rows(anchors_m, distance_m, pairs, factor)
    plan, vertical = _planar(anchors_m, tag_height_m)
    anchors_m = check_anchor_geometry(plan)
    m = anchors_m.shape[0]
    distance_m = _readings("distance_m", distance_m, m)
    if np.any(distance_m < 0):
        raise ValueError(f"distance_m must be non-negative (NaN = not heard), got {float(distance_m[distance_m < 0][0])!r}")
    if isinstance(ref_index, (bool, np.bool_)) or not isinstance(ref_index, (int, np.integer)) or not -m <= ref_index < m:
        raise ValueError(f"ref_index must be an anchor index in [-{m}, {m - 1}], got {ref_index!r}")
    ref_index %= m
    others = np.array([i for i in range(m) if i != ref_index])
    a_r = anchors_m[ref_index]
    a_mat = factor * (a_r - anchors_m[others])
    norms = np.sum(anchors_m**2, axis=1)
    if vertical is not None:
        norms = norms + vertical**2           # |p - a_xy|^2 = d^2 - v^2: the known height joins the anchor terms
    b = (distance_m[..., others] ** 2 - distance_m[..., [ref_index]] ** 2
         - norms[others] + norms[ref_index])
    return a_mat, b


def _pair_indices(n: int, pairs: str):
    if pairs == "consecutive":
        return np.arange(n - 1), np.arange(1, n)
    if pairs == "first":
        return np.zeros(n - 1, int), np.arange(1, n)
    return np.arange(n - 1), np.full(n - 1, n - 1)


def _pair_rows(anchors_m, distance_m, pairs: str, factor: float):
    """The rows of :func:`lateration_system` with ``pairs``."""
    check_choice("pairs", pairs, LATERATION_PAIRS)
    s = as_array("anchors_m", anchors_m, min_ndim=2)
    d = as_array("distance_m", distance_m, min_ndim=1, nan_ok=True)
    n = s.shape[-2]
    if d.shape[-1] != n:
        raise ValueError(f"distance_m has {d.shape[-1]} readings on its last axis, anchors_m has {n} positions")
    if n < 2:
        raise ValueError(f"anchors_m must hold at least two anchor positions (axis -2), got shape {s.shape}")
    if np.any(d < 0):
        raise ValueError(f"distance_m must be non-negative (NaN = not heard); it holds {float(np.nanmin(d)):.6g} at "
                         f"index {tuple(int(i) for i in np.argwhere(d < 0)[0])}")
    i, j = _pair_indices(n, pairs)
    H = factor * (s[..., j, :] - s[..., i, :])
    norms = np.einsum("...k,...k->...", s, s)
    Y = d[..., i] ** 2 - d[..., j] ** 2 - norms[..., i] + norms[..., j]
    return H, Y


def _pair_least_squares(anchors_m, distance_m, pairs: str, variant: str) -> LocalizationResult:
    """:func:`lateration_ls` with ``pairs``: per problem the normal equations ``(H^T H) X = H^T Y`` (``dim x dim``,
    Palvai 2008 Eq. (2.29)) of the rows that are heard; a problem with fewer than ``dim`` rows, or a rank-deficient
    ``H^T H`` (smallest singular value below 1e-10 of the largest), gets NaN and its status."""
    H, Y = lateration_system(anchors_m, distance_m, pairs=pairs, variant=variant)
    H, Y = np.broadcast_arrays(H, Y[..., None])
    Y = Y[..., 0]
    ok_row = np.isfinite(Y)
    Hm = np.where(ok_row[..., None], H, 0.0)
    Ym = np.where(ok_row, Y, 0.0)
    A = np.einsum("...ki,...kj->...ij", Hm, Hm)
    b = np.einsum("...ki,...k->...i", Hm, Ym)
    dim = H.shape[-1]
    enough = ok_row.sum(axis=-1) >= dim
    sv = np.linalg.svd(A, compute_uv=False) if A.size else np.zeros(A.shape[:-1])
    full = enough & (sv[..., -1] > 1e-10 * np.maximum(sv[..., 0], 1e-300))
    safe = np.where(full[..., None, None], A, np.eye(dim))
    pos = np.linalg.solve(safe, b[..., None])[..., 0]
    pos = np.where(full[..., None], pos, np.nan)
    status = np.where(full, "ok", np.where(enough, "degenerate_geometry", "too_few_anchors")).astype("<U19")
    return LocalizationResult(pos, full, None, 0, f"lateration_ls(pairs={pairs}, {variant})", status)


def _shared_pair_least_squares(anchors_m, distance_m, pairs: str, variant: str) -> LocalizationResult:
    """:func:`_pair_least_squares` for anchors ``(n, dim)`` shared by every problem and ``pairs`` "first" or "last",
    the conventions of the reference-anchor path: the shared layout is judged once
    (:func:`check_anchor_geometry` raises :class:`DegenerateGeometryError`), and a problem that did not hear the
    pair reference (anchor 0, or n - 1) takes the first (last) anchor it heard instead, as
    :func:`_ref_in_subset` does, rather than losing every row. Problems that heard the reference are solved exactly
    as before; the others are solved on their anchors with the new reference swapped into the reference's place
    (a per-problem layout; a heard subset too small or collinear gets its status)."""
    check_anchor_geometry(anchors_m)
    res = _pair_least_squares(anchors_m, distance_m, pairs, variant)
    d = as_array("distance_m", distance_m, min_ndim=1, nan_ok=True)
    n = anchors_m.shape[0]
    heard = ~np.isnan(d)
    ref = 0 if pairs == "first" else n - 1
    lost = ~heard[..., ref] & heard.any(axis=-1)
    if not lost.any():
        return res
    h = heard[lost]                                                     # (k, n)
    new_ref = np.argmax(h, axis=-1) if pairs == "first" else n - 1 - np.argmax(h[:, ::-1], axis=-1)
    order = np.broadcast_to(np.arange(n), h.shape).copy()
    rows = np.arange(h.shape[0])
    order[rows, ref], order[rows, new_ref] = new_ref, ref               # swap the heard reference into place
    sub = _pair_least_squares(anchors_m[order], np.take_along_axis(d[lost], order, axis=-1), pairs, variant)
    pos, converged, status = (np.array(v) for v in (res.position_m, res.converged, res.status))   # 0-d for one problem
    pos[lost], converged[lost], status[lost] = sub.position_m, sub.converged, sub.status
    return LocalizationResult(pos, converged, None, 0, res.method, status)


def lateration_ls(anchors_m, distance_m, ref_index: int = 0, *, pairs: str | None = None, variant: str = "corrected",
                  min_anchors: int | None = None, tag_height_m: float | None = None) -> LocalizationResult:
    """Linearized least squares ``p = (A^T A)^{-1} A^T b`` (Eq. (8), George and Vadivukkarasi) of
    :func:`lateration_system`, the one entry point for a linearized lateration fix (weights:
    :func:`lateration_wls`; a box: :func:`lateration_box_ls`; recursively:
    :func:`locbook.static.least_squares.recursive_least_squares` of the same rows).

    Unconstrained: estimates may leave the room, as the paper observes ("some of the results go
    beyond the boundaries"). The result depends slightly on ``ref_index`` (anchor 1 in the paper).
    NaN distances are anchors not heard; ``tag_height_m``: anchors with heights (module docstring).
    Shared anchors: ``pinv(A)`` once for the batch. With ``pairs`` (Palvai 2008, Eq. (2.29); anchors may differ per
    problem, ``(..., N, dim)``): the normal equations per problem, the rows with a missing reading left out
    (``min_anchors`` and ``tag_height_m`` do not apply). ``variant``: :data:`LATERATION_VARIANTS`.

    Degenerate geometry and missing readings, one convention on both paths: shared anchors ``(m, dim)`` that are
    too few, coincident or collinear raise :class:`DegenerateGeometryError` (``pairs="consecutive"`` excepted: its
    rows are judged per problem); a problem whose heard anchors are too few or collinear gets NaN and the status
    ``too_few_anchors`` or ``degenerate_geometry``, as does every problem of per-problem anchors. A reference that
    was not heard is replaced by a heard anchor: the first heard for ``ref_index`` and ``pairs="first"``, the last
    heard for ``pairs="last"``. Remaining difference: per-problem anchors are judged by the rank of ``H^T H``
    (1e-10), shared ones by :func:`check_anchor_geometry` (1e-6 on the centred anchors).
    """
    distance_m = _given_readings("distance_m", distance_m)
    if pairs is not None:
        if min_anchors is not None or tag_height_m is not None:
            raise ParameterError("pairs: min_anchors and tag_height_m do not apply to differenced pairs")
        check_choice("pairs", pairs, LATERATION_PAIRS)
        shared = as_array("anchors_m", anchors_m, min_ndim=2)
        if shared.ndim == 2 and pairs in ("first", "last"):
            return _shared_pair_least_squares(shared, distance_m, pairs, variant)
        return _pair_least_squares(anchors_m, distance_m, pairs, variant)
    a_mat, b = lateration_system(anchors_m, distance_m, ref_index, variant=variant, tag_height_m=tag_height_m)
    min_anchors = _min_anchors(min_anchors, a_mat.shape[1], a_mat.shape[0] + 1)
    if _has_missing(distance_m):
        return _lateration_by_heard(anchors_m, distance_m, ref_index, min_anchors,
                                    lambda a, d, ref: lateration_ls(a, d, ref, variant=variant,
                                                                    tag_height_m=tag_height_m),
                                    f"lateration_ls(ref={ref_index})", tag_height_m)
    with np.errstate(over="ignore", invalid="ignore"):
        pos = b @ np.linalg.pinv(a_mat).T
    ok = np.all(np.isfinite(pos), axis=-1)     # not finite: the squared ranges overflowed
    if not ok.all():                           # a failed problem has no position (not +-inf)
        pos = np.where(ok[..., None], pos, np.nan)
    return LocalizationResult(pos, ok, None, 0, f"lateration_ls(ref={ref_index})", _status(ok))


def lateration_wls(anchors_m, distance_m, weights, ref_index: int = 0, *,
                   min_anchors: int | None = None, tag_height_m: float | None = None) -> LocalizationResult:
    """Weighted linearized least squares ``p = (A^T W A)^{-1} A^T W b`` with diagonal weights
    ``(..., m-1)`` (one per differenced equation, i.e. per non-reference anchor in anchor order), batched.

    ``weights`` has shape ``(m-1,)`` (shared) or ``(..., m-1)`` with batch axes that broadcast to those of
    ``distance_m`` (a scalar is not accepted); finite and non-negative. A zero weight removes its equation: a
    problem whose positively weighted anchors (with the reference) are too few or collinear gets NaN and
    ``status="degenerate_geometry"``. NaN distances are anchors not heard; a problem then keeps the weights of
    its heard anchors (if the reference was not heard, the first heard anchor's weight is unused).
    ``tag_height_m``: anchors with heights (module docstring)."""
    distance_m = _given_readings("distance_m", distance_m)
    a_mat, b = lateration_system(anchors_m, distance_m, ref_index, tag_height_m=tag_height_m)
    min_anchors = _min_anchors(min_anchors, a_mat.shape[1], a_mat.shape[0] + 1)
    weights = as_array("weights", weights)
    batch = b.shape[:-1]
    try:
        fits = weights.ndim >= 1 and weights.shape[-1] == b.shape[-1] and \
            np.broadcast_shapes(weights.shape[:-1], batch) == batch
    except ValueError:
        fits = False
    if not fits:
        raise ValueError(f"weights must have shape (..., {b.shape[-1]}) (one per non-reference anchor) with batch "
                         f"axes that broadcast to the distances' batch {batch}; got shape {weights.shape}")
    w = np.broadcast_to(weights, b.shape)
    if np.any(w < 0):
        raise ValueError(f"weights must be non-negative, got {float(w[w < 0][0])!r}")
    if _has_missing(distance_m):
        anchors_m, distance_m = np.asarray(anchors_m, float), np.asarray(distance_m, float)
        m = anchors_m.shape[0]
        ref = ref_index % m
        flat = distance_m.reshape(-1, m)
        per_anchor = np.zeros((flat.shape[0], m))
        per_anchor[:, [i for i in range(m) if i != ref]] = w.reshape(-1, m - 1)

        def solve_subset(heard, sel):
            sub_ref = _ref_in_subset(ref, heard)
            rows = np.delete(heard, sub_ref)
            return lateration_wls(anchors_m[heard], flat[np.ix_(sel, heard)], per_anchor[np.ix_(sel, rows)], sub_ref,
                                  tag_height_m=tag_height_m)

        return _by_heard_anchors(_planar(anchors_m, tag_height_m)[0], distance_m, min_anchors,
                                 solve_subset, "lateration_wls")
    if not np.all(w > 0):     # zero weights: the equations left may not fix a position
        degenerate = _zero_weights_degenerate(np.asarray(_planar(anchors_m, tag_height_m)[0], float), ref_index, w)
        if degenerate.any():
            m = a_mat.shape[0] + 1
            flat_d, flat_w = np.asarray(distance_m, float).reshape(-1, m), w.reshape(-1, m - 1)
            return _solve_where(~degenerate, batch, a_mat.shape[1],
                                lambda sel: lateration_wls(anchors_m, flat_d[sel], flat_w[sel], ref_index,
                                                           tag_height_m=tag_height_m),
                                "lateration_wls", "degenerate_geometry")
    ata = np.einsum("ki,...k,kj->...ij", a_mat, w, a_mat)
    atb = np.einsum("ki,...k,...k->...i", a_mat, w, b)
    pos = np.linalg.solve(ata, atb[..., None])[..., 0]
    ok = np.all(np.isfinite(pos), axis=-1)
    if not ok.all():                           # a failed problem has no position (not +-inf)
        pos = np.where(ok[..., None], pos, np.nan)
    return LocalizationResult(pos, ok, None, 0, "lateration_wls", _status(ok))


def _zero_weights_degenerate(anchors_m, ref_index: int, w) -> np.ndarray:
    """Per problem (flattened): whether the reference and the anchors with a positive weight fail
    :func:`check_anchor_geometry` (too few, coincident or collinear)."""
    m = anchors_m.shape[0]
    ref = ref_index % m
    others = np.array([i for i in range(m) if i != ref])
    patterns, inverse = np.unique(w.reshape(-1, m - 1) > 0, axis=0, return_inverse=True)
    bad = np.zeros(len(patterns), bool)
    for g, pattern in enumerate(patterns):
        try:
            check_anchor_geometry(anchors_m[np.r_[ref, others[pattern]]])
        except DegenerateGeometryError:
            bad[g] = True
    return bad[inverse.reshape(-1)]


@lru_cache(maxsize=16)
def _box_problem(n_problems, a_key, lower, upper):
    a_mat = np.array(a_key)
    b = cp.Parameter((n_problems, a_mat.shape[0]), name="b")
    p = cp.Variable((n_problems, a_mat.shape[1]), name="position_m")
    constraints = [p >= np.array(lower), p <= np.array(upper)]
    problem = cp.Problem(cp.Minimize(cp.sum_squares(p @ a_mat.T - b)), constraints)
    return problem, b, p


def _solve_box_batch(a_mat, b, lower, upper):
    """Box-constrained LS of every row of ``b`` ``(k, rows)`` in one stacked QP. If that solve fails, the
    batch is halved and each half solved again, so a problem the solver cannot handle is marked alone
    (NaN, not converged) and never costs its batch. Returns positions ``(k, dim)`` and success flags."""
    k, dim = b.shape[0], a_mat.shape[1]
    if k == 0:
        return np.empty((0, dim)), np.ones(0, bool)
    problem, b_par, p_var = _box_problem(k, tuple(map(tuple, a_mat.tolist())), lower, upper)
    b_par.value = b
    try:
        solve(problem, "box-constrained lateration")
        return p_var.value, np.ones(k, bool)
    except (ConvergenceError, cp.error.SolverError):
        if k == 1:
            return np.full((1, dim), np.nan), np.zeros(1, bool)
    half = k // 2
    (p1, ok1), (p2, ok2) = (_solve_box_batch(a_mat, part, lower, upper) for part in (b[:half], b[half:]))
    return np.concatenate([p1, p2]), np.concatenate([ok1, ok2])


@lru_cache(maxsize=64)
def _box_active_sets(a_key, lower, upper):
    """What the active sets of the box LS ``min |A p - b|^2, lower <= p <= upper`` need, from ``A`` and the box
    alone (computed once per anchors and box, for any number of problems).

    With ``p*`` an unconstrained minimiser and ``d = p - p*``, the objective is ``|A p* - b|^2 + d^T G d``
    (``G = A^T A``; exact, since ``A^T (A p* - b) = 0``) and the half-gradient ``A^T (A p - b)`` is ``G d``. An
    active set holds the coordinates ``F`` at bounds ``v_F`` and leaves ``R`` free; its candidate minimises the
    objective over ``p_R``: ``p_R = p*_R - K (v_F - p*_F)`` with ``K = G_RR^+ G_RF`` (``G_RR^{-1}`` for a
    full-rank ``A``; for a rank-deficient one a minimiser), ``p_F = v_F``. So the candidate is affine in ``p*``,
    ``p = M p* + c``, and so is every quantity its KKT test needs to be non-negative: ``p_j - lower_j`` and
    ``upper_j - p_j`` on the free coordinates (primal feasibility), ``+g_j`` at a lower and ``-g_j`` at an upper
    bound (the dual sign; ``g = G (p - p*)``, divided by ``max |G|`` so that one relative tolerance serves).

    Returns ``(pinv(A)^T, levels)``; ``levels[j-1]`` holds the active sets with ``j`` coordinates at a bound:
    ``(weights, offsets, sets)`` such that ``weights @ p* + offsets``, reshaped ``(sets, 3 dim - j, ...)``, gives
    per set the ``2 dim - j`` KKT quantities followed by the ``dim`` coordinates of the candidate.
    """
    a_mat = np.array(a_key)
    dim = a_mat.shape[1]
    gram = a_mat.T @ a_mat
    g_unit = gram / np.max(np.abs(gram))
    lower, upper = np.array(lower), np.array(upper)
    sets = [[] for _ in range(dim + 1)]
    for kinds in product((0, 1, 2), repeat=dim):        # per coordinate: 0 free, 1 at lower, 2 at upper
        kinds = np.array(kinds)
        free, fixed = np.flatnonzero(kinds == 0), np.flatnonzero(kinds > 0)
        if not fixed.size:
            continue                                    # the unconstrained minimiser p* itself
        v_fixed = np.where(kinds[fixed] == 1, lower[fixed], upper[fixed])
        k_mat = np.linalg.pinv(gram[np.ix_(free, free)]) @ gram[np.ix_(free, fixed)]
        m_mat, c = np.zeros((dim, dim)), np.zeros(dim)
        m_mat[free, free] = 1.0
        m_mat[np.ix_(free, fixed)] = k_mat
        c[free], c[fixed] = -k_mat @ v_fixed, v_fixed
        grad_w, grad_c = g_unit @ (m_mat - np.eye(dim)), g_unit @ c
        sign = np.where(kinds[fixed] == 1, 1.0, -1.0)[:, None]
        # rows: the 2 dim - |F| KKT quantities, then the candidate itself
        weights = np.concatenate([m_mat[free], -m_mat[free], sign * grad_w[fixed], m_mat])
        offsets = np.concatenate([c[free] - lower[free], upper[free] - c[free], sign[:, 0] * grad_c[fixed], c])
        sets[fixed.size].append((weights, offsets))
    levels = [(np.concatenate([s[0] for s in level]), np.concatenate([s[1] for s in level])[:, None], len(level))
              for level in sets[1:]]
    return np.linalg.pinv(a_mat).T, levels


def _box_ls_exact(a_mat, b, lower, upper):
    """Box-constrained LS of every row of ``b`` ``(k, rows)``, exactly, by KKT active-set enumeration.

    The unconstrained minimiser ``p* = pinv(A) b`` (that of :func:`lateration_ls`) is the answer where it lies
    in the box. For the other problems the set that holds each coordinate outside the box at the bound it crosses
    is tried first (:func:`_box_guided_code`: the answer of most problems); the problems it does not settle visit
    the active sets (:func:`_box_active_sets`) by the number of
    coordinates held at a bound, 1 to ``dim``, every set of a level tested for the problems still open with one
    matrix product per block of problems (blocks keep the temporaries small: on some machines fresh large
    arrays cost more in page faults than the arithmetic). A candidate is a KKT point if it is primal feasible (its free coordinates within the
    box) and the gradient ``g = A^T (A p - b)`` has the sign of its bounds (``g_i >= 0`` at a lower bound,
    ``g_i <= 0`` at an upper one; zero on the free coordinates by construction). A KKT point of a convex QP is
    a global minimiser, so a problem is settled by the first KKT candidate found (any other has the same
    objective, e.g. when ``A`` is rank-deficient); for a strictly convex QP (``A`` of full column rank) it is
    the unique minimiser, exact up to rounding. The tests allow 1e-9 relative rounding; should rounding leave a
    problem with no KKT candidate, the primal-feasible candidate of least objective is taken (a corner always
    is feasible). Returns positions ``(k, dim)`` (clipped into the box) and success flags (finite).

    With numba (:func:`_box_kernel_module`: enabled, at least ``_BOX_NUMBA_MIN_PROBLEMS`` problems) the same search runs
    problem by problem in one compiled loop (:func:`locbook.static._box_kernels._nb_box_ls`): the same sets in the
    same order, acceptance rule, tolerance and fallback, so the same answers up to the rounding of the products
    (1e-12, ``tests/test_box_ls_speed.py``); a problem inside the box keeps ``p*`` bit for bit either way.
    """
    key = tuple(map(tuple, a_mat.tolist()))
    pinv_t, levels = _box_active_sets(key, lower, upper)
    lo, hi = np.array(lower), np.array(upper)
    with np.errstate(over="ignore", invalid="ignore"):
        p_star = b @ pinv_t
    kernels = _box_kernel_module(len(b))
    if kernels is not None:     # the same search, problem by problem in one compiled loop (no temporaries per set)
        tables = _box_kernel_tables(key, lower, upper)
        pos, ok = np.empty(p_star.shape), np.empty(len(b), bool)
        kernels._nb_box_ls(np.ascontiguousarray(p_star), lo, hi, float(np.max(np.maximum(np.abs(lo), np.abs(hi)))),
                           *tables, np.ascontiguousarray(a_mat, dtype=float), False, pos, ok)
        return pos, ok
    # per coordinate: numpy reductions over an axis of 2 or 3 are slow
    ok, inside = np.ones(len(b), bool), np.ones(len(b), bool)
    for j in range(len(lo)):
        ok &= np.isfinite(p_star[:, j])
        inside &= (p_star[:, j] >= lo[j]) & (p_star[:, j] <= hi[j])
    pos = np.where(ok[:, None], p_star, np.nan)
    todo = np.flatnonzero(ok & ~inside)
    if todo.size:
        pos[todo] = _box_active_set_search(p_star[todo], lo, hi, levels, a_mat)
    return pos, ok


_BOX_BLOCK_VALUES = 32_768     # values of the largest temporary per block of problems (256 kB)
#: problems from which :func:`_box_ls_exact` runs the compiled search (fewer: numpy, without loading numba)
_BOX_NUMBA_MIN_PROBLEMS = 256


def _box_trial():
    """A tiny problem for the box-LS kernel (compiled or loaded once per session: _compiled._kernel_module)."""
    a_mat = np.array([[1.0, 0.0], [0.0, 1.0]])
    tables = _box_kernel_tables(((1.0, 0.0), (0.0, 1.0)), (0.0, 0.0), (1.0, 1.0))
    pos, ok = np.empty((1, 2)), np.empty(1, bool)

    def run(kernels):
        kernels._nb_box_ls(np.array([[2.0, 0.5]]), np.zeros(2), np.ones(2), 1.0, *tables, a_mat, False, pos, ok)
    return run


def _box_kernel_module(n_problems: int):
    """:mod:`locbook.static._box_kernels` when the compiled search applies (at least ``_BOX_NUMBA_MIN_PROBLEMS``
    problems, the compiled paths on and the kernel working here:
    :func:`locbook.tracking._compiled._kernel_module`), else None (the numpy search)."""
    from ..tracking import _compiled
    if n_problems < _BOX_NUMBA_MIN_PROBLEMS:
        return None
    return _compiled._kernel_module("locbook.static._box_kernels", _box_trial, "box LS", stacklevel=5)


def _box_flat_tables(levels, dim: int):
    """The active sets of ``levels`` (:func:`_box_active_sets`) for the compiled search, in the numpy search's order:
    ``weights (rows, dim)`` and ``offsets (rows,)`` of every set one after the other, and per set its first row
    ``start`` and its number of KKT quantities ``n_kkt`` (``2 dim - j`` for ``j`` coordinates at a bound; the
    ``dim`` rows of its candidate follow them)."""
    start, n_kkt, first = [], [], 0
    for j, (weights, _, n_sets) in enumerate(levels, start=1):
        per_set = weights.shape[0] // n_sets
        start += [first + s * per_set for s in range(n_sets)]
        n_kkt += [2 * dim - j] * n_sets
        first += weights.shape[0]
    return (np.ascontiguousarray(np.concatenate([lv[0] for lv in levels]), dtype=float),
            np.ascontiguousarray(np.concatenate([lv[1][:, 0] for lv in levels]), dtype=float),
            np.array(start, np.int64), np.array(n_kkt, np.int64), _box_guided_sets(dim))


def _box_guided_sets(dim: int) -> np.ndarray:
    """``guided[code]``: the index (in :func:`_box_flat_tables`' order) of the active set that holds coordinate ``j``
    free (``kind 0``), at its lower (1) or at its upper bound (2), ``code = sum_j kind_j 3^(dim - 1 - j)``; -1 for
    all free. The sets are ordered by the number of bounds held, then in ``itertools.product`` order (as
    :func:`_box_active_sets` builds them)."""
    patterns = list(product((0, 1, 2), repeat=dim))
    order = sorted(range(1, len(patterns)), key=lambda c: (sum(k > 0 for k in patterns[c]), c))
    guided = np.full(len(patterns), -1, np.int64)
    guided[order] = np.arange(len(order))
    return guided


def _box_guided_code(p_star, lo, hi) -> np.ndarray:
    """The code (:func:`_box_guided_sets`) of the active set that holds each coordinate of ``p_star (n, dim)``
    outside the box at the bound it crosses: the KKT set of most problems (those whose coordinates do not pull one
    another across the bounds: 79 % of the 3-D benchmark's problems outside the box)."""
    code = np.zeros(len(p_star), np.int64)
    for j in range(p_star.shape[1]):
        code = 3 * code + np.where(p_star[:, j] < lo[j], 1, np.where(p_star[:, j] > hi[j], 2, 0))
    return code


@lru_cache(maxsize=64)
def _box_kernel_tables(a_key, lower, upper):
    """:func:`_box_flat_tables` of :func:`_box_active_sets` (once per anchors and box)."""
    return _box_flat_tables(_box_active_sets(a_key, lower, upper)[1], len(lower))


def _box_active_set_search(p_star, lo, hi, levels, a_mat):
    """The KKT search of :func:`_box_ls_exact` for finite unconstrained minimisers ``p_star (n, dim)`` outside
    the box."""
    n, dim = p_star.shape
    size = np.abs(p_star[:, 0])
    for j in range(1, dim):
        size = np.maximum(size, np.abs(p_star[:, j]))
    tol = -1e-9 * (1.0 + np.max(np.maximum(np.abs(lo), np.abs(hi))) + size)
    out = np.empty((n, dim))
    # first, per problem, the set that holds each coordinate outside the box at the bound it crosses
    flat_w, flat_c, starts, n_kkts, guided = _box_flat_tables(levels, dim)
    sets = guided[_box_guided_code(p_star, lo, hi)]
    still = []
    for s in np.unique(sets):
        idx = np.flatnonzero(sets == s)
        if s < 0:                         # inside the box (not for this function): the search decides
            still.append(idx)
            continue
        r0, k = starts[s], n_kkts[s]
        rows = p_star[idx] @ flat_w[r0:r0 + k + dim].T + flat_c[r0:r0 + k + dim]      # (problems, rows)
        settled = rows[:, :k].min(axis=1) >= tol[idx]
        out[idx[settled]] = rows[settled, k:]
        still.append(idx[~settled])
    open_ = np.concatenate(still) if still else np.arange(0)
    for weights, offsets, n_sets in levels:
        if not open_.size:
            break
        # blocks of problems keep the temporaries small (large fresh arrays cost page faults, not arithmetic)
        block = max(256, _BOX_BLOCK_VALUES // weights.shape[0])
        still = []
        for start in range(0, open_.size, block):
            idx = open_[start:start + block]
            rows = (weights @ p_star[idx].T + offsets).reshape(n_sets, -1, idx.size)  # (sets, rows, problems)
            kkt = rows[:, :-dim].min(axis=1) >= tol[idx]                              # (sets, problems)
            best = np.argmax(kkt, axis=0)
            r = np.arange(idx.size)
            settled = kkt[best, r]
            out[idx[settled]] = rows[best[settled], -dim:, r[settled]]
            still.append(idx[~settled])
        open_ = np.concatenate(still)
        if not open_.size:
            break
    if open_.size:     # rounding left no KKT candidate
        out[open_] = _box_least_feasible(p_star[open_], lo, hi, levels, a_mat, tol[open_])
    return np.clip(out, lo, hi)


def _box_least_feasible(p_star, lo, hi, levels, a_mat, tol):
    """The fallback of :func:`_box_active_set_search`: of every active set's candidate the primal-feasible one
    (a corner always is) of least objective ``|A (p - p*)|^2`` (exact too, but it evaluates every set)."""
    n, dim = p_star.shape
    out, least = np.empty((n, dim)), np.full(n, np.inf)
    for weights, offsets, n_sets in levels:
        rows = (weights @ p_star.T + offsets).reshape(n_sets, -1, n)
        for cand in rows[:, -dim:].transpose(0, 2, 1):                     # each set's candidates (n, dim)
            feasible = np.all((cand >= lo + tol[:, None]) & (cand <= hi - tol[:, None]), axis=-1)
            excess = np.sum(((cand - p_star) @ a_mat.T) ** 2, axis=-1)
            take = feasible & (excess < least)
            out[take], least[take] = cand[take], excess[take]
    return out


def lateration_box_ls(anchors_m, distance_m, lower_m, upper_m, ref_index: int = 0, *,
                      min_anchors: int | None = None, tag_height_m: float | None = None,
                      solver: str = "exact") -> LocalizationResult:
    """Linearized least squares constrained to the box ``lower_m <= p <= upper_m``:
    ``min |A p - b|^2`` over the box, with ``A, b`` of :func:`lateration_system` (2-D or 3-D).

    An optional extension to George and Vadivukkarasi (which does not constrain its estimates: "some of the results go
    beyond the boundaries"); a fix kept inside the room.

    ``solver="exact"`` (default): KKT active-set enumeration, exact (no iterations, no solver tolerance). Each
    of the ``3^dim`` (9 or 27) ways to hold every coordinate free, at its lower or at its upper bound gives the
    reduced unconstrained LS in closed form; its reduced matrices depend only on ``A`` and the box, so they are
    computed once per anchors and box (cached). From 256 problems on, one compiled loop (numba; ``LOCBOOK_NUMBA=0``
    turns it off) tries the active sets problem by problem, stopping at the first that passes; otherwise numpy
    evaluates them with matrix products over many problems at once (blocks of about a thousand). Both give the same
    answers (to 1e-12; tests/test_box_ls_speed.py). The answer is the candidate
    that is feasible and meets the KKT sign conditions (gradient ``A^T (A p - b)`` >= 0 at a lower bound, <= 0
    at an upper one, 0 on free coordinates); for this strictly convex QP it is unique (:func:`_box_ls_exact`).
    Where the unconstrained fix is inside the box it is the answer (bit for bit that of :func:`lateration_ls`);
    elsewhere the answer is not that fix clipped into the box, which is wrong in general (correlated
    coordinates: holding one at its bound moves the best value of another).

    ``solver="cvxpy"``: the reference. All problems are stacked into one cvxpy QP (Clarabel, tight
    tolerances), built once per (batch size, anchors, box) with the right-hand sides as a Parameter and
    re-solved by setting its value; if the solve fails, the batch is halved until the failing problems are
    alone. It agrees with the exact solver to Clarabel's tolerance, which is relative to the stacked objective:
    about 1e-6 m for a few problems, up to about 1e-3 m for thousands stacked (one problem per solve at tighter
    tolerances agrees to 1e-7 m; ``tests/test_exact_solvers.py``).

    A problem the solver fails on (or whose arithmetic does not give a finite fix) gets a NaN position and
    ``status="solver_failed"``; the others are kept. NaN distances are anchors not heard;
    ``tag_height_m``: anchors with heights, the box on ``(x, y)`` (module docstring).
    """
    distance_m = _given_readings("distance_m", distance_m)
    check_choice("solver", solver, BOX_LS_SOLVERS)
    a_mat, b = lateration_system(anchors_m, distance_m, ref_index, tag_height_m=tag_height_m)
    dim = a_mat.shape[1]
    min_anchors = _min_anchors(min_anchors, dim, a_mat.shape[0] + 1)
    bounds = []
    for name, value in (("lower_m", lower_m), ("upper_m", upper_m)):
        value = as_array(name, value)
        if value.ndim > 1 or value.size not in (1, dim):
            raise ValueError(f"{name} must be a scalar or have shape ({dim},), got shape {value.shape}")
        bounds.append(tuple(np.broadcast_to(value, (dim,)).tolist()))
    lower, upper = bounds
    if any(lo > hi for lo, hi in zip(lower, upper)):
        raise ValueError(f"empty box: lower {lower} > upper {upper}")
    if _has_missing(distance_m):
        return _lateration_by_heard(anchors_m, distance_m, ref_index, min_anchors,
                                    lambda a, d, ref: lateration_box_ls(a, d, lower, upper, ref,
                                                                        tag_height_m=tag_height_m, solver=solver),
                                    "lateration_box_ls", tag_height_m)
    batch = b.shape[:-1]
    flat_b = b.reshape(-1, b.shape[-1])
    finite = np.all(np.isfinite(flat_b), axis=-1)
    if not finite.all():     # squared ranges that overflow: those problems fail alone, the solver never sees them
        flat_d = np.asarray(distance_m, float).reshape(-1, a_mat.shape[0] + 1)
        return _solve_where(finite, batch, dim,
                            lambda sel: lateration_box_ls(anchors_m, flat_d[sel], lower, upper, ref_index,
                                                          tag_height_m=tag_height_m, solver=solver),
                            "lateration_box_ls", "solver_failed")
    if solver == "exact":
        pos, ok = _box_ls_exact(a_mat, flat_b, lower, upper)
    else:
        pos, ok = _solve_box_batch(a_mat, flat_b, lower, upper)
    return LocalizationResult(pos.reshape(batch + (dim,)), ok.reshape(batch), None, 0, "lateration_box_ls",
                              _status(ok).reshape(batch))


# -- the RSS model of the estimators (issue 47: the readings first, then one RssModel) ------------------------------
def _rss_model_parts(model, who: str, *, form: str | None = None, walls: bool = False, per_step: bool = False,
                     heights: bool = True):
    """``(anchors_m, channel, tag_height_m)`` of the :class:`~locbook.RssModel` ``model`` given to ``who``; what
    ``who`` cannot honour is refused by name in one line: anything but an RssModel (``form``: the call to write),
    per-run anchors, per-run or per-step channel parameters (unless ``per_step``), walls that attenuate (unless
    ``walls``), a tag height (unless ``heights``)."""
    form = form or f"{who}(rss_dbm, RssModel(anchors_m, channel, tag_height_m=...), ...)"
    if not isinstance(model, RssModel):
        raise ValueError(f"{who}: model must be an RssModel (the anchors, the channel and the tag height in one "
                         f"object), got {type(model).__name__}: pass {form}")
    varying = model.per_run_or_step()
    if "anchors_m" in varying:
        raise ValueError(f"{who}: model.anchors_m is per run or per step, shape {varying['anchors_m']}; it takes one "
                         "layout (m, dim) shared by every problem: give each run its own RssModel")
    ch = model.channel
    channel_axes = [name for name in varying if name != "anchors_m"]
    if channel_axes and not per_step:
        raise ValueError(f"{who}: model.{channel_axes[0]} is per run or per step, shape {varying[channel_axes[0]]}; it "
                         "takes scalar or per-anchor (m,) parameters: give each run and step its own RssModel")
    if not walls and model.walls_m is not None and ch.wall_attenuation_db != 0.0:
        raise ValueError(f"{who}: model.walls_m ({model.walls_m.shape[0]} wall(s), {ch.wall_attenuation_db:g} dB each) "
                         "is not modelled by this estimator: give it a model without walls (walls_m=None)")
    if not heights and model.tag_height_m is not None:
        raise ValueError(f"{who}: model.tag_height_m is not supported (the map uses plan distances): give it a model "
                         "with plan anchors (m, 2) and no tag height")
    return model.anchors_m, ch, model.tag_height_m


def _is_old_form(args, kwargs, leading) -> bool:
    """Whether a call is in the form before issue 47: a :class:`~locbook.PathLossModel` third (positionally, or as
    ``model=`` after the two ``leading`` arguments), or ``anchors_m=`` given; an RssModel second is the new form."""
    model = kwargs["model"] if "model" in kwargs else (args[2] if len(args) > 2 else None)
    return "anchors_m" in kwargs or (isinstance(model, PathLossModel)
                                     and len(args) + sum(name in kwargs for name in leading) >= 2)


def _accepts_old_form(old_call):
    """:func:`locbook._deprecation.old_form` of a public function whose ``old_call(args, kwargs)`` is None for a call in
    the new form, else ``(old, new, run)``: the deprecated form, the one to use, and ``run(function)``, the same
    result."""
    return old_form(lambda function, args, kwargs: old_call(args, kwargs))


def _rss_ml_position_v1(anchors_m, rss_dbm, model, initial_m=None, *, max_iter=None, tol_m=None, min_distance_m=None,
                        raise_on_failure=None, min_anchors=None, tag_height_m=None, region_m=None):
    """The signature of :func:`rss_ml_position` before issue 47 (deprecated calls are bound to it)."""


def _grid_ml_position_v1(anchors_m, rss_dbm, model, grid_m, *, chunk=None, min_anchors=None, tag_height_m=None):
    """The signature of :func:`grid_ml_position` before issue 47 (deprecated calls are bound to it)."""


def _old_estimator_call(args, kwargs, who: str, v1):
    """:func:`_accepts_old_form`'s ``old_call`` of the RSS ML estimators: the form before issue 47 (anchors, readings,
    a PathLossModel, ..., ``tag_height_m=``) builds the RssModel; ``grid_m=`` is the old spelling of ``cells_m=``."""
    if _is_old_form(args, kwargs, ("anchors_m", "rss_dbm")):
        given = inspect.signature(v1).bind(*args, **kwargs).arguments      # a TypeError as the old function gave
        anchors_m, rss_dbm, channel = given.pop("anchors_m"), given.pop("rss_dbm"), given.pop("model")
        tag_height_m = given.pop("tag_height_m", None)
        if "grid_m" in given:
            given["cells_m"] = given.pop("grid_m")
        return (f"{who}(anchors_m, rss_dbm, channel, ...)",
                f"{who}(rss_dbm, RssModel(anchors_m, channel, tag_height_m=...), ...)",
                lambda new: new(rss_dbm, RssModel(anchors_m, channel, tag_height_m=tag_height_m), **given))
    if "tag_height_m" in kwargs:
        raise ValueError(f"{who}: tag_height_m is the model's: pass RssModel(anchors_m, channel, "
                         "tag_height_m=...) as model")
    if "grid_m" in kwargs:
        if "cells_m" in kwargs or len(args) > 2:
            raise TypeError(f"{who}() got cells_m and grid_m, its old spelling: give cells_m only")
        kwargs = dict(kwargs)
        kwargs["cells_m"] = kwargs.pop("grid_m")
        return f"{who}(..., grid_m=...)", f"{who}(..., cells_m=...)", lambda new: new(*args, **kwargs)
    return None


def _default_start(anchors_m, rss_dbm, model: PathLossModel, tag_height_m=None) -> np.ndarray:
    """The convex start of :func:`rss_ml_position`: the linearized LS fix on the model's ranges. A problem
    whose ranges overflow (infinite) has no such fix: NaN."""
    with np.errstate(over="ignore"):
        ranges = model.range_m(rss_dbm)
    if np.all(np.isfinite(ranges)):
        return lateration_ls(anchors_m, ranges, tag_height_m=tag_height_m).position_m
    with np.errstate(over="ignore", invalid="ignore"):
        return lateration_ls(anchors_m, np.where(np.isinf(ranges).any(axis=-1, keepdims=True), np.nan, ranges),
                             tag_height_m=tag_height_m).position_m


def _rss_residual_jacobian(pos, anchors, power, model: PathLossModel, clamp_m, vertical_m=None):
    """Residuals, their Jacobian w.r.t. the position and the squared distances (not clamped) of the one RSS model
    (:func:`locbook.models.rss.rss_mean_jacobian`) with the near-field clamp ``clamp_m``; with ``vertical_m`` (anchor
    heights above the tag's plane) the distances are 3-D and the Jacobian keeps the plan columns."""
    diff = pos[..., None, :] - anchors  # (..., m, dim)
    if vertical_m is not None:
        diff = np.concatenate([diff, _lift(pos, vertical_m)[..., None]], axis=-1)
    # the model without its input checks: a distance that overflowed to inf is a valid state here
    mean, grad, d2 = rss_mean_jacobian(diff, np.asarray(model.ref_power_dbm), np.asarray(model.path_loss_exp),
                                       ref_distance_m=model.ref_distance_m, min_distance_m=clamp_m)
    return power - mean, -grad[..., :anchors.shape[-1]], d2    # d resid / d p = - d mean / d p


def _min_eigenvalue(a):
    """Smallest eigenvalue of symmetric ``(..., k, k)`` matrices (closed form for 2 x 2, which is
    an order of magnitude faster than batched LAPACK on tiny matrices)."""
    if a.shape[-1] == 2:
        half_tr = 0.5 * (a[..., 0, 0] + a[..., 1, 1])
        half_diff = 0.5 * (a[..., 0, 0] - a[..., 1, 1])
        return half_tr - np.sqrt(half_diff**2 + a[..., 0, 1] ** 2)
    return np.linalg.eigvalsh(a)[..., 0]


def _solve_small(a, b):
    """Solve ``a x = b`` for ``(..., k, k)`` and ``(..., k)`` (Cramer's rule for 2 x 2)."""
    if a.shape[-1] == 2:
        det = a[..., 0, 0] * a[..., 1, 1] - a[..., 0, 1] * a[..., 1, 0]
        x0 = (a[..., 1, 1] * b[..., 0] - a[..., 0, 1] * b[..., 1]) / det
        x1 = (a[..., 0, 0] * b[..., 1] - a[..., 1, 0] * b[..., 0]) / det
        return np.stack([x0, x1], axis=-1)
    return np.linalg.solve(a, b[..., None])[..., 0]


def _newton_matrix(resid, jac, d2, pos, anchors, model, clamp_m, held=None):
    """Hessian of 0.5 |r|^2: J^T J + sum_j r_j grad^2 r_j, with
    grad^2 r_j = c (I / d_j^2 - 2 (p - a_j)(p - a_j)^T / d_j^4), c = 10 n / ln 10 (the derivative of the one model's
    Jacobian, :func:`locbook.models.rss.rss_mean_jacobian`; 0 within the clamp ``clamp_m``, where the mean is flat).
    Falls back to the Gauss-Newton matrix J^T J where the full Hessian is not positive definite. The second-order
    term matters: shadowing leaves large residuals, where Gauss-Newton converges only linearly. ``held (..., dim)``:
    coordinates held on a bound (projected Newton): their rows and columns are replaced by the identity before the
    test, so the choice is made on the free block, the matrix the step actually uses."""
    jtj = np.einsum("...ki,...kj->...ij", jac, jac)
    diff = pos[..., None, :] - anchors
    c = np.broadcast_to(10.0 * np.asarray(model.path_loss_exp) / np.log(10.0), d2.shape)
    eye = np.eye(pos.shape[-1])
    inside = d2 < clamp_m**2
    d2 = np.maximum(d2, clamp_m**2)            # no value changes outside the clamp; inside the term is 0 below
    hr = c[..., None, None] * (eye / d2[..., None, None]
                                - 2.0 * diff[..., :, None] * diff[..., None, :] / (d2**2)[..., None, None])
    hr = np.where(inside[..., None, None], 0.0, hr)
    full = jtj + np.einsum("...k,...kij->...ij", resid, hr)
    if held is not None and held.any():
        keep = ~(held[..., :, None] | held[..., None, :])
        ident = held[..., :, None] * eye
        full = np.where(keep, full, 0.0) + ident
        jtj = np.where(keep, jtj, 0.0) + ident
    eig_min = _min_eigenvalue(full)
    return np.where((eig_min > 1e-9 * np.trace(jtj, axis1=-2, axis2=-1))[..., None, None], full, jtj)


@_accepts_old_form(lambda args, kwargs: _old_estimator_call(args, kwargs, "rss_ml_position", _rss_ml_position_v1))
def rss_ml_position(rss_dbm, model: RssModel, initial_m=None, *,
                    max_iter: int = 10_000, tol_m: float = 1e-7, min_distance_m: float = 1e-3,
                    raise_on_failure: bool = False, min_anchors: int | None = None,
                    region_m=None) -> LocalizationResult:
    """Maximum-likelihood position from received powers ``(..., m)`` under Gaussian shadowing, for the RSS model
    ``model`` (:class:`locbook.RssModel`: its anchors ``(m, dim)``, its channel, its tag height).

    Minimises ``sum_j (P_j - P_0 + 10 n log10 |p - a_j|)^2``, which equals Dogan's MLE cost (2.4)
    up to the factor ``(10 n)^{-2}`` (by Eq. (2.3), ``log10 d_hat_j - log10 d_j = -(P_j - P(d_j)) / (10 n)``).
    The problem is non-convex; every problem
    starts from ``initial_m`` or, by default, the linearized LS fix on the model's ranges (the convex
    initialiser), and is refined by damped Newton steps (Levenberg-Marquardt with the exact Hessian where it is
    positive definite), vectorized over the batch; each iteration works only on the problems that have not
    converged yet. Problems that do not converge in ``max_iter`` steps are flagged in ``converged``
    (or raise if asked). The default cap is high on purpose: far from the anchors the cost is flat and a problem
    can need a thousand steps or more (George's corridor at 6 dB: up to about 1,500), and a walk stopped midway
    ends wherever its last step left it, which depends on the last bits of every step (numpy's vector ``log10``
    differs between AVX-512 and AVX2): with a cap of 100, such problems moved an RMSE by per cent across machines.
    Only the problems still iterating are computed, so the converged ones cost nothing more. ``converged`` (status ``"ok"``) means a local minimum of the cost was reached, not
    necessarily the global one: from the default convex start a problem can stop in another basin (Dogan's
    initialiser study, ``dogan2015-models``: about 3 % of draws). For the global minimum start from a grid
    (``initial_m=grid_ml_position(rss_dbm, model, cells_m).position_m``), as the Dogan scenarios do.
    The channel's parameters must be scalars or per-anchor ``(m,)`` arrays and the anchors one layout ``(m, dim)``
    shared by every problem; the estimator does not model walls: a model with per-run anchors, per-run or per-step
    parameters, or walls that attenuate (``walls_m`` with a non-zero ``wall_attenuation_db``) is refused by name.
    A NaN power is an anchor not heard (module docstring): the problem is solved on the anchors it heard.

    ``initial_m`` has shape ``(dim,)`` or ``(..., dim)`` broadcasting to the batch; a row that is all NaN
    means "no start given" and gets the default start (so a grid fix that was NaN for too few heard anchors can
    be passed on as it is). A problem without a finite start (its ranges overflow, e.g. for a tiny exponent)
    gets NaN and ``status="solver_failed"`` alone; ``raise_on_failure`` raises :class:`ConvergenceError` if any
    problem of the batch did not converge, whatever the reason.
    ``model.tag_height_m``: anchors ``(m, 3)`` with heights and plan positions (module docstring).

    Garbage never gives a confident answer: a problem with an implausible power (more than
    :data:`IMPLAUSIBLE_SIGMAS` sigma above the model's mean at ``max(min_distance_m, channel.min_distance_m)``, e.g.
    +500 dBm; the assumption: a reading implying a tag closer than 1 mm, the default clamp, to an anchor's antenna
    is not a reading of this channel) gets NaN and ``status="implausible_reading"`` before any iteration, and a
    problem whose cost is infinite or NaN (at the start or at the end) gets NaN and ``status="solver_failed"``, never
    ``converged``.
    Readings that are each possible but impossible together get ``status="poor_fit"`` (position and ``converged``
    kept): a converged problem whose cost over ``sigma^2`` exceeds ``chi2.ppf(1 - alpha, m_heard - dim)``,
    :data:`GOODNESS_OF_FIT_ALPHA` (model with ``sigma_db > 0`` only).

    ``region_m=(lower, upper)``: the maximum likelihood over that box (a room's bounding box, e.g.
    :func:`locbook.geometry.outline_box`) instead of the whole plane: the start is clipped into it and every step
    is projected onto it (projected Levenberg-Marquardt), so no fix leaves the box; a fix on its boundary is the
    constrained optimum, where the unconstrained one lies outside. Without it a fix can land far outside the room
    when the readings point there (deep fades, a biased channel). The cost is not convex: like the free problem,
    the boxed one can stop in another local minimum than a different solver started at the same point.

    The form before issue 47, ``rss_ml_position(anchors_m, rss_dbm, channel, initial_m, ..., tag_height_m=...)`` (a
    :class:`~locbook.PathLossModel` third), is deprecated: it warns and builds the :class:`~locbook.RssModel`.
    """
    anchors_m, channel, tag_height_m = _rss_model_parts(model, "rss_ml_position")
    return _rss_ml(anchors_m, rss_dbm, channel, initial_m, max_iter=max_iter, tol_m=tol_m,
                   min_distance_m=min_distance_m, raise_on_failure=raise_on_failure, min_anchors=min_anchors,
                   tag_height_m=tag_height_m, region_m=region_m)


def _rss_ml(anchors_m, rss_dbm, model: PathLossModel, initial_m=None, *,
            max_iter: int = 10_000, tol_m: float = 1e-7, min_distance_m: float = 1e-3,
            raise_on_failure: bool = False, min_anchors: int | None = None,
            tag_height_m: float | None = None, region_m=None) -> LocalizationResult:
    """:func:`rss_ml_position` on the model's anchors ``(m, k)``, channel ``model`` and tag height; the problems or
    anchors it sets apart (implausible readings, anchors not heard, no finite start) are solved by calls to itself."""
    plan, vertical = _planar(anchors_m, tag_height_m)
    anchors_full = np.asarray(anchors_m, dtype=float)        # with heights: what recursive calls are given
    anchors_m = check_anchor_geometry(plan)
    m, dim = anchors_m.shape
    lower, upper = _region(region_m, dim)
    rss_dbm = _readings("rss_dbm", rss_dbm, m)
    _check_model(model, m)
    check_scalar("max_iter", max_iter, ge=1, integer=True)
    check_scalar("tol_m", tol_m, gt=0)
    check_scalar("min_distance_m", min_distance_m, gt=0)
    min_anchors = _min_anchors(min_anchors, dim, m)
    if initial_m is not None:
        initial_m = as_array("initial_m", initial_m, min_ndim=1, nan_ok=True)
        try:
            initial_m = np.broadcast_to(initial_m, rss_dbm.shape[:-1] + (dim,))
        except ValueError:
            raise ValueError(f"initial_m must broadcast to {rss_dbm.shape[:-1] + (dim,)}, got shape "
                             f"{initial_m.shape}") from None
        no_start = np.isnan(initial_m)
        if np.any(no_start.any(axis=-1) & ~no_start.all(axis=-1)):
            raise ValueError("initial_m must be finite, or all NaN in a problem's row (no start: the default), got "
                             f"a partly NaN row {initial_m[no_start.any(axis=-1) & ~no_start.all(axis=-1)][0].tolist()}")
    implausible = implausible_powers(rss_dbm, model, max(float(min_distance_m), model.min_distance_m)).reshape(-1)
    if implausible.any():             # those problems fail alone, before any arithmetic on their readings
        flat, batch = rss_dbm.reshape(-1, m), rss_dbm.shape[:-1]
        start = None if initial_m is None else initial_m.reshape(-1, dim)
        res = _solve_where(~implausible, batch, dim,
                           lambda sel: _rss_ml(anchors_full, flat[sel], model,
                                               None if start is None else start[sel], max_iter=max_iter,
                                               tol_m=tol_m, min_distance_m=min_distance_m,
                                               min_anchors=min_anchors, tag_height_m=tag_height_m,
                                               region_m=region_m),
                           "rss_ml_lm", "implausible_reading")
        return _raise_if_failed(res, raise_on_failure)
    if np.isnan(rss_dbm).any():
        flat = rss_dbm.reshape(-1, m)
        start = None if initial_m is None else initial_m.reshape(-1, dim)
        res = _by_heard_anchors(
            anchors_m, rss_dbm, min_anchors,
            lambda heard, sel: _rss_ml(
                anchors_full[heard], flat[np.ix_(sel, heard)], _model_subset(model, heard, m),
                None if start is None else start[sel], max_iter=max_iter, tol_m=tol_m,
                min_distance_m=min_distance_m, tag_height_m=tag_height_m, region_m=region_m),
            "rss_ml_lm")
        return _raise_if_failed(res, raise_on_failure)
    if initial_m is None:
        initial_m = _default_start(anchors_full, rss_dbm, model, tag_height_m)
    elif np.isnan(initial_m).any():     # rows without a start get the default one
        initial_m = np.array(initial_m)
        no_start = np.isnan(initial_m).all(axis=-1)
        initial_m[no_start] = _default_start(anchors_full, rss_dbm[no_start], model, tag_height_m)
    batch, dim = rss_dbm.shape[:-1], anchors_m.shape[1]
    pos = np.array(np.broadcast_to(initial_m, batch + (dim,)), dtype=float).reshape(-1, dim)
    startable = np.all(np.isfinite(pos), axis=-1)
    if not startable.all():           # no finite start: those problems fail alone
        flat = rss_dbm.reshape(-1, m)
        res = _solve_where(startable, batch, dim,
                           lambda sel: _rss_ml(anchors_full, flat[sel], model, pos[sel], max_iter=max_iter,
                                               tol_m=tol_m, min_distance_m=min_distance_m,
                                               tag_height_m=tag_height_m, region_m=region_m),
                           "rss_ml_lm", "solver_failed")
        return _raise_if_failed(res, raise_on_failure)
    if lower is not None:
        pos = np.clip(pos, lower, upper)
    power = rss_dbm.reshape(-1, rss_dbm.shape[-1])
    clamp_m = max(float(min_distance_m), model.min_distance_m)     # the model's near-field clamp
    with np.errstate(over="ignore", invalid="ignore"):     # a start so far away that its distances overflow
        resid, jac, d2 = _rss_residual_jacobian(pos, anchors_m, power, model, clamp_m, vertical)
        cost = np.sum(resid**2, axis=-1)
    lam = np.full(cost.shape, 1e-3)
    converged = np.zeros(cost.shape, bool)
    eye = np.eye(dim)
    active = np.flatnonzero(np.isfinite(cost))   # problems still iterating; an infinite cost has nowhere to go
    it = 0
    for it in range(1, max_iter + 1):
        p_a, r_a, j_a, d2_a, c_a, l_a = (a[active] for a in (pos, resid, jac, d2, cost, lam))
        jtr = np.einsum("...ki,...k->...i", j_a, r_a)
        held = None
        if lower is not None:
            # projected Newton (Bertsekas 1982): a coordinate on a bound whose gradient points out of the box is
            # held (its row and column of the system replaced by the identity, its gradient by 0); the others
            # take the Newton step of the reduced problem, clipped into the box
            held = ((p_a <= lower) & (jtr > 0)) | ((p_a >= upper) & (jtr < 0))
            jtr = np.where(held, 0.0, jtr)
        hess = _newton_matrix(r_a, j_a, d2_a, p_a, anchors_m, model, clamp_m, held)
        # damped step: (H + lam diag(H)) delta = -J^T r
        damp = l_a[:, None, None] * (eye * np.diagonal(hess, axis1=-2, axis2=-1)[:, None, :] + 1e-12 * eye)
        step = -_solve_small(hess + damp, jtr)
        if lower is not None:                 # the step that stays inside the box
            step = np.clip(p_a + step, lower, upper) - p_a
        trial = p_a + step
        r_new, j_new, d2_new = _rss_residual_jacobian(trial, anchors_m, power[active], model, clamp_m, vertical)
        c_new = np.sum(r_new**2, axis=-1)
        better = c_new <= c_a
        step_small = np.linalg.norm(step, axis=-1) <= tol_m * (1.0 + np.linalg.norm(p_a, axis=-1))
        gain_small = (c_a - c_new) <= 1e-12 * (1.0 + c_a)
        acc = active[better]
        pos[acc], resid[acc], jac[acc], d2[acc], cost[acc] = (trial[better], r_new[better], j_new[better],
                                                              d2_new[better], c_new[better])
        l_a = np.clip(np.where(better, l_a * 0.3, l_a * 10.0), 1e-12, 1e16)
        lam[active] = l_a
        # converged: an accepted step that is tiny or gains nothing, or no descent even with a
        # vanishing step (a local minimum)
        done = (better & (step_small | gain_small)) | (l_a >= 1e16)
        converged[active[done]] = True
        active = active[~done]
        if active.size == 0:
            break
    status = np.where(converged, "ok", "not_converged").astype("<U19")
    broken = ~(np.isfinite(cost) & np.all(np.isfinite(pos), axis=-1))   # no minimum: never converged
    converged[broken], status[broken], pos[broken] = False, "solver_failed", np.nan
    status = _goodness_of_fit(status, cost, model, m, dim)   # converged on readings no position explains
    if raise_on_failure and not np.all(converged):
        raise ConvergenceError(
            f"RSS maximum likelihood: {int(np.sum(~converged))} of {converged.size} problems did not "
            f"converge in {max_iter} Levenberg-Marquardt iterations (statuses: "
            f"{sorted(set(status.tolist()) - {'ok'})})"
        )
    return LocalizationResult(pos.reshape(batch + (dim,)), converged.reshape(batch), cost.reshape(batch),
                              it, "rss_ml_lm", status.reshape(batch))


def _region(region_m, dim: int):
    """``(lower, upper)`` arrays ``(dim,)`` of a ``region_m`` box, checked (``(None, None)`` without one)."""
    if region_m is None:
        return None, None
    try:
        lower, upper = region_m
    except (TypeError, ValueError):
        raise ValueError(f"region_m must be a pair (lower, upper) of corners, got {region_m!r}") from None
    lower = as_array("region_m lower corner", lower, ndim=1, trailing=(dim,))
    upper = as_array("region_m upper corner", upper, ndim=1, trailing=(dim,))
    if np.any(lower >= upper):
        raise ValueError(f"region_m must have lower < upper in every coordinate, got {lower.tolist()} and "
                         f"{upper.tolist()}")
    return lower, upper


def _check_model(model, m: int) -> None:
    """The channel's parameters are scalars or per-anchor ``(m,)`` arrays, finite."""
    require_path_loss_model(model)
    for name in ("ref_power_dbm", "path_loss_exp", "sigma_db"):
        value = as_array(f"model.{name}", getattr(model, name))
        if value.ndim > 1 or value.size not in (1, m):
            raise ValueError(f"model.{name} must be a scalar or have shape ({m},) (one per anchor), "
                             f"got shape {value.shape}")
    if np.any(np.asarray(model.path_loss_exp) <= 0):
        raise ValueError(f"model.path_loss_exp must be positive, got {model.path_loss_exp!r}")


#: memory of one block of grid costs in :func:`grid_ml_position` (problems x cells doubles; the arithmetic that makes
#: it holds one temporary of the same size)
GRID_ML_BLOCK_BYTES = 256 * 2**20


def _grid_ml_block(chunk, n_problems: int, n_cells: int) -> int:
    """Problems per block of :func:`grid_ml_position`: ``chunk`` (default: as many as fit) capped at
    :data:`GRID_ML_BLOCK_BYTES` of costs, at least two when there are several (a lone row would take BLAS's
    one-row kernel, which rounds differently: the result would depend on the blocking); checked before anything of
    the grid's size is allocated."""
    row = 8 * n_cells
    smallest = min(n_problems, 2)
    if smallest * row > GRID_ML_BLOCK_BYTES:
        raise ValueError(f"cells_m has {n_cells} cells: a block of {smallest} problem(s) of costs would take "
                         f"{smallest * row / 2**20:.4g} MiB, over the limit GRID_ML_BLOCK_BYTES = "
                         f"{GRID_ML_BLOCK_BYTES / 2**20:.4g} MiB; use a coarser grid (or a smaller outline)")
    fit = GRID_ML_BLOCK_BYTES // row
    return max(smallest, min(fit, int(chunk) if chunk is not None else fit))


@_accepts_old_form(lambda args, kwargs: _old_estimator_call(args, kwargs, "grid_ml_position", _grid_ml_position_v1))
def grid_ml_position(rss_dbm, model: RssModel, cells_m, *,
                     chunk: int | None = None, min_anchors: int | None = None) -> LocalizationResult:
    """Grid maximum likelihood: the candidate point of ``cells_m`` ``(G, dim)`` with the smallest RSS-domain squared
    residual of the RSS model ``model`` (:class:`locbook.RssModel`), for every problem; evaluated in chunks to bound
    memory. ``cost`` is that residual; a grid point on an anchor is taken 1 micrometre from it.
    A NaN power is an anchor not heard (module docstring): the residual runs over the heard anchors; with fewer
    than ``min_anchors`` heard the problem gets a NaN position, NaN cost and ``converged=False``. An implausible
    power (above the model's mean at its clamp, ``max(channel.min_distance_m, 1e-6)``, by more than
    :data:`IMPLAUSIBLE_SIGMAS` sigma: a reading implying a tag closer than 1 micrometre to an anchor's antenna)
    gives NaN and ``status="implausible_reading"``; a cost that overflows (e.g. a reading of -1e300 dBm) NaN
    position and cost and ``status="solver_failed"``, without a warning, like :func:`rss_ml_position`. A best cost
    beyond the chi-square bound of :data:`GOODNESS_OF_FIT_ALPHA` (``m_heard - dim`` degrees of freedom, cost over
    sigma^2; model with ``sigma_db > 0``) gives
    ``status="poor_fit"``, position and ``converged`` kept; the cost at a grid point includes the grid's
    discretisation, so a grid far coarser than the shadowing can be flagged too (no grid point fits the readings).
    ``model.tag_height_m``: anchors ``(m, 3)`` with heights, a plan grid ``(G, 2)`` (module docstring). What the model
    may hold and what is refused by name (per-run anchors, per-run or per-step parameters, walls): as
    :func:`rss_ml_position`.

    Memory is bounded whatever the sizes: the problems are scored against the grid in blocks of at most ``chunk``
    problems (default: as many as fit :data:`GRID_ML_BLOCK_BYTES` of costs, 256 MiB; an explicit ``chunk`` is capped
    there too), each problem's arithmetic being the same in any block, so the result does not depend on ``chunk``. A
    grid so large that two problems' costs (one, for a single problem) exceed the limit is refused in one line naming
    ``cells_m``, before anything of its size is allocated.

    The form before issue 47, ``grid_ml_position(anchors_m, rss_dbm, channel, grid_m, ..., tag_height_m=...)`` (a
    :class:`~locbook.PathLossModel` third), is deprecated: it warns and builds the :class:`~locbook.RssModel`;
    ``grid_m=`` is the old spelling of ``cells_m=`` (deprecated too)."""
    anchors_m, channel, tag_height_m = _rss_model_parts(model, "grid_ml_position")
    return _grid_ml(anchors_m, rss_dbm, channel, cells_m, chunk=chunk, min_anchors=min_anchors,
                    tag_height_m=tag_height_m)


def _grid_ml(anchors_m, rss_dbm, model: PathLossModel, cells_m, *, chunk: int | None = None,
             min_anchors: int | None = None, tag_height_m: float | None = None) -> LocalizationResult:
    """:func:`grid_ml_position` on the model's anchors ``(m, k)``, channel ``model`` and tag height; the problems or
    anchors it sets apart are solved by calls to itself."""
    plan, vertical = _planar(anchors_m, tag_height_m)
    anchors_full = np.asarray(anchors_m, dtype=float)
    anchors_m = check_anchor_geometry(plan)
    m, dim = anchors_m.shape
    cells_m = as_array("cells_m", cells_m, ndim=2, trailing=(dim,))
    if cells_m.shape[0] < 1:
        raise ValueError("cells_m must hold at least one candidate point")
    power = _readings("rss_dbm", rss_dbm, m)
    _check_model(model, m)
    if chunk is not None:
        check_scalar("chunk", chunk, ge=1, integer=True)
    block_rows = _grid_ml_block(chunk, int(np.prod(power.shape[:-1], dtype=np.int64)), cells_m.shape[0])
    min_anchors = _min_anchors(min_anchors, dim, m)
    implausible = implausible_powers(power, model, max(model.min_distance_m, 1e-6)).reshape(-1)
    if implausible.any():
        flat_power = power.reshape(-1, m)
        return _solve_where(~implausible, power.shape[:-1], dim,
                            lambda sel: _grid_ml(anchors_full, flat_power[sel], model, cells_m, chunk=chunk,
                                                 min_anchors=min_anchors, tag_height_m=tag_height_m),
                            "grid_ml", "implausible_reading")
    if np.isnan(power).any():
        flat_power = power.reshape(-1, m)
        return _by_heard_anchors(
            anchors_m, power, min_anchors,
            lambda heard, sel: _grid_ml(anchors_full[heard], flat_power[np.ix_(sel, heard)],
                                        _model_subset(model, heard, m), cells_m, chunk=chunk,
                                        tag_height_m=tag_height_m),
            "grid_ml")
    batch = power.shape[:-1]
    flat = power.reshape(-1, power.shape[-1])
    with np.errstate(over="ignore", invalid="ignore"):
        # the one RSS model's mean (G, m); a node may sit on an anchor: clamped at 1 micrometre at least
        mean_grid, _, d2 = rss_mean_jacobian(cells_m[:, None, :] - anchors_m, np.asarray(model.ref_power_dbm),
                                             np.asarray(model.path_loss_exp), ref_distance_m=model.ref_distance_m,
                                             min_distance_m=max(model.min_distance_m, 1e-6),
                                             vertical_m2=None if vertical is None else vertical**2, jacobian=False)
    if not np.all(np.isfinite(d2)):            # finite coordinates (checked): only overflow gets here
        raise ValueError(f"the distances between cells_m and anchors_m overflow: their coordinates reach "
                         f"{max(np.abs(cells_m).max(initial=0), np.abs(anchors_m).max(initial=0)):.3g} m")
    best = np.empty(flat.shape[0], dtype=int)
    best_cost = np.empty(flat.shape[0])
    # a finite power of absurd size (-1e300 dBm: a tag very far away is not implausible) overflows its squares; that
    # problem is marked failed below, so the overflow is expected, not a warning for the caller
    n_flat = flat.shape[0]
    with np.errstate(over="ignore", invalid="ignore"):
        sq_grid = (mean_grid**2).sum(1)
        for start in range(0, n_flat, block_rows):
            stop = min(start + block_rows, n_flat)
            # a lone last row is scored with its predecessor (recomputed to the same bits): one row alone would take
            # BLAS's one-row kernel, whose rounding differs, and the result would depend on chunk
            start = start - 1 if stop - start == 1 and n_flat > 1 else start
            block = flat[start:stop]
            # |P - mu_g|^2 = |P|^2 - 2 P.mu_g + |mu_g|^2; the first term does not change the argmin
            cost = sq_grid - 2.0 * block @ mean_grid.T
            idx = np.argmin(cost, axis=1)
            best[start:stop] = idx
            best_cost[start:stop] = cost[np.arange(len(idx)), idx] + (block**2).sum(1)
    pos = cells_m[best].reshape(batch + (cells_m.shape[1],))
    ok = np.isfinite(best_cost)
    # a cost that overflowed has no meaningful minimum: NaN position and cost, as rss_ml_position gives
    pos = np.where(ok.reshape(batch)[..., None], pos, np.nan)
    best_cost = np.where(ok, best_cost, np.nan)
    status = _goodness_of_fit(_status(ok), best_cost, model, m, dim)
    return LocalizationResult(pos, ok.reshape(batch), best_cost.reshape(batch), 0, "grid_ml", status.reshape(batch))
