"""Per-document scenarios: the geometry, printed numbers and simulation protocol of each source."""
