"""Bounds: static CRLB and the posterior CRLB."""
from .._lazy import lazy_exports

__getattr__, __dir__ = lazy_exports(__name__, {   # submodules load on first access
    "MIN_ANCHORS_FOR_BOUND": "crlb", "MAX_BOUND_CONDITION": "crlb", "check_position_information": "crlb",
    "rss_crlb_checked_m": "crlb",
    "TRIM_FRACTION": "summary", "MIN_VALID_FRACTION": "summary", "MIN_VALID_EPOCHS": "summary",
    "BoundSummary": "summary", "summarize_bound": "summary", "error_bound_ratio": "summary",
})
