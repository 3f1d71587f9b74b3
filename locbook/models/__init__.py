"""Models: the channel, the one RSS measurement model, motion, trajectories and inertial sensors."""
from .._lazy import lazy_exports

__getattr__, __dir__ = lazy_exports(__name__, {})   # submodules load on first access
