"""The round-off and solver bounds the benchmarks' agreement checks use as tolerances (one home for them): each is a
bound from numerical analysis or from a solver's documented stopping rule, evaluated on the row's own inputs, never a
figure taken from our output."""
from __future__ import annotations

import numpy as np

EPS = np.finfo(float).eps
#: Clarabel's default tolerances (duality gap, absolute and relative; feasibility): cvxpy's default solve
CLARABEL_DEFAULT = {"tol_gap_abs": 1e-8, "tol_gap_rel": 1e-8, "tol_feas": 1e-8}
#: the library's stacked cvxpy solves (locbook._cvx)
LIBRARY_TIGHT = {"tol_gap_abs": 1e-10, "tol_gap_rel": 1e-10, "tol_feas": 1e-10}


def ls_round_off_m(H, Y, x):
    """A first-order bound on the round-off of a least-squares solution ``x`` ``(..., n)`` of ``H x = Y``
    ``(..., m, n)``, per problem: the perturbation bound of Golub & Van Loan (Thm. 5.3.1), ``|dx| <= delta (2 kappa /
    cos(theta) + kappa^2 tan(theta)) |x|``, at the backward error ``delta = m n eps`` of a stable solver, plus the
    ``delta kappa^2 |x|`` of the normal equations (``sin(theta) = |r| / |Y|``)."""
    m, n = H.shape[-2:]
    kappa = np.linalg.cond(H)
    fit = np.linalg.norm(np.einsum("...ij,...j->...i", H, x), axis=-1)
    r = np.linalg.norm(Y - np.einsum("...ij,...j->...i", H, x), axis=-1)
    cos_theta = fit / np.hypot(fit, r)
    return m * n * EPS * (2 * kappa / cos_theta + kappa**2 * (1 + r / fit)) * np.linalg.norm(x, axis=-1)


def solver_bound(lam_min, f, tol, scale):
    """How far a solution that Clarabel accepted can be from the exact optimum ``p*`` of ``min |A p - b|^2`` over a
    box: the objective exceeds its minimum by at least ``lambda_min(A^T A) |p - p*|^2`` (strong convexity, and the
    optimality condition at ``p*`` makes the linear term non-negative over the box), and the solver stops within
    the duality gap ``max(tol_gap_abs, tol_gap_rel f)`` of it (Clarabel's stopping rule), so ``|p - p*| <= sqrt(gap /
    lambda_min)``; plus the feasibility tolerance times the data's scale (the box may be violated by that much). ``f``:
    the objective whose relative gap the solver controls (the problem's own, or the sum of a stacked solve's)."""
    gap = np.maximum(tol["tol_gap_abs"], tol["tol_gap_rel"] * f)
    return np.sqrt(gap / lam_min) + tol["tol_feas"] * (1.0 + scale)


def sigma_sum_round_off(n: int, alpha: float, beta: float = 2.0, kappa: float = 0.0) -> float:
    """The relative rounding bound of one weighted sum over the ``N = 2n + 1`` sigma points, ``N eps sum_i |W_i|``
    (Higham, the error of a sum of N products), with the larger of the mean and covariance weights' sums (the scaled
    set: ``c = n + lambda = alpha^2 (n + kappa)``, ``W^0_m = 1 - n / c``, ``W^0_c = W^0_m + 1 - alpha^2 + beta``,
    ``W^i = 1 / (2c)``): about 7.5e-9 at alpha = 1e-3 and n = 8, where the weights are -1e6 and 6.25e4."""
    c = alpha**2 * (n + kappa)
    w0m = 1.0 - n / c
    weights = max(abs(w0m), abs(w0m + 1.0 - alpha**2 + beta)) + n / c
    return (2 * n + 1) * np.finfo(float).eps * weights
