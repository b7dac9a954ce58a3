"""What several ``pm-joint`` commands share: the record options as Workspace keywords, the
identification's preprocessing options, ``update``'s trace folder and its convergence exit.

Apart from :mod:`pm_joint.cli` so that :mod:`pm_joint.cli_modes` (the several-modes
branches of the commands) uses them without importing the parser module.
"""

from __future__ import annotations

import argparse
import sys
from pathlib import Path
from typing import Any

from identification.measurements.signals import DECAY_EDGE_PERIODS
from pm_joint.sampler_defaults import sampler_defaults

__all__ = [
    "EXIT_NOT_CONVERGED",
    "identify_options",
    "trace_folder",
    "verdict_exit",
    "workspace_options",
]

#: Exit code of `pm-joint update` when the posterior is written but did not converge.
EXIT_NOT_CONVERGED = 3


def workspace_options(args: argparse.Namespace) -> dict[str, Any]:
    """The Workspace keywords of the record options."""
    from identification.measurements.columns import ColumnLayout

    layout = ColumnLayout(
        test=args.test, time=args.time, response=args.response, quantity=args.quantity,
        excitation=args.excitation, excitation_kind=args.excitation_kind,
        excitation_gain=args.excitation_gain, frequency=args.frequency, level=args.level,
        decimal_comma=True if args.decimal_comma else None, relative=args.relative_response,
        forcing_gain=args.forcing_gain,
    )  # fmt: skip
    decay = {"window_periods": args.window_periods, "edge_periods": args.edge_periods or 0.0,
             "band_hz": args.band}  # fmt: skip
    return {"layout": layout, "decay_options": decay}


def identify_options(args: argparse.Namespace) -> dict[str, Any]:
    """Preprocessing options of the identification from the record options."""
    edge = args.edge_periods
    if edge is None:
        edge = DECAY_EDGE_PERIODS if args.test == "free-decay" else 20.0
    return {"edge_periods": edge, "band_hz": args.band}


def verdict_exit(idata: Any, out: str) -> int:
    """Print the convergence verdict of ``update``; its exit code (3 when not converged)."""
    from pm_joint.analysis import convergence_verdict

    verdict = convergence_verdict(idata)
    print(f"convergence: {verdict.headline()}")
    if not verdict.converged:
        print(
            f"pm-joint update: NOT CONVERGED: the posterior in {out} is not a result yet; "
            "continue it with --resume and more --draws (exit code "
            f"{EXIT_NOT_CONVERGED})",
            file=sys.stderr,
        )
        return EXIT_NOT_CONVERGED
    return 0


def trace_folder(args: argparse.Namespace, forward: str) -> str | Path | None:
    """``update``'s trace folder: ``--trace``, else the output's name with ``.zarr``; none
    for nutpie, which keeps its draws in memory (a folder asked for is then refused)."""
    if args.trace:
        return args.trace
    sampler = args.sampler or sampler_defaults(args.population, forward).sampler
    return None if sampler == "nutpie" else Path(args.out).with_suffix(".zarr")
