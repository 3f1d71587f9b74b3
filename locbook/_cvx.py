"""One place for how locbook solves its cvxpy problems, and for importing cvxpy.

cvxpy is imported on first use (``cp`` below), not with locbook: the exact solvers are the defaults, and the
import costs every notebook kernel about a second at start-up.
"""
from __future__ import annotations

import importlib

from .errors import ConvergenceError


class _LazyCvxpy:
    """``cp.Variable`` etc.: the cvxpy module, imported when an attribute is first asked for."""

    def __getattr__(self, name):
        return getattr(importlib.import_module("cvxpy"), name)


cp = _LazyCvxpy()

# Stacked problems sum thousands of independent objectives; Clarabel's default gap tolerances are
# relative to that sum, which leaves about 1e-3 m per problem. These keep each problem near 1e-6.
_CLARABEL_TIGHT = {"tol_gap_abs": 1e-10, "tol_gap_rel": 1e-10, "tol_feas": 1e-10, "tol_ktratio": 1e-8}


def solve(problem: cp.Problem, what: str) -> None:
    """Solve with Clarabel at tight tolerances; raise :class:`ConvergenceError` naming ``what``."""
    # the SciPy canonicalisation backend handles matrix-variable products the C++ one lacks
    problem.solve(solver=cp.CLARABEL, canon_backend=cp.SCIPY_CANON_BACKEND, **_CLARABEL_TIGHT)
    if problem.status != cp.OPTIMAL:
        raise ConvergenceError(f"{what}: cvxpy (Clarabel) finished with status {problem.status!r}")
