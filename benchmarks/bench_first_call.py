"""What the first call of each compiled filter family costs: with an empty kernel cache (a fresh install, a CI run, a
new machine), with a warm cache (a new process on a machine that has run it before), and the second call in the same
process, each against the steady state (the median of later calls).

    python benchmarks/bench_first_call.py [full|tiny]

Each figure comes from a fresh interpreter (``python -c``), so nothing is loaded before the call: the "empty cache"
process gets ``NUMBA_CACHE_DIR`` pointing at a new empty folder (numba compiles every kernel the call reaches and
writes it there); the "warm cache" process reuses that folder. Inside each process the inputs are built first (not
timed), then the calls are timed one by one (wall: ``perf_counter``; CPU: ``process_time``). The workloads are the
benchmarks' own (bench_dogan_filters' parallel EKF at 500 runs, bench_ukf_speed's U-path UKF at 500 runs,
bench_particle's filter at 100 runs x 10,000 particles x 10 steps, bench_grid's grid filter at 36,000 cells). The
goal: a first call within 10 s wall with an empty cache and within 0.5 s with a warm one, the second call
at the steady state.
"""
from __future__ import annotations

import json
import os
import subprocess
import sys
import tempfile
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parent))
import _harness as hx  # noqa: E402

HERE = Path(__file__).resolve().parent

#: the setup of each family's call (code run in the fresh process; it defines ``call``), full and tiny sizes
FAMILIES = {
    "parallel EKF": ("import bench_dogan_filters as b\ns = b.setting({runs})\n"
                     "call = lambda: b.locbook_filter('parallel_ekf', s)", {"full": 500, "tiny": 20}),
    "UKF": ("import bench_ukf_speed as b\nst = b.setting({runs})\ncall = lambda: b.locbook_ukf(st, 0.5)",
            {"full": 500, "tiny": 20}),
    "particle filter": ("import numpy as np, locbook as lb, bench_particle as b\n"
                        "model, rss, truth = b.scenario({runs}, 10)\n"
                        "call = lambda: lb.particle_filter(rss, model, rng=np.random.default_rng(1), "
                        "n_particles=10000, region_m=(b.LOWER_M, b.UPPER_M), spread_m=b.SPREAD_M)",
                        {"full": 100, "tiny": 4}),
    "grid Bayes filter": ("import numpy as np, locbook as lb, bench_grid as b\n"
                          "model = lb.RssModel(b.ANCHORS_M, b.CHANNEL)\nxs, ys, cells = b._grid(0.1)\n"
                          "rss = b._readings({runs}, 30, np.random.default_rng(31))\n"
                          "call = lambda: lb.grid_bayes_filter(rss, model, cells, b.SPREAD_M)",
                          {"full": 12, "tiny": 2}),
}

_TIMER = ("import sys, time, json\nsys.path.insert(0, {here!r})\n{setup}\nout = []\n"
          "for _ in range({calls}):\n"
          "    t, c = time.perf_counter(), time.process_time()\n    call()\n"
          "    out.append((time.perf_counter() - t, time.process_time() - c))\n"
          "print(json.dumps(out))")


def _calls(setup: str, cache: str, calls: int) -> list[tuple[float, float]]:
    env = {**os.environ, "NUMBA_CACHE_DIR": cache}
    code = _TIMER.format(here=str(HERE), setup=setup, calls=calls)
    done = subprocess.run([sys.executable, "-c", code], env=env, capture_output=True, text=True, check=True)
    return [tuple(x) for x in json.loads(done.stdout.strip().splitlines()[-1])]


def run(size: str = "full"):
    """Rows per family (tiny: the grid filter alone, the quickest to compile, at a small size): the first call with an
    empty cache, with a warm one, and the second call, each timed once in its own process, the steady state in the
    note (not a paired ratio: each is one call)."""
    size = hx.check_size(size)
    calls = 3 if size == "tiny" else 6
    families = {"grid Bayes filter": FAMILIES["grid Bayes filter"]} if size == "tiny" else FAMILIES
    for family, (setup, runs) in families.items():
        code = setup.format(runs=runs[size])
        load0 = hx._load()
        with tempfile.TemporaryDirectory(prefix="locbook-numba-") as cache:
            empty = _calls(code, cache, calls)
            warm = _calls(code, cache, calls)
        load1 = hx._load()
        later = sorted(warm[2:])
        steady_wall, steady_cpu = later[len(later) // 2]
        workload = f"{family}, bench's workload ({runs[size]} runs)"
        for label, (wall, cpu), goal_s in (("first call, empty kernel cache", empty[0], 10.0),
                                           ("first call, warm kernel cache", warm[0], 0.5),
                                           ("second call (warm cache)", warm[1], None)):
            m = hx.Measurement(wall, cpu, (wall, wall), 1, None, load=(load0, load1))
            goal = "" if goal_s is None else (f"goal <= {goal_s:g} s wall: " + ("met" if wall <= goal_s else "MISSED")
                                              + "; ")
            yield hx.row(label, workload, m, note=f"{goal}{wall / steady_wall:.3g}x the steady state "
                                                  f"({steady_wall:.3g} s wall, {steady_cpu:.3g} s CPU)")


def main():
    hx.print_rows(run(sys.argv[1] if len(sys.argv) > 1 else "full"))


if __name__ == "__main__":
    main()
