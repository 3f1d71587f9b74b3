"""locbook against the batched peers an expert would pick for Monte-Carlo filtering: dynamax (JAX, ``jit(vmap)``),
simdkalman, and a lean numpy SIR particle filter.

    python benchmarks/bench_peers.py [full|tiny]

The peers are benchmark-only dependencies (``pip install -e ".[peers]"``); a peer that is not installed gives no
row (the module says so in a row's note instead of failing). Every side runs on one thread: BLAS is pinned by
run_all.py, and JAX's CPU backend is started with ``--xla_cpu_multi_thread_eigen=false
intra_op_parallelism_threads=1`` (set here before JAX is imported); the ratios are of CPU time (every thread of the
process), so a side that used more threads would pay for them.

- **KF** (the constant-velocity model of a walker, n = 4, position readings m = 2 with 0.5 m noise, dt = 0.5 s): 500
  runs x 1600 steps, each reading missing with probability 0.1 in each run (its own pattern). locbook: NaN readings
  (its rule: NaN = not heard). dynamax ``lgssm_filter`` under ``jit(vmap)``, float64, a missing step given as an
  emission matrix of zeros at that step and run (no update; the states and covariances are then exactly the
  filter's), its compile time apart: the first call, untimed. simdkalman ``KalmanFilter.compute`` (NaN = missing,
  its own rule), which also vectorises over the runs in numpy. The agreement: the largest difference of the filtered
  means and covariances, against a tolerance of 1e-9 of the largest entry (round-off of the same recursion in
  another order).
- **Particle filter**: the setting of bench_particle.py (10,000 particles, 4 anchors, a random walk), 100 runs x 10
  steps. The reference is a lean numpy SIR written as an expert would for speed: float64, the random walk drawn with
  ``Generator.standard_normal`` in place, the RSS log-likelihood by ``einsum``-free broadcasting over the anchors,
  the weights by a max-shifted exp, systematic resampling by ``searchsorted`` on the cumulative weights, one pass per
  step over every run at once. Agreement: the mean position error of both over the runs (independent random streams:
  a difference within 4 standard errors).
"""
from __future__ import annotations

import os
import sys
from pathlib import Path

os.environ.setdefault("XLA_FLAGS", "--xla_cpu_multi_thread_eigen=false intra_op_parallelism_threads=1")
os.environ.setdefault("JAX_PLATFORMS", "cpu")

import numpy as np  # noqa: E402

sys.path.insert(0, str(Path(__file__).resolve().parent))
import _harness as hx  # noqa: E402
import locbook as lb  # noqa: E402

DT_S = 0.5
SIGMA_Z_M = 0.5
Q_INTENSITY = 0.05          # white-acceleration intensity (m^2 / s^3)
MISSING = 0.1


def kf_setting(runs: int, steps: int, seed: int = 0) -> dict:
    """The KF workload: F, Q, H, R, x0, P0 and readings ``(runs, steps, 2)`` with NaN where missing."""
    rng = np.random.default_rng(seed)
    F = np.eye(4)
    F[0, 2] = F[1, 3] = DT_S
    G = np.array([[DT_S ** 2 / 2, 0], [0, DT_S ** 2 / 2], [DT_S, 0], [0, DT_S]])
    Q = Q_INTENSITY / DT_S * G @ G.T + 1e-9 * np.eye(4)
    H = np.eye(2, 4)
    R = SIGMA_Z_M ** 2 * np.eye(2)
    x = np.zeros((runs, 4))
    L = np.linalg.cholesky(Q)
    truth = np.empty((runs, steps, 4))
    for t in range(steps):
        x = x @ F.T + rng.standard_normal((runs, 4)) @ L.T
        truth[:, t] = x
    z = truth[..., :2] + SIGMA_Z_M * rng.standard_normal((runs, steps, 2))
    z[rng.random((runs, steps)) < MISSING] = np.nan
    return dict(F=F, Q=Q, H=H, R=R, x0=np.zeros(4), P0=np.eye(4), z=z)


def locbook_kf(s: dict):
    runs = s["z"].shape[0]
    out = lb.kalman_filter(s["F"], s["Q"], np.broadcast_to(s["x0"], (runs, 4)), s["P0"],
                           lb.LinearMeasurement(s["z"], s["H"], s["R"]), divergence_window=0)
    return np.asarray(out.mean), np.asarray(out.cov)


def dynamax_kf(s: dict):
    """``jit(vmap(lgssm_filter))`` over the runs; a missing step is an emission matrix of zeros. Returns the call
    (compiled on its first use) and a function turning its result into numpy arrays."""
    import jax
    jax.config.update("jax_enable_x64", True)
    import jax.numpy as jnp
    from dynamax.linear_gaussian_ssm.inference import lgssm_filter, make_lgssm_params

    z = s["z"]
    missing = np.isnan(z).any(axis=-1)
    Hs = np.where(missing[..., None, None], 0.0, s["H"])           # (runs, steps, 2, 4)
    y = jnp.asarray(np.nan_to_num(z))
    Hs = jnp.asarray(Hs)
    # dynamax's x0 is the prior at the first reading; locbook (predict_first) predicts from x0, P0 first
    m0 = s["F"] @ s["x0"]
    P0 = s["F"] @ s["P0"] @ s["F"].T + s["Q"]

    def one(H_t, y_r):
        params = make_lgssm_params(jnp.asarray(m0), jnp.asarray(P0), jnp.asarray(s["F"]), jnp.asarray(s["Q"]),
                                   H_t, jnp.asarray(s["R"]))
        post = lgssm_filter(params, y_r)
        return post.filtered_means, post.filtered_covariances

    fn = jax.jit(jax.vmap(one))

    def call():
        means, covs = fn(Hs, y)
        means.block_until_ready()
        return means, covs

    return call


def simdkalman_kf(s: dict):
    import simdkalman
    kf = simdkalman.KalmanFilter(state_transition=s["F"], process_noise=s["Q"], observation_model=s["H"],
                                 observation_noise=s["R"])
    m0 = s["F"] @ s["x0"]
    P0 = s["F"] @ s["P0"] @ s["F"].T + s["Q"]

    def call():
        r = kf.compute(s["z"], 0, initial_value=m0, initial_covariance=P0, filtered=True, smoothed=False)
        return r.filtered.states.mean, r.filtered.states.cov

    return call


def kf_agree(ours, theirs, name: str, tolerance: float = 1e-9) -> str:
    x, P = ours
    xr, Pr = (np.asarray(a) for a in theirs)
    dx, dP = float(np.max(np.abs(x - xr))), float(np.max(np.abs(P - Pr)))
    tol_x, tol_P = (tolerance * max(1.0, float(np.max(np.abs(a)))) for a in (xr, Pr))
    if not (dx <= tol_x and dP <= tol_P):
        raise AssertionError(f"max |x - {name}| {dx:.2g}, |P - {name}| {dP:.2g} beyond {tolerance:g} of the "
                             "largest entry")
    return f"max |x - {name}| {dx:.1e}, |P - {name}| {dP:.1e} (tolerance {tolerance:g} of the largest entry)"


#: dynamax's psd_solve adds 1e-9 I to S before its Cholesky (a "diagonal boost"): the gain then differs from the exact
#: one by about 1e-9 / sigma_z^2 = 4e-9 relative, so its agreement is read at 1e-7 of the largest entry
DYNAMAX_TOLERANCE = 1e-7


def lean_numpy_sir(rss, n_particles: int, rng: np.random.Generator):
    """A lean numpy SIR (module docstring) on bench_particle's setting: coordinates as two ``(R, N)`` arrays, the
    random walk drawn in place, reflection by folding, the RSS log-likelihood accumulated anchor by anchor from the
    squared distance (``5 n log10(d^2)`` = ``10 n log10(d)``: no square root), the weights by a max-shifted exp in
    place, systematic resampling by one ``searchsorted`` over the rows shifted apart, the posterior mean by a dot
    product per row. Returns the posterior means ``(R, T, 2)``."""
    import bench_particle as bp
    R, T, m = rss.shape
    N = n_particles
    lo, hi = bp.LOWER_M, bp.UPPER_M
    width = hi - lo
    x = lo[0] + width[0] * rng.random((R, N))
    y = lo[1] + width[1] * rng.random((R, N))
    out = np.empty((R, T, 2))
    ll, d2, tmp, noise = (np.empty((R, N)) for _ in range(4))
    rows = np.arange(R)[:, None]
    k = -0.5 / bp.SIGMA_DB ** 2
    d2_min = bp.D_MIN_M ** 2
    for t in range(T):
        if t:
            for c, lo_c, w_c in ((x, lo[0], width[0]), (y, lo[1], width[1])):
                rng.standard_normal(out=noise)
                c += bp.SPREAD_M * noise
                c -= lo_c                                        # fold into [0, 2w), then reflect into [0, w]
                np.mod(c, 2 * w_c, out=c)
                np.subtract(2 * w_c, c, out=tmp)
                np.minimum(c, tmp, out=c)
                c += lo_c
        ll.fill(0.0)
        for j in range(m):
            np.subtract(x, bp.ANCHORS_M[j, 0], out=d2)
            d2 *= d2
            np.subtract(y, bp.ANCHORS_M[j, 1], out=tmp)
            tmp *= tmp
            d2 += tmp
            np.maximum(d2, d2_min, out=d2)
            np.log10(d2, out=d2)                                  # h = P0 - 5 n log10(d^2)
            d2 *= 5 * bp.PLE
            d2 += rss[:, t, j, None] - bp.P0_DBM                  # residual z - h
            d2 *= d2
            ll += d2
        ll *= k
        ll -= ll.max(axis=1, keepdims=True)
        np.exp(ll, out=ll)
        ll /= ll.sum(axis=1, keepdims=True)
        out[:, t, 0] = np.einsum("rn,rn->r", ll, x)
        out[:, t, 1] = np.einsum("rn,rn->r", ll, y)
        np.cumsum(ll, axis=1, out=tmp)
        tmp[:, -1] = 1.0
        tmp += rows                                               # rows apart: one search for every run
        points = (rng.random((R, 1)) + np.arange(N)) / N + rows
        idx = np.searchsorted(tmp.ravel(), points.ravel())
        np.minimum(idx, (rows * N + N - 1).repeat(N, axis=1).ravel(), out=idx)
        x = x.ravel()[idx].reshape(R, N)
        y = y.ravel()[idx].reshape(R, N)
    return out


def _installed(module: str) -> bool:
    import importlib.util
    return importlib.util.find_spec(module) is not None


def run(size: str = "full"):
    tiny = hx.check_size(size) == "tiny"
    sizes = [(20, 50)] if tiny else [(500, 1600), (4, 100), (10, 1600)]
    for runs, steps in sizes:
        s = kf_setting(runs, steps)
        workload = f"{runs} runs x {steps} steps, n = 4, m = 2, {MISSING:.0%} missing"
        locbook_kf(s)                                   # the kernel's load (or compile) outside the timing
        if _installed("dynamax"):
            ref = dynamax_kf(s)
            ref()                                       # JAX's compile for these shapes, outside the timing
            m = hx.compare(lambda: locbook_kf(s), ref,
                           agree=lambda a, b: kf_agree(a, b, "dynamax", DYNAMAX_TOLERANCE))
            yield hx.row("KF", workload, m, "dynamax lgssm_filter, jit(vmap), float64 (compiled before timing)")
        if _installed("simdkalman"):
            ref = simdkalman_kf(s)
            m = hx.compare(lambda: locbook_kf(s), ref, agree=lambda a, b: kf_agree(a, b, "simdkalman"))
            yield hx.row("KF", workload, m, "simdkalman KalmanFilter.compute (numpy, vectorised over runs)")
    yield from particle_rows(tiny)


def particle_rows(tiny: bool):
    import bench_particle as bp
    runs, particles, steps = (4, 500, 3) if tiny else (100, 10_000, 10)
    model, rss, truth = bp.scenario(runs, steps)

    def ours():
        return lb.particle_filter(rss, model, rng=np.random.default_rng(1), n_particles=particles,
                                  region_m=(bp.LOWER_M, bp.UPPER_M), spread_m=bp.SPREAD_M).mean

    def agree(a, b):
        ea, eb, diff, se = bp._error_stats(a, b, truth)
        if abs(diff) > 4 * se + 1e-3:
            raise AssertionError(f"mean error locbook {ea:.4f} m vs lean numpy SIR {eb:.4f} m: difference "
                                 f"{diff:.4f} m beyond 4 standard errors ({se:.4f} m)")
        return (f"mean error {ea:.3f} m (locbook) and {eb:.3f} m (lean numpy SIR), difference {diff:+.3f} m, "
                f"standard error {se:.3f} m (own random streams)")

    ours()
    m = hx.compare(ours, lambda: lean_numpy_sir(rss, particles, np.random.default_rng(2)), agree=agree)
    yield hx.row("SIR particle filter", f"{runs} runs x {particles:,} particles x {steps} steps, 5 anchors", m,
                 "lean numpy SIR (in place, no temporaries over the anchors)", goal=5.0,
                 note=f"{runs * particles * steps / m.locbook_cpu_s:.3g} particle-steps per CPU second")


def main():
    hx.print_rows(run(sys.argv[1] if len(sys.argv) > 1 else "full"))


if __name__ == "__main__":
    main()
