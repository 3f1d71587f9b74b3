"""Data: measured data sets and their loader (``measured.py``, ``measured/``), and the numbers each source printed
(package data ``printed/<document>.csv``, read by :mod:`locbook.reproduce.printed_values`)."""
from .._lazy import lazy_exports

__getattr__, __dir__ = lazy_exports(__name__, {})   # submodules load on first access
