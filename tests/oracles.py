"""The reference loop of the filter tests: filterpy's KalmanFilter run over a batch of runs, one filter per run, and
filterpy's RTS smoother over its output. Imported by name (``from oracles import ...``) like builders.py.

filterpy is an independent implementation (its own predict / update / smoother code), so a locbook filter that equals
these loops equals filterpy; tests whose loop checks something at every step (filterpy's ``y``, ``S``, a singular
prior) or runs an EKF / UKF with a scenario's own functions keep their loops."""
from __future__ import annotations

import numpy as np

#: the arguments of :func:`filterpy_kalman` that may carry a leading run axis (``per_run``)
RUN_ARGUMENTS = ("F", "Q", "H", "R", "x0", "P0")


def filterpy_kalman(F, Q, H, R, z, x0, P0, *, per_run=(), components=False, predict_first=True):
    """filterpy's KalmanFilter over every run of ``z`` (``(runs, steps, m)``; ``(steps, m)`` is one run): predict, then
    update with the step's reading, at every step (``predict_first=False``: update, then predict for the next step).

    A step whose reading has a NaN is a prediction only; with ``components=True`` it updates with the components
    present instead (``H`` and ``R`` reduced to those rows), and only a step with none is a prediction only.
    ``per_run`` names the arguments (of :data:`RUN_ARGUMENTS`) that carry a leading run axis; the others are shared.
    Returns the filtered means ``(runs, steps, n)`` and covariances ``(runs, steps, n, n)`` (without the run axis for
    one run)."""
    from filterpy.kalman import KalmanFilter
    unknown = set(per_run) - set(RUN_ARGUMENTS)
    if unknown:
        raise ValueError(f"per_run names no argument: {sorted(unknown)}")
    z = np.asarray(z, dtype=float)
    one_run = z.ndim == 2
    zs = z[None] if one_run else z
    given = {"F": F, "Q": Q, "H": H, "R": R, "x0": x0, "P0": P0}
    n = np.shape(x0)[-1]
    means = np.empty(zs.shape[:2] + (n,))
    covs = np.empty(zs.shape[:2] + (n, n))
    for b in range(zs.shape[0]):
        a = {k: np.asarray(v[b] if k in per_run else v, dtype=float) for k, v in given.items()}
        kf = KalmanFilter(dim_x=n, dim_z=zs.shape[-1])
        kf.F, kf.Q, kf.H, kf.R, kf.x, kf.P = a["F"], a["Q"], a["H"], a["R"], a["x0"].copy(), a["P0"].copy()
        for k, zk in enumerate(zs[b]):
            if predict_first:
                kf.predict()
            keep = np.isfinite(zk)
            if keep.all():
                kf.update(zk)
            elif components and keep.any():
                kf.update(zk[keep], R=a["R"][np.ix_(keep, keep)], H=a["H"][keep])
            means[b, k], covs[b, k] = kf.x, kf.P
            if not predict_first:
                kf.predict()
    return (means[0], covs[0]) if one_run else (means, covs)


def filterpy_rts(F, Q, means, covs):
    """filterpy's RTS smoother (``KalmanFilter.rts_smoother``) over each run of filtered ``means`` ``(runs, steps,
    n)`` and ``covs``: the smoothed means, covariances and the smoother gains (filterpy's, one per step, the last
    zero)."""
    from filterpy.kalman import KalmanFilter
    means, covs = np.asarray(means, dtype=float), np.asarray(covs, dtype=float)
    n = means.shape[-1]
    xs, Ps, Ks = np.empty_like(means), np.empty_like(covs), np.empty_like(covs)
    for b in range(means.shape[0]):
        kf = KalmanFilter(dim_x=n, dim_z=1)
        xs[b], Ps[b], Ks[b], _ = kf.rts_smoother(means[b], covs[b], Fs=[F] * means.shape[1], Qs=[Q] * means.shape[1])
    return xs, Ps, Ks
