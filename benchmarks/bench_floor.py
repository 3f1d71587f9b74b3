"""How far the compiled filters are from their arithmetic floor (the goal: "EKF and UKF within 5x of their
arithmetic floor per run-step").

    python benchmarks/bench_floor.py [full|tiny]

The floor of a workload is its floating-point operation count divided by the rate this machine attains on the same
data layout. Both are stated here so that the figure can be checked:

- The count (:func:`ekf_step_flops`) is the arithmetic of the algorithm the kernel implements, counted at its minimum:
  a multiply-add is 2 operations, a division, square root or logarithm 1 (so the floor is optimistic for the
  transcendental functions), only the nonzero entries of F and H are used, and symmetric results are computed as
  one triangle. The kernel's Joseph-form update ``P - K (H P) + (K S - P H^T) K^T`` is counted as written (it is
  the update the library chose for its numerical properties; the cheaper ``P - K H P`` would lower the floor by the
  ``(K S - P H^T) K^T`` term).
- The rate is measured here, in the same process, by a compiled kernel doing batched 6 x 6 matrix products in the
  filters' layout (runs side by side on the innermost axis, ``W`` of them): the rate of well-vectorised multiply-adds
  on data that stays in cache, i.e. the best the filters' inner loops can reach. It is measured at the lane width
  where the kernel runs fastest (:func:`_harness.best_lane_width`, of 64, 128, 256 and 512 lanes; 256 here, the
  filters' own block width) for every workload: a batch of 10 runs has the same floor per run-step as one of 500 (a
  small batch that fills fewer lanes pays for that in the ratio, not in a lower floor).
- The rate moves with the machine's state (a burst of calls starts slow here, and the attainable rate differed by
  1.5x between runs of the same machine), so the product kernel is the row's paired reference: it alternates with
  the filter call in one process (:func:`_harness.compare`), each of its calls about as long as one filter call, and
  the floor is the count at the rate of the same repeats. Short calls get more repeats (about a second of each).
  Its arrays start on a 64-byte boundary (:func:`_harness.aligned`): at other offsets the same kernel ran at 11.1
  instead of 18.3 Gop/s here (AVX-512 loads across two cache lines), and numpy's placement decided which.

The row's ratio is floor / locbook: at least 0.2 means within 5x of the floor. The goal is read at the issue's own
workload (500 runs: "the whole workload is 0.05-0.1 s of arithmetic"); the 10-run rows are shown without one.
"""
from __future__ import annotations

import dataclasses
import sys
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parent))
import _harness as hx  # noqa: E402
import bench_dogan_filters as bd  # noqa: E402

try:
    import numba
except ImportError:                     # numba is a dependency of locbook; this only guards a broken install
    numba = None


def _rate_kernel(A, B, C, reps):
    """``reps`` times C = A B for 6 x 6 matrices, ``W`` of them side by side on the last axis (2 * 6^3 operations per
    product and lane)."""
    n, W = A.shape[0], A.shape[2]
    for _ in range(reps):
        for i in range(n):
            for j in range(n):
                for w in range(W):
                    C[i, j, w] = 0.0
                for k in range(n):
                    for w in range(W):
                        C[i, j, w] += A[i, k, w] * B[k, j, w]
        for i in range(n):                  # feed C back so that the loop is not optimised away
            for w in range(W):
                A[i, i, w] = 0.5 * A[i, i, w] + 1e-3 * C[i, i, w]
    return C[0, 0, 0]


# compiled in memory (no disk cache: run_all loads this file under a module name of its own, which numba's cache
# records and a later process loading the file otherwise could not import)
_rate_compiled = numba.njit(nogil=True, error_model="numpy")(_rate_kernel) if numba else _rate_kernel


def rate_call(width: int, seconds: float):
    """``(call, operations)``: a call of the compiled 6 x 6 products at ``width`` lanes lasting about ``seconds``, and
    the operations it does (2 * 6^3 per product and lane)."""
    rng = np.random.default_rng(0)
    A, B, C = (hx.aligned(rng.standard_normal((6, 6, width))) for _ in range(3))
    _rate_compiled(A, B, C, 1)              # compile
    per_rep = 2.0 * 6**3 * width
    reps = max(1, int(seconds * 1e10 / per_rep))
    return (lambda: _rate_compiled(A, B, C, reps)), reps * per_rep


def update_flops(n: int, m: int, k: int) -> int:
    """One Kalman update with ``m`` rows of ``k`` nonzeros each, state size ``n`` (Cholesky of S, the Joseph form as
    the kernel writes it; symmetric products as one triangle)."""
    tri_n, tri_m = n * (n + 1) // 2, m * (m + 1) // 2
    return (2 * m * k                       # innovation z - H x
            + 2 * m * k * n                 # H P
            + 2 * k * tri_m + tri_m         # H P H^T + R
            + m**3 // 3 + 2 * m             # Cholesky (m square roots)
            + 2 * m * m * n + m * n         # K^T = S^-1 H P (two triangular solves)
            + 2 * n * m                     # x += K nu
            + 2 * m * m + m                 # NIS, log det
            + 2 * n * m * m                 # K S
            + 2 * 2 * m * tri_n)            # - K (H P) + (K S - P H^T) K^T, one triangle


def predict_flops(F: np.ndarray, n_q_entries: int) -> int:
    """``x = F x``, ``P = F P F^T + Q`` with F's nonzeros, one triangle of the result."""
    n = F.shape[0]
    nnz = int(np.count_nonzero(F))
    upper = sum(i + 1 for i, _ in zip(*np.nonzero(F)))            # (F P) F^T: row i of F feeds columns a <= i
    return 2 * nnz + 2 * nnz * n + 2 * upper + n_q_entries


RSS_ROW_FLOPS = 2 * 2 + 1 + 1 + 4 + 2 * 2       # squared distance, sqrt, log10, mean, Jacobian (2-D)


def ekf_step_flops(name: str, s: dict) -> float:
    """Operations per run-step of the Dogan setting's filter ``name`` (averaged over the steps: the accelerometer at
    every step, the 4 RSS readings at one step in ten)."""
    F = s["model"].F
    n = F.shape[0]
    steps, epochs = s["tr"].time_s.size, s["tr"].rss_steps.size
    per_step = predict_flops(F, n * (n + 1) // 2) + update_flops(n, 2, 1)
    if name == "serial_ekf":
        rss = 4 * (update_flops(n, 1, 2) + RSS_ROW_FLOPS)
    elif name == "parallel_ekf":
        rss = update_flops(n, 4, 2) + 4 * RSS_ROW_FLOPS
    else:                                                       # KF: the MLE fix, 2 rows of 1 nonzero
        rss = update_flops(n, 2, 1)
    return per_step + rss * epochs / steps


SIZES = {"full": [500, 10], "tiny": [4]}


def run(size: str = "full"):
    """The benchmark protocol (benchmarks/run_all.py): the serial and parallel EKF at 500 and 10 runs (tiny: 4) on the
    Dogan setting against their floor, the product kernel timed alternately with each filter call. A batch narrower
    than 64 runs also gets a row without a goal: the floor at the rate the same product kernel attains with as many
    lanes as runs (how much of the gap the layout itself costs a small batch). The goal's lane width is the fastest
    of a scan (:func:`_harness.best_lane_width`)."""
    best, rates = hx.best_lane_width(_rate_at)
    scan = ", ".join(f"{w}: {r / 1e9:.1f}" for w, r in rates.items())
    for runs in SIZES[hx.check_size(size)]:
        s = bd.setting(runs)
        T = s["tr"].time_s.size
        for name in ("serial_ekf", "parallel_ekf"):
            for width in (best, runs) if runs < 64 else (best,):
                yield _floor_row(name, s, runs, T, width, best, scan)


def _rate_at(width: int) -> float:
    """The product kernel's rate at ``width`` lanes, operations per second (median of 3 calls of about 50 ms)."""
    call, ops = rate_call(width, 0.05)
    call()
    return ops / float(np.median([hx.call(call, memory=False).cpu_s for _ in range(3)]))


def _floor_row(name: str, s: dict, runs: int, T: int, width: int, best: int, scan: str) -> dict:
    """One row: the filter ``name`` on ``runs`` runs against its floor at the rate of ``width`` lanes (``best``: the
    goal's width; ``scan``: the rates of the scan that chose it, Gop/s by width)."""
    flops = ekf_step_flops(name, s)
    total = flops * runs * T
    with bd._path(True):
        bd.locbook_filter(name, s)                          # load the kernel
        first = hx.call(lambda: bd.locbook_filter(name, s), memory=False).cpu_s
        call, ops = rate_call(width, first)
        m = hx.compare(lambda: bd.locbook_filter(name, s), call, reference_scale=total / ops, memory=False,
                       repeats=min(101, max(hx.MIN_REPEATS, int(1.0 / max(first, 1e-3)))))
    rate = ops / (m.reference_cpu_s / m.reference_scale)
    m = dataclasses.replace(m, reference_scale=1.0)          # the reference times are the floor's
    m.agreement = (f"{flops:.0f} operations per run-step; {m.locbook_cpu_s / (runs * T) * 1e9:.0f} ns per "
                   f"run-step measured, floor {m.reference_cpu_s / (runs * T) * 1e9:.1f} ns")
    label, workload = bd.LABELS[name] + ", compiled", f"{runs} runs x {T} steps"
    if width == best:
        small = runs < 64
        return hx.row(label, workload, m,
                      f"arithmetic floor at {rate / 1e9:.1f} Gop/s ({width} lanes, measured alternately)",
                      goal=None if small else 0.2,
                      note=f"ratio = floor / locbook; the rate at its best lane width (Gop/s by lanes: {scan})"
                           + ("; no goal: the issue's floor goal is read at its own workload, 500 runs (its text: "
                              "'the whole workload is 0.05-0.1 s of arithmetic'); this batch cannot fill the lanes "
                              "(next row)" if small else ""))
    return hx.row(label, workload, m, f"floor at the product kernel's rate with {width} lanes, {rate / 1e9:.1f} Gop/s "
                  "(measured alternately)", note=f"ratio = floor / locbook; not the goal's floor ({best} lanes): what "
                  f"the layout itself attains with {width} runs side by side")


if __name__ == "__main__":
    hx.print_rows(run(sys.argv[1] if len(sys.argv) > 1 else "full"))
