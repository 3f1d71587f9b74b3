"""Package data: the numbers each source document printed (``printed/<document>.csv``)."""
