"""Time Gudipati's fusion UKF over many Monte-Carlo runs of the U-path with locbook's batched UKF and with a per-run
filterpy UnscentedKalmanFilter loop on the same inputs.

    python benchmarks/bench_ukf_speed.py [--runs 1000] [--filterpy-runs 10] [--alpha 1e-3]

The 8-D constant-acceleration + heading model, 6 anchors, the inertial stream (body frame) then the RSS stream at
every 0.1 s step (scenarios/gudipati.py defaults, shadowing 1.45 dB). filterpy runs a subset, scaled to the full count;
both results are compared on the common runs.
"""
import argparse
import time
from dataclasses import replace

import numpy as np
from filterpy.kalman import MerweScaledSigmaPoints, UnscentedKalmanFilter

import locbook as lb
from locbook.scenarios import gudipati as gu


def main():
    ap = argparse.ArgumentParser()
    ap.add_argument("--runs", type=int, default=1000)
    ap.add_argument("--filterpy-runs", type=int, default=10)
    ap.add_argument("--alpha", type=float, default=1e-3)
    args = ap.parse_args()
    s = replace(gu.WalkSettings(), shadowing_sigma_db=1.45)
    w = gu.simulate_walk("u", 6, s, args.runs, np.random.default_rng(0))
    model = lb.HeadingKinematicModel(s.dt_s, s.q, s.q_angular)
    x0, P0 = gu._initial(w, model, 8)
    imu, rss = gu._imu_stream(w, False), gu._rss_stream(w, model)
    T = w.truth.time_s.size
    t0 = time.perf_counter()
    ours = lb.unscented_kalman_filter(model.F, model.Q, x0, P0, [imu, rss], alpha=args.alpha, beta=2.0, kappa=0.0)
    t_ours = time.perf_counter() - t0
    a, ch = w.anchors_m, rss.channel
    points = MerweScaledSigmaPoints(8, alpha=args.alpha, beta=2.0, kappa=0.0)

    def h_rss(x):
        return ch.mean_power_dbm(np.linalg.norm(x[:2] - a, axis=1))

    h_imu = lb.inertial_measurement_function("body")
    r_rss = ch.sigma_db**2 * np.eye(a.shape[0])
    z_imu = np.concatenate([w.acc_m_s2, w.gyro_rad_s[..., None]], axis=-1)
    n_fp = min(args.filterpy_runs, args.runs)
    t0 = time.perf_counter()
    diff = 0.0
    compared = 0
    for r in range(n_fp):
        complete = bool(np.isfinite(w.rss_dbm[r]).all())      # filterpy has no partial (missing-reading) update
        compared += complete
        f = UnscentedKalmanFilter(8, 3, s.dt_s, h_imu, lambda x, dt: model.F @ x, points)
        f.x, f.P, f.Q = x0.copy(), P0.copy(), model.Q
        for k in range(T):
            f.predict()
            f.sigmas_f = points.sigma_points(f.x, f.P)
            f.update(z_imu[r, k], R=imu.R, hx=h_imu)
            f.sigmas_f = points.sigma_points(f.x, f.P)
            zr = w.rss_dbm[r, k]
            if np.all(np.isfinite(zr)):
                f.update(zr, R=r_rss, hx=h_rss)
            if complete:
                diff = max(diff, float(np.abs(f.x - ours.x[r, k]).max()))
    t_fp = (time.perf_counter() - t0) * args.runs / n_fp
    print(f"U-path, {T} steps, alpha = {args.alpha:g}: locbook {args.runs} runs in one call {t_ours:.1f} s; "
          f"filterpy per-run loop {t_fp:.1f} s (scaled from {n_fp} runs); ratio x{t_fp / t_ours:.0f}; "
          f"largest state difference {diff:.1e} over the {compared} filterpy runs that heard every packet")


if __name__ == "__main__":
    main()
