"""Path-loss fit on many samples: the closed form (default) at 10 million samples, time and peak memory.

The target: memory linear in the samples, well under 1 GB at 10^7 (the cvxpy path needed 5.2 GB at
3.3 * 10^6 and then stopped at optimal_inaccurate). No reference (nothing else fits 10^7 samples in that memory);
the accuracy figure is the fit against the parameters the samples were drawn with, from the timed calls
(``hx.repeat``: 5 calls, medians of CPU and wall time, the peak resident-set increase of each call). Tolerance: each
parameter within 4 of its sampling standard errors (closed form from the design and the sigma drawn); beyond it the
row is a disagreement.

    python benchmarks/bench_path_loss_fit.py [full|tiny|n_samples]
"""
from __future__ import annotations

import sys
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parent))
import _harness as hx  # noqa: E402
import locbook as lb  # noqa: E402

#: the parameters the samples are drawn with
P0_DBM, EXP, SIGMA_DB = -45.0, 2.2, 4.0


def measure(n: int = 10_000_000, repeats: int = hx.MIN_REPEATS):
    rng = np.random.default_rng(0)
    d = rng.uniform(0.5, 30.0, n)
    p = P0_DBM - 10 * EXP * np.log10(d) + rng.normal(scale=SIGMA_DB, size=n)
    p[rng.random(n) < 0.05] = np.nan                     # 5 % not heard
    inputs_mb = (d.nbytes + p.nbytes) / 2**20

    def standard_errors():
        """The sampling standard errors of the least-squares fit, closed form from the design (the heard
        distances) and the sigma drawn: Var(n) = sigma^2 / (100 Sxx), Var(P0) = sigma^2 (1 / N + mean(log10 d)^2 /
        Sxx), and sigma's own sigma / sqrt(2 (N - 2)) (Gaussian residuals)."""
        heard = np.log10(d[~np.isnan(p)])
        sxx = float(np.sum((heard - heard.mean()) ** 2))
        return {"P0": SIGMA_DB * np.sqrt(1 / heard.size + heard.mean() ** 2 / sxx),
                "n": SIGMA_DB / (10 * np.sqrt(sxx)), "sigma": SIGMA_DB / np.sqrt(2 * (heard.size - 2))}

    def accuracy(fit):
        se = standard_errors()
        got = {"P0": float(fit.ref_power_dbm), "n": float(fit.path_loss_exp), "sigma": float(fit.residual_sigma_db)}
        drawn = {"P0": P0_DBM, "n": EXP, "sigma": SIGMA_DB}
        worst = float(np.max([abs(got[k] - drawn[k]) / se[k] for k in got]))       # NaN if a parameter is NaN
        text = (f"P0 = {got['P0']:.3f} dBm (drawn {P0_DBM}), n = {got['n']:.4f} ({EXP}), sigma = {got['sigma']:.3f} "
                f"dB ({SIGMA_DB}), status {fit.status}: at most {worst:.2g} standard errors (tolerance 4)")
        if not worst <= 4:
            raise AssertionError(text)
        return text

    m = hx.repeat(lambda: lb.fit_path_loss(d, p), repeats=repeats, agree=accuracy)
    yield hx.row("closed-form path-loss fit", f"{n:,} samples ({inputs_mb:.0f} MiB of inputs)", m,
                 note="no reference")


def run(size: str = "full"):
    """The benchmark protocol (benchmarks/run_all.py): full = 10^7 samples, tiny = 10^5."""
    return measure(100_000 if hx.check_size(size) == "tiny" else 10_000_000)


if __name__ == "__main__":
    arg = sys.argv[1] if len(sys.argv) > 1 else "full"
    hx.print_rows(measure(int(arg)) if arg.isdigit() else run(arg))
