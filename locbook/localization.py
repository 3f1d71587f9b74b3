"""Static localization from ranges or received powers, batched over many problems.

Every estimator takes anchors ``(m, 2)`` shared by all problems and measurements with leading batch
axes ``(..., m)``, and returns a :class:`LocalizationResult` whose ``position_m`` has shape ``(..., 2)``.

- :func:`lateration_ls`: linearized least squares, Eq. (8) of George and Vadivukkarasi (document 003):
  subtracting the circle of a reference anchor r from circle i gives the linear system
  ``2 (a_r - a_i)^T p = d_i^2 - d_r^2 - |a_i|^2 + |a_r|^2``.
- :func:`lateration_wls`: the same system with weights.
- :func:`lateration_box_ls`: the same objective with a box constraint, one stacked cvxpy problem.
- :func:`rss_ml_position`: maximum likelihood in the RSS domain (Gaussian shadowing), i.e. Eq. (2.4) of
  Dogan (2015), solved by batched Levenberg-Marquardt from a convex (linear LS) initialiser.
- :func:`grid_ml_position`: exhaustive maximum likelihood over candidate points.
"""
from __future__ import annotations

from dataclasses import dataclass
from functools import lru_cache

import cvxpy as cp
import numpy as np

from ._cvx import solve
from .channel import PathLossModel, pairwise_distance_m
from .errors import ConvergenceError, DegenerateGeometryError

__all__ = [
    "LocalizationResult",
    "check_anchor_geometry",
    "lateration_system",
    "lateration_ls",
    "lateration_wls",
    "lateration_box_ls",
    "rss_ml_position",
    "grid_ml_position",
]


@dataclass(frozen=True)
class LocalizationResult:
    """Estimated positions ``(..., 2)`` with per-problem solver information."""

    position_m: np.ndarray
    converged: np.ndarray
    cost: np.ndarray | None
    n_iter: int
    method: str


def check_anchor_geometry(anchors_m) -> np.ndarray:
    """Validate anchors ``(m, dim)``: at least ``dim + 1`` anchors, not all on one line (plane).

    Raises :class:`DegenerateGeometryError` naming the problem.
    """
    anchors_m = np.asarray(anchors_m, dtype=float)
    if anchors_m.ndim != 2:
        raise ValueError(f"anchors must have shape (m, dim), got {anchors_m.shape}")
    m, dim = anchors_m.shape
    if m < dim + 1:
        raise DegenerateGeometryError(
            f"{dim}-D localization needs at least {dim + 1} anchors, got {m}"
        )
    centred = anchors_m - anchors_m.mean(axis=0)
    sv = np.linalg.svd(centred, compute_uv=False)
    if sv[dim - 1] <= 1e-9 * max(sv[0], 1.0):
        raise DegenerateGeometryError(
            f"the {m} anchors are collinear (rank {np.sum(sv > 1e-9 * max(sv[0], 1.0))} < {dim}); "
            "their position cannot be resolved across the line they lie on"
        )
    return anchors_m


def lateration_system(anchors_m, distance_m, ref_index: int = 0):
    """Matrices of the linearized lateration system ``A p = b`` (Eq. (8), document 003).

    Returns ``A`` of shape ``(m-1, dim)`` (``2 (a_r - a_i)``, rows for i != r) and ``b`` of shape
    ``(..., m-1)`` (``d_i^2 - d_r^2 - |a_i|^2 + |a_r|^2``).
    """
    anchors_m = check_anchor_geometry(anchors_m)
    distance_m = np.asarray(distance_m, dtype=float)
    m = anchors_m.shape[0]
    if distance_m.shape[-1] != m:
        raise ValueError(f"distances have {distance_m.shape[-1]} anchors on the last axis, anchors have {m}")
    if not -m <= ref_index < m:
        raise ValueError(f"ref_index {ref_index} out of range for {m} anchors")
    ref_index %= m
    others = np.array([i for i in range(m) if i != ref_index])
    a_r = anchors_m[ref_index]
    a_mat = 2.0 * (a_r - anchors_m[others])
    norms = np.sum(anchors_m**2, axis=1)
    b = (distance_m[..., others] ** 2 - distance_m[..., [ref_index]] ** 2
         - norms[others] + norms[ref_index])
    return a_mat, b


def lateration_ls(anchors_m, distance_m, ref_index: int = 0) -> LocalizationResult:
    """Linearized least squares ``p = (A^T A)^{-1} A^T b`` (Eq. (8), George and Vadivukkarasi).

    Unconstrained: estimates may leave the room, as the paper observes ("some of the results go
    beyond the boundaries"). The result depends slightly on ``ref_index`` (anchor 1 in the paper).
    """
    a_mat, b = lateration_system(anchors_m, distance_m, ref_index)
    pos = b @ np.linalg.pinv(a_mat).T
    ok = np.all(np.isfinite(pos), axis=-1)
    return LocalizationResult(pos, ok, None, 0, f"lateration_ls(ref={ref_index})")


def lateration_wls(anchors_m, distance_m, weights, ref_index: int = 0) -> LocalizationResult:
    """Weighted linearized least squares ``p = (A^T W A)^{-1} A^T W b`` with diagonal weights
    ``(..., m-1)`` (one per differenced equation), batched."""
    a_mat, b = lateration_system(anchors_m, distance_m, ref_index)
    w = np.broadcast_to(np.asarray(weights, dtype=float), b.shape)
    if np.any(w < 0):
        raise ValueError("weights must be non-negative")
    ata = np.einsum("ki,...k,kj->...ij", a_mat, w, a_mat)
    atb = np.einsum("ki,...k,...k->...i", a_mat, w, b)
    pos = np.linalg.solve(ata, atb[..., None])[..., 0]
    return LocalizationResult(pos, np.all(np.isfinite(pos), axis=-1), None, 0, "lateration_wls")


@lru_cache(maxsize=16)
def _box_problem(n_problems, a_key, lower, upper):
    a_mat = np.array(a_key)
    b = cp.Parameter((n_problems, a_mat.shape[0]), name="b")
    p = cp.Variable((n_problems, a_mat.shape[1]), name="position_m")
    constraints = [p >= np.array(lower), p <= np.array(upper)]
    problem = cp.Problem(cp.Minimize(cp.sum_squares(p @ a_mat.T - b)), constraints)
    return problem, b, p


def lateration_box_ls(anchors_m, distance_m, lower_m, upper_m, ref_index: int = 0) -> LocalizationResult:
    """Linearized least squares constrained to the box ``lower_m <= p <= upper_m``.

    All problems are stacked into one cvxpy QP, built once per (batch size, anchors, box) with the
    right-hand sides as a Parameter and re-solved by setting its value. An optional extension to
    document 003 (which does not constrain its estimates).
    """
    a_mat, b = lateration_system(anchors_m, distance_m, ref_index)
    batch = b.shape[:-1]
    k = int(np.prod(batch))
    lower = tuple(np.broadcast_to(np.asarray(lower_m, float), (a_mat.shape[1],)).tolist())
    upper = tuple(np.broadcast_to(np.asarray(upper_m, float), (a_mat.shape[1],)).tolist())
    if any(lo > hi for lo, hi in zip(lower, upper)):
        raise ValueError(f"empty box: lower {lower} > upper {upper}")
    problem, b_par, p_var = _box_problem(k, tuple(map(tuple, a_mat.tolist())), lower, upper)
    b_par.value = b.reshape(k, -1)
    solve(problem, "box-constrained lateration")
    pos = p_var.value.reshape(batch + (a_mat.shape[1],))
    return LocalizationResult(pos, np.ones(batch, bool), None, 0, "lateration_box_ls")


def _rss_residual_jacobian(pos, anchors, power, model: PathLossModel, min_distance_m):
    diff = pos[..., None, :] - anchors  # (..., m, 2)
    d2 = np.maximum(np.einsum("...i,...i->...", diff, diff), min_distance_m**2)
    d = np.sqrt(d2)
    resid = power - model.mean_power_dbm(d)  # (..., m)
    slope = 10.0 * np.asarray(model.path_loss_exp) / np.log(10.0)
    # d resid / d p = +10 n / ln10 * (p - a_j) / d_j^2
    jac = (np.broadcast_to(slope, d.shape) / d2)[..., None] * diff
    return resid, jac, d2


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


def _newton_matrix(resid, jac, d2, pos, anchors, model):
    """Hessian of 0.5 |r|^2: J^T J + sum_j r_j grad^2 r_j, with
    grad^2 r_j = c (I / d_j^2 - 2 (p - a_j)(p - a_j)^T / d_j^4), c = 10 n / ln 10. Falls back to the
    Gauss-Newton matrix J^T J where the full Hessian is not positive definite. The second-order
    term matters: shadowing leaves large residuals, where Gauss-Newton converges only linearly."""
    jtj = np.einsum("...ki,...kj->...ij", jac, jac)
    diff = pos[..., None, :] - anchors
    c = np.broadcast_to(10.0 * np.asarray(model.path_loss_exp) / np.log(10.0), d2.shape)
    eye = np.eye(pos.shape[-1])
    hr = c[..., None, None] * (eye / d2[..., None, None]
                                - 2.0 * diff[..., :, None] * diff[..., None, :] / (d2**2)[..., None, None])
    full = jtj + np.einsum("...k,...kij->...ij", resid, hr)
    eig_min = _min_eigenvalue(full)
    return np.where((eig_min > 1e-9 * np.trace(jtj, axis1=-2, axis2=-1))[..., None, None], full, jtj)


def rss_ml_position(anchors_m, power_dbm, model: PathLossModel, initial_m=None, *,
                    max_iter: int = 100, tol_m: float = 1e-7, min_distance_m: float = 1e-3,
                    raise_on_failure: bool = False) -> LocalizationResult:
    """Maximum-likelihood position from received powers ``(..., m)`` under Gaussian shadowing.

    Minimises ``sum_j (P_j - P_0 + 10 n log10 |p - a_j|)^2``, which equals Dogan's MLE cost (2.4)
    up to the factor ``(10 n)^{-2}`` (note 000, section 2.3). The problem is non-convex; every problem
    starts from ``initial_m`` or, by default, the linearized LS fix on the model's ranges (the convex
    initialiser), and is refined by damped Newton steps (Levenberg-Marquardt with the exact Hessian where it is
    positive definite), vectorized over the batch; each iteration works only on the problems that have not
    converged yet. Problems that do not converge in ``max_iter`` steps are flagged in ``converged``
    (or raise if asked). The model's parameters must be scalars or per-anchor ``(m,)`` arrays.
    """
    anchors_m = check_anchor_geometry(anchors_m)
    power_dbm = np.asarray(power_dbm, dtype=float)
    if initial_m is None:
        initial_m = lateration_ls(anchors_m, model.range_m(power_dbm)).position_m
    batch, dim = power_dbm.shape[:-1], anchors_m.shape[1]
    pos = np.array(np.broadcast_to(initial_m, batch + (dim,)), dtype=float).reshape(-1, dim)
    power = power_dbm.reshape(-1, power_dbm.shape[-1])
    resid, jac, d2 = _rss_residual_jacobian(pos, anchors_m, power, model, min_distance_m)
    cost = np.sum(resid**2, axis=-1)
    lam = np.full(cost.shape, 1e-3)
    converged = np.zeros(cost.shape, bool)
    eye = np.eye(dim)
    active = np.arange(cost.size)          # indices of problems still iterating
    it = 0
    for it in range(1, max_iter + 1):
        p_a, r_a, j_a, d2_a, c_a, l_a = (a[active] for a in (pos, resid, jac, d2, cost, lam))
        hess = _newton_matrix(r_a, j_a, d2_a, p_a, anchors_m, model)
        jtr = np.einsum("...ki,...k->...i", j_a, r_a)
        # damped step: (H + lam diag(H)) delta = -J^T r
        damp = l_a[:, None, None] * (eye * np.diagonal(hess, axis1=-2, axis2=-1)[:, None, :] + 1e-12 * eye)
        step = -_solve_small(hess + damp, jtr)
        trial = p_a + step
        r_new, j_new, d2_new = _rss_residual_jacobian(trial, anchors_m, power[active], model, min_distance_m)
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
    if raise_on_failure and not np.all(converged):
        raise ConvergenceError(
            f"RSS maximum likelihood: {int(np.sum(~converged))} of {converged.size} problems did not "
            f"converge in {max_iter} Levenberg-Marquardt iterations"
        )
    return LocalizationResult(pos.reshape(batch + (dim,)), converged.reshape(batch), cost.reshape(batch),
                              it, "rss_ml_lm")


def grid_ml_position(anchors_m, power_dbm, model: PathLossModel, grid_m, *,
                     chunk: int = 2048) -> LocalizationResult:
    """Grid maximum likelihood: the candidate point of ``grid_m`` ``(G, 2)`` with the smallest
    RSS-domain squared residual, for every problem; evaluated in chunks to bound memory."""
    anchors_m = check_anchor_geometry(anchors_m)
    grid_m = np.asarray(grid_m, dtype=float)
    power = np.asarray(power_dbm, dtype=float)
    batch = power.shape[:-1]
    flat = power.reshape(-1, power.shape[-1])
    mean_grid = model.mean_power_dbm(np.maximum(pairwise_distance_m(grid_m, anchors_m), 1e-6))  # (G, m)
    best = np.empty(flat.shape[0], dtype=int)
    best_cost = np.empty(flat.shape[0])
    for start in range(0, flat.shape[0], chunk):
        block = flat[start:start + chunk]
        # |P - mu_g|^2 = |P|^2 - 2 P.mu_g + |mu_g|^2; the first term does not change the argmin
        cost = (mean_grid**2).sum(1) - 2.0 * block @ mean_grid.T
        idx = np.argmin(cost, axis=1)
        best[start:start + chunk] = idx
        best_cost[start:start + chunk] = cost[np.arange(len(idx)), idx] + (block**2).sum(1)
    pos = grid_m[best].reshape(batch + (grid_m.shape[1],))
    return LocalizationResult(pos, np.ones(batch, bool), best_cost.reshape(batch), 0, "grid_ml")
