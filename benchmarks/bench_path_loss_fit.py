"""Path-loss fit on many samples: the closed form (default) at 10 million samples, time and peak memory.

Issue 12 target: memory linear in the samples, well under 1 GB at 10^7 (the cvxpy path needed 5.2 GB at
3.3 * 10^6 and then stopped at optimal_inaccurate). Prints measured figures; not a test.

    python benchmarks/bench_path_loss_fit.py [n_samples]
"""
import sys
import time
import tracemalloc

import numpy as np

import locbook as lb


def main(n: int = 10_000_000) -> None:
    rng = np.random.default_rng(0)
    d = rng.uniform(0.5, 30.0, n)
    p = -45.0 - 10 * 2.2 * np.log10(d) + rng.normal(scale=4.0, size=n)
    p[rng.random(n) < 0.05] = np.nan                     # 5 % not heard
    inputs_mb = (d.nbytes + p.nbytes) / 2**20
    tracemalloc.start()
    t0 = time.perf_counter()
    fit = lb.fit_path_loss(d, p)
    seconds = time.perf_counter() - t0
    _, peak = tracemalloc.get_traced_memory()
    tracemalloc.stop()
    print(f"closed-form path-loss fit, {n:,} samples ({inputs_mb:.0f} MB of inputs): {seconds:.2f} s, "
          f"peak extra memory {peak / 2**20:.0f} MB; P0 = {float(fit.ref_power_dbm):.3f} dBm, "
          f"n = {float(fit.path_loss_exp):.4f}, sigma = {float(fit.residual_sigma_db):.3f} dB, status {fit.status}")


if __name__ == "__main__":
    main(int(sys.argv[1]) if len(sys.argv) > 1 else 10_000_000)
