"""Benchmark: the main demo (``pm-joint demo``, full size), wall and CPU seconds per stage.

Runs :func:`pm_joint.demo.run_demo` once in a temporary folder and times every stage it
prints: the wall clock, and the CPU seconds of this process and of every process it
starts (the campaign's writer pool, PyMC's chain processes), read by a thread that samples
the process tree every half second (a worker's last half second before it exits may be
missed). The machine is shared: the CPU seconds show the work where other jobs slow the
wall clock; the target is a wall figure on a quiet machine with a warm numba cache (run it
twice after an install, report the second). Each posterior's convergence verdict is
printed beside the times: a faster demo counts only where every verdict is still reached.

Target (issue #27, item 8): the whole demo ≤ 330 s; baseline 6 min 34 s (394 s) measured
on the development machine, 2026-11-26 (docs/demo.md).

Run: ``.venv/bin/python bench/demo_speed.py [--out FOLDER]``. Prints a table, then one
JSON line, and writes ``bench/results/demo_speed.json``.
"""

from __future__ import annotations

import argparse
import json
import os
import tempfile
import threading
import time
from pathlib import Path
from typing import NamedTuple

import psutil

from pm_joint import demo

TARGET_S = 330.0
BASELINE_S = 394.0
RESULTS = Path(__file__).parent / "results"


class _TreeClock:
    """CPU seconds of this process and of every process it started, dead ones included."""

    def __init__(self, period_s: float = 0.5) -> None:
        self._me = psutil.Process()
        self._children: dict[int, float] = {}
        self._lock = threading.Lock()
        self._stop = threading.Event()
        self._thread = threading.Thread(target=self._poll, args=(period_s,), daemon=True)
        self._thread.start()

    def _sample(self) -> None:
        for child in self._me.children(recursive=True):
            try:
                times = child.cpu_times()
            except psutil.Error:
                continue  # gone between listing and reading: its last sample stands
            with self._lock:
                self._children[child.pid] = times.user + times.system

    def _poll(self, period_s: float) -> None:
        while not self._stop.wait(period_s):
            self._sample()

    def seconds(self) -> float:
        self._sample()
        with self._lock:
            children = sum(self._children.values())
        return time.process_time() + children

    def close(self) -> None:
        self._stop.set()
        self._thread.join()


class TimedDemo(NamedTuple):
    """One timed demo run: its result, whole wall and CPU seconds, and per stage."""

    result: demo.DemoResult
    wall_s: float
    cpu_s: float
    stage_wall_s: dict[str, float]
    stage_cpu_s: dict[str, float]


def timed_demo(out: Path, **options) -> TimedDemo:
    """:func:`pm_joint.demo.run_demo` into ``out`` (``options`` passed on), timed: the
    demo's own stage timer, CPU seconds of the process tree beside it."""
    clock = _TreeClock()
    cpu_s: dict[str, float] = {}
    timed = demo._Stages.run

    def run(self, name, function, *a, **k):
        start = clock.seconds()
        result = timed(self, name, function, *a, **k)
        cpu_s[name] = round(clock.seconds() - start, 1)
        return result

    demo._Stages.run = run
    try:
        wall, cpu = time.perf_counter(), clock.seconds()
        result = demo.run_demo(out, **options)
        wall, cpu = time.perf_counter() - wall, clock.seconds() - cpu
    finally:
        demo._Stages.run = timed
        clock.close()
    wall_s = json.loads((out / "timings.json").read_text())
    return TimedDemo(result, wall, cpu, wall_s, cpu_s)


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--out", help="keep the demo's folder here (default: a temporary one)")
    args = parser.parse_args()
    with tempfile.TemporaryDirectory(prefix="pm_joint_bench_demo_") as tmp:
        result, wall, cpu, wall_s, cpu_s = timed_demo(Path(args.out or tmp))
    load = os.getloadavg()[0]
    print("Main demo (pm-joint demo, full size): wall and CPU seconds per stage")
    for name, seconds in wall_s.items():
        print(f"  {name:<24} {seconds:8.1f} s wall {cpu_s.get(name, float('nan')):8.1f} s CPU")
    print(f"  {'whole demo':<24} {wall:8.1f} s wall {cpu:8.1f} s CPU")
    for name, verdict in result.verdicts.items():
        print(f"  {name}: {verdict['headline']}")
    print(f"  load average (1 min): {load:.2f}")
    figures = {
        "bench": "demo_speed",
        "demo_wall_s": round(wall, 1),
        "demo_cpu_s": round(cpu, 1),
        "stage_wall_s": wall_s,
        "stage_cpu_s": cpu_s,
        "converged": result.converged,
        "verdicts": {k: v["headline"] for k, v in result.verdicts.items()},
        "target_wall_s": TARGET_S,
        "baseline_wall_s": BASELINE_S,
        "load_average_1min": round(load, 2),
    }
    RESULTS.mkdir(exist_ok=True)
    (RESULTS / "demo_speed.json").write_text(json.dumps(figures, indent=1) + "\n")
    print(json.dumps(figures))


if __name__ == "__main__":
    main()
