"""Static localization: lateration, RSS maximum likelihood, fingerprinting, calibration."""
