"""Time the SIR particle filter against a plain vectorized numpy SIR on the same readings.

    python benchmarks/bench_particle.py [full|tiny]

Workload: ``runs`` Monte-Carlo runs x 10,000 particles x ``steps`` steps, 2-D, 5 anchors in a 20 m x 15 m room
(log-distance channel P0 = -40 dBm, n = 2.5, sigma = 4 dB, clamp 0.1 m), a Gaussian random walk (D = 0.5 m)
reflected at the walls, systematic resampling at every step, the posterior mean as the estimate. The truth walks the
same random walk; the readings are drawn from the model.

Reference ("a plain vectorized numpy SIR", what a researcher writes by hand): particles ``(R, N, 2)``, the random
walk and reflection by ``np.mod``, the RSS log-likelihood by broadcasting ``(R, N, m)``, logsumexp normalisation,
systematic resampling with one ``searchsorted`` over the rows (shifted apart) and ``take_along_axis``, the weighted
mean. It draws its own random stream, so the two agree within Monte-Carlo error: the rows give both mean position
errors against the truth and the standard error of their difference (over runs).

Rows: the filter (CPU-time ratio, goal 5x; the peak memory of each), and the fused RSS log-likelihood against
:meth:`locbook.RssModel.log_likelihood` on the same particles (the maximum relative difference).
"""
from __future__ import annotations

import sys
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parent))
import _harness as hx  # noqa: E402
import locbook as lb  # noqa: E402
from locbook.models.motion import reflect_into_box  # noqa: E402
from locbook.tracking.particle import _fused_rss_log_likelihood  # noqa: E402

ANCHORS_M = np.array([[0.0, 0.0], [20.0, 0.0], [20.0, 15.0], [0.0, 15.0], [10.0, 7.5]])
LOWER_M, UPPER_M = np.zeros(2), np.array([20.0, 15.0])
P0_DBM, PLE, SIGMA_DB, D_MIN_M, SPREAD_M = -40.0, 2.5, 4.0, 0.1, 0.5


def scenario(runs: int, steps: int, seed: int = 0):
    """The model, readings ``(R, T, m)`` and true positions ``(R, T, 2)``."""
    rng = np.random.default_rng(seed)
    model = lb.RssModel(ANCHORS_M, lb.PathLossModel(P0_DBM, PLE, SIGMA_DB, min_distance_m=D_MIN_M))
    x = LOWER_M + (UPPER_M - LOWER_M) * rng.random((runs, 2))
    truth = np.empty((runs, steps, 2))
    for t in range(steps):
        if t:
            x = reflect_into_box(x + SPREAD_M * rng.standard_normal(x.shape), LOWER_M, UPPER_M)
        truth[:, t] = x
    rss = model.mean_rss_dbm(truth.reshape(-1, 2))[0].reshape(runs, steps, -1)
    return model, rss + SIGMA_DB * rng.standard_normal(rss.shape), truth


def numpy_sir(rss, n_particles: int, rng: np.random.Generator):
    """The reference: a plain vectorized numpy SIR (module docstring); returns the posterior means ``(R, T, 2)``."""
    R, T, m = rss.shape
    width = UPPER_M - LOWER_M
    x = LOWER_M + width * rng.random((R, n_particles, 2))
    out = np.empty((R, T, 2))
    rows = 2.0 * np.arange(R)[:, None]
    for t in range(T):
        if t:
            x = x + SPREAD_M * rng.standard_normal(x.shape)
            folded = np.mod(x - LOWER_M, 2 * width)
            x = LOWER_M + np.where(folded > width, 2 * width - folded, folded)
        d = np.sqrt(((x[:, :, None, :] - ANCHORS_M) ** 2).sum(-1))                  # (R, N, m)
        h = P0_DBM - 10 * PLE * np.log10(np.maximum(d, D_MIN_M))
        ll = -0.5 * (((rss[:, t, None, :] - h) / SIGMA_DB) ** 2).sum(-1)
        ll -= ll.max(-1, keepdims=True)
        w = np.exp(ll)
        w /= w.sum(-1, keepdims=True)
        out[:, t] = np.einsum("rn,rnd->rd", w, x)
        c = np.cumsum(w, -1)
        c[:, -1] = 1.0
        points = (rng.random((R, 1)) + np.arange(n_particles)) / n_particles
        idx = np.searchsorted((c + rows).ravel(), (points + rows).ravel()).reshape(R, n_particles)
        idx = np.minimum(idx - n_particles * np.arange(R)[:, None], n_particles - 1)
        x = np.take_along_axis(x, idx[..., None], axis=1)
    return out


def _error_stats(est_a, est_b, truth):
    """Mean position errors (m) of two estimates and the standard error of their difference (over runs)."""
    ea = np.linalg.norm(est_a - truth, axis=-1).mean(axis=-1)
    eb = np.linalg.norm(est_b - truth, axis=-1).mean(axis=-1)
    diff = ea - eb
    return ea.mean(), eb.mean(), diff.mean(), diff.std(ddof=1) / np.sqrt(diff.size)


def measure(runs: int, particles: int, steps: int, repeats: int = 5):
    model, rss, truth = scenario(runs, steps)

    def ours():
        return lb.particle_filter(rss, model, rng=np.random.default_rng(1), n_particles=particles,
                                  region_m=(LOWER_M, UPPER_M), spread_m=SPREAD_M).mean

    def reference():
        return numpy_sir(rss, particles, np.random.default_rng(2))

    def agree(a, b):
        ea, eb, diff, se = _error_stats(a, b, truth)
        if abs(diff) > 4 * se + 1e-3:
            raise AssertionError(f"mean error locbook {ea:.4f} m vs numpy SIR {eb:.4f} m: difference {diff:.4f} m "
                                 f"> 4 standard errors ({se:.4f} m)")
        return (f"mean error locbook {ea:.4f} m, numpy SIR {eb:.4f} m: difference {diff:+.4f} m "
                f"(standard error {se:.4f} m over {runs} runs)")

    lb.particle_filter(rss[:2, :2], model, rng=np.random.default_rng(0), n_particles=particles,
                       region_m=(LOWER_M, UPPER_M))                       # warm-up: compiled kernels loaded
    m = hx.compare(ours, reference, repeats=repeats, agree=agree)
    work = f"{runs} runs x {particles} particles x {steps} steps, 2-D, {len(ANCHORS_M)} anchors"
    yield hx.row("SIR particle filter (RssModel, random walk, systematic every step)", work, m,
                 "plain vectorized numpy SIR (broadcast (R, N, m) likelihood, logsumexp, searchsorted)", goal=5,
                 note=f"{runs * particles * steps / m.locbook_wall_s:.3g} particle-steps/s")

    # the fused likelihood against the model's numpy log-likelihood on the same particles
    rng = np.random.default_rng(3)
    x = LOWER_M + (UPPER_M - LOWER_M) * rng.random((runs, particles, 2))
    z = rss[:, 0]
    z_heard = z.copy()
    z_heard[::3, 1] = np.nan                                              # some readings not heard

    def fused():
        return _fused_rss_log_likelihood(model, z_heard, x, 0)

    def numpy_ll():
        return model.log_likelihood(z_heard, x, 0, constant=False)

    def same(a, b):
        rel = float(np.max(np.abs(a - b) / np.maximum(np.abs(b), 1e-300)))
        if rel > 1e-12:
            raise AssertionError(f"max relative difference {rel:.2e} > 1e-12")
        return f"max relative difference {rel:.2e}"

    m = hx.compare(fused, numpy_ll, repeats=repeats, agree=same)
    yield hx.row("fused RSS log-likelihood (one compiled pass)", f"{runs} runs x {particles} particles, "
                 f"{len(ANCHORS_M)} anchors, NaN readings", m, "RssModel.log_likelihood(constant=False)")


def run(size: str = "full"):
    """full: 100 runs x 10,000 particles x 10 steps; tiny: 4 runs x 5,000 particles x 3 steps."""
    if hx.check_size(size) == "tiny":
        return measure(4, 5000, 3)
    return measure(100, 10_000, 10)


if __name__ == "__main__":
    hx.print_rows(run(sys.argv[1] if len(sys.argv) > 1 else "full"))
