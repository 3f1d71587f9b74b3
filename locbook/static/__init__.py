"""Static localization: lateration, RSS maximum likelihood, fingerprinting, calibration."""
from .._lazy import lazy_exports

__getattr__, __dir__ = lazy_exports(__name__, {})   # submodules load on first access
