"""Static localization from ranges or received powers: the names of the former single module, re-exported.

The estimators now live along their seams (import from there in new code):

- :mod:`locbook.static.result`: :class:`LocalizationResult`, :data:`LOCALIZATION_STATUSES` (and the conventions the
  estimators share: shapes, statuses, failures);
- :mod:`locbook.static.checks`: :func:`check_anchor_geometry` (:data:`ANCHOR_CONDITION_RTOL`),
  :func:`implausible_powers` (:data:`IMPLAUSIBLE_SIGMAS`), :data:`GOODNESS_OF_FIT_ALPHA`, anchor heights;
- :mod:`locbook.static.missing`: missing readings (NaN = not heard);
- :mod:`locbook.static.lateration`: :func:`lateration_system`, :func:`lateration_ls`, :func:`lateration_wls`
  (:data:`LATERATION_PAIRS`, :data:`LATERATION_VARIANTS`);
- :mod:`locbook.static.box_ls`: :func:`lateration_box_ls` and its active-set solver (:data:`BOX_LS_SOLVERS`);
- :mod:`locbook.static.rss_ml`: :func:`rss_ml_position`;
- :mod:`locbook.static.grid_ml`: :func:`grid_ml_position` (:data:`GRID_ML_BLOCK_BYTES`);
- :mod:`locbook.static.rss_form`: the RSS estimators' call form (one RssModel; the form before issue 47).
"""
from .box_ls import BOX_LS_SOLVERS, lateration_box_ls
from .checks import (ANCHOR_CONDITION_RTOL, GOODNESS_OF_FIT_ALPHA, IMPLAUSIBLE_SIGMAS, check_anchor_geometry,
                     implausible_powers)
from .grid_ml import GRID_ML_BLOCK_BYTES, grid_ml_position
from .lateration import LATERATION_PAIRS, LATERATION_VARIANTS, lateration_ls, lateration_system, lateration_wls
from .result import LOCALIZATION_STATUSES, LocalizationResult
from .rss_ml import rss_ml_position

__all__ = [
    "LocalizationResult",
    "check_anchor_geometry",
    "lateration_system",
    "lateration_ls",
    "lateration_wls",
    "lateration_box_ls",
    "LATERATION_PAIRS",
    "LATERATION_VARIANTS",
    "BOX_LS_SOLVERS",
    "ANCHOR_CONDITION_RTOL",
    "rss_ml_position",
    "grid_ml_position",
    "GRID_ML_BLOCK_BYTES",
    "LOCALIZATION_STATUSES",
    "IMPLAUSIBLE_SIGMAS",
    "implausible_powers",
    "GOODNESS_OF_FIT_ALPHA",
]
