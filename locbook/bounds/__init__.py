"""Bounds: static CRLB and the posterior CRLB."""
from .._lazy import lazy_exports

__getattr__, __dir__ = lazy_exports(__name__, {})   # submodules load on first access
