"""The result of every static estimator, :class:`LocalizationResult`, and its statuses.

The estimators (lateration: :mod:`locbook.static.lateration`; box LS: :mod:`locbook.static.box_ls`; RSS maximum
likelihood: :mod:`locbook.static.rss_ml`; grid maximum likelihood: :mod:`locbook.static.grid_ml`; range NLS:
:mod:`locbook.static.ranging`) share one convention. They take anchors ``(m, dim)`` shared by all problems and
measurements with leading batch axes ``(..., m)``, and return a :class:`LocalizationResult` whose ``position_m`` has
shape ``(..., dim)``. The distance-based lateration family takes ``(anchors_m, distance_m, ...)``; the RSS estimators
take the readings first, then the one RSS measurement model, :class:`locbook.RssModel` (its anchors, channel and tag
height), then keyword-only options.

Failures are per problem: a problem the solver fails on, or whose finite readings overflow the arithmetic (ranges
whose squares are infinite), gets NaN and ``status="solver_failed"``; no estimator raises for its batch (except
:func:`~locbook.static.rss_ml.rss_ml_position` when asked to, ``raise_on_failure=True``). Infinite readings, and
non-finite anchors, model parameters, grids, boxes and weights, are rejected with a ``ValueError`` naming the
argument; so are shapes that do not match (nothing is broadcast silently). Missing readings (NaN = not heard):
:mod:`locbook.static.missing`; anchor heights (``tag_height_m``): :func:`locbook.static.checks.plan_anchors`.
"""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np

__all__ = ["LocalizationResult", "LOCALIZATION_STATUSES"]   # status_array serves the estimators

#: values of :attr:`LocalizationResult.status`
LOCALIZATION_STATUSES = ("ok", "too_few_anchors", "degenerate_geometry", "solver_failed", "not_converged",
                         "implausible_reading", "poor_fit")

@dataclass(frozen=True)
class LocalizationResult:
    """Estimated positions ``(..., dim)`` with per-problem solver information.

    ``converged`` is True only for a problem whose estimate is what the method promises. ``status`` (same
    batch shape) says why not: one of :data:`LOCALIZATION_STATUSES`:

    - ``"ok"``: converged;
    - ``"too_few_anchors"``: fewer than ``min_anchors`` anchors heard (:mod:`locbook.static.missing`);
    - ``"degenerate_geometry"``: the anchors the problem uses are collinear or coincide (for
      :func:`~locbook.static.lateration.lateration_wls` also: the anchors with a positive weight);
    - ``"solver_failed"``: the solver did not reach an optimum, or the arithmetic did not give a finite
      estimate (e.g. ranges so large that their squares overflow, or no finite start for the iterations);
    - ``"not_converged"``: the iteration limit was reached (the last iterate is returned);
    - ``"implausible_reading"`` (RSS estimators): a heard power more than
      :data:`~locbook.static.checks.IMPLAUSIBLE_SIGMAS` shadowing standard deviations above the model's mean at the
      estimator's near-field clamp, e.g. +500 dBm or 1e300 dBm (:func:`~locbook.static.checks.implausible_powers`):
      a reading implying a tag closer than 1 mm (the RSS ML's default clamp) to an anchor's antenna is taken as
      implausible;
    - ``"poor_fit"`` (RSS estimators, model with ``sigma_db > 0``): converged, but the readings do not fit the model
      together: the minimised cost over the shadowing variance exceeds the chi-square bound of
      :data:`~locbook.static.checks.GOODNESS_OF_FIT_ALPHA` with ``m_heard - dim`` degrees of freedom (e.g. four equal
      powers of +100 dBm around a 10 m square). The position (the ML answer for those readings) and
      ``converged=True`` are kept.

    ``converged`` is never True with an infinite or NaN ``cost``.

    Problems with any status but ``"ok"``, ``"not_converged"`` and ``"poor_fit"`` have a NaN position. ``cost`` is
    NaN where no cost was evaluated.
    """

    position_m: np.ndarray
    converged: np.ndarray
    cost: np.ndarray | None
    n_iter: int
    method: str
    status: np.ndarray | None = None

    def __post_init__(self):
        if self.status is None:
            object.__setattr__(self, "status", np.where(self.converged, "ok", "not_converged").astype("<U19"))


def status_array(ok: np.ndarray, failure: str = "solver_failed") -> np.ndarray:
    """Per-problem status: ``"ok"`` where ``ok``, else ``failure``."""
    return np.where(ok, "ok", failure).astype("<U19")

