"""Nearest-neighbour fingerprinting in RSSI space (RADAR / LANDMARC style).

A fingerprint map holds one RSSI vector per cell (``(C, m)`` for ``m`` readers). The target's RSSI vector
``s`` is compared with every cell by the Euclidean distance in RSSI space (Ozkaya 2011, Eq. (3.1))

    E_j = || R_j - s ||,

the ``k`` nearest cells are kept, and the estimate is their weighted centroid (Eqs. (3.2)-(3.3))

    x = sum_i w_i x_i,   w_i = (1/E_i^2) / sum_j (1/E_j^2).

Eq. (3.3) as printed divides by ``sum_j E_j^2`` instead, which does not normalise the weights (a typo:
the normalised form, LANDMARC's, reproduces the simulation tables); it is kept as ``weighting="literal_ozkaya2011"``.

Two ways to build the map (Ozkaya 2011, Sec. 3.1):
- pattern based: the stored mean RSSI vector measured at each training location (:func:`pattern_fingerprints`);
- parameter based: the path-loss model evaluated at each cell centre (:func:`model_fingerprints`, the cells then the
  one RSS model, :class:`locbook.RssModel`), Eq. (3.4) (printed as "3.14"),
  ``R_ij = alpha_i - 10 n_i log10(d_ij/d0) - c_ij WAF``.
"""
from __future__ import annotations

import inspect
from dataclasses import replace

import numpy as np

from .._validate import as_array, check_choice, check_scalar
from ..models.channel import PathLossModel, pairwise_distance_m, require_path_loss_model, wall_crossings
from ..models.rss import RssModel
from .rss_form import accepts_old_form, is_old_form, rss_model_parts

__all__ = ["KNN_WEIGHTINGS", "KNN_BLOCK_BYTES", "knn_position", "model_fingerprints", "pattern_fingerprints"]

KNN_WEIGHTINGS = ("inverse_square", "literal_ozkaya2011", "uniform")


def _model_fingerprints_v1(cells_m, anchors_m, model, walls_m=None, min_distance_m=None):
    """The earlier signature of :func:`model_fingerprints`, the anchors second (deprecated calls are bound to it)."""


def _old_fingerprints_call(args, kwargs):
    """:func:`~locbook.static.rss_form.accepts_old_form`'s ``old_call`` of :func:`model_fingerprints`: the earlier
    form (cells, anchors, a PathLossModel, walls; deprecated) goes to the same arithmetic, :func:`_fingerprints`,
    directly (its parameters may carry any batch axes ``(..., m)``, more than an RssModel holds)."""
    if not is_old_form(args, kwargs, ("cells_m", "anchors_m")):
        if "walls_m" in kwargs:
            raise ValueError("model_fingerprints: walls_m is the model's: pass RssModel(anchors_m, channel, walls_m) "
                             "as model")
        return None
    given = inspect.signature(_model_fingerprints_v1).bind(*args, **kwargs).arguments
    return ("model_fingerprints(cells_m, anchors_m, channel, walls_m, ...)",
            "model_fingerprints(cells_m, RssModel(anchors_m, channel, walls_m), ...)",
            lambda new: _fingerprints(given["cells_m"], given["anchors_m"], given["model"], given.get("walls_m"),
                                      given.get("min_distance_m", 0.1)))


@accepts_old_form(_old_fingerprints_call)
def model_fingerprints(cells_m, model: RssModel, *, min_distance_m: float = 0.1):
    """Parameter-based map: mean RSSI ``(..., C, m)`` of the RSS model ``model`` (:class:`locbook.RssModel`: its
    anchors ``(m, dim)``, its channel, its walls ``model.walls_m``) at cell centres ``(C, dim)``, Eq. (3.4).

    The channel's parameters broadcast against the reader axis; per-run and per-step parameters (e.g. online
    calibration per step, ``(R, T, m)``) give one map per run and step, ``(R, T, C, m)``. Distances below
    ``min_distance_m`` (> 0) are clipped (a cell centre on a reader; the channel's own ``min_distance_m`` if larger).
    The cells must be finite. Per-run anchors and a tag height are refused by name.

    The earlier form, ``model_fingerprints(cells_m, anchors_m, channel, walls_m=None, min_distance_m=0.1)`` (a
    :class:`~locbook.PathLossModel` third), is deprecated: it warns and gives the same map.
    """
    anchors_m, channel, _ = rss_model_parts(model, "model_fingerprints", walls=True, per_step=True, heights=False,
                                             form="model_fingerprints(cells_m, RssModel(anchors_m, channel, walls_m))")
    return _fingerprints(cells_m, anchors_m, channel, model.walls_m, min_distance_m)


def _fingerprints(cells_m, anchors_m, model: PathLossModel, walls_m=None, min_distance_m: float = 0.1):
    """:func:`model_fingerprints` of the anchors ``(m, 2)``, the channel ``model`` and the walls: mean RSSI
    ``(..., C, m)``. The channel's parameters broadcast against the reader axis; leading batch axes on them, any
    ``(..., m)``, give one map per batch entry (the reference-tag calibration's per-step fits). ``anchors_m`` must be
    finite, like the cells; ``walls_m`` is checked by :func:`locbook.wall_crossings`.
    """
    require_path_loss_model(model)
    anchors_m = as_array("anchors_m", anchors_m, ndim=2)
    m, dim = anchors_m.shape
    cells_m = as_array("cells_m", cells_m, ndim=2, trailing=(dim,))
    for name in ("ref_power_dbm", "path_loss_exp"):
        value = np.asarray(getattr(model, name))
        if value.ndim and value.shape[-1] not in (1, m):
            raise ValueError(f"model.channel.{name} must be a scalar or have shape (..., 1) or (..., {m}) (one per "
                             f"reader), got shape {value.shape}")
    check_scalar("min_distance_m", min_distance_m, gt=0)
    distance = pairwise_distance_m(cells_m, anchors_m, names=("cells_m", "anchors_m"))
    n_walls = 0 if walls_m is None else wall_crossings(cells_m, anchors_m, walls_m)

    def per_cell(value):   # (..., m) parameters -> (..., 1, m), so they broadcast over the cell axis
        return np.asarray(value, float)[..., None, :] if np.ndim(value) else value

    batched = replace(model, ref_power_dbm=per_cell(model.ref_power_dbm), path_loss_exp=per_cell(model.path_loss_exp),
                      min_distance_m=max(model.min_distance_m, min_distance_m))
    return batched.mean_rss_dbm(distance, n_walls)


def pattern_fingerprints(rss_dbm, axis: int = -2):
    """Pattern-based map: the mean RSSI vector of the training samples at each location.

    ``rss_dbm`` has the samples on ``axis`` (default: shape ``(C, samples, m)``); Ozkaya keeps only the
    mean of 40 vectors per location (Sec. 6.3).

    Missing readings: a NaN sample is a packet the reader did not hear; each entry is the mean of the samples
    heard. A reader that heard none of a location's samples leaves NaN in the map: :func:`knn_position`
    rejects such a map, so fill that entry (e.g. with the reader's sensitivity floor) or drop the reader.
    """
    rss_dbm = as_array("rss_dbm", rss_dbm, min_ndim=2, nan_ok=True)
    if isinstance(axis, (bool, np.bool_)) or not isinstance(axis, (int, np.integer)) or \
            not -rss_dbm.ndim <= axis < rss_dbm.ndim or axis % rss_dbm.ndim == rss_dbm.ndim - 1:
        raise ValueError(f"axis must be a sample axis of rss_dbm (shape {rss_dbm.shape}), not the reader axis "
                         f"(the last), got {axis!r}")
    mean = np.mean(rss_dbm, axis=axis)
    missing = np.isnan(mean)
    if missing.any():      # the mean over the heard samples, only where some sample was not heard
        heard = ~np.isnan(rss_dbm)
        n_heard = heard.sum(axis=axis)
        total = np.where(heard, rss_dbm, 0.0).sum(axis=axis)
        with np.errstate(invalid="ignore", divide="ignore"):
            mean[missing] = np.where(n_heard > 0, total / n_heard, np.nan)[missing]
    return mean


#: memory of one block of RSSI-space differences in :func:`knn_position` (queries x cells x readers doubles)
KNN_BLOCK_BYTES = 64 * 2**20


def knn_position(rss_dbm, fingerprints_dbm, cells_m, k: int, weighting: str = "inverse_square", *,
                 min_anchors: int = 3, chunk: int | None = None):
    """Weighted k-nearest-neighbour position in RSSI space, Eqs. (3.1)-(3.3) of Ozkaya (2011), weights corrected.

    Each query ``s`` is compared with every cell's fingerprint ``R_j`` by the Euclidean distance in RSSI space,
    ``E_j = |R_j - s|``; the ``k`` nearest cells are kept and the estimate is their weighted centroid
    ``x = sum_i w_i x_i`` (module docstring). ``k = C`` (all cells) is the weighted centroid used in the thesis's
    experiments.

    Parameters
    ----------
    rss_dbm : array_like, shape (..., m)
        Target RSSI vectors. A NaN is a reader not heard: that query is compared with the map over the readers it
        heard, and with fewer than ``min(min_anchors, m)`` heard its position is NaN (a query that heard every
        reader is always compared).
    fingerprints_dbm : array_like, shape (C, m) or (..., C, m)
        The map (one map per batch entry if batched; its batch axes must broadcast against those of ``rss_dbm``).
        It must be complete: a cell a reader never heard has no fingerprint to compare (fill it, or drop that
        reader).
    cells_m : array_like, shape (C, 2)
        The cells' positions.
    k : int
        Neighbours kept, from 1 to ``C``.
    weighting : {"inverse_square", "literal_ozkaya2011", "uniform"}, default "inverse_square"
        :data:`KNN_WEIGHTINGS`: ``w_i = (1/E_i^2) / sum_j (1/E_j^2)`` (LANDMARC's normalised form), Eq. (3.3) as
        printed (not normalised), or equal weights.
    min_anchors : int, default 3
        Heard readers a query needs.
    chunk : int, optional
        Queries per block (default: as many as fit :data:`KNN_BLOCK_BYTES` of differences, 64 MiB). Each query's
        arithmetic is the same in any block, so the result does not depend on ``chunk``.

    Returns
    -------
    numpy.ndarray, shape (..., 2)
        The positions (NaN for a query that heard too few readers).

    Raises
    ------
    ValueError
        A NaN in the map (naming the cell and reader), shapes that do not match or do not broadcast, ``k`` out of
        range, an unknown ``weighting``.

    References
    ----------
    Ozkaya (2011), Eq. (3.1) (the RSSI-space distance), Eqs. (3.2)-(3.3) (the weighted centroid; Eq. (3.3) as
    printed divides by ``sum_j E_j^2``, kept as ``weighting="literal_ozkaya2011"``).

    Examples
    --------
    A query equal to a cell's fingerprint gives that cell:

    >>> import numpy as np
    >>> import locbook as lb
    >>> anchors = np.array([[0.0, 0.0], [10.0, 0.0], [0.0, 10.0], [10.0, 10.0]])
    >>> channel = lb.PathLossModel(-40.0, 2.5)
    >>> xs = np.arange(0.5, 10.0, 1.0)
    >>> cells = np.stack(np.meshgrid(xs, xs, indexing="ij"), axis=-1).reshape(-1, 2)
    >>> fingerprints = channel.mean_rss_dbm(lb.pairwise_distance_m(cells, anchors))
    >>> query = channel.mean_rss_dbm(lb.pairwise_distance_m(np.array([3.5, 4.5]), anchors))
    >>> print(np.round(lb.knn_position(query, fingerprints, cells, 1), 2))
    [3.5 4.5]
    """
    rss_dbm, fingerprints_dbm, cells_m = _checked_knn_inputs(rss_dbm, fingerprints_dbm, cells_m, (k,), weighting,
                                                             min_anchors, chunk)
    return _knn_per_k(rss_dbm, fingerprints_dbm, cells_m, (k,), weighting, int(min_anchors), chunk)[0]


def knn_position_per_k(rss_dbm, fingerprints_dbm, cells_m, ks, weighting: str = "inverse_square", *,
                       min_anchors: int = 3, chunk: int | None = None) -> np.ndarray:
    """:func:`knn_position` for every ``k`` of ``ks`` at once: shape ``(len(ks), ..., 2)``, each ``[i]`` equal to
    ``knn_position(..., ks[i], ...)`` bit for bit. The RSSI-space distances (Eq. (3.1) of Ozkaya 2011) are computed
    once for all the ``k``, which is what choosing ``k`` by cross-validation needs."""
    ks = tuple(ks)
    if not ks:
        raise ValueError("ks must hold at least one k")
    rss_dbm, fingerprints_dbm, cells_m = _checked_knn_inputs(rss_dbm, fingerprints_dbm, cells_m, ks, weighting,
                                                             min_anchors, chunk)
    return _knn_per_k(rss_dbm, fingerprints_dbm, cells_m, ks, weighting, int(min_anchors), chunk)


def _checked_knn_inputs(rss_dbm, fingerprints_dbm, cells_m, ks, weighting, min_anchors, chunk):
    """The arguments of :func:`knn_position` checked (one line naming the argument), as arrays."""
    check_choice("weighting", weighting, KNN_WEIGHTINGS)
    fingerprints_dbm = as_array("fingerprints_dbm", fingerprints_dbm, min_ndim=2, nan_ok=True)
    _check_complete_map(fingerprints_dbm)
    m = fingerprints_dbm.shape[-1]
    rss_dbm = as_array("rss_dbm", rss_dbm, min_ndim=1, nan_ok=True, trailing=(m,))
    cells_m = as_array("cells_m", cells_m, ndim=2)
    n_cells = cells_m.shape[0]
    if fingerprints_dbm.shape[-2] != n_cells:
        raise ValueError(f"fingerprints_dbm has {fingerprints_dbm.shape[-2]} cells (shape {fingerprints_dbm.shape}) "
                         f"but cells_m has {n_cells} cell centres (shape {cells_m.shape})")
    try:
        np.broadcast_shapes(rss_dbm.shape[:-1], fingerprints_dbm.shape[:-2])
    except ValueError:
        raise ValueError(f"the batch axes of rss_dbm {rss_dbm.shape[:-1]} (shape {rss_dbm.shape}) and of "
                         f"fingerprints_dbm {fingerprints_dbm.shape[:-2]} (shape {fingerprints_dbm.shape}) must "
                         "broadcast against each other") from None
    for k in ks:
        if isinstance(k, (bool, np.bool_)) or not isinstance(k, (int, np.integer)) or not 1 <= k <= n_cells:
            raise ValueError(f"k must be between 1 and the number of cells ({n_cells}), got {k}")
    check_scalar("min_anchors", min_anchors, ge=1, integer=True)
    if chunk is not None:
        check_scalar("chunk", chunk, ge=1, integer=True)
    return rss_dbm, fingerprints_dbm, cells_m


def _knn_per_k(rss_dbm, fingerprints_dbm, cells_m, ks, weighting, min_anchors, chunk):
    """Checked inputs -> positions ``(len(ks), ..., 2)``: in blocks of queries, or by pattern of heard readers."""
    m, n_cells = fingerprints_dbm.shape[-1], cells_m.shape[0]
    if np.isnan(rss_dbm).any():
        return _knn_by_heard_readers(rss_dbm, fingerprints_dbm, cells_m, ks, weighting, min(min_anchors, m), chunk)
    batch = np.broadcast_shapes(rss_dbm.shape[:-1], fingerprints_dbm.shape[:-2])
    n_queries = int(np.prod(batch, dtype=np.int64))
    block = int(chunk) if chunk is not None else max(1, KNN_BLOCK_BYTES // (8 * n_cells * max(m, 1)))
    queries = np.broadcast_to(rss_dbm, batch + (m,)).reshape(-1, m)
    maps = (fingerprints_dbm if fingerprints_dbm.ndim == 2 else
            np.broadcast_to(fingerprints_dbm, batch + fingerprints_dbm.shape[-2:])
            .reshape((-1,) + fingerprints_dbm.shape[-2:]))
    out = np.empty((len(ks), n_queries, cells_m.shape[1]))
    for start in range(0, n_queries, block):
        stop = min(start + block, n_queries)
        out[:, start:stop] = _knn_block(queries[start:stop], maps if maps.ndim == 2 else maps[start:stop], cells_m,
                                        ks, weighting)
    return out.reshape((len(ks),) + batch + (cells_m.shape[1],))


def _k_nearest(dist2, k: int):
    """Indices ``(..., k)`` of the ``k`` smallest ``dist2`` along the last axis, in increasing cell index; of cells
    tied at the k-th distance, the lowest-indexed. Integer RSSI fingerprints are often exactly equidistant from a
    query, and the order in which ``np.argpartition`` returns ties depends on the processor's vector code (AVX-512
    or not): the tie rule makes the neighbours, and the position, the same on every machine."""
    nearest = np.argpartition(dist2, k - 1, axis=-1)[..., :k]
    kth = np.take_along_axis(dist2, nearest, axis=-1).max(axis=-1, keepdims=True)  # the k-th smallest: no ambiguity
    flat_d2, flat_nn, flat_kth = dist2.reshape(-1, dist2.shape[-1]), nearest.reshape(-1, k), kth.reshape(-1, 1)
    tied_rows = np.flatnonzero(np.sum(flat_d2 <= flat_kth, axis=-1) > k)   # more cells than k at or below it
    if tied_rows.size:                # only rows with a tie at the k-th distance pay for the rule
        d2, kt = flat_d2[tied_rows], flat_kth[tied_rows]
        tied = d2 == kt
        room = k - np.sum(d2 < kt, axis=-1, keepdims=True)          # >= 1: how many of the ties are taken
        chosen = (d2 < kt) | (tied & (np.cumsum(tied, axis=-1) <= room))
        flat_nn = flat_nn.copy()
        flat_nn[tied_rows] = np.nonzero(chosen)[1].reshape(-1, k)
    # in increasing index: the weighted sums then add the neighbours in one order on every machine
    return np.sort(flat_nn, axis=-1).reshape(nearest.shape)


def _knn_block(rss_dbm, fingerprints_dbm, cells_m, ks, weighting):
    """Eqs. (3.1)-(3.3) for queries ``(Q, m)`` against a map ``(C, m)`` or ``(Q, C, m)``, no missing readings: the
    positions ``(len(ks), Q, 2)``, one distance computation for every ``k``."""
    diff = fingerprints_dbm - rss_dbm[..., None, :]
    dist2 = np.einsum("...ci,...ci->...c", diff, diff)                  # E_j^2, (..., C)
    return np.stack([_knn_weighted(dist2, cells_m, k, weighting) for k in ks])


def _knn_weighted(dist2, cells_m, k, weighting):
    """Eqs. (3.2)-(3.3): the weighted centroid of the ``k`` cells nearest in RSSI space (``dist2`` = E_j^2)."""
    n_cells = cells_m.shape[0]
    nearest = _k_nearest(dist2, k) if k < n_cells else np.broadcast_to(np.arange(n_cells), dist2.shape)
    e2 = np.take_along_axis(dist2, nearest, axis=-1)
    if weighting == "uniform":
        w = np.full(e2.shape, 1.0 / k)
    else:
        # an exact match (E = 0) takes all the weight: floor E^2 far below any real RSSI distance
        inv = 1.0 / np.maximum(e2, 1e-300)
        if weighting == "inverse_square":
            w = inv / inv.sum(axis=-1, keepdims=True)
        else:   # literal Eq. (3.3): (1/E_i^2) / sum_j E_j^2, not normalised
            w = inv / e2.sum(axis=-1, keepdims=True)
    return np.einsum("...k,...kd->...d", w, cells_m[nearest])


def _check_complete_map(fingerprints_dbm: np.ndarray) -> None:
    """A NaN in the map (a cell a reader never heard) is an error naming the cell and the reader."""
    missing = np.isnan(fingerprints_dbm)
    if missing.any():
        where = tuple(int(i) for i in np.argwhere(missing)[0])
        raise ValueError(f"fingerprints_dbm must be finite (the map must be complete); got {int(missing.sum())} NaN "
                         f"value(s), the first at index {where} (cell {where[-2]}, reader {where[-1]}): fill the "
                         "entries a reader never heard (e.g. with its sensitivity floor) or drop that reader")


def _knn_by_heard_readers(rss_dbm, fingerprints_dbm, cells_m, ks, weighting, min_anchors, chunk):
    """Group the queries by their pattern of heard readers and compare each group over those readers (every ``k``
    of ``ks``: positions ``(len(ks), ..., 2)``)."""
    m = rss_dbm.shape[-1]
    batch = np.broadcast_shapes(rss_dbm.shape[:-1], fingerprints_dbm.shape[:-2])
    flat = np.broadcast_to(rss_dbm, batch + (m,)).reshape(-1, m)
    maps = (None if fingerprints_dbm.ndim == 2 else
            np.broadcast_to(fingerprints_dbm, batch + fingerprints_dbm.shape[-2:])
            .reshape((-1,) + fingerprints_dbm.shape[-2:]))
    out = np.full((len(ks), flat.shape[0], cells_m.shape[1]), np.nan)
    patterns, inverse = np.unique(~np.isnan(flat), axis=0, return_inverse=True)
    inverse = inverse.reshape(-1)
    for g, heard in enumerate(patterns):
        if heard.sum() < min_anchors:
            continue
        sel = np.flatnonzero(inverse == g)
        group_maps = fingerprints_dbm[:, heard] if fingerprints_dbm.ndim == 2 else maps[sel][..., heard]
        out[:, sel] = _knn_per_k(flat[np.ix_(sel, heard)], group_maps, cells_m, ks, weighting, min_anchors, chunk)
    return out.reshape((len(ks),) + batch + (cells_m.shape[1],))
