"""The ``pm-joint`` command.

Each subcommand is a small function taking the parsed arguments; bad input
ends in a one-line reason on stderr and exit code 2.
"""

from __future__ import annotations

import argparse
import sys
from collections.abc import Sequence

from identification.effects import CATALOGUE
from identification.model import PRESETS, JointModel


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


def _cmd_demo(args: argparse.Namespace) -> None:
    from pm_joint.demo import run_demo

    run_demo(out=args.out)


def build_parser() -> argparse.ArgumentParser:
    parser = argparse.ArgumentParser(
        prog="pm-joint",
        description="Stochastic model updating of nonlinear structural joints.",
    )
    sub = parser.add_subparsers(dest="command", required=True)

    p = sub.add_parser("effects", help="list the effects catalogue")
    p.set_defaults(func=_cmd_effects)

    p = sub.add_parser("model", help="show a joint model (preset or JSON file)")
    source = p.add_mutually_exclusive_group(required=True)
    source.add_argument("--preset", choices=sorted(PRESETS), help="named model")
    source.add_argument("--json", help="model JSON file")
    p.add_argument("--out", help="write the model as JSON here")
    p.set_defaults(func=_cmd_model)

    p = sub.add_parser("demo", help="run the pipeline on the embedded default")
    p.add_argument("--out", default="demo_out", help="output folder (default: demo_out)")
    p.set_defaults(func=_cmd_demo)
    return parser


def main(argv: Sequence[str] | None = None) -> int:
    """Entry point of the ``pm-joint`` command."""
    args = build_parser().parse_args(argv)
    try:
        args.func(args)
    except (ValueError, FileNotFoundError) as exc:
        print(f"pm-joint {args.command}: error: {exc}", file=sys.stderr)
        return 2
    return 0


if __name__ == "__main__":
    sys.exit(main())
