"""Path-loss fit on many samples: the closed form (default) at 10 million samples, time and peak memory.

Issue 12 target: memory linear in the samples, well under 1 GB at 10^7 (the cvxpy path needed 5.2 GB at
3.3 * 10^6 and then stopped at optimal_inaccurate). Reports measured figures; not a test.

    python benchmarks/bench_path_loss_fit.py [n_samples] [--size tiny]
"""
from __future__ import annotations

import argparse
import sys
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parent))
import _harness as hx  # noqa: E402

import locbook as lb  # noqa: E402


def measure(n: int = 10_000_000) -> list[dict]:
    rng = np.random.default_rng(0)
    d = rng.uniform(0.5, 30.0, n)
    p = -45.0 - 10 * 2.2 * np.log10(d) + rng.normal(scale=4.0, size=n)
    p[rng.random(n) < 0.05] = np.nan                     # 5 % not heard
    inputs_mb = (d.nbytes + p.nbytes) / 2**20
    seconds, _, fit = hx.timed(lambda: lb.fit_path_loss(d, p))
    peak = hx.peak_mb(lambda: lb.fit_path_loss(d, p))
    return [hx.row("closed-form path-loss fit", f"{n:,} samples ({inputs_mb:.0f} MiB of inputs)", seconds, peak=peak,
                   note=f"P0 = {float(fit.ref_power_dbm):.3f} dBm, n = {float(fit.path_loss_exp):.4f}, "
                        f"sigma = {float(fit.residual_sigma_db):.3f} dB, status {fit.status}; no reference")]


def run(size: str = "full") -> list[dict]:
    """The benchmark protocol (benchmarks/run_all.py): full = 10^7 samples, tiny = 10^5."""
    return measure(100_000 if hx.check_size(size) == "tiny" else 10_000_000)


def main():
    ap = argparse.ArgumentParser()
    ap.add_argument("n_samples", type=int, nargs="?", default=10_000_000)
    ap.add_argument("--size", choices=hx.SIZES, default=None, help="the run(size) preset instead of n_samples")
    args = ap.parse_args()
    hx.print_rows(run(args.size) if args.size else measure(args.n_samples))


if __name__ == "__main__":
    main()
