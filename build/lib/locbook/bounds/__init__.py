"""Bounds: static CRLB and the posterior CRLB."""
