"""Measurement fusion of two independent estimates of the same quantity (Gudipati 2017, Sec. 4.3):

    z = z_1 + R_1 (R_1 + R_2)^{-1} (z_2 - z_1)        (4.8)
    R = (R_1^{-1} + R_2^{-1})^{-1}                      (4.9)

the covariance-weighted (minimum-variance) combination, which equals ``R (R_1^{-1} z_1 + R_2^{-1} z_2)``.

The thesis applies (4.8) to the RSS powers ``Z^1`` (N values) and the inertial readings ``Z^2`` (accelerations and
rates), which are different quantities of different sizes, so it cannot be applied literally (our finding; the
section's title, "Fusing the Position Estimates", supports the first interpretation). Two interpretations are
implemented and labelled:

- ``"position"``: fuse two 2-D position estimates (the RSS trilateration fix and the inertial dead-reckoned
  position) with :func:`fuse_estimates`, and give the fused position to a KF/EKF/UKF as a position measurement;
- ``"stacked"``: give the filter the RSS and inertial measurements as streams of the same step (their noises
  are independent, so sequential updates are the stacked update ``z = [Z^1; Z^2]``, ``R = blkdiag(R_1, R_2)``;
  exactly for a KF, to the linearisation point for an EKF/UKF).
"""
from __future__ import annotations

import numpy as np

from .._deprecation import renamed_constants
from .._validate import as_array

__all__ = ["FUSION_INTERPRETATIONS", "fuse_estimates"]

FUSION_INTERPRETATIONS = ("position", "stacked")
# the name before "reading" meant only a sensor measurement (deprecated for one release)
__getattr__ = renamed_constants(__name__, {"FUSION_READINGS": ("FUSION_INTERPRETATIONS", FUSION_INTERPRETATIONS)})


def fuse_estimates(z1, R1, z2, R2):
    """Eqs. (4.8)-(4.9): the fused estimate ``(..., d)`` and covariance ``(..., d, d)`` of two independent
    estimates ``z1``, ``z2`` ``(..., d)`` with covariances ``R1``, ``R2`` ``(..., d, d)`` (positive definite).

    Missing estimates (any NaN component) follow the library's rule: where ``z1`` is missing the result is
    ``(z2, R2)``, where ``z2`` is missing ``(z1, R1)``, and where both are missing NaN."""
    z1 = as_array("z1", z1, min_ndim=1, nan_ok=True)
    z2 = as_array("z2", z2, min_ndim=1, nan_ok=True)
    d = z1.shape[-1]
    R1 = as_array("R1", R1, min_ndim=2, trailing=(d, d))
    R2 = as_array("R2", R2, min_ndim=2, trailing=(d, d))
    if z2.shape[-1] != d:
        raise ValueError(f"z1 and z2 must estimate the same quantity: {d} and {z2.shape[-1]} components")
    has1 = np.all(np.isfinite(z1), axis=-1)
    has2 = np.all(np.isfinite(z2), axis=-1)
    a = np.where(has1[..., None], z1, 0.0)
    b = np.where(has2[..., None], z2, 0.0)
    both = R1 + R2
    try:
        gain = np.swapaxes(np.linalg.solve(both, np.swapaxes(R1, -1, -2)), -1, -2)     # R1 (R1 + R2)^{-1}
    except np.linalg.LinAlgError:
        raise ValueError("R1 + R2 is singular: the two estimates' covariances must be positive definite") from None
    z = a + (gain @ (b - a)[..., None])[..., 0]
    R = R1 - gain @ R1                      # = (R1^-1 + R2^-1)^-1, without inverting R1 or R2
    R = 0.5 * (R + np.swapaxes(R, -1, -2))
    shape = np.broadcast_shapes(z.shape, np.shape(has1) + (d,), np.shape(has2) + (d,))
    z = np.broadcast_to(z, shape)
    R = np.broadcast_to(R, shape + (d,))
    h1, h2 = np.broadcast_to(has1, shape[:-1]), np.broadcast_to(has2, shape[:-1])
    z = np.where((h1 & h2)[..., None], z, np.where(h1[..., None], a, np.where(h2[..., None], b, np.nan)))
    R1b, R2b = np.broadcast_to(R1, R.shape), np.broadcast_to(R2, R.shape)
    R = np.where((h1 & h2)[..., None, None], R, np.where(h1[..., None, None], R1b,
                                                          np.where(h2[..., None, None], R2b, np.nan)))
    return z, R
