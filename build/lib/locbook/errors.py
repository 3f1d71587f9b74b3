"""Exceptions that name what is wrong with the input, so a notebook run stops with a clear message."""

__all__ = ["LocbookError", "DegenerateGeometryError", "ConvergenceError", "ParameterError", "SingularCovarianceError"]


class LocbookError(Exception):
    """Base class for locbook's own errors."""


class DegenerateGeometryError(LocbookError, ValueError):
    """Anchors or calibration points that cannot determine the unknowns (collinear anchors,
    too few anchors, all calibration distances equal)."""


class ConvergenceError(LocbookError, RuntimeError):
    """A solver stopped without reaching an optimal solution."""


class ParameterError(LocbookError, ValueError):
    """A notebook parameter that does not exist, or a value of the wrong type."""


class SingularCovarianceError(LocbookError, ArithmeticError):
    """A filter's innovation covariance ``S = H P H^T + R`` is singular or not positive definite at some step
    (e.g. a zero measurement noise with a zero prior covariance). The message names the step and the first
    affected run; the filter never continues with NaN."""
