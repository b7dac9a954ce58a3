"""The ``pm-joint`` command.

Each subcommand is a thin wrapper over one function of :mod:`pm_joint.pipeline`;
bad input ends in a one-line reason on stderr and exit code 2, and every
warning is one line naming what it is about.

``backbones``, ``identify``, ``train-surrogate``, ``criticize``, ``update`` and
``report`` read records alike: a folder or a file in the TRC layout, or in a
column layout (CSV/TSV with a header, MAT, HDF5; a folder of them is a campaign,
one record per file, each file one assembly), with the test type and, for
column files, the columns' roles given by the record options
(:func:`add_record_options`), e.g.
``pm-joint backbones ring.csv --test free-decay --response displacement
--quantity displacement``.
"""

from __future__ import annotations

import argparse
import contextlib
import sys
import warnings
from collections.abc import Iterator, Sequence
from pathlib import Path
from typing import Any

from identification.effects import CATALOGUE
from identification.measurements.modal_filter import SECOND_MODE_SHARE
from identification.measurements.quantities import EXCITATION_KINDS, QUANTITIES, TEST_TYPES
from identification.measurements.signals import DECAY_EDGE_PERIODS
from identification.model import PRESETS, JointModel
from identification.rig import MODAL_RIG_PRESETS, RIG_PRESETS
from identification.rig.modal_rig import TESTS as MODAL_RIG_TESTS
from identification.rig.presets import TWO_MODE_RATIO
from identification.sindy import PAPER_LIBRARY
from pm_joint.cli_common import (
    EXIT_NOT_CONVERGED,
    identify_options,
    trace_folder,
    verdict_exit,
    workspace_options,
)
from pm_joint.cli_modes import (
    decay_mode_backbones,
    identify_modal_model,
    is_modal_model,
    modal_hold_backbones,
    train_modal_surrogates,
    update_modal_model,
)
from pm_joint.sampler_defaults import (
    DEFAULT_FORWARD,
    FORWARD_MODELS,
    POPULATION_MODELS,
    SAMPLERS,
    default_help,
    forward_help,
)
from surrogates.labels import MISFIT_POLICIES


def _effect_list(text: str) -> list[str]:
    names = [n.strip() for n in text.split(",") if n.strip()]
    for name in names:
        if name not in CATALOGUE:
            raise argparse.ArgumentTypeError(
                f"unknown effect {name!r}; the catalogue has: {', '.join(CATALOGUE)}"
            )
    return names


@contextlib.contextmanager
def _executor(args: argparse.Namespace) -> Iterator[Any]:
    """A dask Client on ``--scheduler`` or on a ``--workers`` LocalCluster; None: serial."""
    if args.scheduler is None and (args.workers or 1) < 2:
        yield None
        return
    from dask.distributed import Client, LocalCluster

    if args.scheduler is not None:
        with Client(args.scheduler) as client:
            yield client
        return
    with (
        LocalCluster(
            n_workers=args.workers, threads_per_worker=1, dashboard_address=None
        ) as cluster,
        Client(cluster) as client,
    ):
        yield client


def _add_executor_options(p: argparse.ArgumentParser, workers_help: str) -> None:
    p.add_argument("--workers", type=int, help=workers_help)
    p.add_argument(
        "--scheduler", metavar="ADDRESS",
        help="address of a running dask scheduler (e.g. tcp://host:8786) to compute on",
    )  # fmt: skip


def _band(text: str) -> tuple[float, float]:
    try:
        low, high = (float(v) for v in text.split(","))
    except ValueError:
        raise argparse.ArgumentTypeError(f"--band needs LOW,HIGH in Hz, got {text!r}") from None
    if not 0 < low < high:
        raise argparse.ArgumentTypeError(f"--band needs 0 < LOW < HIGH, got {text!r}")
    return low, high


def add_record_options(parser: argparse.ArgumentParser) -> None:
    """The options that say how records read (the same on every command that reads them)."""
    group = parser.add_argument_group(
        "records (TRC folders take --test and --decimal-comma; column files all)"
    )
    group.add_argument("--test", choices=TEST_TYPES, default="phase-resonance",
                       help="test type (default phase-resonance: PLL holds)")  # fmt: skip
    group.add_argument("--time", metavar="NAME", help="time column (default: time or t)")
    group.add_argument("--response", metavar="NAME[,NAME…]",
                       help="response column; several, comma-separated, are the sensors of a "
                       "multi-point record (the first is the one-mode response)")  # fmt: skip
    group.add_argument("--quantity", choices=QUANTITIES,
                       help="what the response is (default: from its name)")  # fmt: skip
    group.add_argument("--relative-response", action="store_true",
                       help="the response is relative to the base (default: absolute)")  # fmt: skip
    group.add_argument("--excitation", metavar="NAME", help="excitation column")
    group.add_argument("--excitation-kind", choices=EXCITATION_KINDS,
                       help="what the excitation is (default: from its name)")  # fmt: skip
    group.add_argument("--excitation-gain", type=float, default=1.0, metavar="GAIN",
                       help="SI units of the excitation per unit of its column, e.g. N/V "
                       "for a force read as a voltage (default 1)")  # fmt: skip
    group.add_argument("--forcing-gain", type=float, metavar="G",
                       help="modal forcing gain of a force-driven test (1/kg; default: "
                       "measured from the record's decay)")  # fmt: skip
    group.add_argument("--frequency", metavar="NAME",
                       help="controller frequency column (Hz; default: frequency…)")  # fmt: skip
    group.add_argument("--level", metavar="NAME",
                       help="commanded level column: its runs of one value are the holds "
                       "(default: level…)")  # fmt: skip
    group.add_argument("--decimal-comma", action="store_true",
                       help="text files write 0,5 for 0.5 (else detected)")  # fmt: skip
    group.add_argument("--edge-periods", type=float, metavar="N",
                       help="periods left out at the ends of a record for identification "
                       f"(default 20, {DECAY_EDGE_PERIODS:g} for a free decay) and at the start "
                       "of a decay for its backbone (default 0)")  # fmt: skip
    group.add_argument("--window-periods", type=float, default=6.0, metavar="N",
                       help="periods per window of a decay's backbone (default 6)")  # fmt: skip
    group.add_argument("--band", type=_band, metavar="LOW,HIGH",
                       help="pass band of the identification and where a decay's mode is "
                       "looked for (Hz; default: frequency channel or spectrum)")  # fmt: skip


def _cmd_effects(args: argparse.Namespace) -> None:
    width = max(len(n) for n in CATALOGUE)
    for effect in CATALOGUE.values():
        shape = ", ".join(f"{n} [{effect.shape_units[n]}]" for n in effect.shape)
        extra = f"  (shape: {shape})" if shape else ""
        print(f"{effect.name:<{width}}  {effect.term:<24} {effect.reading}{extra}")


def _cmd_model(args: argparse.Namespace) -> None:
    model = JointModel.preset(args.preset) if args.preset else JointModel.from_json(args.json)
    print(model.equation())
    print(f"linear natural frequency: {model.linear_frequency_hz:.3f} Hz")
    if args.out:
        model.to_json(args.out)
        print(f"wrote {args.out}")


def _cmd_rig(args: argparse.Namespace) -> None:
    from pm_joint.pipeline import write_rig_campaign

    preset = args.preset_name or args.preset
    if preset is None:
        raise ValueError("name a rig preset (positional or --preset)")
    if args.preset_name and args.preset and args.preset_name != args.preset:
        raise ValueError(f"two rig presets named: {args.preset!r} and {args.preset_name!r}")
    if preset in MODAL_RIG_PRESETS:
        _modal_rig(preset, args)
        return
    if args.ratio is not None or args.test is not None or args.mode is not None:
        raise ValueError(
            f"--ratio, --test and --mode belong to the modal presets "
            f"({', '.join(MODAL_RIG_PRESETS)}), not to {preset!r}"
        )
    with contextlib.ExitStack() as stack:
        # --workers alone keeps its process pool; --scheduler sends the records to dask.
        client = stack.enter_context(_executor(args)) if args.scheduler else None
        campaign = write_rig_campaign(
            preset, args.out, assemblies=args.assemblies, runs=args.runs, seed=args.seed,
            n_levels=args.levels, workers=args.workers, executor=client,
            force_driven=args.force_driven, quantity=args.quantity,
        )  # fmt: skip
    layout = "column layout, force-driven" if args.force_driven else "TRC layout"
    print(f"wrote {len(campaign)} record(s) of rig preset {preset!r} to {args.out} ({layout})")


def _modal_rig(preset: str, args: argparse.Namespace) -> None:
    """A campaign of a rig preset of several modes (records one after another)."""
    from identification.rig import rig_for_preset

    if args.force_driven:
        raise ValueError(f"rig preset {preset!r} has no force-driven test")
    test = args.test or "pll"
    options = {"ratio": args.ratio, "test": test, "mode": args.mode or 1}
    rig = rig_for_preset(preset, levels=args.levels, **options)
    campaign = rig.write_campaign(
        args.out, assemblies=args.assemblies, runs=args.runs, seed=args.seed
    )
    what = f"PLL locking mode {rig.mode}" if test == "pll" else f"free decays ({rig.decay_start})"
    print(
        f"wrote {len(campaign)} record(s) of rig preset {preset!r} to {args.out} "
        f"(TRC layout, {what}, ground truth in ground_truth.json)"
    )


def _cmd_backbones(args: argparse.Namespace) -> None:
    from identification.measurements.extraction import extraction_summary
    from pm_joint.pipeline import campaign_backbones
    from pm_joint.workspace import Workspace

    workspace = Workspace(args.dir, backbones_csv=args.out, n_periods=args.periods,
                          **workspace_options(args))  # fmt: skip
    if args.modes > 1:
        if args.test == "free-decay":
            decay_mode_backbones(workspace, args)
        else:
            modal_hold_backbones(workspace, args)
        return
    backbones = campaign_backbones(workspace, mode_shapes=args.mode_shapes,
                                   second_mode_share=args.second_mode_share)  # fmt: skip
    points = sum(len(b) for b in backbones)
    print(f"extracted {len(backbones)} backbone(s), {points} points ({args.test}) to "
          f"{workspace.backbones_csv}")  # fmt: skip
    print(extraction_summary(backbones))
    if args.test == "free-decay":
        from pm_joint.pipeline import decay_second_mode_warnings

        for line in decay_second_mode_warnings(workspace, mode_shapes=args.mode_shapes):
            print(line, file=sys.stderr)


def _positive_int(text: str) -> int:
    try:
        value = int(text)
    except ValueError:
        value = 0
    if value < 1:
        raise argparse.ArgumentTypeError(f"needs an integer ≥ 1, got {text!r}")
    return value


def _cmd_identify(args: argparse.Namespace) -> None:
    from pm_joint.pipeline import identify_campaign
    from pm_joint.workspace import Workspace

    workspace = Workspace(args.dir, **workspace_options(args))
    if args.modes > 1:
        identify_modal_model(workspace, args)
        return
    result = identify_campaign(workspace, args.effects, n_records=args.records, out=args.out,
                               **identify_options(args))  # fmt: skip
    print(result.summary())
    print(result.model.equation())
    print(f"wrote {args.out}")


def _cmd_train_surrogate(args: argparse.Namespace) -> None:
    from pm_joint.pipeline import label_records, train_surrogate_stage
    from pm_joint.workspace import Workspace

    if is_modal_model(args.model):
        train_modal_surrogates(args)
        return
    workspace = Workspace(args.dir, model=args.model, **workspace_options(args))
    labels = label_records(workspace, **identify_options(args))
    with _executor(args) as executor:
        runtime = train_surrogate_stage(
            workspace, args.out, labels=labels, n_curves=args.curves,
            n_amplitudes=args.amplitudes, max_epochs=args.epochs,
            hold_out_measured=not args.measured_in_training, misfit_policy=args.label_misfit,
            seed=args.seed, executor=executor,
        )  # fmt: skip
    print(f"wrote {args.out}/surrogate.onnx for parameters {', '.join(runtime.parameter_names)}")
    data, test = runtime.metadata["training"]["data"], runtime.metadata["test"]
    print(f"curves per origin and split: {data['splits']}")
    for origin in ("analytical", "measured"):
        ratios = (test.get(origin) or {}).get("ratios", {}).get("frequency_hz")
        if ratios:
            scatter = ratios.get("to_scatter_max")
            print(
                f"test ({origin}), frequency: ÷ linear baseline {ratios['to_linear']:.3g}, "
                "÷ assembly scatter (worst amplitude) "
                + ("unknown" if scatter is None else f"{scatter:.3g}")
            )


def _cmd_criticize(args: argparse.Namespace) -> None:
    from pm_joint.html import rounds_text
    from pm_joint.pipeline import criticize_campaign
    from pm_joint.workspace import Workspace

    workspace = Workspace(args.dir, **workspace_options(args))
    with _executor(args) as executor:
        crit = criticize_campaign(
            workspace, args.model, args.out, rounds=args.rounds, executor=executor
        )
    print(rounds_text(crit.rounds))
    print(f"wrote {args.out}/criticism.json")
    if args.add_mode:
        added = crit.add_mode()
        print(added.text)
        print(f"wrote {added.model.to_json(Path(args.out) / 'two_mode_model.json')}")


def _cmd_update(args: argparse.Namespace) -> int:
    from pm_joint.pipeline import posterior_report, update_backbones
    from pm_joint.workspace import Workspace

    if args.model and is_modal_model(args.model):
        return update_modal_model(args)
    forward = args.forward or DEFAULT_FORWARD[args.population]
    if forward == "surrogate" and not args.surrogate:
        raise ValueError("--forward surrogate needs --surrogate SURROGATE_DIR")
    if forward != "surrogate" and not args.model:
        raise ValueError(f"--forward {forward} needs --model model.json")
    workspace = Workspace(args.dir, model=args.model, surrogate=args.surrogate,
                          **workspace_options(args))  # fmt: skip
    trace = trace_folder(args, forward)
    idata = update_backbones(
        workspace, args.out, population=args.population, forward=forward,
        sampler=args.sampler, draws=args.draws, tune=args.tune, chains=args.chains,
        seed=args.seed, trace=trace, resume=args.resume,
    )  # fmt: skip
    print(f"wrote {args.out}")
    print(f"sampler: {idata.attrs['sampler']} ({idata.attrs['sampler_reason']})")
    if args.report:
        posterior_report(workspace, args.report)
        print(f"wrote {args.report}/report.json")
    return verdict_exit(idata, args.out)


def _cmd_report(args: argparse.Namespace) -> None:
    from pm_joint.pipeline import run_report
    from pm_joint.workspace import Workspace

    workspace = Workspace(args.dir, posterior=args.posterior, **workspace_options(args))
    index = run_report(workspace, args.out, criticism=args.criticism)
    print(f"wrote {index}")


def _cmd_predict(args: argparse.Namespace) -> None:
    from pm_joint.predict import predict_record, write_prediction

    layout = workspace_options(args)["layout"]
    prediction = predict_record(args.model, args.record, layout=layout,
                                mode_shapes=args.mode_shapes)  # fmt: skip
    write_prediction(prediction, args.out)
    print(prediction.headline())


def _cmd_demo(args: argparse.Namespace) -> int:
    from pm_joint.demo import run_demo

    result = run_demo(out=args.out, size=args.size, case=args.case)
    if not result.converged:
        lines = "\n".join(f"  {line}" for line in result.not_converged())
        print(
            f"pm-joint demo: NOT CONVERGED: the report in {args.out} holds posteriors that are "
            f"not a result yet (exit code {EXIT_NOT_CONVERGED}):\n{lines}",
            file=sys.stderr,
        )
        return EXIT_NOT_CONVERGED
    return 0


def build_parser() -> argparse.ArgumentParser:
    parser = argparse.ArgumentParser(
        prog="pm-joint",
        description="Stochastic model updating of nonlinear structural joints.",
    )
    sub = parser.add_subparsers(dest="command", required=True, metavar="COMMAND")

    p = sub.add_parser("effects", help="list the effects catalogue")
    p.set_defaults(func=_cmd_effects)

    p = sub.add_parser("model", help="show a joint model (preset or JSON file)")
    source = p.add_mutually_exclusive_group(required=True)
    source.add_argument("--preset", choices=sorted(PRESETS), help="named model")
    source.add_argument("--json", help="model JSON file")
    p.add_argument("--out", help="write the model as JSON here")
    p.set_defaults(func=_cmd_model)

    p = sub.add_parser("rig", help="write a virtual test campaign in the TRC layout")
    rig_presets = sorted([*RIG_PRESETS, *MODAL_RIG_PRESETS])
    p.add_argument("preset", nargs="?", choices=rig_presets, help="rig preset")
    p.add_argument(
        "--preset",
        dest="preset_name",
        choices=rig_presets,
        help="rig preset (instead of the positional name)",
    )
    p.add_argument("--out", required=True, help="campaign folder")
    p.add_argument("--assemblies", type=int, default=5, help="assemblies (default 5)")
    p.add_argument("--runs", type=int, default=1, help="runs per assembly (default 1)")
    p.add_argument("--seed", type=int, default=0, help="random seed (default 0)")
    p.add_argument("--levels", type=int, default=10, help="excitation levels (default 10)")
    _add_executor_options(p, "processes writing records (default: one per CPU)")
    p.add_argument(
        "--force-driven", action="store_true",
        help="drive the structure by a measured force and end each record in a ring-down; "
        "written in the column layout (HDF5)",
    )  # fmt: skip
    p.add_argument("--quantity", choices=QUANTITIES, default="velocity",
                   help="response of a force-driven record (default velocity)")  # fmt: skip
    p.add_argument(
        "--ratio",
        type=float,
        help="modal presets: second mode's over first mode's frequency "
        f"(default {TWO_MODE_RATIO} for two-mode)",
    )
    p.add_argument(
        "--test", choices=MODAL_RIG_TESTS, help="modal presets: PLL holds (default) or free decays"
    )
    p.add_argument("--mode", type=int, help="modal presets: the mode the PLL locks (default 1)")
    p.set_defaults(func=_cmd_rig)

    records = "campaign folder or record file (TRC or column layout)"
    p = sub.add_parser("backbones", help="extract backbones from every record of a campaign")
    p.add_argument("dir", help=records)
    p.add_argument("--out", help="CSV file (default DIR/backbones.csv, FILE_backbones.csv)")
    p.add_argument("--periods", type=int, default=70, help="periods per hold (default 70)")
    p.add_argument(
        "--modes", type=_positive_int, default=1, metavar="N",
        help="modes read per record (default 1: one backbone per record); 2 or more: a backbone "
        "per mode by the modal filter of the sensors (TRC panel points, --response a,b,c), "
        "a `mode` column and every mode's participation in the CSV",
    )  # fmt: skip
    p.add_argument(
        "--mode-shapes", metavar="FILE",
        help="mode shapes at the sensors: one row per sensor (the --response columns in order, "
        "or the 15 TRC panel points), then a row of frequencies (Hz) (default: the TRC modes "
        "file, else estimated from the records)",
    )  # fmt: skip
    p.add_argument(
        "--second-mode-share", type=float, default=SECOND_MODE_SHARE, metavar="FRACTION",
        help="with one mode read, warn of a record whose given shapes show another mode above "
        f"this share of the energy (default {SECOND_MODE_SHARE:g})",
    )  # fmt: skip
    add_record_options(p)
    p.set_defaults(func=_cmd_backbones)

    p = sub.add_parser("identify", help="SINDy identification of a joint model")
    p.add_argument("dir", help=records)
    p.add_argument(
        "--effects", type=_effect_list, default=list(PAPER_LIBRARY),
        help="library: comma-separated effect names (default: the paper's library, every "
        "catalogue effect but microslip)",
    )  # fmt: skip
    p.add_argument("--out", required=True, help="model JSON file")
    p.add_argument("--records", type=int, default=3, help="records fitted jointly (default 3)")
    p.add_argument(
        "--modes", type=_positive_int, default=1, metavar="N",
        help="modes of the model (default 1: a joint model); 2 or more: coupled modal equations "
        "(modal filter of the sensors, or the modes' bands of one sensor), a ModalModel JSON",
    )  # fmt: skip
    p.add_argument(
        "--mode-shapes", metavar="FILE",
        help="with --modes N: mode shapes at the sensors, as for backbones (default: the TRC "
        "modes file, else estimated from the records)",
    )  # fmt: skip
    p.add_argument(
        "--joint-sensor", metavar="NAME",
        help="with --modes N: the sensor the joint coordinate is read at (default: the response "
        "sensor, the TRC centre point or the first --response column)",
    )  # fmt: skip
    add_record_options(p)
    p.set_defaults(func=_cmd_identify)

    p = sub.add_parser("train-surrogate", help="dataset, training and ONNX export of a surrogate")
    p.add_argument("dir", help=f"{records}: the measured curves")
    p.add_argument("--model", required=True, help="model JSON file; a ModalModel JSON "
                   "(identify --modes N) gets one surrogate per measured mode")  # fmt: skip
    p.add_argument("--out", required=True, help="surrogate folder")
    p.add_argument("--curves", type=int, default=500, help="training curves (default 500)")
    p.add_argument("--epochs", type=int, help="epochs per stage (default: the paper-sized run)")
    p.add_argument(
        "--amplitudes", type=int, default=41,
        help="response amplitudes of the grid, over the amplitudes at least 3 measured curves "
        "cover (default 41)",
    )  # fmt: skip
    p.add_argument(
        "--measured-in-training", action="store_true",
        help="split the measured curves like the analytical ones, as the paper (default: all "
        "in the test split, so the likelihood's curves are no training data)",
    )  # fmt: skip
    p.add_argument(
        "--label-misfit", choices=MISFIT_POLICIES, default="downweight",
        help="measured curves whose label misfits them beyond the assembly scatter: "
        "downweight (default), exclude or keep",
    )  # fmt: skip
    p.add_argument("--seed", type=int, default=0, help="random seed (default 0)")
    _add_executor_options(
        p, "dask LocalCluster workers computing the dataset (default: serial; the dataset "
        "does not depend on it)",
    )  # fmt: skip
    add_record_options(p)
    p.set_defaults(func=_cmd_train_surrogate)

    p = sub.add_parser(
        "criticize",
        help="where the model fails and which effect it lacks",
        description="Criticise a model against a campaign. The verdicts and what to do next "
        "after each: docs/criticism.md, section Verdicts.",
    )
    p.add_argument("dir", help=f"{records}, or a backbones CSV")
    p.add_argument("--model", required=True, help="model JSON file")
    p.add_argument("--out", required=True, help="report folder (criticism.json + figures)")
    p.add_argument(
        "--rounds",
        type=int,
        default=0,
        help="add up to this many effects, best proposed first, each round followed by a swap step",
    )
    p.add_argument(
        "--add-mode",
        action="store_true",
        help="add the named second mode to the (last round's) model and write the two-mode "
        "model to OUT/two_mode_model.json (exit 2 where no mode is named at a located frequency)",
    )
    _add_executor_options(
        p, "dask LocalCluster workers refitting the candidate effects (default: serial; the "
        "report does not depend on it)",
    )  # fmt: skip
    add_record_options(p)
    p.set_defaults(func=_cmd_criticize)

    p = sub.add_parser(
        "update", help="stochastic updating of the model on measured backbones",
        description="Exit codes: 0 converged, 2 bad input, 3 posterior written but NOT "
        "converged (r̂ > 1.01, ESS < 400 or divergences).",
    )  # fmt: skip
    p.add_argument("dir", help=f"{records}, or a backbones CSV")
    p.add_argument(
        "--population", choices=POPULATION_MODELS, default="matching",
        help="matching: the paper's population matching (a population range); hierarchical: "
        "per-curve parameters from an estimated population, with a likelihood of every "
        "measured point (LOO) (default: matching)",
    )  # fmt: skip
    p.add_argument("--model", help="model JSON file (for --forward harmonic|pll); a ModalModel "
                   "JSON (identify --modes N) is updated on each mode's backbones")  # fmt: skip
    p.add_argument("--forward", choices=FORWARD_MODELS,
                   help=f"forward model (default: {forward_help()})")  # fmt: skip
    p.add_argument("--surrogate", help="surrogate folder (for --forward surrogate; with a "
                   "ModalModel, the N-mode surrogate train-surrogate wrote for it)")  # fmt: skip
    p.add_argument("--out", required=True, help="posterior netCDF file")
    # The defaults' words come from the table the updating reads (SAMPLER_DEFAULTS).
    p.add_argument("--sampler", choices=SAMPLERS, help=f"default: {default_help('sampler')}")
    p.add_argument("--draws", type=int,
                   help=f"draws per chain (default: {default_help('draws')})")  # fmt: skip
    p.add_argument("--tune", type=int,
                   help=f"tuning steps per chain (default: {default_help('tune')})")  # fmt: skip
    p.add_argument("--chains", type=int, default=2, help="chains (default 2)")
    p.add_argument("--seed", type=int, default=0, help="random seed (default 0)")
    p.add_argument("--report", help="also write the arviz report into this folder")
    p.add_argument(
        "--trace", help="zarr folder the draws are written to as they are taken (default: "
        "OUT with the suffix .zarr; none for nutpie, which keeps its draws in memory)",
    )  # fmt: skip
    p.add_argument(
        "--resume", action="store_true",
        help="continue a stopped run from its trace instead of starting again",
    )  # fmt: skip
    add_record_options(p)
    p.set_defaults(func=_cmd_update)

    p = sub.add_parser("report", help="HTML report of a run")
    p.add_argument("dir", help=f"{records}, or a backbones CSV")
    p.add_argument("--posterior", help="posterior netCDF file of `pm-joint update`")
    p.add_argument("--criticism", help="folder written by `pm-joint criticize`")
    p.add_argument("--out", required=True, help="report folder (index.html)")
    add_record_options(p)
    p.set_defaults(func=_cmd_report)

    p = sub.add_parser(
        "predict", help="simulate a model from a record's start and its prediction error",
        description="Simulates MODEL from the start of RECORD (initial modal state fitted on its "
        "first two periods, its base excitation replayed), writes the sensors' prediction to "
        "FILE (time, then one column per sensor) and FILE.json (NMTE, per sensor), and prints "
        "NMTE x.xx %%. Exit code 2 with one line when the simulation diverges.",
    )  # fmt: skip
    p.add_argument("record", help="one record file (TRC or column layout)")
    p.add_argument("--model", required=True,
                   help="a JointModel JSON file or preset, or a ModalModel JSON file")  # fmt: skip
    p.add_argument("--out", required=True, help="CSV file of the prediction (FILE.json beside)")
    p.add_argument(
        "--mode-shapes", metavar="FILE",
        help="mode shapes at the sensors, as for backbones (default: the TRC modes file, else "
        "estimated from the record)",
    )  # fmt: skip
    add_record_options(p)
    p.set_defaults(func=_cmd_predict)

    p = sub.add_parser("demo", help="run the pipeline on the embedded default")
    p.add_argument("--out", default="demo_out", help="output folder (default: demo_out)")
    p.add_argument(
        "--size", choices=("full", "small"), default="full",
        help="full: the paper-sized campaign; small: a quick check (default: full)",
    )  # fmt: skip
    p.add_argument(
        "--case", choices=("one-mode", "two-modes"), default="one-mode",
        help="one-mode: the TRC-like joint (default); two-modes: the two-mode virtual TRC "
        "(per-mode backbones, identify --modes 2, two-mode updating, the criticism of a "
        "one-mode model, held-out decays predicted by both)",
    )  # fmt: skip
    p.set_defaults(func=_cmd_demo)
    return parser


def main(argv: Sequence[str] | None = None) -> int:
    """Entry point of the ``pm-joint`` command."""
    args = build_parser().parse_args(argv)
    formatwarning = warnings.formatwarning

    def one_line(message, category, *_, **__) -> str:
        return f"pm-joint {args.command}: {category.__name__}: {message}\n"

    shown: set[str] = set()

    def show(message, category, *_, **__) -> None:
        from tqdm.auto import tqdm

        line = one_line(message, category).rstrip("\n")
        # Each warning once per process: Python's own once-per-place memory is wiped whenever
        # a library changes the warning filters (every catch_warnings block does), so e.g.
        # pytensor's notice that the surrogate's onnxruntime call runs in numba's object mode
        # (by design: onnxruntime is no numba code) came once per compiled function.
        if line in shown:
            return
        shown.add(line)
        # Through tqdm: a progress bar on the terminal is cleared first and redrawn after.
        tqdm.write(line, file=sys.stderr)

    showwarning = warnings.showwarning
    warnings.formatwarning = one_line  # a warning is one line, as an error is
    # Only where warnings reach the terminal: a caller that records them (pytest.warns,
    # catch_warnings(record=True)) swaps the module's private printer for its own list.
    printer = getattr(warnings, "_showwarnmsg_impl", None)
    if showwarning.__module__ == "warnings" and getattr(printer, "__module__", None) == "warnings":
        warnings.showwarning = show
    try:
        code = args.func(args) or 0
    except (ValueError, FileNotFoundError, NotADirectoryError) as exc:
        reason = str(exc).splitlines()[0] if str(exc) else type(exc).__name__
        print(f"pm-joint {args.command}: error: {reason}", file=sys.stderr)
        return 2
    finally:
        warnings.formatwarning = formatwarning
        warnings.showwarning = showwarning
    return code


if __name__ == "__main__":
    sys.exit(main())
