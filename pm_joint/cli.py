"""The ``pm-joint`` command.

Each subcommand is a thin wrapper over one function of :mod:`pm_joint.pipeline`;
bad input ends in a one-line reason on stderr and exit code 2.
"""

from __future__ import annotations

import argparse
import sys
import warnings
from collections.abc import Sequence
from pathlib import Path

from identification.effects import CATALOGUE
from identification.model import PRESETS, JointModel
from identification.rig import RIG_PRESETS


def _effect_list(text: str) -> list[str]:
    names = [n.strip() for n in text.split(",") if n.strip()]
    for name in names:
        if name not in CATALOGUE:
            raise argparse.ArgumentTypeError(
                f"unknown effect {name!r}; the catalogue has: {', '.join(CATALOGUE)}"
            )
    return names


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

    campaign = write_rig_campaign(
        args.preset, args.out, assemblies=args.assemblies, runs=args.runs, seed=args.seed,
        n_levels=args.levels, workers=args.workers,
    )  # fmt: skip
    print(f"wrote {len(campaign)} record(s) of rig preset {args.preset!r} to {args.out}")


def _cmd_backbones(args: argparse.Namespace) -> None:
    from pm_joint.pipeline import campaign_backbones
    from pm_joint.workspace import Workspace

    workspace = Workspace(args.dir, backbones_csv=args.out, n_periods=args.periods)
    backbones = campaign_backbones(workspace)
    print(f"extracted {len(backbones)} backbone(s) to {workspace.backbones_csv}")


def _cmd_identify(args: argparse.Namespace) -> None:
    from pm_joint.pipeline import identify_campaign
    from pm_joint.workspace import Workspace

    workspace = Workspace(args.dir)
    result = identify_campaign(workspace, args.effects, n_records=args.records, out=args.out)
    print(result.summary())
    print(result.model.equation())
    print(f"wrote {args.out}")


def _cmd_train_surrogate(args: argparse.Namespace) -> None:
    from pm_joint.pipeline import label_records, train_surrogate_stage
    from pm_joint.workspace import Workspace

    workspace = Workspace(args.dir, model=args.model)
    runtime = train_surrogate_stage(
        workspace, args.out, labels=label_records(workspace), n_curves=args.curves,
        max_epochs=args.epochs, seed=args.seed,
    )  # fmt: skip
    print(f"wrote {args.out}/surrogate.onnx for parameters {', '.join(runtime.parameter_names)}")


def _cmd_criticize(args: argparse.Namespace) -> None:
    from pm_joint.pipeline import criticize_campaign

    crit = criticize_campaign(args.dir, args.model, args.out, rounds=args.rounds)
    print(crit.summary())
    print(f"wrote {args.out}/criticism.json")


def _cmd_update(args: argparse.Namespace) -> None:
    from pm_joint.pipeline import posterior_report, update_backbones
    from pm_joint.workspace import Workspace

    if args.forward == "surrogate" and not args.surrogate:
        raise ValueError("--forward surrogate needs --surrogate SURROGATE_DIR")
    if args.forward != "surrogate" and not args.model:
        raise ValueError(f"--forward {args.forward} needs --model model.json")
    workspace = Workspace(args.dir, model=args.model, surrogate=args.surrogate)
    update_backbones(
        workspace, args.out, forward=args.forward, sampler=args.sampler, draws=args.draws,
        tune=args.tune, chains=args.chains, seed=args.seed,
        trace=args.trace or Path(args.out).with_suffix(".zarr"), resume=args.resume,
    )  # fmt: skip
    print(f"wrote {args.out}")
    if args.report:
        posterior_report(workspace, args.report)
        print(f"wrote {args.report}/report.json")


def _cmd_report(args: argparse.Namespace) -> None:
    from pm_joint.pipeline import run_report
    from pm_joint.workspace import Workspace

    workspace = Workspace(args.dir, posterior=args.posterior)
    index = run_report(workspace, args.out, criticism=args.criticism)
    print(f"wrote {index}")


def _cmd_demo(args: argparse.Namespace) -> None:
    from pm_joint.demo import run_demo

    run_demo(out=args.out, size=args.size)


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
    p.add_argument("preset", choices=sorted(RIG_PRESETS), help="rig preset")
    p.add_argument("--out", required=True, help="campaign folder")
    p.add_argument("--assemblies", type=int, default=5, help="assemblies (default 5)")
    p.add_argument("--runs", type=int, default=1, help="runs per assembly (default 1)")
    p.add_argument("--seed", type=int, default=0, help="random seed (default 0)")
    p.add_argument("--levels", type=int, default=10, help="excitation levels (default 10)")
    p.add_argument("--workers", type=int, help="processes writing records (default: one per CPU)")
    p.set_defaults(func=_cmd_rig)

    p = sub.add_parser("backbones", help="extract backbones from every record of a campaign")
    p.add_argument("dir", help="campaign folder (TRC layout)")
    p.add_argument("--out", help="CSV file (default DIR/backbones.csv)")
    p.add_argument("--periods", type=int, default=70, help="periods per hold (default 70)")
    p.set_defaults(func=_cmd_backbones)

    p = sub.add_parser("identify", help="SINDy identification of a joint model")
    p.add_argument("dir", help="campaign folder (TRC layout)")
    p.add_argument(
        "--effects", type=_effect_list, required=True, help="library: comma-separated effect names"
    )
    p.add_argument("--out", required=True, help="model JSON file")
    p.add_argument("--records", type=int, default=3, help="records fitted jointly (default 3)")
    p.set_defaults(func=_cmd_identify)

    p = sub.add_parser("train-surrogate", help="dataset, training and ONNX export of a surrogate")
    p.add_argument("dir", help="campaign folder (TRC layout): the measured curves")
    p.add_argument("--model", required=True, help="model JSON file")
    p.add_argument("--out", required=True, help="surrogate folder")
    p.add_argument("--curves", type=int, default=500, help="training curves (default 500)")
    p.add_argument("--epochs", type=int, help="epochs per stage (default: the paper-sized run)")
    p.add_argument("--seed", type=int, default=0, help="random seed (default 0)")
    p.set_defaults(func=_cmd_train_surrogate)

    p = sub.add_parser("criticize", help="where the model fails and which effect it lacks")
    p.add_argument("dir", help="campaign folder (TRC layout)")
    p.add_argument("--model", required=True, help="model JSON file")
    p.add_argument("--out", required=True, help="report folder (criticism.json + figures)")
    p.add_argument(
        "--rounds", type=int, default=0, help="add the best proposed effect this many times"
    )
    p.set_defaults(func=_cmd_criticize)

    p = sub.add_parser("update", help="stochastic updating of the model on measured backbones")
    p.add_argument("dir", help="campaign folder (TRC layout) or a backbones CSV")
    p.add_argument("--model", help="model JSON file (for --forward harmonic|pll)")
    p.add_argument("--forward", choices=("surrogate", "harmonic", "pll"), default="surrogate")
    p.add_argument("--surrogate", help="surrogate folder (for --forward surrogate)")
    p.add_argument("--out", required=True, help="posterior netCDF file")
    p.add_argument(
        "--sampler", choices=("metropolis", "demetropolisz", "nuts"), default="metropolis"
    )
    p.add_argument("--draws", type=int, default=30_000, help="draws per chain (default 30000)")
    p.add_argument("--tune", type=int, default=2_000, help="tuning steps (default 2000)")
    p.add_argument("--chains", type=int, default=2, help="chains (default 2)")
    p.add_argument("--seed", type=int, default=0, help="random seed (default 0)")
    p.add_argument("--report", help="also write the arviz report into this folder")
    p.add_argument(
        "--trace", help="zarr folder the draws are written to as they are taken (default: "
        "OUT with the suffix .zarr)",
    )  # fmt: skip
    p.add_argument(
        "--resume", action="store_true",
        help="continue a stopped run from its trace instead of starting again",
    )  # fmt: skip
    p.set_defaults(func=_cmd_update)

    p = sub.add_parser("report", help="HTML report of a run")
    p.add_argument("dir", help="campaign folder (TRC layout) or a backbones CSV")
    p.add_argument("--posterior", help="posterior netCDF file of `pm-joint update`")
    p.add_argument("--criticism", help="folder written by `pm-joint criticize`")
    p.add_argument("--out", required=True, help="report folder (index.html)")
    p.set_defaults(func=_cmd_report)

    p = sub.add_parser("demo", help="run the pipeline on the embedded default")
    p.add_argument("--out", default="demo_out", help="output folder (default: demo_out)")
    p.add_argument(
        "--size", choices=("full", "small"), default="full",
        help="full: the paper-sized campaign; small: a quick check (default: full)",
    )  # fmt: skip
    p.set_defaults(func=_cmd_demo)
    return parser


def main(argv: Sequence[str] | None = None) -> int:
    """Entry point of the ``pm-joint`` command."""
    args = build_parser().parse_args(argv)
    formatwarning = warnings.formatwarning

    def one_line(message, category, *_, **__) -> str:
        return f"pm-joint {args.command}: {category.__name__}: {message}\n"

    warnings.formatwarning = one_line  # a warning is one line, as an error is
    try:
        args.func(args)
    except (ValueError, FileNotFoundError, NotADirectoryError) as exc:
        reason = str(exc).splitlines()[0] if str(exc) else type(exc).__name__
        print(f"pm-joint {args.command}: error: {reason}", file=sys.stderr)
        return 2
    finally:
        warnings.formatwarning = formatwarning
    return 0


if __name__ == "__main__":
    sys.exit(main())
