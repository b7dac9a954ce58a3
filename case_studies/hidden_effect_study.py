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
# # Which physics is the model missing? The criticism loop on hidden effects
#
# The virtual rig writes test records of a jointed panel whose ground truth
# contains effects the starting model lacks. The loop compares the model with
# the measured backbones, says where it fails, ranks the catalogue effects by
# how much they would reduce the misfit (penalised by BIC), adds the best one
# and repeats until nothing significant is missing.
#
# `PM_JOINT_SIZE=small` runs one scenario; the default runs two, including
# the one with two hidden effects at once.

# %%
import os

import matplotlib

matplotlib.use("Agg")
import matplotlib.pyplot as plt

from identification.criticism.plots import plot_comparison, plot_history
from identification.rig import RIG_PRESETS
from studies import criticism_study

SMALL = os.environ.get("PM_JOINT_SIZE") == "small"
OUT = os.environ.get("PM_JOINT_OUT", "case_study_output")
os.makedirs(OUT, exist_ok=True)
SCENARIOS = ["hidden-microslip"] if SMALL else ["hidden-microslip", "hidden-two"]

# %% [markdown]
# ## The scenarios: ground truth and the model a user would start from

# %%
for name in SCENARIOS:
    preset = RIG_PRESETS[name]
    print(f"{name}: {preset.description}")
    print(f"  truth: {preset.model.equation()}")
    print(f"  start: {preset.base_model.equation()}")

# %% [markdown]
# ## The loop
#
# Each round prints where the model fails and the ranked candidates; the
# effect ranked first is added and everything refitted.

# %%
results = {}
for name in SCENARIOS:
    result = criticism_study(name, seed=0, assemblies=3, levels=6 if SMALL else 8)
    results[name] = result
    for k, crit in enumerate(result.criticisms):
        print(f"--- {name}, round {k}: {crit.model.equation()}")
        print(crit.summary())
    print(f"hidden: {list(result.hidden)}; added: {result.added}")

# %% [markdown]
# ## Before and after, and the error history

# %%
for name, result in results.items():
    first, last = result.criticisms[0], result.criticisms[-1]
    for label, crit in (("start", first), ("end", last)):
        fig = plt.figure(figsize=(11, 7), layout="constrained")
        columns = 3 if crit.data.has_harmonics else 2
        plot_comparison(crit, fig.subplots(2, columns))
        fig.suptitle(f"{name}: {label}")
        fig.savefig(os.path.join(OUT, f"{name}_{label}.png"), dpi=100)
    fig, ax = plt.subplots(figsize=(7, 4), layout="constrained")
    plot_history(last.history, ax)
    ax.set_title(f"{name}: the error falls as the missing effects are added")
    fig.savefig(os.path.join(OUT, f"{name}_history.png"), dpi=100)
