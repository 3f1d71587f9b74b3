"""Channel, motion (and later inertial) models."""
