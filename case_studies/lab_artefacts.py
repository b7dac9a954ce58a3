# ---
# jupyter:
#   jupytext:
#     formats: py:percent
#     text_representation:
#       extension: .py
#       format_name: percent
#   kernelspec:
#     display_name: Python 3
#     language: python
#     name: python3
# ---

# %% [markdown]
# # What today's criticism says about lab measurements
#
# The lab rig (`identification.rig.lab`) writes records as a laboratory measures
# them: a multiply-and-low-pass PLL whose frequency channel ripples, shaker
# distortion, drift, vibrometer dropouts, and joints outside the catalogue. Here
# the backbone extraction and the criticism as they are today meet those records.
#
# * **Null campaigns** (the truth *is* the starting model's structure, only the lab
#   differs): anything proposed is a false discovery.
# * **Out-of-catalogue campaigns** (an Iwan joint, a clearance, a preloaded contact,
#   power-law damping, a second mode): the right answer is "not explained by the
#   catalogue"; a catalogue effect proposed as physics is a false explanation.
#
# The start is what a user would start from: the scenario's base model (for the null
# campaigns the truth's structure) with its coefficients fitted to the backbones.
# Rerun after the criticism changes to see what moved: the table at the end is the
# record. `PM_JOINT_SIZE=small` runs two scenarios on small campaigns.

# %%
import os
import time

import matplotlib

matplotlib.use("Agg")
import matplotlib.pyplot as plt
import numpy as np

from identification.criticism.criticism import criticize
from identification.criticism.plots import plot_comparison
from identification.fitting.least_squares import fit_backbones
from identification.measurements.extraction import extract_backbones
from identification.rig import RIG_PRESETS, rig_for_preset

SMALL = os.environ.get("PM_JOINT_SIZE") == "small"
OUT = os.environ.get("PM_JOINT_OUT", "case_study_output")
os.makedirs(OUT, exist_ok=True)
NULL = ["lab-all"] if SMALL else [
    "lab-pure", "lab-distorted", "lab-ripple", "lab-lock", "lab-drift", "lab-dropouts", "lab-all",
    "lab-all-hardening",
]  # fmt: skip
OUT_OF_CATALOGUE = ["lab-iwan"] if SMALL else [
    "lab-iwan", "lab-clearance", "lab-contact", "lab-power-law-damping", "lab-second-mode",
]  # fmt: skip
ASSEMBLIES, LEVELS, HOLD_S = (2, 4, 1.5) if SMALL else (5, 10, 2.5)
SEED = 0

# %% [markdown]
# ## The scenarios

# %%
for name in NULL + OUT_OF_CATALOGUE:
    print(f"{name}: {RIG_PRESETS[name].description}")

# %% [markdown]
# ## Records → backbones → criticism
#
# Each campaign: `ASSEMBLIES` assemblies in test order (the drift runs over them),
# levels stepped up (and down where the scenario says so).

# %%
rows, criticisms = [], {}
for name in NULL + OUT_OF_CATALOGUE:
    start_s = time.perf_counter()
    rig = rig_for_preset(name, levels=LEVELS, hold_s=HOLD_S)
    records = [record for record, _ in rig.campaign(assemblies=ASSEMBLIES, seed=SEED)]
    measured = extract_backbones(records)
    start = fit_backbones(RIG_PRESETS[name].base_model, measured).model
    crit = criticize(start, measured)
    criticisms[name] = crit
    proposed = crit.missing()
    first = proposed[0] if proposed else None
    rows.append({
        "scenario": name,
        "kind": "null" if name in NULL else "out of catalogue",
        "points": sum(len(c) for c in measured),
        "proposed": len(proposed),
        "first": first.effect if first else "—",
        "delta_bic": first.delta_ic if first else float("nan"),
        "frequency_rmse_hz": (crit.fit.frequency_rmse_hz,
                              first.fit.frequency_rmse_hz if first else float("nan")),
        "damping_rmse_pct": (100 * crit.fit.damping_rmse,
                             100 * first.fit.damping_rmse if first else float("nan")),
        "seconds": time.perf_counter() - start_s,
    })  # fmt: skip
    print(f"--- {name} ({ASSEMBLIES} records)")
    print(crit.summary())

# %% [markdown]
# ## The record
#
# `proposed`: candidates past the ΔBIC threshold (every one of them is a false
# discovery on a null campaign); RMSE pairs are before → after adding the first.

# %%
header = f"{'scenario':<24}{'kind':<18}{'points':>7}{'proposed':>9}  {'first':<30}{'ΔBIC':>10}"
print(header + "  frequency RMSE (Hz)    damping RMSE (%-pt)   time")
for r in rows:
    f0, f1 = r["frequency_rmse_hz"]
    d0, d1 = r["damping_rmse_pct"]
    print(
        f"{r['scenario']:<24}{r['kind']:<18}{r['points']:>7}{r['proposed']:>9}  {r['first']:<30}"
        f"{r['delta_bic']:>10.1f}  {f0:8.4f} → {f1:8.4f}   {d0:7.4f} → {d1:7.4f}  "
        f"{r['seconds']:5.1f} s"
    )
null_rows = [r for r in rows if r["kind"] == "null"]
print(
    f"false discoveries: {sum(r['proposed'] > 0 for r in null_rows)} of {len(null_rows)} null "
    f"campaigns proposed something ({sum(r['proposed'] for r in null_rows)} candidates in all)"
)

# %% [markdown]
# ## Comparison figures: a null campaign and an out-of-catalogue one

# %%
for name in (NULL[-1], OUT_OF_CATALOGUE[0]):
    crit = criticisms[name]
    fig = plt.figure(figsize=(11, 7), layout="constrained")
    plot_comparison(crit, fig.subplots(2, 3 if crit.data.has_harmonics else 2))
    fig.suptitle(f"{name}: the start model against the lab campaign")
    fig.savefig(os.path.join(OUT, f"lab_artefacts_{name}.png"), dpi=100)
    plt.close(fig)
print(np.round([r["seconds"] for r in rows], 1).tolist())
