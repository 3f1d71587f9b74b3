"""Missing readings, the library's one rule: a NaN received power or range means "not heard" (the anchor got no
packet in that epoch).

Each problem uses the anchors heard in it; problems are grouped by their pattern of heard anchors and each group is
solved with that subset (:func:`by_heard_anchors`), so a problem with no NaN goes through exactly the computation it
always did (and a problem with one anchor missing gets exactly what the estimator gives on the anchors it heard). A
problem with fewer than ``min_anchors`` heard anchors (default ``dim + 1``; at most the number of anchors), or whose
heard anchors are collinear or coincide, gets a NaN position, ``converged=False`` and a ``status`` saying why
(:class:`~locbook.static.result.LocalizationResult`), alone: its batch is unaffected. If the reference anchor of the
linearized system is not heard, the first heard anchor serves as reference for that problem (:func:`ref_in_subset`).
"""
from __future__ import annotations

from dataclasses import replace

import numpy as np

from .._validate import as_array, check_scalar
from ..errors import DegenerateGeometryError
from ..models.channel import PathLossModel
from .checks import check_anchor_geometry
from .result import LocalizationResult

__all__ = ["checked_readings", "given_readings", "has_missing", "ref_in_subset", "channel_subset",
           "by_heard_anchors", "solve_where", "check_min_anchors"]


def checked_readings(name: str, values, m: int) -> np.ndarray:
    """Measurements ``(..., m)``: NaN = not heard; infinities and a wrong anchor axis are errors."""
    values = as_array(name, values, min_ndim=1, nan_ok=True)
    if values.shape[-1] != m:
        raise ValueError(f"{name} must have shape (..., {m}), one value per anchor ({m} anchors), "
                         f"got shape {values.shape}")
    return values


def given_readings(name: str, values) -> np.ndarray:
    """Readings as the public entry got them, converted once (:func:`locbook._validate.as_array`: a masked entry is
    NaN, not heard), so that every later look at them (which anchors were heard, the per-subset solves) sees the same
    values; the shape is checked where the anchors are known."""
    return as_array(name, values, nan_ok=True)


def has_missing(values) -> bool:
    """Whether any reading is NaN (not heard). Decided on the readings themselves, never on quantities derived
    from them (a linearized right-hand side can be NaN from overflow with every anchor heard)."""
    return bool(np.isnan(np.asarray(values, dtype=float)).any())


def ref_in_subset(ref_index: int, heard: np.ndarray) -> int:
    """Position of the reference anchor among the heard ones; the first heard anchor if it was not heard."""
    hit = np.flatnonzero(heard == ref_index)
    return int(hit[0]) if hit.size else 0


def channel_subset(model: PathLossModel, heard: np.ndarray, m: int) -> PathLossModel:
    """The channel restricted to the heard anchors (per-anchor parameters are subset, scalars kept)."""
    def pick(value):
        value = np.asarray(value)
        return value[..., heard] if value.ndim and value.shape[-1] == m else value
    return replace(model, ref_power_dbm=pick(model.ref_power_dbm), path_loss_exp=pick(model.path_loss_exp),
                   sigma_db=pick(model.sigma_db))


def by_heard_anchors(anchors_m, readings, min_anchors, solve_subset, method: str) -> LocalizationResult:
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


def solve_where(usable, batch, dim: int, solve, method: str, failure: str) -> LocalizationResult:
    """Solve the problems where the flat mask ``usable`` holds with ``solve(indices) -> LocalizationResult`` of
    those problems; the others get NaN, ``converged=False`` and status ``failure``, alone."""
    k = usable.size
    pos, converged, cost = np.full((k, dim), np.nan), np.zeros(k, bool), np.full(k, np.nan)
    status, n_iter = np.full(k, failure, dtype="<U19"), 0
    if usable.any():
        sel = np.flatnonzero(usable)
        res = solve(sel)
        pos[sel], converged[sel] = res.position_m.reshape(-1, dim), res.converged.ravel()
        status[sel] = res.status.ravel()
        if res.cost is not None:
            cost[sel] = res.cost.ravel()
        n_iter = res.n_iter
    return LocalizationResult(pos.reshape(batch + (dim,)), converged.reshape(batch), cost.reshape(batch), n_iter,
                              method, status.reshape(batch))


def check_min_anchors(min_anchors, dim: int, m: int) -> int:
    """``min_anchors`` checked: an integer from ``dim + 1`` (the default) to the number of anchors ``m``."""
    if min_anchors is None:
        return dim + 1
    check_scalar("min_anchors", min_anchors, ge=dim + 1, integer=True)
    if min_anchors > m:
        raise ValueError(f"min_anchors must be <= the number of anchors ({m}), got {min_anchors!r}: "
                         "no problem could ever be solved")
    return int(min_anchors)

