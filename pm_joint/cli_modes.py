"""The several-modes branches of the ``pm-joint`` commands: ``backbones --modes N``,
``identify --modes N``, and ``train-surrogate`` and ``update`` with a ModalModel."""

from __future__ import annotations

import argparse
import json
from pathlib import Path
from typing import Any

from pm_joint.cli_common import identify_options, trace_folder, verdict_exit, workspace_options

__all__ = [
    "decay_mode_backbones",
    "extract_mode_backbones",
    "identify_modal_model",
    "is_modal_model",
    "modal_hold_backbones",
    "mode_backbones",
    "train_modal_surrogates",
    "update_modal_model",
]


def decay_mode_backbones(workspace: Any, args: argparse.Namespace) -> None:
    """``backbones --test free-decay --modes N`` (N ≥ 2): each mode's backbone."""
    from pm_joint.pipeline import campaign_decay_modes

    decays = campaign_decay_modes(workspace, args.modes, mode_shapes=args.mode_shapes)
    for decay in decays:
        print("\n".join(decay.summary()))
    print(f"extracted {len(decays)} decay(s) by mode ({args.modes} modes) to "
          f"{workspace.backbones_csv}")  # fmt: skip


def modal_hold_backbones(workspace, args: argparse.Namespace) -> None:
    from identification.measurements.modal_backbones import sidecar_path
    from pm_joint.pipeline import campaign_modal_backbones

    result = campaign_modal_backbones(workspace, args.modes, mode_shapes=args.mode_shapes)
    holds = sum(len(c.holds) for c in result)
    print(f"extracted {len(result)} record(s) × {args.modes} modes, {holds} holds ({args.test}) "
          f"to {workspace.backbones_csv} (sensors and shapes: "
          f"{sidecar_path(workspace.backbones_csv)})")  # fmt: skip
    for curve in result:
        f = curve.modal_filter
        worst = int(curve.reconstruction_error.argmax())
        print(
            f"{curve.label}: locked mode {curve.locked_mode} of "
            + ", ".join(f"{x:.5g}" for x in f.frequencies_hz)
            + f" Hz; shapes {f.source}; complex-to-real error up to {f.alignment_error.max():.2g}"
            f"; reconstruction error up to {curve.reconstruction_error[worst]:.2g} "
            f"({f.sensor_names[worst]})"
        )


def identify_modal_model(workspace: Any, args: argparse.Namespace) -> None:
    """``identify --modes N`` (N ≥ 2): coupled modal equations, a ModalModel JSON."""
    from identification.measurements.modes import read_modes
    from identification.sindy.modal_coordinates import ModalSettings
    from identification.sindy.modal_identify import identify_modes

    shapes = None
    if args.mode_shapes:
        shapes = read_modes(args.mode_shapes, decimal_comma=args.decimal_comma or None, points=None)
    records = workspace.records[: min(args.records, len(workspace.records))]
    settings = ModalSettings(edge_periods=identify_options(args)["edge_periods"],
                             band_hz=args.band, joint_sensor=args.joint_sensor)  # fmt: skip
    result = identify_modes(records, args.modes, args.effects, mode_shapes=shapes,
                            settings=settings)  # fmt: skip
    result.model.to_json(args.out)
    print(result.summary())
    for mode in range(1, args.modes + 1):
        print(result.model.equation(mode))
    print(f"wrote {args.out}")


def train_modal_surrogates(args: argparse.Namespace) -> None:
    """``train-surrogate`` with a ModalModel: one surrogate per measured mode."""
    from identification.multimode.model import ModalModel
    from pm_joint.modal_surrogate import train_modal_surrogate

    model = ModalModel.from_json(args.model)
    measured = mode_backbones(args, model)
    surrogate = train_modal_surrogate(
        model, measured, args.out, n_curves=args.curves, n_amplitudes=args.amplitudes,
        max_epochs=args.epochs, seed=args.seed,
    )  # fmt: skip
    names = ", ".join(surrogate.parameter_names)
    print(f"wrote {args.out}/modal_surrogate.json: modes {surrogate.modes}, parameters {names}")
    for mode, runtime in surrogate.runtimes.items():
        analytical = runtime.metadata["test"]["analytical"]
        for channel in ("frequency_hz", "damping_ratio"):
            ratios = analytical["ratios"][channel]
            scatter = ratios.get("to_scatter_max")
            print(
                f"mode {mode} test (analytical), {channel}: ÷ linear baseline "
                f"{ratios['to_linear']:.3g}, ÷ cubic {ratios['to_cubic']:.3g}, ÷ assembly "
                "scatter (worst amplitude) " + ("unknown" if scatter is None else f"{scatter:.3g}")
            )


def mode_backbones(args: argparse.Namespace, model: Any) -> dict:
    """The campaign's per-mode backbones (the ``--modes N`` table, written first when
    missing), by mode."""
    from pm_joint.inference.modal import read_mode_backbones
    from pm_joint.workspace import Workspace

    workspace = Workspace(args.dir, **workspace_options(args))
    if not workspace.backbones_csv.is_file():
        extract_mode_backbones(workspace, model.n_modes, args)
    return read_mode_backbones(workspace.backbones_csv)


def is_modal_model(source: str) -> bool:
    """Whether ``--model`` names a ModalModel JSON file (its versioned format says so)."""
    from identification.multimode.model import FORMAT as MODAL_FORMAT

    path = Path(source)
    if path.suffix.lower() != ".json" or not path.is_file():
        return False  # a preset name, or a file JointModel's reader reports on
    try:
        data = json.loads(path.read_text(encoding="utf-8"))
    except (UnicodeDecodeError, json.JSONDecodeError):
        return False
    return isinstance(data, dict) and data.get("format") == MODAL_FORMAT


def update_modal_model(args: argparse.Namespace) -> int:
    """``update`` with a ModalModel: every mode's backbones (the ``--modes N`` table)."""
    from identification.multimode.model import ModalModel
    from pm_joint.inference.modal import MODAL_FORWARD, MODAL_SURROGATE_FORWARD
    from pm_joint.modal_update import mode_report, update_modes
    from surrogates.modal import ModalSurrogate

    if args.forward == "pll" or (args.forward == "surrogate" and not args.surrogate):
        raise ValueError(
            f"{args.model} is a ModalModel: it updates through its N-mode harmonic balance "
            "graph (--forward harmonic, the default) or, with --surrogate DIR, through the "
            "N-mode surrogate train-surrogate wrote for it; not the PLL"
        )
    if args.surrogate and args.forward == "harmonic":
        raise ValueError("--forward harmonic and --surrogate: give one forward model")
    model = ModalModel.from_json(args.model)
    surrogate = ModalSurrogate.load(args.surrogate) if args.surrogate else None
    measured = mode_backbones(args, model)
    forward = MODAL_FORWARD if surrogate is None else MODAL_SURROGATE_FORWARD
    trace = trace_folder(args, forward)
    idata = update_modes(
        model, measured, args.out, population=args.population, sampler=args.sampler,
        draws=args.draws, tune=args.tune, chains=args.chains, seed=args.seed, trace=trace,
        resume=args.resume, surrogate=surrogate,
    )  # fmt: skip
    if "outside_surrogate_box" in idata.attrs:
        share = idata.attrs["outside_surrogate_box"]
        print(f"draws outside the surrogate's training box: {100 * share:.1f} %")
    print(f"wrote {args.out} (modes {', '.join(map(str, sorted(measured)))} of {args.model})")
    print(f"sampler: {idata.attrs['sampler']} ({idata.attrs['sampler_reason']})")
    if args.report:
        for m in measured:
            folder = Path(args.report) / f"mode{m}"
            mode_report(idata, measured, m, folder)
            print(f"wrote {folder}/report.json")
    return verdict_exit(idata, args.out)


def extract_mode_backbones(workspace: Any, n_modes: int, args: argparse.Namespace) -> None:
    """The per-mode backbones a ModalModel is updated on, when the campaign has none yet."""
    from pm_joint.pipeline import campaign_decay_modes, campaign_modal_backbones

    extract = campaign_decay_modes if args.test == "free-decay" else campaign_modal_backbones
    extract(workspace, n_modes)
