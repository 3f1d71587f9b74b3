"""Time one Dogan (2015) table setting with locbook's batched KF and EKFs and with per-run filterpy loops.

    python benchmarks/bench_dogan_filters.py [--runs 500] [--filterpy-runs 20] [--filter serial_ekf ...] [--size tiny]

One setting = Table 3.8's first row (sigma_RSS = 6 dB, alpha = 3, the tables' sigma_ACC, RSS/IMU fusion) on the default
trajectory at 20 Hz under the default fusion reading (start from rest, Q and P_0 from sigma_ACC, scenarios/dogan.py):
``runs`` Monte-Carlo runs of 1620 steps in one vectorized call, against filterpy's KalmanFilter (KF (MLE)) or
ExtendedKalmanFilter (parallel and serial EKF) looped over runs and steps on the same inputs (a subset of
``filterpy-runs`` runs, scaled to the full count), paired and alternated (benchmarks/_harness.py). Reports both times
(CPU and wall), their ratios and the largest state and covariance difference on the common runs, at 500 runs and at
10 runs (the issue's two batch sizes). locbook's EKFs run compiled (the default); the serial EKF is also timed on the
numpy loop (``LOCBOOK_NUMBA=0``).
"""
from __future__ import annotations

import argparse
import sys
from pathlib import Path

import numpy as np
from filterpy.kalman import ExtendedKalmanFilter, KalmanFilter

sys.path.insert(0, str(Path(__file__).resolve().parent))
import _harness as hx  # noqa: E402
import locbook as lb  # noqa: E402
from locbook.scenarios import dogan as dg  # noqa: E402
from locbook.tracking import _compiled  # noqa: E402

FILTERS = ("kalman_filter", "parallel_ekf", "serial_ekf")
LABELS = {"kalman_filter": "KF (MLE fixes + accelerometer)", "parallel_ekf": "parallel EKF (RSS + accelerometer)",
          "serial_ekf": "serial EKF (RSS + accelerometer)"}


def setting(runs: int, seed: int = 1, steps: int | None = None) -> dict:
    """The inputs of the timed setting: trajectory (its first ``steps`` steps, default all 1620), channel, RSS at the
    epochs, accelerometer, MLE fixes and their MSE."""
    tr = dg.walk_trajectory()
    if steps is not None:
        tr = tr.head(steps)
    sigma_acc = dg.TABLE_SIGMA_ACC_MPS2
    q, p0_acc = dg.filter_noise(dg.DEFAULT_NOISE_INTERPRETATION, sigma_acc)
    model = dg.motion_model(dg.DT_S, q)
    rng = np.random.default_rng(seed)
    channel = lb.PathLossModel(dg.REF_POWER_DBM, dg.PATH_LOSS_EXP, dg.SIGMA_RSS_DB)
    rss = dg.simulate_rss(tr, channel, runs, rng)
    acc = dg.simulate_acceleration(tr, sigma_acc, runs, rng)
    fix = dg.mle_positions(rss, channel).position_m
    mse = np.mean((fix - tr.position_m[tr.rss_steps]) ** 2, axis=(0, 1))
    return dict(tr=tr, model=model, channel=channel, rss=rss, acc=acc, fix=fix, mse=mse, sigma_acc=sigma_acc,
                p0_acc=p0_acc)


def locbook_filter(name: str, s: dict):
    """locbook's batched filter on all runs (recorded at the RSS epochs, scenarios/dogan.py run_filter)."""
    return dg.run_filter(name, s["tr"], s["rss"], s["fix"], s["mse"], s["channel"], acc_mps2=s["acc"],
                         sigma_acc_mps2=s["sigma_acc"], model=s["model"], p0_acc_var=s["p0_acc"])


def filterpy_inputs(s: dict, n: int):
    """The same inputs for the first ``n`` runs on the grid after step 0 (the filter starts at the first epoch):
    RSS and fixes at the later epochs (NaN elsewhere), the accelerometer from step 1, x0 and P0 from the first fix."""
    tr = s["tr"]
    rss = np.full((n, tr.time_s.size - 1, 4), np.nan)
    rss[:, tr.rss_steps[1:] - 1] = s["rss"][:n, 1:]
    fix = np.full((n, tr.time_s.size - 1, 2), np.nan)
    fix[:, tr.rss_steps[1:] - 1] = s["fix"][:n, 1:]
    x0, P0 = dg.initial_state(s["fix"][:n, 0], np.broadcast_to(s["mse"], (n, 2)), acc_var=s["p0_acc"])
    return rss, fix, s["acc"][:n, 1:], x0, P0


def filterpy_track(model, channel, rss_grid, acc, x0, P0, serial, sigma_acc):
    """filterpy's ExtendedKalmanFilter per run: predict, accelerometer update, RSS update(s) at RSS epochs (Table 3.5).
    Returns the states and covariances at every step, ``(runs, T, 6)`` and ``(runs, T, 6, 6)``."""
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

    xs, Ps = np.empty(rss_grid.shape[:2] + (6,)), np.empty(rss_grid.shape[:2] + (6, 6))
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
            xs[b, k], Ps[b, k] = f.x, f.P
    return xs, Ps


def filterpy_kf_track(model, fix_grid, acc, x0, P0, sigma_acc, mse):
    """filterpy's KalmanFilter per run: predict, accelerometer update, MLE-fix update at RSS epochs with
    R = diag(MSE_MLE) (KF (MLE), Eq. (3.21)). Returns the states and covariances at every step."""
    h_acc, r_acc = model.derivative_measurement_matrix(2), sigma_acc**2 * np.eye(2)
    h_pos, r_pos = model.position_measurement_matrix(), np.diag(mse)
    xs, Ps = np.empty(fix_grid.shape[:2] + (6,)), np.empty(fix_grid.shape[:2] + (6, 6))
    for b in range(fix_grid.shape[0]):
        f = KalmanFilter(dim_x=6, dim_z=2)
        f.x, f.P, f.F, f.Q = x0[b].copy(), P0[b].copy(), model.F, model.Q
        for k in range(fix_grid.shape[1]):
            f.predict()
            f.update(acc[b, k], R=r_acc, H=h_acc)
            if np.isfinite(fix_grid[b, k, 0]):
                f.update(fix_grid[b, k], R=r_pos, H=h_pos)
            xs[b, k], Ps[b, k] = f.x, f.P
    return xs, Ps


def filterpy_filter(name: str, s: dict, n: int):
    """The filterpy loop of ``name`` on the first ``n`` runs (states and covariances at every grid step)."""
    rss, fix, acc, x0, P0 = filterpy_inputs(s, n)
    if name == "kalman_filter":
        return filterpy_kf_track(s["model"], fix, acc, x0, P0, s["sigma_acc"], s["mse"])
    return filterpy_track(s["model"], s["channel"], rss, acc, x0, P0, name == "serial_ekf", s["sigma_acc"])


def max_difference(s: dict, ours, ref_x, ref_P) -> tuple[float, float]:
    """Largest |state| and |covariance| difference on the common runs, at the recorded RSS epochs."""
    n, at = ref_x.shape[0], s["tr"].rss_steps[1:] - 1
    return (float(np.max(np.abs(ours.mean[:n, 1:] - ref_x[:, at]))),
            float(np.max(np.abs(ours.cov[:n, 1:] - ref_P[:, at]))))


def _path(numba: bool):
    """A context in which locbook's EKF takes the compiled path (``numba``) or the numpy loop, whatever the size."""
    class _Use:
        def __enter__(self):
            self.saved = _compiled._NUMBA_ENABLED, _compiled._NUMBA_MIN_WORK
            _compiled._NUMBA_ENABLED, _compiled._NUMBA_MIN_WORK = numba, 0
        def __exit__(self, *exc):
            _compiled._NUMBA_ENABLED, _compiled._NUMBA_MIN_WORK = self.saved
    return _Use()


#: (runs, filterpy runs, goal for the EKFs): the issue's two batch sizes; filterpy runs a subset, scaled
SIZES = {"full": [(500, 20, 200.0), (10, 10, 20.0)], "tiny": [(4, 2, None)]}


def measure(sizes, filters=FILTERS, numpy_rows: bool = True):
    """Rows (yielded as they finish): each filter at each batch size against the per-run filterpy loop, paired and
    alternated (benchmarks/_harness.py); the EKFs on the default (compiled) path, and the serial EKF also on the
    numpy loop (``LOCBOOK_NUMBA=0``) at the largest size."""
    for runs, filterpy_runs, goal in sizes:
        s = setting(runs)
        T = s["tr"].time_s.size
        n = min(filterpy_runs, runs)
        workload = f"{runs} runs x {T} steps"
        reference = "filterpy per-run loop" + ("" if n == runs else f" ({n} of {runs} runs, scaled)")
        for name in filters:
            paths = [True] + ([False] if numpy_rows and name == "serial_ekf" and runs == sizes[0][0] else [])
            for numba in paths:
                with _path(numba):
                    locbook_filter(name, s)                     # warm-up (numba: load the cached kernel)

                    def agree(ours, ref):
                        dx, dP = max_difference(s, ours, *ref)
                        if dx > 1e-9 or dP > 1e-9:
                            raise AssertionError(f"max |x - filterpy| {dx:.1e}, |P - filterpy| {dP:.1e} > 1e-9")
                        return f"max |x - filterpy| {dx:.1e}, |P - filterpy| {dP:.1e} on {n} runs"

                    m = hx.compare(lambda: locbook_filter(name, s), lambda: filterpy_filter(name, s, n),
                                   reference_scale=runs / n, agree=agree)
                label = LABELS[name] + ("" if name == "kalman_filter" else (", compiled" if numba else
                                                                            ", numpy loop (LOCBOOK_NUMBA=0)"))
                yield hx.row(label, workload, m, reference,
                             goal=goal if name != "kalman_filter" and numba else None,
                             note="" if name != "kalman_filter" else "one covariance for all runs (numpy)")


def run(size: str = "full"):
    """The benchmark protocol (benchmarks/run_all.py): full = 500 runs (filterpy on 20) and 10 runs (filterpy on 10),
    tiny = 4 runs (filterpy on 2)."""
    yield from measure(SIZES[hx.check_size(size)])


def main():
    ap = argparse.ArgumentParser()
    ap.add_argument("--runs", type=int, default=500)
    ap.add_argument("--filterpy-runs", type=int, default=20)
    ap.add_argument("--filter", choices=FILTERS, nargs="+", default=list(FILTERS))
    ap.add_argument("--size", choices=hx.SIZES, default=None, help="the run(size) preset instead of --runs")
    args = ap.parse_args()
    hx.print_rows(run(args.size) if args.size else
                  measure([(args.runs, args.filterpy_runs, None)], args.filter))


if __name__ == "__main__":
    main()
