"""Benchmark: reading a long TRC record (500 MB of text) with ``read_record``.

The record is generated once in a temporary folder (not timed) in the rig's
layout: 20 blank-separated columns, time with 10 significant digits, the other
channels with 7 (``precision=6``, as ``Rig.write_campaign`` writes), at 10 kHz.
Each read runs in a fresh child process (so memory is measured from a clean
start) on a file in the page cache: the figure is the parsing speed, not the
disk's.

Memory: the child resets its peak resident set (``echo 5 > /proc/self/clear_refs``,
Linux) after its imports, reads, and reports ``VmHWM − VmRSS`` measured before
the read: the peak RSS increase over the read, against the size of the
returned float64 array. Wall and CPU seconds are both printed: the machine is
shared, and the CPU time shows the cost when other work slows the wall clock.

For comparison the same file is read once with the plain one-call path
(``pandas.read_csv(sep=r"\\s+", dtype=float64).to_numpy()``), what
``read_record`` did before.

Run: ``.venv/bin/python bench/records.py [--size-mb 500] [--repeats 2]``.
Prints a table, then one JSON line. The folder is deleted at the end.
"""

import argparse
import json
import os
import subprocess
import sys
import tempfile
import time
from pathlib import Path

import numpy as np

from identification.measurements.records import StepSchedule

THROUGHPUT_TARGET_MB_S = 100.0
PEAK_TARGET_OVER_ARRAY = 3.0
FS = 10_000.0
BLOCK_ROWS = 65_536

CHILD = r"""
import json, os, resource, sys, time
path, how = sys.argv[1], sys.argv[2]
import numpy as np, pandas as pd
from identification.measurements.records import read_record

def status(key):
    with open("/proc/self/status") as fh:
        for line in fh:
            if line.startswith(key):
                return int(line.split()[1]) * 1024

try:
    with open("/proc/self/clear_refs", "w") as fh:
        fh.write("5")  # reset the peak RSS to the current RSS
    method = "VmHWM after clear_refs"
except OSError:
    method = "ru_maxrss (upper bound: includes the import peak)"
before = status("VmRSS:")
wall, cpu = time.perf_counter(), time.process_time()
if how == "read_record":
    data = read_record(path).data
else:
    data = pd.read_csv(path, sep=r"\s+", header=None, dtype=np.float64, engine="c").to_numpy()
wall, cpu = time.perf_counter() - wall, time.process_time() - cpu
peak = status("VmHWM:") if method.startswith("VmHWM") else resource.getrusage(
    resource.RUSAGE_SELF).ru_maxrss * 1024
print(json.dumps({"wall_s": wall, "cpu_s": cpu, "rows": data.shape[0],
                  "array_bytes": data.nbytes, "peak_increase_bytes": peak - before,
                  "method": method}))
"""


def generate(folder: Path, size_mb: float) -> Path:
    """A record of about ``size_mb`` MB (random velocities, a 10 kHz clock)."""
    rng = np.random.default_rng(0)
    # Formatting 500 MB with np.savetxt takes minutes on this machine: format
    # one block of the 19 data channels and give each repeat its own clock.
    channels = rng.standard_normal((BLOCK_ROWS, 19)) * 1e-3
    channels[:, -2] = 100.0 + rng.random(BLOCK_ROWS)  # frequency (Hz)
    channels[:, -1] = rng.uniform(-180.0, 180.0, BLOCK_ROWS)  # phase (deg)
    rest = [" ".join(f"{v:.6e}" for v in row) for row in channels]
    path = folder / "Config1_PRT_Assemb1"
    rows = 0
    with open(path, "w") as fh:
        while fh.tell() < size_mb * 1e6:
            times = (rows + np.arange(BLOCK_ROWS)) / FS
            fh.write("".join(f"{t:.9e} {r}\n" for t, r in zip(times, rest, strict=True)))
            rows += BLOCK_ROWS
    steps = StepSchedule([0.0, (rows - 1) / FS], [1.0, 1.0])
    (folder / "Config1_PRT_amplitude_steps").write_text(steps.to_text())
    return path


def measure(path: Path, how: str) -> dict:
    env = {**os.environ, "OMP_NUM_THREADS": "1", "PYTHONPATH": str(Path(__file__).parents[1])}
    out = subprocess.run(
        [sys.executable, "-c", CHILD, str(path), how],
        check=True,
        capture_output=True,
        text=True,
        env=env,
    )
    return json.loads(out.stdout.strip().splitlines()[-1])


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--size-mb", type=float, default=500.0)
    parser.add_argument("--repeats", type=int, default=2)
    args = parser.parse_args()
    with tempfile.TemporaryDirectory(prefix="pm_joint_bench_records_") as tmp:
        start = time.perf_counter()
        path = generate(Path(tmp), args.size_mb)
        generate_s = time.perf_counter() - start
        size_mb = path.stat().st_size / 1e6
        runs = [measure(path, "read_record") for _ in range(args.repeats)]
        baseline = measure(path, "pandas")
    best = min(runs, key=lambda r: r["wall_s"])
    array_mb = best["array_bytes"] / 1e6
    figures = {
        "file_mb": round(size_mb, 1),
        "rows": best["rows"],
        "array_mb": round(array_mb, 1),
        "read_s": round(best["wall_s"], 3),
        "read_mb_s": round(size_mb / best["wall_s"], 1),
        "read_mb_s_all_runs": [round(size_mb / r["wall_s"], 1) for r in runs],
        "read_mb_per_cpu_s": round(size_mb / best["cpu_s"], 1),
        "peak_rss_increase_mb": round(max(r["peak_increase_bytes"] for r in runs) / 1e6, 1),
        "peak_over_array": round(max(r["peak_increase_bytes"] for r in runs) / 1e6 / array_mb, 3),
        "baseline_pandas_one_call_mb_s": round(size_mb / baseline["wall_s"], 1),
        "baseline_pandas_one_call_mb_per_cpu_s": round(size_mb / baseline["cpu_s"], 1),
        "baseline_pandas_one_call_peak_over_array": round(
            baseline["peak_increase_bytes"] / baseline["array_bytes"], 3
        ),
    }
    load = os.getloadavg()[0]
    print(f"TRC record read benchmark ({size_mb:.0f} MB generated in {generate_s:.0f} s, untimed)")
    for name, value in figures.items():
        print(f"  {name:<44} {value}")
    print(f"  {'memory method':<44} {best['method']}")
    print(f"  {'load average (1 min, 2 cores)':<44} {load:.2f}")
    print(
        json.dumps(
            {
                "bench": "records",
                **figures,
                "read_target_mb_s": THROUGHPUT_TARGET_MB_S,
                "peak_target_over_array": PEAK_TARGET_OVER_ARRAY,
                "memory_method": best["method"],
                "load_average_1min": round(load, 2),
            }
        )
    )


if __name__ == "__main__":
    main()
