"""Time Gudipati's fusion UKF over many Monte-Carlo runs of the U-path with locbook's UKF (the compiled kernel of
locbook/tracking/_ukf_kernels.py when numba is enabled) and with a per-run filterpy UnscentedKalmanFilter loop on the
same inputs, and compare its time per run-step with the UKF's arithmetic floor.

    python benchmarks/bench_ukf_speed.py [full | tiny]

The 8-D constant-acceleration + heading model, 6 anchors, the inertial stream (body frame) then the RSS stream at
every 0.1 s step (scenarios/gudipati.py defaults, shadowing 1.45 dB; the issue-7 setting). filterpy runs a subset,
scaled to the full count; a step with some RSS readings missing updates filterpy with the anchors heard (reduced h
and R, locbook's rule for missing readings), so every run is compared. At the thesis's alpha = 1e-3 the sigma-point
weights are -1e6 and 6e4 and two correct implementations differ by round-off amplified to about 1e-8; at alpha = 0.5
or 1 they agree to about 1e-13. The tolerance is that rounding bound, of one weighted sum over the 17 sigma points:
17 eps sum |W_i| (`_tolerances.sigma_sum_round_off`, 7.5e-9 at alpha = 1e-3) times the largest |x| (|P|) entry; beyond
it the row is a disagreement.

Rows (benchmarks/_harness.py): 500 runs and 10 runs against filterpy on a subset of the runs (its time scaled by the
number of runs), goals 200x and 20x on the CPU-time ratio, with the agreement max |x - filterpy| and
|P - filterpy| on that subset; then the time per run-step against the floor of :func:`floor_per_run_step` (goal: within
5x; a time against a computed floor: no results compared, no tolerance).

The floor. One run-step of this UKF (n = 8 states, N = 2n + 1 = 17 sigma points; the inertial update, m = 3, and the
RSS update, m = 6, each with fresh sigma points) needs at least the floating-point operations counted by
:func:`ukf_flops` (a multiply-add counts 2, triangles of symmetric products are counted once): per update the Cholesky
factor of ``c P`` (n^3 / 3), the sigma points (2 n^2), the readings at the distinct points (an RSS reading depends on x
and y only: 5 distinct points of 17), the mean (2 N m), the deviations (N m), P_zz (N m (m + 1) + N m), D (2 n m), S,
its Cholesky factor (m^3 / 3), P_xz = L D (n (n + 1) m), the gain (2 n m^2), the state (2 n m), R~ = S - c D^T D
(m (m + 1) (n + 1)), M = L - c K D^T (2 n^2 (m + 1)), R~ K^T (2 n m^2) and P+ = M M^T / c + K R~ K^T (n (n + 1) (2n +
2m + 1) / 2); the prediction F x, F P F^T + Q with F's nonzero entries. Besides, transcendental calls: 6 anchors x 5
distinct points logarithms, 15 distinct headings' sine and cosine. The floor is the FLOPs at the machine's rate for
this loop shape (multiply-adds over runs side by side, measured here by a numba loop at the best of 64, 128, 256 and
512 lanes; ~1 FLOP per ns is the scalar rate) plus the calls at their measured cost.
"""
from __future__ import annotations

import sys
import time
from dataclasses import replace
from pathlib import Path

import numpy as np
from filterpy.kalman import MerweScaledSigmaPoints, UnscentedKalmanFilter

sys.path.insert(0, str(Path(__file__).resolve().parent))
import _harness as hx  # noqa: E402
import locbook as lb  # noqa: E402
from _tolerances import sigma_sum_round_off  # noqa: E402
from locbook.scenarios import gudipati as gu  # noqa: E402


def setting(runs: int, steps: int | None = None, seed: int = 0) -> dict:
    """The U-path walk of ``runs`` Monte-Carlo runs (the first ``steps`` steps, default all) and the UKF's inputs."""
    s = replace(gu.WalkSettings(), shadowing_sigma_db=1.45)
    w = gu.simulate_walk("u", 6, s, runs, np.random.default_rng(seed))
    model = lb.HeadingKinematicModel(s.dt_s, s.q, s.q_angular)
    x0, P0 = gu._initial(w, model, 8)
    imu, rss = gu._imu_stream(w, False), gu._rss_stream(w, model)
    if steps is not None:
        imu = imu.replace(z=np.asarray(imu.z)[:, :steps])
        rss = rss.replace(z=np.asarray(rss.z)[:, :steps])
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
    h_imu = lambda x: imu.model.mean(x, step=0)          # noqa: E731 - the model's h (one state: (n,) -> (3,))
    z_imu, z_rss = np.asarray(imu.z), np.asarray(rss.rss_dbm)
    p0 = np.broadcast_to(ch.ref_power_dbm, a.shape[:1])
    ple = np.broadcast_to(ch.path_loss_exp, a.shape[:1])
    T = z_imu.shape[1]
    xs, Ps = np.empty((runs, T, 8)), np.empty((runs, T, 8, 8))
    F = model.F                      # once: the model's property builds the matrix at each access
    for r in range(runs):
        f = UnscentedKalmanFilter(8, 3, st["settings"].dt_s, h_imu, lambda x, dt: F @ x, points)
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


def _first_steps(st: dict, steps: int) -> dict:
    """The setting ``st`` cut to its first ``steps`` steps (the same walk)."""
    return dict(st, imu=st["imu"].replace(z=np.asarray(st["imu"].z)[:, :steps]),
                rss=st["rss"].replace(z=np.asarray(st["rss"].z)[:, :steps]))


def _filterpy_agreement(n: int, steps: int, alpha: float):
    """The agreement figure of the harness: max |x - filterpy|, |P - filterpy| on the first ``n`` runs and ``steps``
    steps (where filterpy ran); the tolerance, the rounding bound of one sigma-point sum
    (`_tolerances.sigma_sum_round_off`) times the largest |x| (|P|) entry of filterpy's: two implementations of the same
    arithmetic in another order."""
    rel = sigma_sum_round_off(8, alpha)

    def agree(ours, ref):
        ref_x, ref_P = ref
        dx = float(np.max(np.abs(ours.mean[:n, :steps] - ref_x)))
        dP = float(np.max(np.abs(ours.cov[:n, :steps] - ref_P)))
        tx, tP = rel * float(np.max(np.abs(ref_x))), rel * float(np.max(np.abs(ref_P)))
        text = (f"max |x - filterpy| {dx:.1e} (tolerance {tx:.1e}), |P - filterpy| {dP:.1e} (tolerance {tP:.1e}) on "
                f"{n} run{'s' * (n > 1)} x {steps} steps; {ours.floored_updates} floored updates")
        if not (dx <= tx and dP <= tP):
            raise AssertionError(f"{text}: beyond the sigma-point sums' round-off")
        return text
    return agree


def ukf_flops(n: int, ms, distinct_points, f_nonzero: int) -> int:
    """Floating-point operations of one run-step of the UKF (module docstring): linear prediction with ``f_nonzero``
    entries of F, then one update per entry of ``ms`` (readings per update), whose measurement function is evaluated at
    ``distinct_points`` of the ``2n + 1`` sigma points (about 10 FLOPs per RSS reading, 6 per inertial point)."""
    N = 2 * n + 1
    flops = 2 * f_nonzero + 2 * f_nonzero * n + f_nonzero * (n + 1) + n * (n + 1) // 2
    for m, points in zip(ms, distinct_points):
        h = points * m * 10 if m == 6 else points * 6
        flops += (n * (n + 1) // 2 + n**3 // 3 + 2 * n * n + h + 2 * N * m + N * m + N * m * (m + 1) + N * m
                  + 2 * n * m + m * (m + 1) // 2 + m**3 // 3 + n * (n + 1) * m + 2 * n * m * m + m * m + 2 * m
                  + 2 * n * m + m * (m + 1) * (n + 1) + 2 * n * n * (m + 1) + 2 * n * m * m
                  + n * (n + 1) * (2 * n + 2 * m + 1) // 2)
    return flops


def _rate_kernels():
    """The numba loops of :func:`machine_rates`, compiled in memory (run_all.py loads this module under a name numba's
    disk cache cannot import)."""
    import numba
    jit = numba.njit(error_model="numpy")

    def fma(A, B, C, reps):
        n, W = B.shape
        for _ in range(reps):
            for i in range(n):
                for k in range(n):
                    for w in range(W):
                        C[i, w] += A[i, k, w] * B[k, w]

    def logs(a, out, reps):
        for _ in range(reps):
            for i in range(a.size):
                out[i] += np.log(a[i])

    def trig(a, out, reps):
        for _ in range(reps):
            for i in range(a.size):
                out[i] += np.cos(a[i]) + np.sin(a[i])
    return jit(fma), jit(logs), jit(trig)


def machine_rates() -> dict:
    """The machine's rates for the floor, measured by numba loops: multiply-adds with the runs on the innermost axis
    (the kernels' loop shape) in FLOP per ns, and the cost of a logarithm and of a sine + cosine in ns (best of 5)."""
    fma, logs, trig = _rate_kernels()
    rng = np.random.default_rng(0)

    def best_time(fn, args, reps):
        fn(*args, 1)
        best = np.inf
        for _ in range(5):
            t = time.process_time()
            fn(*args, reps)
            best = min(best, time.process_time() - t)
        return best

    def flop_rate(W):            # FLOP per second of the multiply-adds at W lanes
        A, B, C = (hx.aligned(rng.random(shape)) for shape in ((8, 8, W), (8, W), (8, W)))
        reps = max(1, 2000 * 64 // W)
        return 2 * 8 * 8 * W * reps / best_time(fma, (A, B, C), reps)

    width, by_width = hx.best_lane_width(flop_rate)
    a, out = rng.random(64) + 0.5, np.zeros(64)
    rates = {"flop_per_ns": by_width[width] / 1e9, "lanes": width,
             "by_lanes": ", ".join(f"{w}: {r / 1e9:.1f}" for w, r in by_width.items())}
    for name, fn, args in (("log_ns", logs, (a, out)), ("sincos_ns", trig, (a, out))):
        rates[name] = best_time(fn, args, 10000) / (64 * 10000) * 1e9
    return rates


def floor_per_run_step(st: dict) -> dict:
    """The arithmetic floor of one run-step on this setting (module docstring): FLOPs, calls, and ns at the measured
    rates and at 1 FLOP per ns."""
    n = 8
    f_nonzero = int(np.count_nonzero(st["model"].F))
    flops = ukf_flops(n, (3, 6), (2 * n + 1, 5), f_nonzero)
    n_log, n_trig = 6 * 5, 2 * 7 + 1
    rates = machine_rates()
    calls_ns = n_log * rates["log_ns"] + n_trig * rates["sincos_ns"]
    return dict(flops=flops, n_log=n_log, n_trig=n_trig, rates=rates, calls_ns=calls_ns,
                floor_ns=flops / rates["flop_per_ns"] + calls_ns, floor_1flop_ns=flops + calls_ns)


def run(size: str = "full"):
    """The benchmark protocol (benchmarks/run_all.py), at the thesis's alpha = 1e-3: full = 500 runs and 10 runs over
    the whole walk (1164 steps), filterpy on 1 run x the first 400 steps (a filterpy step costs the same all along the
    walk, so its time is scaled by runs x 1164 / 400; the full walk would take 5 x 2 filterpy runs, ~40 s at least,
    beyond the benchmark's 90 s), then the floor row; tiny = 6 runs x 60 steps and 3 runs x 60 steps (filterpy on 1 run
    x 30 steps)."""
    tiny = hx.check_size(size) == "tiny"
    alpha = 1e-3
    steps, ref_steps = (60, 30) if tiny else (None, 400)
    per_step = None
    for runs, goal in ((6, None), (3, None)) if tiny else ((500, 200), (10, 20)):
        st = setting(runs, steps)
        T = np.shape(st["imu"].z)[1]
        ref_st = _first_steps(st, ref_steps)
        locbook_ukf(st, alpha)                     # numba's load and the kernel's first call, outside the timing
        m = hx.compare(lambda: locbook_ukf(st, alpha), lambda: filterpy_ukf(ref_st, 1, alpha),
                       repeats=5, reference_scale=runs * T / ref_steps, agree=_filterpy_agreement(1, ref_steps, alpha))
        ns = m.locbook_cpu_s / (runs * T) * 1e9
        if per_step is None:
            per_step = (m, st, runs, T)
        yield hx.row(f"UKF (inertial + RSS), alpha = {alpha:g}", f"U-path, {runs} runs x {T} steps", m,
                     f"filterpy per-run loop (1 run x {ref_steps} steps, scaled)", goal=goal,
                     note=f"{ns:.0f} ns CPU per run-step")
    m, st, runs, T = per_step
    ns = m.locbook_cpu_s / (runs * T) * 1e9
    fl = floor_per_run_step(st)
    r = fl["rates"]
    floor_s = fl["floor_ns"] * 1e-9 * runs * T
    # the locbook calls of the first row (paired repeats), against the floor of the same workload
    floor = replace(m, reference_wall_s=floor_s, reference_cpu_s=floor_s, reference_peak_mb=None, reference_scale=1.0,
                    agreement=(f"{fl['flops']} FLOPs + {fl['n_log']} log + {fl['n_trig']} sin/cos per run-step; "
                               f"measured {ns:.0f} ns per run-step, floor {fl['floor_ns']:.0f} ns "
                               f"({ns / fl['floor_ns']:.1f}x)"))
    yield hx.row("UKF (inertial + RSS), compiled, vs its arithmetic floor", f"U-path, {runs} runs x {T} steps (n = 8, "
                 "17 sigma points, m = 3 + 6)", floor,
                 f"arithmetic floor at {r['flop_per_ns']:.2f} FLOP/ns ({r['lanes']} lanes, measured) "
                 f"+ log {r['log_ns']:.1f} ns, sin + cos {r['sincos_ns']:.1f} ns", goal=0.2,
                 note=f"ratio = floor / locbook; the rate at its best lane width (FLOP/ns by lanes: {r['by_lanes']}); "
                      f"at 1 FLOP/ns the floor would be {fl['floor_1flop_ns']:.0f} ns")


if __name__ == "__main__":
    hx.print_rows(run(sys.argv[1] if len(sys.argv) > 1 else "full"))
