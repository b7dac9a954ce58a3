"""Benchmark: seconds per lab-rig record beside the ideal rig's, on the same machine.

One record is 10 levels stepped up, each a 0.1 s ramp and a 2.5 s hold at 10 kHz
(260 000 samples of 20 channels), simulated in memory (engine, sensor noise,
dropouts, channels; writing the text file is the same ``write_record`` path for
both rigs and is timed once apart). The baseline is the ideal rig
(``Rig.preset("trc-like")``: the adaptive-filter PLL simulator, white noise) on
the same schedule. Lab presets: ``lab-pure`` (clean lock-in PLL, linear truth),
``lab-all`` (every artefact), ``lab-iwan`` (12 Jenkins sliders) and
``lab-second-mode`` (two degrees of freedom), each with its levels stepped up
only. Compilation is done before timing; each figure is the best of
``--repeats`` runs (wall clock) with its CPU time beside it: the machine is shared, so
the lab/ideal ratio is taken on CPU time.

Run: ``.venv/bin/python bench/lab_rig.py [--repeats 3]``. Prints a table, then
one JSON line.
"""

from __future__ import annotations

import argparse
import json
import os
import tempfile
import time

import numpy as np

from identification.measurements.records import write_record
from identification.rig import Rig, rig_for_preset

LEVELS = 10
LAB_PRESETS = ("lab-pure", "lab-all", "lab-iwan", "lab-second-mode")
#: The lab engine does more per sample (a second degree of freedom, joints, a detector
#: per channel pair, per-channel noise and dropouts): allow it twice the ideal rig's CPU time
#: (CPU, not wall: on the shared 2-core machine the wall clock measures the neighbours).
TARGET_RATIO = 2.0


def _best(function, repeats: int) -> tuple[float, float]:
    """Best wall time and the CPU time of that run (s)."""
    best = (np.inf, np.inf)
    for _ in range(repeats):
        wall, cpu = time.perf_counter(), time.process_time()
        function()
        wall, cpu = time.perf_counter() - wall, time.process_time() - cpu
        best = min(best, (wall, cpu))
    return best


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--repeats", type=int, default=3)
    args = parser.parse_args()

    ideal = Rig.preset("trc-like", levels=LEVELS)
    model, gain = ideal.draw(np.random.default_rng([0, 1]))
    name = "Config1_PRT_Assemb1"

    def ideal_record():
        return ideal.simulate(model, gain, np.random.default_rng([0, 1, 1]), name)

    ideal_record()  # compile
    figures = {"samples_per_record": int(ideal_record().data.shape[0])}
    wall, cpu = _best(ideal_record, args.repeats)
    figures["ideal_rig_record_s"] = round(wall, 3)
    figures["ideal_rig_record_cpu_s"] = round(cpu, 3)
    rigs = {p: rig_for_preset(p, levels=LEVELS, schedule="up") for p in LAB_PRESETS}
    for preset, rig in rigs.items():
        rig.campaign(assemblies=1)  # compile
        wall, cpu = _best(lambda rig=rig: rig.campaign(assemblies=1), args.repeats)
        key = preset.replace("-", "_")
        figures[f"{key}_record_s"] = round(wall, 3)
        figures[f"{key}_record_cpu_s"] = round(cpu, 3)
        figures[f"{key}_over_ideal_cpu"] = round(cpu / figures["ideal_rig_record_cpu_s"], 2)
        engine, _ = _best(lambda rig=rig: rig.run(rig.nominal), args.repeats)
        figures[f"{key}_engine_us_per_sample"] = round(
            1e6 * engine / figures["samples_per_record"], 2
        )
    record = rigs["lab-all"].campaign(assemblies=1)[0][0]
    with tempfile.TemporaryDirectory(prefix="pm_joint_bench_lab_") as folder:
        wall, _ = _best(lambda: write_record(record, folder, precision=6), 1)
    figures["write_record_s"] = round(wall, 3)
    worst = max(figures[f"{p.replace('-', '_')}_over_ideal_cpu"] for p in LAB_PRESETS)

    print(f"Lab rig: one record of {LEVELS} levels × 2.6 s at 10 kHz, best of {args.repeats}")
    for key, value in figures.items():
        print(f"  {key:<44} {value}")
    print(f"  {'load average (1 min, 2 cores)':<44} {os.getloadavg()[0]:.2f}")
    print(
        json.dumps(
            {
                "bench": "lab_rig",
                **figures,
                "worst_over_ideal_cpu": worst,
                "target_over_ideal_cpu": TARGET_RATIO,
                "baseline": "ideal rig (Rig.preset('trc-like')), same schedule, same machine",
                "paper": None,
            }
        )
    )


if __name__ == "__main__":
    main()
