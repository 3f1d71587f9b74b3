"""Exceptions that name what is wrong with the input, so a notebook run stops with a clear message."""

__all__ = ["LocbookError", "DegenerateGeometryError", "ConvergenceError", "ParameterError"]


class LocbookError(Exception):
    """Base class for locbook's own errors."""


class DegenerateGeometryError(LocbookError, ValueError):
    """Anchors or calibration points that cannot determine the unknowns (collinear anchors,
    too few anchors, all calibration distances equal)."""


class ConvergenceError(LocbookError, RuntimeError):
    """A solver stopped without reaching an optimal solution."""


class ParameterError(LocbookError, ValueError):
    """A notebook parameter that does not exist, or a value of the wrong type."""
