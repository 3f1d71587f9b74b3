"""The UKF at Gudipati's alpha = 1e-3 over a long run: is the covariance still symmetric positive definite?

    python benchmarks/bench_ukf_stability.py [full|tiny]
    python benchmarks/bench_ukf_stability.py [--steps 100000] [--alpha 1e-3] [--runs 1]

An 8-D constant-acceleration + heading model (HeadingKinematicModel) travels laps around a 30 m x 10 m hall at
10 Hz; six anchors (Gudipati Table 5.2's S and C, corner and mid-wall positions) give RSS with 4 dB shadowing at
every step and a body-frame accelerometer + gyroscope every step. At alpha = 1e-3 and n = 8 the sigma-point
weights are -1e6 and 6.25e4. Reports the time per step (one call, ``hx.once``: timed and its peak resident memory
measured together), the smallest eigenvalue of P over all steps, the largest asymmetry, how often the guard (R~
floored) acted, and the position error over the run and its last lap, in metres and as the NEES (the squared error
in units of the filter's own position covariance). No reference; the checks: P positive definite, its asymmetry
within the round-off of two sigma-point sums (``_tolerances.sigma_sum_round_off`` times the largest |P|), and
the mean NEES, over the run and over the last lap, at most 25: if the covariance is right the NEES is chi-square
with 2 degrees of freedom, and a mean of such terms exceeds 25 with a probability below 1.3e-4 however correlated
the steps. Beyond any, the row is a disagreement.
"""
from __future__ import annotations

import argparse
import gc
import sys
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parent))
import _harness as hx  # noqa: E402
import locbook as lb  # noqa: E402
from _tolerances import sigma_sum_round_off  # noqa: E402

#: the mean NEES (2-D position) allowed: exceeded with a probability below 1.3e-4 if the covariance is right
NEES_BOUND = 25.0
ANCHORS = np.array([[0.0, 0.0], [30.0, 0.0], [30.0, 10.0], [0.0, 10.0], [15.0, 0.0], [15.0, 10.0]])
S_DBM = np.array([-31.79, -43.64, -40.42, -30.9, -42.4, -34.55])
C = np.array([1.84, 3.1, 1.72, 1.2, 1.34, 1.5])


def measure(steps: int = 100_000, alpha: float = 1e-3, runs: int = 1, seed: int = 1):
    rng = np.random.default_rng(seed)
    dt, speed = 0.1, 0.8
    lap = [[3.0, 3.0], [27.0, 3.0], [27.0, 7.0], [3.0, 7.0]]
    laps = int(np.ceil(steps * dt * speed / 50.0)) + 2     # a lap is about 54 m with its rounded corners
    waypoints = np.array(lap * laps + [lap[0]])
    truth = lb.waypoint_trajectory(waypoints, speed_m_s=speed, accel_m_s2=0.5, dt_s=dt, turn_radius_m=1.0)
    T = min(steps, truth.time_s.size)
    sl = slice(0, T)
    channel = lb.PathLossModel(S_DBM, C, 4.0)
    d = lb.pairwise_distance_m(truth.position_m[sl], ANCHORS)
    rss = channel.sample_rss_dbm(np.broadcast_to(d, (runs,) + d.shape), rng=rng)
    acc = lb.accelerometer_readings(truth.acceleration_m_s2[sl], truth.heading_rad[sl], bias_m_s2=0.0,
                                    sigma_m_s2=0.05, rng=rng) + np.zeros((runs, 1, 1))
    gyro = lb.gyroscope_readings(truth.yaw_rate_rad_s[sl], bias_rad_s=0.0, sigma_rad_s=0.01, rng=rng)
    z_imu = np.concatenate([acc, np.broadcast_to(gyro[:, None], (runs, T, 1))], axis=-1)
    model = lb.HeadingKinematicModel(dt, q=0.05, q_angular=0.01)
    R_imu = np.diag([0.05**2, 0.05**2, 0.01**2])
    x0 = model.state_from(truth.position_m[0], angular=(truth.heading_rad[0], 0.0))
    P0 = np.diag([1.0, 1.0, 0.1, 0.1, 0.1, 0.1, 0.01, 0.01])

    def ukf(k=T):
        imu = lb.Stream(z_imu[:, :k], lb.InertialMeasurement(R_imu, frame="body", name="accelerometer + gyroscope"))
        return lb.unscented_kalman_filter(model.F, model.Q, x0, P0,
                                          [imu, lb.RssMeasurement(rss[:, :k], ANCHORS, channel, model.position_index)],
                                          alpha=alpha)

    def figures(res):
        P = res.cov
        e = res.mean[..., :2] - truth.position_m[sl]
        err = np.linalg.norm(e, axis=-1)
        last = slice(max(0, T - int(56.0 / (speed * dt))), T)
        # the position error in the filter's own units (NEES, chi-square with 2 degrees of freedom if the filter's
        # covariance is right): its mean over any steps, however correlated, exceeds NEES_BOUND with a probability
        # below (c / 2) e^(1 - c / 2) = 1.3e-4 (Jensen and Chernoff on the chi-square's moment generating function)
        nees = np.einsum("...i,...ij,...j->...", e, np.linalg.inv(P[..., :2, :2]), e)
        smallest, asym = float(np.linalg.eigvalsh(P).min()), float(np.abs(P - np.swapaxes(P, -1, -2)).max())
        # P is a covariance: positive definite; its two triangles differ by round-off at most (two sigma-point sums)
        asym_tol = 2 * sigma_sum_round_off(8, alpha) * float(np.abs(P).max())
        text = (f"smallest eigenvalue of P {smallest:.2e} (> 0), largest |P - P^T| {asym:.1e} (<= {asym_tol:.0e}); "
                f"guard floored R~ in {res.floored_updates} of {2 * T * runs} updates; position error mean "
                f"{err.mean():.3f} m, last lap {err[..., last].mean():.3f} m; mean NEES {nees.mean():.2f}, last lap "
                f"{nees[..., last].mean():.2f} (<= {NEES_BOUND:g})")
        if not (smallest > 0 and asym <= asym_tol and nees.mean() <= NEES_BOUND
                and nees[..., last].mean() <= NEES_BOUND):
            raise AssertionError(text)
        return text

    ukf(20)         # compiled kernels (numba) compiled or loaded from their cache before the timed call
    gc.collect()
    gc.freeze()     # the imported modules' objects out of the collector: the harness collects before every call
    m = hx.once(ukf, agree=figures)
    yield hx.row(f"UKF long run, alpha = {alpha:g}", f"{runs} run(s) x {T:,} steps (inertial + 6-anchor RSS)", m,
                 note=f"{1e6 * m.locbook_wall_s / T:.0f} us per step (wall); no reference")


def run(size: str = "full"):
    """The benchmark protocol (benchmarks/run_all.py): full = 100,000 steps (2.8 h of walking), timed once; tiny =
    1,000."""
    return measure(1_000 if hx.check_size(size) == "tiny" else 100_000)


def main():
    ap = argparse.ArgumentParser()
    ap.add_argument("size", nargs="?", choices=hx.SIZES, default=None, help="the run(size) preset")
    ap.add_argument("--steps", type=int, default=100_000)
    ap.add_argument("--alpha", type=float, default=1e-3)
    ap.add_argument("--runs", type=int, default=1)
    ap.add_argument("--seed", type=int, default=1)
    args = ap.parse_args()
    hx.print_rows(run(args.size) if args.size else measure(args.steps, args.alpha, args.runs, args.seed))


if __name__ == "__main__":
    main()
