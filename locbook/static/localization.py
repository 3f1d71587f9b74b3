"""Static localization from ranges or received powers: the names of the former single module, re-exported.

The estimators now live along their seams (import from there in new code):

- :mod:`locbook.static.result`: ``LocalizationResult``, ``LOCALIZATION_STATUSES`` (and the conventions the
  estimators share: shapes, statuses, failures);
- :mod:`locbook.static.checks`: ``check_anchor_geometry`` (``ANCHOR_CONDITION_RTOL``), ``implausible_powers``
  (``IMPLAUSIBLE_SIGMAS``), ``GOODNESS_OF_FIT_ALPHA``, anchor heights;
- :mod:`locbook.static.missing`: missing readings (NaN = not heard);
- :mod:`locbook.static.lateration`: ``lateration_system``, ``lateration_ls``, ``lateration_wls``
  (``LATERATION_PAIRS``, ``LATERATION_VARIANTS``);
- :mod:`locbook.static.box_ls`: ``lateration_box_ls`` and its active-set solver (``BOX_LS_SOLVERS``);
- :mod:`locbook.static.rss_ml`: ``rss_ml_position``;
- :mod:`locbook.static.grid_ml`: ``grid_ml_position`` (``GRID_ML_BLOCK_BYTES``);
- :mod:`locbook.static.rss_form`: the RSS estimators' call form (one RssModel; the earlier, deprecated form).
"""
from .box_ls import BOX_LS_SOLVERS, lateration_box_ls
from .checks import (
    ANCHOR_CONDITION_RTOL,
    GOODNESS_OF_FIT_ALPHA,
    IMPLAUSIBLE_SIGMAS,
    check_anchor_geometry,
    implausible_powers,
)
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
