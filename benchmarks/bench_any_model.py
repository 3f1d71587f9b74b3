"""Time the issue-30 paths of the Kalman family against a per-run filterpy loop on the same inputs: a time-varying
linear model with a control input (F, Q, H, R per step), the RTS smoother on it, and a UKF with nonlinear motion and
its unscented RTS smoother.

    python benchmarks/bench_any_model.py [full|tiny]

- time-varying KF: ``kalman_filter(per_step(F), per_step(Q), ..., LinearMeasurement(z, per_step(H), per_step(R)),
  B=B, u=u)`` on every run at once (the covariance recursion is the same in every run, so it runs once per step)
  against filterpy's ``KalmanFilter.batch_filter(zs, Fs, Qs, Hs, Rs, Bs, us)`` per run;
- RTS smoother: the same filter recording its predictions and cross-covariances, then ``rts_smoother``, against
  filterpy's ``batch_filter`` + ``rts_smoother(Xs, Ps, Fs, Qs)`` per run (no control input here: filterpy's smoother
  leaves B u out of its prediction);
- UKF with nonlinear motion (a unicycle, ranges to three anchors) and its unscented RTS smoother against filterpy's
  ``UnscentedKalmanFilter`` predict/update loop + its ``rts_smoother`` per run.

filterpy runs a subset of the runs, scaled to the full count; the two alternate in one process (``hx.compare``) and
the differences to filterpy on that subset come from the same calls. Tolerance: round-off, 1e-9 of the largest |x|
(|P|) entry, at least 1e-9 (the same arithmetic in another order; the filterpy comparisons of the tests); beyond it
the row is a disagreement.
"""
from __future__ import annotations

import gc
import sys
from pathlib import Path

import numpy as np
from filterpy.kalman import KalmanFilter, MerweScaledSigmaPoints, UnscentedKalmanFilter

sys.path.insert(0, str(Path(__file__).resolve().parent))
import _harness as hx  # noqa: E402
import locbook as lb  # noqa: E402


def _spd(rng, shape, n, scale):
    A = rng.normal(size=shape + (n, n))
    return scale * (A @ np.swapaxes(A, -1, -2) / n + 0.3 * np.eye(n))


def linear_setting(runs: int, T: int, seed: int = 0) -> dict:
    rng = np.random.default_rng(seed)
    n, m, p = 4, 2, 1
    return dict(Fs=np.eye(n) + 0.05 * rng.normal(size=(T, n, n)), Qs=_spd(rng, (T,), n, 0.05),
                Hs=rng.normal(size=(T, m, n)), Rs=_spd(rng, (T,), m, 0.5), B=rng.normal(size=(n, p)),
                u=rng.normal(size=(runs, T, p)), z=rng.normal(size=(runs, T, m)), x0=np.zeros(n), P0=np.eye(n))


def locbook_tv(st, smooth: bool):
    meas = lb.LinearMeasurement(st["z"], lb.per_step(st["Hs"]), lb.per_step(st["Rs"]))
    runs = st["z"].shape[0]
    x0 = np.broadcast_to(st["x0"], (runs, st["x0"].size))
    if not smooth:
        return lb.kalman_filter(lb.per_step(st["Fs"]), lb.per_step(st["Qs"]), x0, st["P0"], meas, B=st["B"],
                                u=st["u"], divergence_window=0)
    run = lb.kalman_filter(lb.per_step(st["Fs"]), lb.per_step(st["Qs"]), x0, st["P0"], meas,
                           outputs=("x_pred", "P_pred", "P_cross"), divergence_window=0)
    return lb.rts_smoother(run)


def filterpy_tv(st, runs: int, smooth: bool):
    Fs, Qs, Hs, Rs = list(st["Fs"]), list(st["Qs"]), list(st["Hs"]), list(st["Rs"])
    T, n = st["z"].shape[1], st["x0"].size
    xs, Ps = np.empty((runs, T, n)), np.empty((runs, T, n, n))
    for r in range(runs):
        kf = KalmanFilter(dim_x=n, dim_z=st["z"].shape[-1], dim_u=st["u"].shape[-1])
        kf.x, kf.P = st["x0"].copy(), st["P0"].copy()
        if smooth:
            mu, cov, _, _ = kf.batch_filter(list(st["z"][r]), Fs=Fs, Qs=Qs, Hs=Hs, Rs=Rs)
            xs[r], Ps[r], _, _ = kf.rts_smoother(mu, cov, Fs=Fs, Qs=Qs)
        else:
            xs[r], Ps[r], _, _ = kf.batch_filter(list(st["z"][r]), Fs=Fs, Qs=Qs, Hs=Hs, Rs=Rs,
                                                 Bs=[st["B"]] * T, us=list(st["u"][r]))
    return xs, Ps


DT = 0.5
ANCHORS = np.array([[0.0, 0.0], [20.0, 0.0], [0.0, 20.0]])


def _unicycle(x):
    out = np.array(x, dtype=float, copy=True)
    out[..., 0] += DT * x[..., 3] * np.cos(x[..., 2])
    out[..., 1] += DT * x[..., 3] * np.sin(x[..., 2])
    return out


def _ranges(x):
    return np.linalg.norm(x[..., None, :2] - ANCHORS, axis=-1)


def unicycle_setting(runs: int, T: int, seed: int = 1) -> dict:
    rng = np.random.default_rng(seed)
    state = np.broadcast_to([5.0, 5.0, 0.3, 1.0], (runs, 4)).copy()
    truth = np.empty((runs, T, 4))
    for k in range(T):
        state = _unicycle(state)
        state[:, 2] += rng.normal(0, 0.05, runs)
        truth[:, k] = state
    z = _ranges(truth) + rng.normal(0, 0.3, (runs, T, 3))
    return dict(z=z, Q=np.diag([0.01, 0.01, 0.01, 0.02]), R=0.09 * np.eye(3), x0=np.array([5.0, 5.0, 0.3, 1.0]),
                P0=np.diag([1.0, 1.0, 0.1, 0.1]))


def locbook_ukf(st):
    runs = st["z"].shape[0]
    run = lb.unscented_kalman_filter(lb.NonlinearMotion(_unicycle), st["Q"], np.broadcast_to(st["x0"], (runs, 4)),
                                     st["P0"], lb.NonlinearMeasurement(st["z"], _ranges, st["R"]), alpha=0.5,
                                     outputs=("x_pred", "P_pred", "P_cross"), divergence_window=0)
    return lb.rts_smoother(run)


def filterpy_ukf(st, runs: int):
    T = st["z"].shape[1]
    xs, Ps = np.empty((runs, T, 4)), np.empty((runs, T, 4, 4))
    for r in range(runs):
        ukf = UnscentedKalmanFilter(4, 3, DT, _ranges, lambda x, dt: _unicycle(x),
                                    MerweScaledSigmaPoints(4, alpha=0.5, beta=2.0, kappa=0.0))
        ukf.x, ukf.P, ukf.Q, ukf.R = st["x0"].copy(), st["P0"].copy(), st["Q"], st["R"]
        mu, cov = np.empty((T, 4)), np.empty((T, 4, 4))
        for k in range(T):
            ukf.predict()
            ukf.update(st["z"][r, k])
            mu[k], cov[k] = ukf.x, ukf.P
        xs[r], Ps[r], _ = ukf.rts_smoother(mu, cov)
    return xs, Ps


def _head(result, n: int):
    """Copies of the first ``n`` runs' means and covariances: all the agreement check needs (the harness keeps every
    call's result, so the full arrays are dropped inside the timed call rather than held over the repeats)."""
    return result.mean[:n].copy(), result.cov[:n].copy()


#: the same arithmetic in another order: round-off, relative to the largest entry (at least 1), as the filterpy
#: comparisons of tests/tracking/test_compiled_equality.py (the UKF here has alpha = 0.5, weights -3 and 0.5 for n = 4:
#: no amplification of the round-off)
TOL = 1e-9


def _agree(ours, ref) -> str:
    (x, P), (rx, rP) = ours, ref
    dx, dP = float(np.max(np.abs(x - rx))), float(np.max(np.abs(P - rP)))
    tx, tP = TOL * max(1.0, float(np.max(np.abs(rx)))), TOL * max(1.0, float(np.max(np.abs(rP))))
    if not (dx <= tx and dP <= tP):
        raise AssertionError(f"max |x - filterpy| {dx:.1e} (tolerance {tx:.1e}), |P - filterpy| {dP:.1e} "
                             f"(tolerance {tP:.1e}): beyond round-off ({TOL:g} of the largest entry)")
    return f"max |x - filterpy| {dx:.1e}, |P - filterpy| {dP:.1e} (tolerance {TOL:g} of the largest entry)"


def measure(runs: int, T: int, filterpy_runs: int, ukf_runs: int, ukf_T: int, ukf_filterpy_runs: int,
            repeats: int = hx.MIN_REPEATS):
    """Rows as each comparison finishes: locbook on every run against filterpy on the first ``filterpy_runs``
    (scaled by runs / filterpy_runs), alternated ``repeats`` times; agreement on those runs, from the same calls."""
    locbook_tv(linear_setting(2, 5), False)     # compiled kernels (numba) compiled or loaded from their cache
    locbook_tv(linear_setting(2, 5), True)      # before the timed calls
    locbook_ukf(unicycle_setting(2, 5))
    st = linear_setting(runs, T)
    n = min(filterpy_runs, runs)
    gc.collect()
    gc.freeze()     # the imported modules' objects out of the collector: the harness collects before every call
    for smooth, method in ((False, "time-varying KF (F, Q, H, R per step, control B u)"),
                           (True, "time-varying KF + RTS smoother")):
        m = hx.compare(lambda: _head(locbook_tv(st, smooth), n), lambda: filterpy_tv(st, n, smooth),
                       repeats=repeats, reference_scale=runs / n, agree=_agree)
        yield hx.row(method, f"{runs} runs x {T} steps, n = 4, m = 2", m,
                     "filterpy per-run loop" + ("" if n == runs else f" ({n} of {runs} runs, scaled)"))
    st = unicycle_setting(ukf_runs, ukf_T)
    n = min(ukf_filterpy_runs, ukf_runs)
    m = hx.compare(lambda: _head(locbook_ukf(st), n), lambda: filterpy_ukf(st, n), repeats=repeats,
                   reference_scale=ukf_runs / n, agree=_agree)
    yield hx.row("UKF, nonlinear motion + unscented RTS smoother", f"unicycle, {ukf_runs} runs x {ukf_T} steps", m,
                 "filterpy per-run loop" + ("" if n == ukf_runs else f" ({n} of {ukf_runs} runs, scaled)"))


def run(size: str = "full"):
    """full: 500 runs x 500 steps (filterpy on 5), UKF 250 runs x 200 steps (filterpy on 3), about 25 s with the
    repeats; tiny: a few runs. (The first figures were 2000 runs and 1000 UKF runs, timed once: reduced to fit the
    suite's time budget with 5 alternated repeats; the work is per run, so the ratio hardly depends on the count.)"""
    if hx.check_size(size) == "tiny":
        return measure(runs=20, T=30, filterpy_runs=3, ukf_runs=10, ukf_T=20, ukf_filterpy_runs=2)
    return measure(runs=500, T=500, filterpy_runs=5, ukf_runs=250, ukf_T=200, ukf_filterpy_runs=3)


if __name__ == "__main__":
    hx.print_rows(run(sys.argv[1] if len(sys.argv) > 1 else "full"))
