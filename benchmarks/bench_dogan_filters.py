"""Time one Dogan (2015) table setting with locbook's batched EKF and with a per-run filterpy loop.

    python benchmarks/bench_dogan_filters.py [--runs 500] [--filterpy-runs 50] [--filter serial_ekf]

One setting = Table 3.8's first row (sigma_RSS = 6 dB, alpha = 3, the tables' sigma_ACC, RSS/IMU fusion) on the default
trajectory at 20 Hz under the default fusion reading (start from rest, Q and P_0 from sigma_ACC, scenarios/dogan.py): ``runs`` Monte-Carlo runs in one vectorized call, against filterpy's
ExtendedKalmanFilter looped over runs and steps on the same inputs (a subset of ``filterpy-runs`` runs, scaled to
the full count). Prints both times, their ratio, and the largest state difference on the common runs.
"""
import argparse
import time

import numpy as np
from filterpy.kalman import ExtendedKalmanFilter

import locbook as lb
from locbook.scenarios import dogan as dg


def filterpy_track(model, channel, rss_grid, acc, x0, P0, serial, sigma_acc):
    """filterpy per run: predict, accelerometer update, RSS update(s) at RSS epochs (Table 3.5)."""
    idx, a = model.position_index, dg.ANCHORS_M
    h_acc, r_acc = model.derivative_measurement_matrix(2), sigma_acc**2 * np.eye(2)
    p0, ple, s2 = channel.ref_power_dbm, channel.path_loss_exp, channel.sigma_db**2

    def hx(x, j):
        return p0 - 10 * ple * np.log10(np.linalg.norm(x[idx] - a[j], axis=-1))

    def jac(x, j):
        j = np.atleast_1d(j)
        diff = x[idx] - a[j]
        out = np.zeros((len(j), 6))
        out[:, idx] = -10 * ple / np.log(10) * diff / np.sum(diff**2, axis=1, keepdims=True)
        return out

    out = np.empty(rss_grid.shape[:2] + (6,))
    for b in range(rss_grid.shape[0]):
        f = ExtendedKalmanFilter(6, 1)
        f.x, f.P, f.F, f.Q = x0[b].copy(), P0[b].copy(), model.F, model.Q
        for k in range(rss_grid.shape[1]):
            f.predict()
            f.update(acc[b, k], lambda x: h_acc, lambda x: h_acc @ x, R=r_acc)
            z = rss_grid[b, k]
            if np.isfinite(z[0]):
                if serial:
                    for j in np.argsort(-z):
                        f.update(z[j:j + 1], lambda x, j=j: jac(x, j), lambda x, j=j: np.atleast_1d(hx(x, j)),
                                 R=np.array([[s2]]))
                else:
                    f.update(z, lambda x: jac(x, np.arange(4)), lambda x: hx(x, np.arange(4)), R=s2 * np.eye(4))
            out[b, k] = f.x
    return out


def main():
    ap = argparse.ArgumentParser()
    ap.add_argument("--runs", type=int, default=500)
    ap.add_argument("--filterpy-runs", type=int, default=50)
    ap.add_argument("--filter", choices=["serial_ekf", "parallel_ekf"], default="serial_ekf")
    args = ap.parse_args()
    tr = dg.polyline_trajectory()
    sigma_acc = dg.TABLE_SIGMA_ACC_MPS2
    q, p0_acc = dg.filter_noise(dg.DEFAULT_NOISE_READING, sigma_acc)
    model = dg.motion_model(dg.DT_S, q)
    rng = np.random.default_rng(1)
    channel = lb.PathLossModel(dg.REF_POWER_DBM, dg.PATH_LOSS_EXP, dg.SIGMA_RSS_DB)
    rss = dg.simulate_rss(tr, channel, args.runs, rng)
    acc = dg.simulate_acceleration(tr, sigma_acc, args.runs, rng)
    t = time.perf_counter()
    fix = dg.mle_positions(rss, channel).position_m
    t_mle = time.perf_counter() - t
    mse = np.mean((fix - tr.position_m[tr.rss_steps]) ** 2, axis=(0, 1))
    t = time.perf_counter()
    ours = dg.run_filter(args.filter, tr, rss, fix, mse, channel, acc_mps2=acc, sigma_acc_mps2=sigma_acc, model=model,
                         p0_acc_var=p0_acc)
    t_ours = time.perf_counter() - t
    # the same inputs for filterpy: the RSS on the grid after step 0, the accelerometer from step 1
    n = args.filterpy_runs
    grid = np.full((n, tr.time_s.size - 1, 4), np.nan)
    grid[:, tr.rss_steps[1:] - 1] = rss[:n, 1:]
    x0, P0 = dg.initial_state(fix[:n, 0], np.broadcast_to(mse, (n, 2)), acc_var=p0_acc)
    t = time.perf_counter()
    ref = filterpy_track(model, channel, grid, acc[:n, 1:], x0, P0, args.filter == "serial_ekf", sigma_acc)
    t_ref = (time.perf_counter() - t) * args.runs / n
    diff = np.max(np.abs(ours.x[:n, 1:] - ref[:, tr.rss_steps[1:] - 1]))
    print(f"setting: Table 3.8, sigma_RSS 6 dB, fused {args.filter}, {args.runs} runs x {tr.time_s.size} steps")
    print(f"MLE (grid + LM, {args.runs} x {tr.rss_steps.size} problems): {t_mle:.2f} s")
    print(f"locbook batched {args.filter}: {t_ours:.2f} s")
    print(f"filterpy per-run loop: {t_ref:.1f} s (measured on {n} runs, scaled to {args.runs})")
    print(f"ratio filterpy / locbook: {t_ref / t_ours:.0f}x; max |state difference| on common runs: {diff:.1e}")


if __name__ == "__main__":
    main()
