"""Grid maximum likelihood, :func:`grid_ml_position`: exhaustive maximum likelihood over candidate points.

Shapes, statuses and failures: :mod:`locbook.static.result`; missing readings: :mod:`locbook.static.missing`; anchor
heights: :mod:`locbook.static.checks`.
"""
from __future__ import annotations

import numpy as np

from .._validate import as_array, check_scalar
from ..models.channel import PathLossModel
from ..models.rss import RssModel, rss_mean_jacobian
from .checks import check_anchor_geometry, check_channel, goodness_of_fit, implausible_powers, plan_anchors
from .missing import by_heard_anchors, channel_subset, check_min_anchors, checked_readings, solve_where
from .result import LocalizationResult, status_array
from .rss_form import accepts_old_form, old_estimator_call, rss_model_parts

__all__ = ["grid_ml_position", "GRID_ML_BLOCK_BYTES"]


def _grid_ml_position_v1(anchors_m, rss_dbm, model, grid_m, *, chunk=None, min_anchors=None, tag_height_m=None):
    """The earlier signature of :func:`grid_ml_position`, the anchors first (deprecated calls are bound to it)."""


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


@accepts_old_form(lambda args, kwargs: old_estimator_call(args, kwargs, "grid_ml_position", _grid_ml_position_v1))
def grid_ml_position(rss_dbm, model: RssModel, cells_m, *,
                     chunk: int | None = None, min_anchors: int | None = None) -> LocalizationResult:
    """Grid maximum likelihood: the candidate point with the smallest RSS-domain squared residual, per problem.

    For every problem the point of ``cells_m`` whose mean powers under ``model`` are nearest the readings in the
    least-squares sense; evaluated in blocks to bound memory. A grid point on an anchor is taken 1 micrometre
    from it.

    Parameters
    ----------
    rss_dbm : array_like, shape (..., m)
        Received powers (dBm); NaN is an anchor not heard (:mod:`locbook.static.missing`): the residual runs over
        the heard anchors.
    model : RssModel
        The one RSS measurement model; ``model.tag_height_m``: anchors ``(m, 3)`` with heights, a plan grid
        ``(G, 2)`` (:mod:`locbook.static.checks`). What the model may hold and what is refused by name (per-run
        anchors, per-run or per-step parameters, walls): as :func:`~locbook.static.rss_ml.rss_ml_position`.
    cells_m : array_like, shape (G, dim)
        The candidate points.
    chunk : int, optional
        At most this many problems per block (default: as many as fit :data:`GRID_ML_BLOCK_BYTES` of costs, 256
        MiB; an explicit ``chunk`` is capped there too). Each problem's arithmetic is the same in any block, so the
        result does not depend on ``chunk``.
    min_anchors : int, optional
        Heard anchors a problem needs (default ``dim + 1``); with fewer the problem gets a NaN position, NaN cost
        and ``converged=False``.

    Returns
    -------
    LocalizationResult
        ``position_m`` ``(..., dim)`` (a point of ``cells_m``), ``cost`` the residual there (dB^2), ``status``. An
        implausible power (above the model's mean at its clamp, ``max(channel.min_distance_m, 1e-6)``, by more
        than :data:`~locbook.static.checks.IMPLAUSIBLE_SIGMAS` sigma: a reading implying a tag closer than 1
        micrometre to an anchor's antenna) gives NaN and ``status="implausible_reading"``; a cost that overflows
        (e.g. a reading of -1e300 dBm) NaN position and cost and ``status="solver_failed"``, without a warning, like
        :func:`~locbook.static.rss_ml.rss_ml_position`. A best cost beyond the chi-square bound of
        :data:`~locbook.static.checks.GOODNESS_OF_FIT_ALPHA` (``m_heard - dim`` degrees of freedom, cost over
        sigma^2; model with ``sigma_db > 0``) gives ``status="poor_fit"``, position and ``converged`` kept; the
        cost at a grid point includes the grid's discretisation, so a grid far coarser than the shadowing can be
        flagged too (no grid point fits the readings).

    Raises
    ------
    ValueError
        A grid so large that two problems' costs (one, for a single problem) exceed :data:`GRID_ML_BLOCK_BYTES`,
        refused in one line naming ``cells_m`` before anything of its size is allocated; a model the estimator
        cannot honour (named); shapes that do not match.
    DegenerateGeometryError
        Anchors that are too few, coincident or collinear.

    Notes
    -----
    The earlier form, ``grid_ml_position(anchors_m, rss_dbm, channel, grid_m, ..., tag_height_m=...)`` (a
    :class:`~locbook.PathLossModel` third), is deprecated: it warns and builds the :class:`~locbook.RssModel`;
    ``grid_m=`` is the old spelling of ``cells_m=`` (deprecated too).

    References
    ----------
    Dogan (2015), Eq. (2.4): the maximum-likelihood cost, minimised here over a finite set of points.

    Examples
    --------
    Noise-free powers of a tag on a grid point give that point back, at zero cost:

    >>> import numpy as np
    >>> import locbook as lb
    >>> anchors = np.array([[0.0, 0.0], [10.0, 0.0], [0.0, 10.0], [10.0, 10.0]])
    >>> channel = lb.PathLossModel(-40.0, 2.5)
    >>> xs = np.arange(0.0, 10.01, 0.5)
    >>> cells = np.stack(np.meshgrid(xs, xs, indexing="ij"), axis=-1).reshape(-1, 2)
    >>> power = channel.mean_rss_dbm(lb.pairwise_distance_m(np.array([3.0, 4.0]), anchors))
    >>> fix = lb.grid_ml_position(power, lb.RssModel(anchors, channel), cells)
    >>> print(np.round(fix.position_m, 2), fix.status, np.round(fix.cost, 6))
    [3. 4.] ok 0.0
    """
    anchors_m, channel, tag_height_m = rss_model_parts(model, "grid_ml_position")
    return _grid_ml(anchors_m, rss_dbm, channel, cells_m, chunk=chunk, min_anchors=min_anchors,
                    tag_height_m=tag_height_m)


def _grid_ml(anchors_m, rss_dbm, model: PathLossModel, cells_m, *, chunk: int | None = None,
             min_anchors: int | None = None, tag_height_m: float | None = None) -> LocalizationResult:
    """:func:`grid_ml_position` on the model's anchors ``(m, k)``, channel ``model`` and tag height; the problems or
    anchors it sets apart are solved by calls to itself."""
    plan, vertical = plan_anchors(anchors_m, tag_height_m)
    anchors_full = np.asarray(anchors_m, dtype=float)
    anchors_m = check_anchor_geometry(plan)
    m, dim = anchors_m.shape
    cells_m = as_array("cells_m", cells_m, ndim=2, trailing=(dim,))
    if cells_m.shape[0] < 1:
        raise ValueError("cells_m must hold at least one candidate point")
    power = checked_readings("rss_dbm", rss_dbm, m)
    check_channel(model, m)
    if chunk is not None:
        check_scalar("chunk", chunk, ge=1, integer=True)
    block_rows = _grid_ml_block(chunk, int(np.prod(power.shape[:-1], dtype=np.int64)), cells_m.shape[0])
    min_anchors = check_min_anchors(min_anchors, dim, m)
    implausible = implausible_powers(power, model, max(model.min_distance_m, 1e-6)).reshape(-1)
    if implausible.any():
        flat_power = power.reshape(-1, m)
        return solve_where(~implausible, power.shape[:-1], dim,
                            lambda sel: _grid_ml(anchors_full, flat_power[sel], model, cells_m, chunk=chunk,
                                                 min_anchors=min_anchors, tag_height_m=tag_height_m),
                            "grid_ml", "implausible_reading")
    if np.isnan(power).any():
        flat_power = power.reshape(-1, m)
        return by_heard_anchors(
            anchors_m, power, min_anchors,
            lambda heard, sel: _grid_ml(anchors_full[heard], flat_power[np.ix_(sel, heard)],
                                        channel_subset(model, heard, m), cells_m, chunk=chunk,
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
    status = goodness_of_fit(status_array(ok), best_cost, model, m, dim)
    return LocalizationResult(pos, ok.reshape(batch), best_cost.reshape(batch), 0, "grid_ml", status.reshape(batch))
