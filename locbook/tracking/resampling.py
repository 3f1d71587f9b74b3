"""Particle resampling schemes, vectorized over leading axes (Douc, Cappe and Moulines 2005; Arulampalam et al.
2002, Alg. 2 for systematic resampling).

Every scheme returns ancestor indices ``(..., M)`` whose expected counts are ``M w_j`` (unbiased); they differ in
variance: multinomial > stratified > systematic in general, residual in between. ``M = n_out`` is the number of
particles drawn, ``N`` (the number given) by default; any other ``M`` resamples to a different count (up- or
down-sampling, Stone Soup's ``nparts``): the same schemes with the sample points spaced ``1 / M`` (systematic,
stratified), ``M`` draws (multinomial), ``floor(M w_j)`` copies plus ``M - sum floor(M w)`` drawn from the residuals
(residual; Douc, Cappe and Moulines 2005, Sec. 2.2 with ``N`` replaced by ``M``).

Weights may be given as unnormalised log-weights (``log_weights=True``, the form a particle filter accumulates):
they are normalised as ``w_j = exp(l_j - max_k l_k) / sum_i exp(l_i - max_k l_k)`` (log-sum-exp), which neither
overflows nor underflows to an all-zero row; ``-inf`` is a zero weight. ``N_eff``-triggered resampling (resample
only where ``N_eff < threshold``) is :func:`resample_where`.
"""
from __future__ import annotations

import numpy as np

from .._deprecation import keyword_rng
from .._validate import as_array, check_choice, check_scalar

__all__ = ["RESAMPLING_METHODS", "RESAMPLING_CDFS", "resample", "systematic_resample", "counts_to_indices",
           "resample_where", "effective_sample_size"]

RESAMPLING_METHODS = ("systematic", "stratified", "multinomial", "residual")
#: the cumulative sums of :func:`systematic_resample`: the standard one and Table 4.2 of Ozkaya (2011) as printed
RESAMPLING_CDFS = ("standard", "literal_ozkaya2011")

#: relative round-off allowed in ``N w`` before the residual scheme's floor (normalising N weights and scaling by N
#: err by a few ulps; 64 ulps is far below any weight difference that matters)
_FLOOR_RTOL = 64 * np.finfo(float).eps


def _check_weights(weights, log_weights: bool = False) -> np.ndarray:
    if log_weights:
        return _weights_from_log(weights)
    w = as_array("weights", weights, min_ndim=1)
    if w.shape[-1] == 0 or np.any(w < 0) or np.any(w.sum(axis=-1) <= 0):
        raise ValueError(f"weights must be non-negative with a positive sum in every row, got shape {w.shape}")
    return w / w.sum(axis=-1, keepdims=True)


def _weights_from_log(log_weights) -> np.ndarray:
    """Normalised weights ``(..., N)`` from unnormalised log-weights by log-sum-exp (module docstring): ``-inf`` is a
    zero weight; a row that is ``-inf`` everywhere (no weight at all), or holds NaN or ``+inf``, is an error naming
    that row."""
    try:
        lw = np.asarray(log_weights, dtype=float)
    except (TypeError, ValueError) as exc:
        raise ValueError(f"weights (log-weights) must be numeric, got {type(log_weights).__name__}: {exc}") from None
    if lw.ndim < 1 or lw.shape[-1] == 0:
        raise ValueError(f"weights (log-weights) must have at least one particle per row, got shape {lw.shape}")
    bad = np.isnan(lw) | (lw == np.inf)
    if bad.any():
        row = tuple(int(i) for i in np.argwhere(bad)[0][:-1])
        raise ValueError(f"weights (log-weights) must be finite or -inf (a zero weight); row {row} holds "
                         f"{int(bad[row].sum())} NaN or +inf value(s), the first at particle "
                         f"{int(np.argmax(bad[row]))}")
    top = lw.max(axis=-1, keepdims=True)
    empty = np.isneginf(top[..., 0])
    if empty.any():
        row = tuple(int(i) for i in np.argwhere(empty)[0])
        raise ValueError(f"weights (log-weights) row {row} is -inf for every particle: no weight to resample from "
                         f"({int(empty.sum())} such row(s))")
    w = np.exp(lw - top)
    return w / w.sum(axis=-1, keepdims=True)


def _n_out(n_out, n: int) -> int:
    if n_out is None:
        return n
    return int(check_scalar("n_out", n_out, ge=1, integer=True))


def effective_sample_size(weights):
    """``N_eff = 1 / sum_j w_j^2`` of normalised weights along the last axis (Ozkaya 2011, Eq. (4.28); Arulampalam
    et al. 2002, Eq. (51)). Every filter of locbook triggers resampling on ``N_eff`` below a fraction of ``N``."""
    weights = as_array("weights", weights, min_ndim=1)
    if weights.shape[-1] == 0:              # 1 / 0 = inf would be a confident answer from no weights
        raise ValueError(f"weights must hold at least one weight along the last axis, got shape {weights.shape}")
    return 1.0 / np.einsum("...n,...n->...", weights, weights)


def _search_rows(cdf, points):
    """Row-wise ``searchsorted(cdf_r, points_r, side="left")`` for ``(B, N)`` arrays with values in [0, 1], in one
    call (row r is shifted by 2r so the rows do not overlap)."""
    n_rows, n = cdf.shape
    offset = 2.0 * np.arange(n_rows)[:, None]
    idx = np.searchsorted((cdf + offset).ravel(), (points + offset).ravel(), side="left").reshape(points.shape)
    return np.minimum(idx - n * np.arange(n_rows)[:, None], n - 1)


def systematic_resample(weights, uniforms, cdf: str = "standard", *, n_out: int | None = None,
                        log_weights: bool = False):
    """Systematic resampling (Ozkaya 2011, Table 4.2; Arulampalam et al. 2002, Alg. 2) of every row of
    ``weights (..., N)``.

    ``uniforms (...)`` are the single draws ``u_1 ~ U[0, 1)``, scaled here to ``U[0, 1/M)``; the sample
    points are ``u_i = (u_1 + i - 1) / M``, ``i = 1..M`` (``M = n_out``, default ``N``) and particle ``j`` is copied
    for each ``u_i`` with ``c_j-1 < u_i <= c_j``. ``cdf="standard"`` uses ``c_j = w_1 + ... + w_j``. The table
    prints ``c_1 = 0``, ``c_j = c_j-1 + w_j``, which drops ``w_1`` and shifts every particle's interval; that is
    kept as the flagged ``"literal_ozkaya2011"`` (indices beyond the last particle are clipped to it).
    ``log_weights=True``: ``weights`` are unnormalised log-weights (module docstring).
    Returns integer indices ``(..., M)``.
    """
    check_choice("cdf", cdf, RESAMPLING_CDFS)
    if log_weights:
        weights = _weights_from_log(weights)
    else:
        weights = as_array("weights", weights, min_ndim=1)
    batch, n = weights.shape[:-1], weights.shape[-1]
    if n == 0 or np.any(weights < 0) or np.any(weights.sum(axis=-1) <= 0):
        raise ValueError(f"weights must be non-negative with a positive sum in every row, got shape {weights.shape}")
    m = _n_out(n_out, n)
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
    u = (uniforms_arr.reshape(-1, 1) + np.arange(m)) / m
    return _search_rows(c, u).reshape(batch + (m,))


def counts_to_indices(counts, *, n_out: int | None = None):
    """Offspring counts ``(..., N)`` (non-negative integers summing to ``n_out`` per row, default N) -> sorted
    ancestor indices ``(..., n_out)``."""
    counts = np.asarray(counts)
    batch, n = counts.shape[:-1], counts.shape[-1]
    m = _n_out(n_out, n)
    c = np.cumsum(counts.reshape(-1, n), axis=-1).astype(float)
    if np.any(c[:, -1] != m):
        raise ValueError("offspring counts must sum to the number of particles in every row" if n_out is None else
                         f"offspring counts must sum to n_out = {m} in every row")
    # ancestor of slot i: the first j with cumsum_j > i (scaled to [0, 1] for the row-wise search)
    return _search_rows(c / m, np.broadcast_to((np.arange(m) + 0.5) / m, (c.shape[0], m))).reshape(batch + (m,))


@keyword_rng(1, "method")
def resample(weights, *, rng: np.random.Generator, method: str = "systematic", n_out: int | None = None,
             log_weights: bool = False):
    """Ancestor indices ``(..., M)`` for every row of ``weights (..., N)`` (normalised here), ``M = n_out``
    (default ``N``: the same draws, bit for bit, as without it).

    - ``"systematic"``: one uniform per row, points ``(u + i) / M`` (:func:`systematic_resample`);
    - ``"stratified"``: one uniform per stratum, points ``(u_i + i) / M``;
    - ``"multinomial"``: M independent draws from the weights;
    - ``"residual"``: ``floor(M w_j)`` copies of each particle, the remaining ``M - sum floor(M w)`` drawn
      multinomially from the residual weights (``M w_j`` within 64 ulps under an integer counts as that integer, so
      equal weights are resampled deterministically, as by filterpy and Stone Soup).

    These are Stone Soup's ``SystematicResampler``, ``StratifiedResampler``, ``MultinomialResampler`` and
    ``ResidualResampler`` (``nparts = n_out``; its residual scheme keeps ``M = N``) up to the order of the cumulative
    sum: Stone Soup sums the weights sorted ascending, locbook in the particles' order. ``log_weights=True``:
    ``weights`` are unnormalised log-weights (``-inf`` = zero weight; module docstring). ``rng`` and ``method`` are
    keyword-only (the positional form ``resample(weights, rng, method)`` is deprecated, for one release).
    """
    check_choice("method", method, RESAMPLING_METHODS)
    if not isinstance(rng, np.random.Generator):
        raise ValueError(f"rng must be a numpy.random.Generator, got {type(rng).__name__}")
    w = _check_weights(weights, log_weights)
    batch, n = w.shape[:-1], w.shape[-1]
    m = _n_out(n_out, n)
    if method == "systematic":
        return systematic_resample(w, rng.random(batch), n_out=m)
    flat = w.reshape(-1, n)
    if method == "stratified":
        cdf = np.cumsum(flat, axis=-1)
        cdf[:, -1] = 1.0
        points = (np.arange(m) + rng.random((flat.shape[0], m))) / m
        return _search_rows(cdf, points).reshape(batch + (m,))
    if method == "multinomial":
        counts = rng.multinomial(m, flat)
        return counts_to_indices(counts, n_out=m).reshape(batch + (m,))
    scaled = m * flat
    # N w computed in floating point can land a few ulps under an integer (equal weights at N = 20, 49, 1000): round
    # such a value up, as exact arithmetic would, so equal weights copy each particle once with nothing drawn
    det = np.floor(scaled * (1.0 + _FLOOR_RTOL)).astype(np.int64)
    over = det.sum(axis=-1) > m                 # the tolerance never creates more than M offspring in a row
    if over.any():
        det[over] = np.floor(scaled[over]).astype(np.int64)
    rest = m - det.sum(axis=-1)
    resid = np.maximum(scaled - det, 0.0)
    total = resid.sum(axis=-1, keepdims=True)
    pvals = np.where(total > 0, resid / np.where(total > 0, total, 1.0), 1.0 / n)
    extra = rng.multinomial(rest, pvals)
    return counts_to_indices(det + extra, n_out=m).reshape(batch + (m,))


@keyword_rng(1, "method")
def resample_where(weights, *, rng: np.random.Generator, method: str = "systematic", threshold=None,
                   log_weights: bool = False):
    """Resample only the rows whose effective sample size ``1 / sum w^2`` is below ``threshold`` (default: always,
    the SIR filter's every-step resampling). Returns ``(indices (..., N), resampled (...) bool)``; rows not
    resampled keep the identity indices (and the caller keeps their weights). ``log_weights``, ``rng`` and ``method``
    (keyword-only): as in :func:`resample`."""
    w = _check_weights(weights, log_weights)
    n = w.shape[-1]
    idx = resample(w, rng=rng, method=method)
    if threshold is None:
        return idx, np.ones(w.shape[:-1], bool)
    do = effective_sample_size(w) < threshold
    return np.where(do[..., None], idx, np.arange(n)), do
