"""Particle resampling schemes, vectorized over leading axes (Douc, Cappe and Moulines 2005; Arulampalam et al.
2002, Alg. 2 for systematic resampling).

Every scheme returns ancestor indices ``(..., N)`` whose expected counts are ``N w_j`` (unbiased); they differ in
variance: multinomial > stratified > systematic in general, residual in between. ``N_eff``-triggered
resampling (resample only where ``N_eff < threshold``) is :func:`resample_where`.
"""
from __future__ import annotations

import numpy as np

from .._validate import as_array, check_choice

__all__ = ["RESAMPLING_METHODS", "RESAMPLING_CDFS", "resample", "systematic_resample", "counts_to_indices",
           "resample_where", "effective_sample_size"]

RESAMPLING_METHODS = ("systematic", "stratified", "multinomial", "residual")
#: the cumulative sums of :func:`systematic_resample`: the standard one and Table 4.2 of Ozkaya (2011) as printed
RESAMPLING_CDFS = ("standard", "literal_ozkaya2011")

#: relative round-off allowed in ``N w`` before the residual scheme's floor (normalising N weights and scaling by N
#: err by a few ulps; 64 ulps is far below any weight difference that matters)
_FLOOR_RTOL = 64 * np.finfo(float).eps


def _check_weights(weights) -> np.ndarray:
    w = as_array("weights", weights, min_ndim=1)
    if w.shape[-1] == 0 or np.any(w < 0) or np.any(w.sum(axis=-1) <= 0):
        raise ValueError(f"weights must be non-negative with a positive sum in every row, got shape {w.shape}")
    return w / w.sum(axis=-1, keepdims=True)


def effective_sample_size(weights):
    """``N_eff = 1 / sum_j w_j^2`` of normalised weights along the last axis (Ozkaya 2011, Eq. (4.28); Arulampalam
    et al. 2002, Eq. (51)). Every filter of locbook triggers resampling on ``N_eff`` below a fraction of ``N``."""
    weights = as_array("weights", weights, min_ndim=1)
    return 1.0 / np.einsum("...n,...n->...", weights, weights)


def _search_rows(cdf, points):
    """Row-wise ``searchsorted(cdf_r, points_r, side="left")`` for ``(B, N)`` arrays with values in [0, 1], in one
    call (row r is shifted by 2r so the rows do not overlap)."""
    n_rows, n = cdf.shape
    offset = 2.0 * np.arange(n_rows)[:, None]
    idx = np.searchsorted((cdf + offset).ravel(), (points + offset).ravel(), side="left").reshape(points.shape)
    return np.minimum(idx - n * np.arange(n_rows)[:, None], n - 1)


def systematic_resample(weights, uniforms, cdf: str = "standard"):
    """Systematic resampling (Ozkaya 2011, Table 4.2; Arulampalam et al. 2002, Alg. 2) of every row of
    ``weights (..., N)``.

    ``uniforms (...)`` are the single draws ``u_1 ~ U[0, 1)``, scaled here to ``U[0, 1/N)``; the sample
    points are ``u_i = (u_1 + i - 1) / N`` and particle ``j`` is copied for each ``u_i`` with
    ``c_j-1 < u_i <= c_j``. ``cdf="standard"`` uses ``c_j = w_1 + ... + w_j``. The table prints ``c_1 = 0``,
    ``c_j = c_j-1 + w_j``, which drops ``w_1`` and shifts every particle's interval; that is kept as the
    flagged ``"literal_ozkaya2011"`` (indices beyond the last particle are clipped to it).
    Returns integer indices ``(..., N)``.
    """
    check_choice("cdf", cdf, RESAMPLING_CDFS)
    weights = as_array("weights", weights, min_ndim=1)
    batch, n = weights.shape[:-1], weights.shape[-1]
    if n == 0 or np.any(weights < 0) or np.any(weights.sum(axis=-1) <= 0):
        raise ValueError(f"weights must be non-negative with a positive sum in every row, got shape {weights.shape}")
    uniforms_arr = as_array("uniforms", uniforms)
    if uniforms_arr.shape != batch or np.any(uniforms_arr < 0) or np.any(uniforms_arr >= 1):
        raise ValueError(f"uniforms must be draws in [0, 1) of shape {batch} (one per row of weights), "
                         f"got shape {uniforms_arr.shape}")
    w = weights.reshape(-1, n)
    c = np.cumsum(w, axis=-1)
    c /= c[:, -1:]
    if cdf == "literal_ozkaya2011":
        c = np.concatenate([np.zeros((c.shape[0], 1)), c[:, 1:] - c[:, :1]], axis=-1)
    else:
        c[:, -1] = 1.0                                     # guard against round-off below the last u_i
    u = (uniforms_arr.reshape(-1, 1) + np.arange(n)) / n
    return _search_rows(c, u).reshape(batch + (n,))


def counts_to_indices(counts):
    """Offspring counts ``(..., N)`` (non-negative integers summing to N per row) -> sorted ancestor indices."""
    counts = np.asarray(counts)
    batch, n = counts.shape[:-1], counts.shape[-1]
    c = np.cumsum(counts.reshape(-1, n), axis=-1).astype(float)
    if np.any(c[:, -1] != n):
        raise ValueError("offspring counts must sum to the number of particles in every row")
    # ancestor of slot i: the first j with cumsum_j > i (scaled to [0, 1] for the row-wise search)
    return _search_rows(c / n, np.broadcast_to((np.arange(n) + 0.5) / n, c.shape)).reshape(batch + (n,))


def resample(weights, rng: np.random.Generator, method: str = "systematic"):
    """Ancestor indices ``(..., N)`` for every row of ``weights (..., N)`` (normalised here).

    - ``"systematic"``: one uniform per row, points ``(u + i) / N`` (:func:`systematic_resample`);
    - ``"stratified"``: one uniform per stratum, points ``(u_i + i) / N``;
    - ``"multinomial"``: N independent draws from the weights;
    - ``"residual"``: ``floor(N w_j)`` copies of each particle, the remaining ``N - sum floor(N w)`` drawn
      multinomially from the residual weights (``N w_j`` within 64 ulps under an integer counts as that integer, so
      equal weights are resampled deterministically, as by filterpy and Stone Soup).
    """
    check_choice("method", method, RESAMPLING_METHODS)
    if not isinstance(rng, np.random.Generator):
        raise ValueError(f"rng must be a numpy.random.Generator, got {type(rng).__name__}")
    w = _check_weights(weights)
    batch, n = w.shape[:-1], w.shape[-1]
    if method == "systematic":
        return systematic_resample(w, rng.random(batch))
    flat = w.reshape(-1, n)
    if method == "stratified":
        cdf = np.cumsum(flat, axis=-1)
        cdf[:, -1] = 1.0
        points = (np.arange(n) + rng.random(flat.shape)) / n
        return _search_rows(cdf, points).reshape(batch + (n,))
    if method == "multinomial":
        counts = rng.multinomial(n, flat)
        return counts_to_indices(counts).reshape(batch + (n,))
    scaled = n * flat
    # N w computed in floating point can land a few ulps under an integer (equal weights at N = 20, 49, 1000): round
    # such a value up, as exact arithmetic would, so equal weights copy each particle once with nothing drawn
    det = np.floor(scaled * (1.0 + _FLOOR_RTOL)).astype(np.int64)
    over = det.sum(axis=-1) > n                 # the tolerance never creates more than N offspring in a row
    if over.any():
        det[over] = np.floor(scaled[over]).astype(np.int64)
    rest = n - det.sum(axis=-1)
    resid = np.maximum(scaled - det, 0.0)
    total = resid.sum(axis=-1, keepdims=True)
    pvals = np.where(total > 0, resid / np.where(total > 0, total, 1.0), 1.0 / n)
    extra = rng.multinomial(rest, pvals)
    return counts_to_indices(det + extra).reshape(batch + (n,))


def resample_where(weights, rng: np.random.Generator, method: str = "systematic", *, threshold=None):
    """Resample only the rows whose effective sample size ``1 / sum w^2`` is below ``threshold`` (default: always,
    the SIR filter's every-step resampling). Returns ``(indices (..., N), resampled (...) bool)``; rows not
    resampled keep the identity indices (and the caller keeps their weights)."""
    w = _check_weights(weights)
    n = w.shape[-1]
    idx = resample(w, rng, method)
    if threshold is None:
        return idx, np.ones(w.shape[:-1], bool)
    do = effective_sample_size(w) < threshold
    return np.where(do[..., None], idx, np.arange(n)), do
