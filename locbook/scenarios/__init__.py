"""Per-document scenarios: the geometry, printed numbers and simulation protocol of each source.

The scenario functions that run a Kalman-family filter report the NIS guard's flags over runs as described in
:mod:`locbook.tracking.divergence` (``with_divergence=True``).
"""
