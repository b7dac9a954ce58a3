"""Diagnosis: why the surrogate's error at the grid ends of the ±50 % box misses its yardstick.

No network is trained; what is measured (on the demo campaign of
``bench/surrogate.py``, its cache in ``--workdir``):

1. **Rows and degree.** The amplitude-grid dataset of the ±50 % box at each
   ``--n-curves``: the training rows with a backbone at each grid amplitude, the
   degree the cubic regression (the baseline, and the head the network learns
   the residual of, fitted on the same rows) carries there
   (:attr:`~surrogates.baselines.PolynomialBaseline.carried_degree`), and its test
   RMSE per amplitude beside the linear one's.
2. **The fold.** At the top amplitude, the cubic's test error against how close
   each curve is to its fold (the rise of the base-acceleration level over the
   last grid step, in terciles) and whether the curve has a masked amplitude.
3. **The yardstick.** The measured curves that cover each end of the grid: their
   spread at the end and at amplitudes every curve covers, beside all curves'
   spread there (is the 3-curve scatter the assembly scatter, or that of a
   selected subset?), and the χ² 95 % interval of σ / s for 3 curves.
4. **The decay rate.** The damping ratio through ``σ = 2π f ζ``
   (:func:`~surrogates.nets.to_decay_rate`, what ``damping_target="decay_rate"``
   trains on): a cubic and a quartic fitted to σ, ζ recovered over the fit's own
   frequency or the true one, beside the same degree fitted to ζ.

Prints tables, then ONE JSON line.

    .venv/bin/python bench/surrogate_ends.py [--n-curves 475,2000]
"""

from __future__ import annotations

import argparse
import itertools
import json
import math
from pathlib import Path

import numpy as np
from surrogate import CHANNELS, demo_front, scatter_interval

from identification.model import parameter_bounds
from surrogates.baselines import ROWS_PER_COEFFICIENT, PolynomialBaseline
from surrogates.dataset import generate_dataset
from surrogates.evaluate import channel_errors
from surrogates.grid import assembly_scatter, measured_grid, measured_on_grid
from surrogates.nets import to_decay_rate


def rows_and_degrees(model, names, grid, scatter, n_curves: int) -> dict:
    """Items 1 and 2 for one dataset size (the bench's seed and splits)."""
    data = generate_dataset(
        model, names, n_curves, representation="amplitude_grid",
        bounds=parameter_bounds(model, names, 0.5), amplitude_range_m=grid.range_m,
        n_levels=grid.amplitudes_m.size, seed=0, progress=False,
    ).with_splits(0.1, 0.1, seed=0)  # fmt: skip
    train, test = data.in_split("train"), data.in_split("test")
    weights = data.loss_weights()
    fits = {d: PolynomialBaseline.fit(data.spec, data.X[train], data.Y[train], weights[train], d)
            for d in (1, 3)}  # fmt: skip
    truth, used = data.Y[test], weights[test] > 0
    predicted = {d: fit.predict(data.X[test]) for d, fit in fits.items()}
    errors = {d: channel_errors(p, truth, weights[test], data.spec) for d, p in predicted.items()}
    out = {
        "n_curves": n_curves,
        "train_rows_per_level": (weights[train][..., 0] > 0).sum(axis=0).tolist(),
        "cubic_rows_needed": ROWS_PER_COEFFICIENT * math.comb(len(names) + 3, 3),
        "cubic_degree_per_level": fits[3].carried_degree[:, 0].tolist(),
    }
    for index, channel in enumerate(CHANNELS):
        for degree, name in ((1, "linear"), (3, "cubic")):
            rmse = np.array(errors[degree][channel]["rmse_per_level"], dtype=float)
            out[f"{channel}_rmse_per_level_{name}"] = rmse.tolist()
            out[f"{channel}_{name}_to_scatter_per_level"] = (rmse / scatter[:, index]).tolist()
    # Item 4: the damping through the decay rate σ = 2π f ζ: a cubic or quartic fitted to σ
    # (every channel, as the head) and ζ = σ / 2π f with the fit's own frequency (as the
    # exported graph) or the true one (what σ alone leaves), beside the same degree on ζ.
    damping, frequency = CHANNELS.index("damping_ratio"), CHANNELS.index("frequency_hz")
    rate = to_decay_rate(data.Y, weights, (damping, frequency))[0]
    for degree in (3, 4):
        on_zeta = PolynomialBaseline.fit(data.spec, data.X[train], data.Y[train], weights[train],
                                         degree).predict(data.X[test])  # fmt: skip
        on_rate = PolynomialBaseline.fit(data.spec, data.X[train], rate[train], weights[train],
                                         degree).predict(data.X[test])  # fmt: skip
        sigma = on_rate[..., damping]
        for name, zeta in (
            ("ratio", on_zeta[..., damping]),
            ("rate_own_frequency", sigma / (2 * np.pi * on_rate[..., frequency])),
            ("rate_true_frequency", sigma / (2 * np.pi * np.where(
                used[..., frequency], truth[..., frequency], 1))),
        ):  # fmt: skip
            estimate = on_zeta.copy()
            estimate[..., damping] = zeta
            errors = channel_errors(estimate, truth, weights[test], data.spec)["damping_ratio"]
            rmse = np.array(errors["rmse_per_level"], dtype=float)
            out[f"damping_degree{degree}_{name}_to_scatter_per_level"] = (
                rmse / scatter[:, damping]
            ).tolist()
    # Item 2: at the top amplitude, the cubic's frequency error by closeness to the fold.
    top = -1
    level = truth[..., CHANNELS.index("base_acceleration_m_s2")]
    held = used[:, top, 0]
    error = predicted[3][:, top, 0] - truth[:, top, 0]
    rise = np.log(level[held, top] / level[held, top - 1])
    edges = np.quantile(rise, [0, 1 / 3, 2 / 3, 1])
    out["top"] = {
        "test_curves_with_backbone": int(held.sum()),
        "of_test_curves": int(test.size),
        "with_a_masked_amplitude": int((~used[held, :, 0]).any(axis=1).sum()),
        "rise_terciles": edges.tolist(),
        "cubic_rmse_hz_by_rise_tercile": [
            float(np.sqrt(np.mean(error[held][(rise >= a) & (rise <= b)] ** 2)))
            for a, b in itertools.pairwise(edges)
        ],
    }
    return out


def ends_of_the_yardstick(measured, grid) -> dict:
    """Item 3: the curves that cover each end of the grid against all curves."""
    placed = [measured_on_grid(c, grid.amplitudes_m) for c in measured]
    values = np.array([np.where(o[:, None], v, np.nan) for v, o in placed])
    out = {}
    for end, at, levels in (("bottom", 0, (0, 1, 2, 5)), ("top", -1, (36, 37, 38, 39, 40))):
        who = np.isfinite(values[:, at, 0])
        rows = []
        for lvl in levels:
            subset, every = values[who, lvl], values[:, lvl]
            rows.append({
                "level": lvl,
                "subset_sd": np.nanstd(subset, axis=0, ddof=1)[:2].tolist(),
                "all_sd": np.nanstd(every, axis=0, ddof=1)[:2].tolist(),
                "all_n": int(np.isfinite(every[:, 0]).sum()),
            })  # fmt: skip
        out[end] = {"curves": np.flatnonzero(who).tolist(), "levels": rows}
    low, high = scatter_interval(np.array([3]))
    out["sigma_over_s_ci95_3_curves"] = [float(low[0]), float(high[0])]
    return out


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--workdir", default="out/bench_surrogate", help="campaign cache")
    parser.add_argument("--n-curves", default="475,2000", help="comma-separated dataset sizes")
    args = parser.parse_args()
    model, names, measured, _, _ = demo_front(Path(args.workdir))
    grid = measured_grid(measured, 41)
    scatter = assembly_scatter(measured, grid.amplitudes_m)
    sizes = [rows_and_degrees(model, names, grid, scatter, int(n))
             for n in args.n_curves.split(",")]  # fmt: skip
    show = lambda xs: " ".join(f"{v:.2g}" for v in xs)  # noqa: E731
    for s in sizes:
        print(
            f"\n±50 % box, {s['n_curves']} curves: train rows with a backbone, last 5 amplitudes "
            f"{s['train_rows_per_level'][-5:]} (a cubic in {len(names)} parameters needs "
            f"{s['cubic_rows_needed']}); the 'cubic' carries degree "
            f"{s['cubic_degree_per_level'][-5:]} there"
        )
        for channel in CHANNELS:
            print(
                f"   {channel:<24s} cubic ÷ scatter, first 3: "
                f"{show(s[f'{channel}_cubic_to_scatter_per_level'][:3])}; last 3: "
                f"{show(s[f'{channel}_cubic_to_scatter_per_level'][-3:])}   (linear, last 3: "
                f"{show(s[f'{channel}_linear_to_scatter_per_level'][-3:])})"
            )
        for degree in (3, 4):
            print(
                f"   damping, degree {degree} ÷ scatter, last 3 amplitudes: fitted to "
                + "; ".join(
                    f"{label} {show(s[f'damping_degree{degree}_{key}_to_scatter_per_level'][-3:])}"
                    for key, label in (
                        ("ratio", "ζ"), ("rate_own_frequency", "σ, over its own 2π f"),
                        ("rate_true_frequency", "σ, over the true 2π f"),
                    )
                )
            )  # fmt: skip
        t = s["top"]
        print(
            f"   top amplitude: {t['test_curves_with_backbone']} of {t['of_test_curves']} test "
            f"curves have a backbone there, {t['with_a_masked_amplitude']} of them a masked "
            "amplitude anywhere; cubic frequency RMSE by the level's rise over the last step "
            f"(terciles {show(t['rise_terciles'])}): {show(t['cubic_rmse_hz_by_rise_tercile'])} Hz"
        )
    ends = ends_of_the_yardstick(measured, grid)
    print(
        f"\nσ / s for 3 curves, 95 %: {show(ends['sigma_over_s_ci95_3_curves'])}. "
        "The curves at each end of the grid against all curves (SD of frequency Hz, damping):"
    )
    for end in ("bottom", "top"):
        print(f"   {end}: curves {ends[end]['curves']}")
        for row in ends[end]["levels"]:
            print(
                f"     amplitude {row['level']:>2d}: these {show(row['subset_sd'])}; all "
                f"{row['all_n']} curves {show(row['all_sd'])}"
            )
    print(json.dumps({"bench": "surrogate_ends", "sizes": sizes, "yardstick_ends": ends}))


if __name__ == "__main__":
    main()
