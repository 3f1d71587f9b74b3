"""Floor geometry for measured data: point-in-outline tests, grids inside a floor outline, and distances to a
reference path made of straight segments (the usual scoring of a walk without per-sample ground truth)."""
from __future__ import annotations

import numpy as np
from matplotlib.path import Path as _PolygonPath

from ._validate import as_array, check_scalar

__all__ = ["inside_outline", "grid_in_outline", "outline_box", "box_outline", "distance_to_segments",
           "nearest_on_segments", "nearest_on_outline"]


def _outline(outline_m) -> np.ndarray:
    outline = as_array("outline_m", outline_m, ndim=2, trailing=(None, 2))
    if outline.shape[0] < 3:
        raise ValueError(f"outline_m needs at least 3 vertices, got {outline.shape[0]}")
    return outline


def inside_outline(points_m, outline_m, *, tolerance_m: float = 1e-9):
    """Whether each point ``(..., 2)`` lies inside the closed polygon ``outline_m (V, 2)`` (points on the boundary,
    within ``tolerance_m``, count as inside). NaN points are outside."""
    outline = _outline(outline_m)
    points = as_array("points_m", points_m, min_ndim=1, trailing=(2,), nan_ok=True)
    flat = points.reshape(-1, 2)
    finite = np.isfinite(flat).all(axis=1)
    polygon = _PolygonPath(np.vstack([outline, outline[:1]]), closed=True)
    # the sign of the radius that grows the polygon depends on its orientation: test both, keep the larger set
    inside = np.zeros(flat.shape[0], bool)
    if finite.any():
        grow = [polygon.contains_points(flat[finite], radius=r) for r in (tolerance_m, -tolerance_m)]
        inside[finite] = grow[0] | grow[1]
    return inside.reshape(points.shape[:-1])


def outline_box(outline_m) -> tuple[np.ndarray, np.ndarray]:
    """The outline's bounding box ``(lower (2,), upper (2,))``."""
    outline = _outline(outline_m)
    return outline.min(axis=0), outline.max(axis=0)


def box_outline(lower_m, upper_m) -> np.ndarray:
    """The rectangle with corners ``lower_m`` and ``upper_m`` ``(2,)`` as an outline ``(4, 2)``, counter-clockwise
    from the lower corner (the inverse of :func:`outline_box` for a rectangle)."""
    lower = as_array("lower_m", lower_m, ndim=1, trailing=(2,))
    upper = as_array("upper_m", upper_m, ndim=1, trailing=(2,))
    if np.any(upper <= lower):
        raise ValueError(f"upper_m {upper.tolist()} must exceed lower_m {lower.tolist()} on both axes")
    (x0, y0), (x1, y1) = lower, upper
    return np.array([[x0, y0], [x1, y0], [x1, y1], [x0, y1]], float)


def grid_in_outline(outline_m, spacing_m: float) -> np.ndarray:
    """Cell centres ``(C, 2)`` of a square lattice of pitch ``spacing_m`` over the outline's bounding box (the first
    centre half a pitch from its lower corner), kept where they lie inside the outline; row-major in y then x."""
    check_scalar("spacing_m", spacing_m, gt=0)
    lower, upper = outline_box(outline_m)
    xs = np.arange(lower[0] + spacing_m / 2, upper[0], spacing_m)
    ys = np.arange(lower[1] + spacing_m / 2, upper[1], spacing_m)
    cells = np.stack(np.meshgrid(xs, ys), axis=-1).reshape(-1, 2)
    cells = cells[inside_outline(cells, outline_m)]
    if cells.shape[0] == 0:
        raise ValueError(f"no cell of pitch {spacing_m} m lies inside the outline")
    return cells


def nearest_on_segments(points_m, segments_m):
    """``(nearest (..., 2), distance (...))``: the nearest point of the straight segments ``(S, 2, 2)``
    (``[[x0, y0], [x1, y1]]`` each) to each point ``(..., 2)``, and its distance. NaN points give NaN."""
    segments = as_array("segments_m", segments_m, ndim=3, trailing=(None, 2, 2))
    points = as_array("points_m", points_m, min_ndim=1, trailing=(2,), nan_ok=True)
    a, b = segments[:, 0], segments[:, 1]
    ab = b - a
    length2 = np.einsum("si,si->s", ab, ab)
    rel = points[..., None, :] - a                                     # (..., S, 2)
    with np.errstate(invalid="ignore", divide="ignore"):
        t = np.where(length2 > 0, np.einsum("...si,si->...s", rel, ab) / np.where(length2 > 0, length2, 1.0), 0.0)
    t = np.clip(t, 0.0, 1.0)
    nearest = a + t[..., None] * ab
    gap = np.linalg.norm(points[..., None, :] - nearest, axis=-1)
    best = np.argmin(np.where(np.isnan(gap), np.inf, gap), axis=-1)
    point = np.take_along_axis(nearest, best[..., None, None], axis=-2)[..., 0, :]
    return np.where(np.isnan(points), np.nan, point), np.min(gap, axis=-1)


def distance_to_segments(points_m, segments_m):
    """Distance ``(...)`` from each point ``(..., 2)`` to the nearest of the straight segments ``(S, 2, 2)``
    (``[[x0, y0], [x1, y1]]`` each). NaN points give NaN."""
    return nearest_on_segments(points_m, segments_m)[1]


def nearest_on_outline(points_m, outline_m) -> np.ndarray:
    """The nearest point ``(..., 2)`` of the outline's boundary (its closed polygon ``(V, 2)``) to each point."""
    outline = _outline(outline_m)
    return nearest_on_segments(points_m, np.stack([outline, np.roll(outline, -1, axis=0)], axis=1))[0]
