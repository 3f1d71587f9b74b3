"""Time and peak memory of a data set of 10^7 readings: the loader (manifest, long-format checks, windowing to
epochs) and the measured-data battery (calibration fit, every static method on every scored epoch, every tracker on
one track).

    python benchmarks/bench_dataset_scale.py [full|tiny] [--readings 10000000]

The data set is the synthetic example of ``locbook data example`` (raw packets at 4 Hz per anchor, 8 anchors, a
calibration survey, 12 static points, two walks) with walks long enough for the number of readings asked for.
Each stage runs in a fresh Python process and reports its wall time and the process's peak resident memory
(``ru_maxrss``: everything the process held, Python objects, pandas and numpy included, not only traced
allocations); the target is 4 GiB for each. Each stage is timed once (one process each; the harness's ``once`` in
spirit, with the child's own clocks: wall, CPU, peak RSS). The suite's full size is 2 x 10^5 readings (the
battery's trackers step through every tick in Python: 10^7 readings take about 15 minutes); the goal's figure is
``--readings 10000000``.
"""
from __future__ import annotations

import argparse
import json
import os
import subprocess
import sys
import tempfile
import textwrap
import time
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parent))
import _harness as hx  # noqa: E402

#: readings per second of walking in the example (both walks together): 8 anchors x 4 Hz x 2 walks, ~88 % kept
_READINGS_PER_WALK_S = 8 * 4.0 * 2 * 0.88
#: readings of the full size (the goal's 10^7 take about 15 minutes: ``--readings 10000000``)
FULL_READINGS = 200_000
#: readings of the example's survey and static points (independent of the walks)
_FIXED_READINGS = 11_700

_LOAD = """
import json, resource, time
t, c = time.perf_counter(), time.process_time()
from locbook.data.dataset import load_dataset
ds = load_dataset(FOLDER)
n_readings = sum(int(r.readings["rssi_dbm"].notna().sum()) for r in ds.recordings.values())
n_epochs = sum(len(ds.epochs(name)) for name in ds.recordings)
print(json.dumps({"seconds": time.perf_counter() - t, "cpu_s": time.process_time() - c, "readings": n_readings,
                  "epochs": n_epochs,
                  "peak_mb": resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024}))
"""

_BATTERY = """
import json, resource, time
import numpy as np
t0, c0 = time.perf_counter(), time.process_time()
from locbook.data.dataset import load_dataset
from locbook.scenarios import measured as me
ds = load_dataset(FOLDER)
steps = {"load": time.perf_counter() - t0}
t = time.perf_counter()
model = me.channel(me.calibrate(ds))
steps["calibrate"] = time.perf_counter() - t
t = time.perf_counter()
proto = me.protocol(ds, model, grid_spacing_m=GRID, knn_k=5, q=0.05, spread_m=1.0)
static = me.static_results(ds, model, proto, seed=1, n_bootstrap=2, block_s=10.0)
n_fixes = sum(len(v) for fixes in static["fixes"].values() for v in fixes.values())
steps["static fixes"] = time.perf_counter() - t
t = time.perf_counter()
tracking = me.tracking_results(ds, model, proto, seed=1, n_particles=PARTICLES, particle_runs=1, n_bootstrap=2,
                               block_s=10.0, recordings=["walk_a"])
reg = tracking["tracks"]["walk_a"][0].measured_rss_dbm
steps["trackers (walk_a)"] = time.perf_counter() - t
print(json.dumps({"steps": steps, "cpu_s": time.process_time() - c0, "fixes": n_fixes, "ticks": len(reg),
                  "peak_mb": resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024}))
"""


def _stage(code: str, **values) -> dict:
    for key, value in values.items():
        code = code.replace(key, repr(value))
    out = subprocess.run([sys.executable, "-c", textwrap.dedent(code)], capture_output=True, text=True, check=False)
    if out.returncode != 0:
        raise RuntimeError(out.stderr.strip().splitlines()[-1] if out.stderr.strip() else f"exit {out.returncode}")
    return json.loads(out.stdout.strip().splitlines()[-1])


def _once(seconds: float, cpu_s: float, peak_mb: float, load) -> hx.Measurement:
    """A stage measured once in its own process (its wall and CPU time and peak RSS, as the child reported them)."""
    return hx.Measurement(seconds, cpu_s, (seconds, seconds), 1, peak_mb, load=load)


def run(size: str = "full", readings: int | None = None):
    """full: 2 x 10^5 readings (10^7, the goal's figure, takes about 15 minutes: ``--readings 10000000``); tiny: 3 x
    10^4. Each stage timed once, in its own process."""
    hx.check_size(size)
    import numpy as np

    from locbook.data.example import write_example_dataset

    target = readings or (FULL_READINGS if size == "full" else 30_000)
    walk_s = max(30.0, (target - _FIXED_READINGS) / _READINGS_PER_WALK_S)
    grid, particles = (0.25, 500) if size == "full" else (0.5, 100)
    with tempfile.TemporaryDirectory() as tmp:
        folder = str(Path(tmp) / "scale")
        t = time.perf_counter()
        write_example_dataset(folder, np.random.default_rng(1), walk_s=walk_s)
        seconds = time.perf_counter() - t
        size_mb = sum(p.stat().st_size for p in Path(folder).glob("*.csv")) / 2**20
        load0 = os.getloadavg()[0]
        load = _stage(_LOAD, FOLDER=folder)
        workload = f"{load['readings']:,} readings ({size_mb:,.0f} MiB of CSV) -> {load['epochs']:,} epochs"
        yield hx.row("load_dataset + epochs", workload, _once(load["seconds"], load["cpu_s"], load["peak_mb"],
                                                              (load0, os.getloadavg()[0])),
                     note=f"peak = the process's peak RSS (not an increase; target 4 GiB); writing the example took "
                          f"{seconds:.0f} s; no reference")
        load0 = os.getloadavg()[0]
        battery = _stage(_BATTERY, FOLDER=folder, GRID=grid, PARTICLES=particles)
        total = sum(battery["steps"].values())
        detail = ", ".join(f"{k} {v:.1f} s" for k, v in battery["steps"].items())
        yield hx.row("measured battery", f"{workload}; {battery['fixes']:,} static fixes, a {battery['ticks']:,}-tick "
                     f"track, grid {grid} m, {particles} particles",
                     _once(total, battery["cpu_s"], battery["peak_mb"], (load0, os.getloadavg()[0])),
                     note=f"peak = the process's peak RSS (load included; target 4 GiB); {detail}; no reference")


if __name__ == "__main__":
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("size", nargs="?", choices=hx.SIZES, default="full")
    parser.add_argument("--readings", type=int, help="readings to generate (default 2 x 10^5; tiny: 3 x 10^4)")
    args = parser.parse_args()
    hx.print_rows(run(args.size, args.readings))
