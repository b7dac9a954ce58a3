"""Run the benchmark scripts and write BENCHMARKS.md.

Each script in ``bench/`` ends by printing one JSON line of figures; this
script runs them (all, or those named with ``--only``), keeps each JSON in
``bench/results/NAME.json``, and builds the tables of BENCHMARKS.md from those
files, so the tables are generated, never typed. No other file is written: the
README links to BENCHMARKS.md instead of repeating its table.

    python bench/run_all.py                 # every benchmark (about 30 min)
    python bench/run_all.py --only pll      # one benchmark, the rest from bench/results
    python bench/run_all.py --tables-only   # rebuild the tables from bench/results
"""

from __future__ import annotations

import argparse
import json
import os
import platform
import subprocess
import sys
import time
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
RESULTS = ROOT / "bench" / "results"
SCRIPTS = (
    "harmonic", "pll", "multimode_harmonic", "multimode_pll", "identify", "surrogate", "scaling",
    "sampling", "population_coverage", "criticism", "records", "lab_rig",
)  # fmt: skip


def _box_rows(box: str, first: str) -> tuple[tuple[str, ...], ...]:
    """Rows of one box of ``bench/surrogate.py``: ratios to the linear baseline and the scatter."""
    return (
        (first, "surrogate", f"{box}_frequency_to_linear", "×", "≤ 0.1", "—"),
        ("… analytical curves generated (80 % train)", "surrogate", f"{box}_n_curves", "", "—",
         "—"),
        ("… ÷ assembly scatter, worst amplitude (3 curves at the grid ends)", "surrogate",
         f"{box}_frequency_to_scatter_max", "×", "≤ 0.1", "—"),
        ("… damping ratio ÷ assembly scatter, worst amplitude", "surrogate",
         f"{box}_damping_ratio_to_scatter_max", "×", "≤ 0.1", "—"),
        ("… damping ratio ÷ assembly scatter, worst amplitude ≥ 10 curves cover", "surrogate",
         f"{box}_damping_ratio_to_scatter_max_10_curves", "×", "—", "—"),
        ("… base acceleration ÷ assembly scatter, worst amplitude", "surrogate",
         f"{box}_base_acceleration_m_s2_to_scatter_max", "×", "≤ 0.1", "—"),
    )  # fmt: skip


#: (figure, script, key in its JSON, unit, target, the paper's value)
HEADLINES = (
    ("Harmonic balance: 1000 backbones × 41 amplitudes, single harmonic", "harmonic",
     "single_1000x41_ms", "ms", "≤ 50 ms", "—"),
    ("Harmonic balance: 1000 × 41, H = 5 (AFT)", "harmonic", "multi_h5_1000x41_s", "s",
     "≤ 5 s", "—"),
    ("PLL backbone, 41 levels, one core", "pll", "backbone_s", "s", "≤ 0.1 s",
     "Simulink, \"computationally exhaustive\""),
    ("PLL batch: 500 backbones, 2 cores", "pll", "batch_500_s", "s", "≤ 40 s", "—"),
    ("SINDy from 60 s of 10 kHz records, paper library", "identify", "paper_library_s", "s",
     "≤ 10 s", "—"),
    ("Surrogate (paper network: latent 64, conv 64/32, FFNN 4 × 512, cubic head), demo box "
     "(±20 %), test: frequency RMSE", "surrogate", "demo_frequency_rmse_hz", "Hz", "—", "—"),
    *_box_rows("demo", "… ÷ linear-regression baseline's"),
    *_box_rows("wide", "Surrogate, same network, ±50 % box, test: frequency RMSE ÷ linear "
               "baseline's"),
    # the same box and command with a quartic head (bench/results/surrogate_wide_2000_head4.json)
    ("Surrogate, same network, quartic head, ±50 % box, test: damping ratio ÷ assembly "
     "scatter, worst amplitude (3 curves at the top)", "surrogate_wide_2000_head4",
     "wide_damping_ratio_to_scatter_max", "×", "≤ 0.1", "—"),
    ("… frequency ÷ assembly scatter, worst amplitude", "surrogate_wide_2000_head4",
     "wide_frequency_to_scatter_max", "×", "≤ 0.1", "—"),
    ("… frequency ÷ linear baseline's", "surrogate_wide_2000_head4", "wide_frequency_to_linear",
     "×", "≤ 0.1", "—"),
    ("… base acceleration ÷ assembly scatter, worst amplitude", "surrogate_wide_2000_head4",
     "wide_base_acceleration_m_s2_to_scatter_max", "×", "≤ 0.1", "—"),
    ("Surrogate, demo box, test: MSE of amplitude at excitation levels", "surrogate",
     "demo_mse_amplitude_mm2", "mm²", "—", "5.119e-6 mm²"),
    ("Surrogate: 100 predictions (onnxruntime, 1 thread)", "surrogate", "demo_predict_100_ms",
     "ms", "≤ 4 ms", "407.3 ms"),
    ("Surrogate: training on the demo box, CPU, 1 thread", "surrogate", "demo_train_cpu_s", "s",
     "—", "—"),
    ("Surrogate dataset: speed-up 1 → 2 dask workers, 2000 curves", "scaling",
     "dask_speedup_1_to_2", "×", "—", "—"),
    ("Surrogate dataset: CPU per curve (H = 5, 41 amplitudes)", "scaling", "cpu_ms_per_curve",
     "ms", "—", "—"),
    ("MCMC, surrogate forward model (bench net: latent 32, conv 32/16, FFNN 3 × 128), "
     "pm-joint's Metropolis: min bulk ESS/s", "sampling", "surrogate_metropolis_ess_per_s",
     "1/s", "—", "—"),
    ("MCMC, same surrogate, same posterior: pm-joint's Metropolis over the paper's "
     "coordinate-wise Metropolis (min ESS/s)", "sampling", "surrogate_metropolis_vs_paper", "×",
     "≥ 1×", "—"),
    ("MCMC, harmonic-balance graph: pm-joint's default sampler over nutpie (min ESS/s)",
     "sampling", "harmonic_default_vs_nutpie", "×", "≥ 1.0×", "—"),
    ("Hierarchical model, 90 % intervals over PLL campaigns: parameters whose log-mean and "
     "log-spread coverage lie within two-sided binomial bounds", "population_coverage",
     "within_bounds", "", "true", "—"),
    ("Criticism: 5 records → ranked missing effects", "criticism", "total_s", "s", "≤ 60 s", "—"),
    ("Records: read throughput, 500 MB file", "records", "read_mb_s", "MB/s", "≥ 100 MB/s", "—"),
    ("Records: peak memory / numeric array", "records", "peak_over_array", "×", "≤ 3", "—"),
    ("Lab rig: one record (10 levels × 2.6 s, 10 kHz), every artefact, CPU", "lab_rig",
     "lab_all_record_cpu_s", "s", "—", "—"),
    ("Lab rig over the ideal rig, same record, worst lab preset (CPU)", "lab_rig",
     "worst_over_ideal_cpu", "×", "≤ 2×", "—"),
)  # fmt: skip


def run(name: str) -> dict:
    """Run ``bench/NAME.py``; its last output line is its JSON."""
    script = ROOT / "bench" / f"{name}.py"
    print(f"== {name}", flush=True)
    start = time.perf_counter()
    done = subprocess.run(
        [sys.executable, str(script)], cwd=ROOT, text=True, stdout=subprocess.PIPE
    )
    print(done.stdout, end="")
    if done.returncode != 0:
        raise SystemExit(f"bench/{name}.py failed with exit code {done.returncode}")
    figures = json.loads(done.stdout.strip().splitlines()[-1])
    figures["_run"] = {
        "seconds": round(time.perf_counter() - start, 1),
        "date": time.strftime("%Y-%m-%d %H:%M UTC", time.gmtime()),
        "machine": f"{platform.machine()}, {os.cpu_count()} cores",
    }
    RESULTS.mkdir(exist_ok=True)
    (RESULTS / f"{name}.json").write_text(json.dumps(figures, indent=1) + "\n")
    return figures


def _value(figures: dict | None, key: str) -> str:
    if figures is None or key not in figures:
        return "not run"
    value = figures[key]
    return f"{value:.4g}" if isinstance(value, float) else str(value)


def headline_table(results: dict[str, dict]) -> str:
    lines = ["| figure | ours | target | paper |", "|---|---|---|---|"]
    for label, script, key, unit, target, paper in HEADLINES:
        value = _value(results.get(script), key)
        shown = f"{value} {unit}".strip() if value != "not run" else value
        lines.append(f"| {label} | {shown} | {target} | {paper} |")
    return "\n".join(lines)


def table5(results: dict[str, dict]) -> str:
    surrogate = results.get("surrogate")
    if not surrogate or "table5" not in surrogate:
        return "_Table 5 study not run._"
    paper = surrogate.get("paper", {}).get("table5", {})
    config, rows = surrogate.get("config", {}), surrogate["table5"]
    net, cap = config.get("net", {}), surrogate.get("table5_epoch_cap")
    setup = (
        f"Network: latent {net.get('latent_dim')}, conv {net.get('conv_filters')}, FFNN "
        f"{net.get('ffnn_depth')} × {net.get('ffnn_width')}, head degree "
        f"{config.get('head_degree')}; test split of {rows[0]['n_test'] if rows else '—'} "
        "analytical curves; epochs "
        + (f"capped at {cap}" if cap else f"not capped ({config.get('max_epochs')} per stage, "
           f"{config.get('finetune_epochs')} fine-tune, early stopping)")
        + ".\n\n"
    )  # fmt: skip
    lines = [
        "| training curves | frequency RMSE (Hz) | ÷ linear | ÷ scatter (worst) "
        "| MSE (mm²) ours | MSE (mm²) paper | MAE (mm) ours | MAE (mm) paper |",
        "|---|---|---|---|---|---|---|---|",
    ]
    for row in rows:
        size = str(row.get("n_train"))
        mse, mae, _ = paper.get(size, ("—", "—", "—"))  # the paper's (MSE, MAE, MAPE)
        cells = [
            row.get(key) for key in ("rmse_frequency_hz", "frequency_to_linear",
                                     "frequency_to_scatter_max", "mse_amplitude_mm2")
        ]  # fmt: skip
        shown = ["—" if v is None else f"{v:.3g}" for v in cells]
        mae_ours = row.get("mae_amplitude_mm")
        lines.append(
            f"| {size} | {' | '.join(shown)} | {mse} "
            f"| {'—' if mae_ours is None else f'{mae_ours:.3g}'} | {mae} |"
        )
    return setup + "\n".join(lines)


def _counted(entry: dict) -> str:
    """``k of n (95 % CP low–high %)`` of a rate the criticism benches print."""
    return (
        f"{entry['count']} of {entry['runs']} (95 % Clopper–Pearson "
        f"{100 * entry['ci95_low']:.1f}–{100 * entry['ci95_high']:.1f} %)"
    )


def _seeds(seeds: int | dict) -> str:
    """A study's seeds as its JSON line names them (a count, before studies.seeds)."""
    if isinstance(seeds, int):
        return f"{seeds} seeds"
    return f"{seeds['kind']} seeds {seeds['first']}–{seeds['last']}"


def criticism_studies(results: dict[str, dict]) -> str:
    """The hidden-effect study's outcomes and the model-term groups' false-flag rate."""
    lines = []
    hidden = results.get("criticism_hidden")
    if hidden and "hidden_outcomes" in hidden:
        outcomes = ", ".join(f"{n} {o}" for o, n in hidden["hidden_outcomes"].items())
        lines.append(
            f"- Hidden catalogue effects ({_seeds(hidden['seeds'])}, starts "
            f"{', '.join(hidden['starts'])}): {outcomes}; found (first, in a flagged group or "
            f"held by the loop's final model) with the key error down ≥ 80 %: "
            f"{_counted(hidden['hidden_hits'])} of the hidden rows"
        )
        sizes = hidden.get("group_sizes")
        if sizes:
            shown = {
                key: ", ".join(f"{n} of {size}" for size, n in counts.items()) or "none"
                for key, counts in sizes.items()
            }
            lines.append(
                f"- … groups of the first criticisms by members: ranked candidates' "
                f"{shown['groups']}; model-term groups (the term and its stand-ins) "
                f"{shown['term_groups']}"
            )
    terms = results.get("criticism_terms")
    if terms:
        flags = terms["false_flags"]
        lines.append(
            f"- Model-term groups flagged although the data tell the term from the stand-in "
            f"(λ ≥ {terms['separation']}): {_counted(flags)} over {terms['campaigns']} "
            f"campaigns (the Δχ² rule alone predicts "
            f"{100 * flags['predicted_by_delta_chi2_rule']:.1f} %); null verdicts with "
            f"something proposed: {_counted(terms['null_verdicts'])}"
        )
        if "preferred_over_true_term" in terms:
            lines.append(
                "- Stand-ins the data prefer to a true term (what the term swap would replace, "
                f"falsely): {_counted(terms['preferred_over_true_term'])} stand-in refits"
            )
    return "\n".join(lines) or "_Criticism studies not run._"


def run_line(run: dict) -> str:
    """How a result file was made: date, seconds (when run_all timed it), machine, command."""
    parts = [run["date"]]
    if "seconds" in run:
        parts.append(f"{run['seconds']} s")
    parts.append(run["machine"])
    if "command" in run:
        parts.append(f"`{run['command']}`")
    return ", ".join(parts)


def write_tables(results: dict[str, dict]) -> None:
    runs = "\n".join(
        f"- `{name}.json`: {run_line(run)}"
        for name, run in ((n, r["_run"]) for n, r in results.items() if "_run" in r)
    )
    headline = headline_table(results)
    text = (
        "# Benchmarks\n\n"
        "Generated by `python bench/run_all.py` from the JSON line each script in `bench/` "
        "prints (kept in `bench/results/`); do not edit by hand. Dated runs of the demo and "
        "of the studies the documentation quotes are in `docs/demo.md`, `docs/updating.md` "
        "and `docs/criticism.md`.\n\n"
        f"{headline}\n\n## Table 5 of the paper, repeated\n\n"
        "Amplitude-grid surrogate on the demo box (±20 % around the model, widened to the "
        "labels), independent test split; the paper's "
        "amplitude figures come from inverting its base-acceleration channel onto excitation "
        f"levels.\n\n{table5(results)}\n\n"
        f"## Criticism studies\n\n{criticism_studies(results)}\n\n"
        f"## Runs\n\n{runs}\n"
    )
    (ROOT / "BENCHMARKS.md").write_text(text)


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--only", nargs="*", choices=SCRIPTS, help="benchmarks to run")
    parser.add_argument("--tables-only", action="store_true", help="run nothing")
    args = parser.parse_args()
    chosen = [] if args.tables_only else (args.only or list(SCRIPTS))
    for name in chosen:
        run(name)
    results = {path.stem: json.loads(path.read_text()) for path in sorted(RESULTS.glob("*.json"))}
    write_tables(results)
    print(f"wrote BENCHMARKS.md from {len(results)} result file(s)")


if __name__ == "__main__":
    main()
