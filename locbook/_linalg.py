"""Linear-algebra helpers of the filters and models (internal): covariance checks with errors that name the argument,
batched small-matrix inverses and solves, the Joseph form, and the errors an update raises (module docstring of
:mod:`locbook.tracking.results`, "Batch isolation")."""
from __future__ import annotations

import numpy as np

from ._validate import as_array
from .errors import SingularCovarianceError

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


class _Singular(SingularCovarianceError):
    """Raised inside an update; the time loop turns it into a SingularCovarianceError naming the step. Raised out of
    a model called directly (no step to name), it is that error itself, its message without the step."""

    def __init__(self, bad, message: str = ""):
        super().__init__()
        self.bad = bad
        self.message = message      # "": the innovation covariance; else the text of the failure ({step} filled in)

    def __str__(self) -> str:
        text = self.message or ("the innovation covariance is singular, not positive definite or not finite")
        return text.replace(" at step {step}", "").replace("{step}", "?") + _first_bad(self.bad)


def _refuse_not_finite(name: str, values, bad, batch_ndim: int, step: int, what: str) -> None:
    """A ValueError naming the user function ``name``, the step and the first run when its output ``values`` is NaN or
    infinite at some entry of the mask ``bad`` (the runs: the first ``batch_ndim`` axes, the rest reduced): a function
    that fails is never taken for a missing reading or an overflow of the filter."""
    bad = np.asarray(bad)
    if not bad.any():
        return
    runs = bad.reshape(bad.shape[:batch_ndim] + (-1,)).any(axis=-1)
    first = tuple(int(i) for i in np.argwhere(bad)[0])
    kind = "NaN" if np.isnan(np.broadcast_to(values, bad.shape)[first]) else "an infinite value"
    raise ValueError(f"{name} returned {kind} at step {step}{_first_bad(runs)} (output index {first[batch_ndim:]}) "
                     f"{what}")


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



def _batch_shape(*named):
    """The broadcast batch shape of the arguments' leading axes ``(name, shape)``; an error naming them if none."""
    try:
        return np.broadcast_shapes(*(shape for _, shape in named))
    except ValueError:
        raise ValueError("the run (batch) axes of the arguments do not broadcast: " +
                         ", ".join(f"{name} {shape}" for name, shape in named if shape)) from None


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


_LOG_2PI = float(np.log(2.0 * np.pi))


def _logdet(S):
    """``log det S`` of a batch of symmetric positive definite matrices (closed form for 1 x 1 and 2 x 2, else
    LAPACK's ``slogdet``). A missing reading's row and column (zero H row, unit decoupled noise) add 0."""
    if S.shape[-1] == 1:
        return np.log(S[..., 0, 0])
    if S.shape[-1] == 2:
        return np.log(S[..., 0, 0] * S[..., 1, 1] - S[..., 0, 1] * S[..., 1, 0])
    return np.linalg.slogdet(S)[1]


def _gaussian_log_likelihood(nis, logdet, dof):
    """``log N(nu; 0, S) = -(nu^T S^{-1} nu + log det S + dof log 2 pi) / 2`` from its three parts (0 when dof = 0:
    no reading, the likelihood of nothing is 1)."""
    return -0.5 * (nis + logdet + dof * _LOG_2PI)


def psd_root(name: str, cov) -> np.ndarray:
    """A factor ``L`` ``(..., n, k)`` with ``cov = L L^T`` from the eigen-decomposition, so that a singular
    (positive semi-definite) covariance is fine; only the directions of positive variance are kept. A covariance that
    is not symmetric positive semi-definite is refused naming ``name``."""
    w, v = np.linalg.eigh(cov)
    scale = np.max(np.abs(w), initial=0.0)
    if np.any(w < -1e-9 * max(scale, 1e-300)) or not np.allclose(cov, np.swapaxes(cov, -1, -2), rtol=0,
                                                                   atol=1e-12 * max(scale, 1e-300)):
        raise ValueError(f"{name} must be symmetric positive semi-definite, its smallest eigenvalue is {w.min()}")
    keep = np.any(w > 4 * w.shape[-1] * np.finfo(float).eps * scale, axis=tuple(range(w.ndim - 1)))
    return v[..., keep] * np.sqrt(np.clip(w[..., keep], 0.0, None))[..., None, :]


def _location_information(gain, gradient, heard=None):
    """The Fisher information ``sum_j w_j g_j g_j^T`` ``(..., d, d)`` of independent Gaussian readings about a
    location, from each reading's weight ``gain`` ``(..., m)`` (``1 / sigma_j^2``) and gradient ``gradient``
    ``(..., m, d)``; ``heard``: booleans broadcastable to the weights, False where a reading is not there (its term
    is left out). The one form of the RSS and the range information."""
    if heard is not None:
        heard = np.asarray(heard)
        if heard.dtype != bool:
            raise ValueError(f"heard must be booleans (False = not heard), got dtype {heard.dtype}")
        try:
            gain = gain * np.broadcast_to(heard, gain.shape)
        except ValueError:
            raise ValueError(f"heard must broadcast to {gain.shape}, got shape {heard.shape}") from None
    return np.einsum("...j,...ji,...jk->...ik", gain, gradient, gradient)
