"""Time Gudipati's fusion UKF over many Monte-Carlo runs of the U-path with locbook's batched UKF and with a per-run
filterpy UnscentedKalmanFilter loop on the same inputs.

    python benchmarks/bench_ukf_speed.py [--runs 1000] [--filterpy-runs 5] [--alpha 1e-3] [--size tiny]

The 8-D constant-acceleration + heading model, 6 anchors, the inertial stream (body frame) then the RSS stream at
every 0.1 s step (scenarios/gudipati.py defaults, shadowing 1.45 dB; the issue-7 setting). filterpy runs a subset,
scaled to the full count; a step with some RSS readings missing updates filterpy with the anchors heard (reduced h
and R, locbook's rule for missing readings), so every run is compared. At the thesis's alpha = 1e-3 the sigma-point
weights are -1e6 and 6e4 and two correct implementations differ by round-off amplified to about 1e-8; at alpha = 0.5
or 1 they agree to about 1e-13.
"""
from __future__ import annotations

import argparse
import sys
from dataclasses import replace
from pathlib import Path

import numpy as np
from filterpy.kalman import MerweScaledSigmaPoints, UnscentedKalmanFilter

sys.path.insert(0, str(Path(__file__).resolve().parent))
import _harness as hx  # noqa: E402

import locbook as lb  # noqa: E402
from locbook.scenarios import gudipati as gu  # noqa: E402


def setting(runs: int, steps: int | None = None, seed: int = 0) -> dict:
    """The U-path walk of ``runs`` Monte-Carlo runs (the first ``steps`` steps, default all) and the UKF's inputs."""
    s = replace(gu.WalkSettings(), shadowing_sigma_db=1.45)
    w = gu.simulate_walk("u", 6, s, runs, np.random.default_rng(seed))
    model = lb.HeadingKinematicModel(s.dt_s, s.q, s.q_angular)
    x0, P0 = gu._initial(w, model, 8)
    imu, rss = gu._imu_stream(w, False), gu._rss_stream(w, model)
    if steps is not None:
        imu = replace(imu, z=np.asarray(imu.z)[:, :steps])
        rss = replace(rss, rss_dbm=np.asarray(rss.rss_dbm)[:, :steps])
    return dict(settings=s, model=model, x0=x0, P0=P0, imu=imu, rss=rss, anchors=w.anchors_m)


def locbook_ukf(st: dict, alpha: float):
    m = st["model"]
    return lb.unscented_kalman_filter(m.F, m.Q, st["x0"], st["P0"], [st["imu"], st["rss"]], alpha=alpha, beta=2.0,
                                      kappa=0.0)


def filterpy_ukf(st: dict, runs: int, alpha: float):
    """filterpy's UnscentedKalmanFilter per run, sigma points redrawn around the current estimate before each update
    (Gudipati Eq. (3.18)): the inertial update, then the RSS update with the anchors heard. States and covariances at
    every step, ``(runs, T, 8)`` and ``(runs, T, 8, 8)``."""
    model, imu, rss, a = st["model"], st["imu"], st["rss"], st["anchors"]
    ch = rss.channel
    points = MerweScaledSigmaPoints(8, alpha=alpha, beta=2.0, kappa=0.0)
    h_imu = imu.h
    z_imu, z_rss = np.asarray(imu.z), np.asarray(rss.rss_dbm)
    p0 = np.broadcast_to(ch.ref_power_dbm, a.shape[:1])
    ple = np.broadcast_to(ch.path_loss_exp, a.shape[:1])
    T = z_imu.shape[1]
    xs, Ps = np.empty((runs, T, 8)), np.empty((runs, T, 8, 8))
    for r in range(runs):
        f = UnscentedKalmanFilter(8, 3, st["settings"].dt_s, h_imu, lambda x, dt: model.F @ x, points)
        f.x, f.P, f.Q = st["x0"].copy(), st["P0"].copy(), model.Q
        for k in range(T):
            f.predict()
            f.sigmas_f = points.sigma_points(f.x, f.P)
            f.update(z_imu[r, k], R=imu.R, hx=h_imu)
            zr = z_rss[r, k]
            heard = np.isfinite(zr)
            if heard.any():
                f.sigmas_f = points.sigma_points(f.x, f.P)
                ah, p0h, pleh = a[heard], p0[heard], ple[heard]

                def h_rss(x, ah=ah, p0h=p0h, pleh=pleh):
                    d = np.maximum(np.linalg.norm(x[:2] - ah, axis=1), ch.min_distance_m)
                    return p0h - 10 * pleh * np.log10(d / ch.ref_distance_m)
                f.update(zr[heard], R=ch.sigma_db**2 * np.eye(int(heard.sum())), hx=h_rss)
            xs[r, k], Ps[r, k] = f.x, f.P
    return xs, Ps


def measure(runs: int = 1000, filterpy_runs: int = 5, alphas=(1e-3,), steps: int | None = None,
            repeat: int = 1) -> list[dict]:
    st = setting(runs, steps)
    T = np.shape(st["imu"].z)[1]
    n = min(filterpy_runs, runs)
    rows = []
    for alpha in alphas:
        t_ref, cpu_ref, (ref_x, ref_P) = hx.timed(lambda: filterpy_ukf(st, n, alpha))
        t, cpu, ours = hx.timed(lambda: locbook_ukf(st, alpha), repeat)
        peak = hx.peak_mb(lambda: locbook_ukf(st, alpha))
        dx = float(np.max(np.abs(ours.x[:n] - ref_x)))
        dP = float(np.max(np.abs(ours.P[:n] - ref_P)))
        scale = runs / n
        rows.append(hx.row(f"UKF (inertial + RSS), alpha = {alpha:g}", f"U-path, {runs} runs x {T} steps", t,
                           "filterpy per-run loop" + ("" if n == runs else f" ({n} runs, scaled)"), t_ref * scale,
                           peak, f"max |x - filterpy| {dx:.1e}, |P - filterpy| {dP:.1e} on {n} runs; "
                                 f"{ours.floored_updates} floored updates; CPU-time ratio x{cpu_ref * scale / cpu:.0f}"))
    return rows


def run(size: str = "full") -> list[dict]:
    """The benchmark protocol (benchmarks/run_all.py): full = 1000 runs x 1164 steps at alpha 1e-3 (filterpy on 5 runs)
    and 200 runs at alpha 0.5; tiny = 6 runs x 60 steps (filterpy on 2)."""
    if hx.check_size(size) == "tiny":
        return measure(runs=6, filterpy_runs=2, alphas=(1e-3, 0.5), steps=60)
    return measure() + measure(runs=200, filterpy_runs=3, alphas=(0.5,))


def main():
    ap = argparse.ArgumentParser()
    ap.add_argument("--runs", type=int, default=1000)
    ap.add_argument("--filterpy-runs", type=int, default=5)
    ap.add_argument("--alpha", type=float, default=1e-3)
    ap.add_argument("--steps", type=int, default=None, help="the first STEPS steps of the walk (default all)")
    ap.add_argument("--size", choices=hx.SIZES, default=None, help="the run(size) preset instead of --runs")
    args = ap.parse_args()
    rows = run(args.size) if args.size else measure(args.runs, args.filterpy_runs, (args.alpha,), args.steps)
    hx.print_rows(rows)


if __name__ == "__main__":
    main()
