"""Forward models for PyMC: ONNX surrogate, harmonic balance, PLL simulator.

Every forward model maps a parameter vector θ of shape ``(..., n_params)``
(leading batch axes allowed) to a backbone tensor of shape ``(..., n_points, 3)``
with the columns :data:`BACKBONE_COLUMNS`: amplitude (m), frequency (Hz),
damping ratio. NaN marks a channel the model does not give (a surrogate trained
without damping, a PLL hold that did not lock) and a parameter vector the
model cannot evaluate: the forward models never raise on a bad θ mid-chain,
the likelihood turns NaN into ``logp = -inf``. Each one exposes
``parameter_names`` (the order of θ) and ``n_points``.

:class:`~pm_joint.forward.surrogate.SurrogateOp`
    The exported ONNX surrogate on onnxruntime; points are its grid (excitation
    levels, m/s², or response amplitudes, m). Gradient: backpropagation through
    :func:`~pm_joint.forward.surrogate.surrogate_graph`, the same network
    rebuilt in pytensor from the ONNX initializers.
:class:`~pm_joint.forward.surrogate.SurrogateGraph`
    That network as a native pytensor graph (``forward_model("surrogate",
    ..., native_graph=True)``): gradient samplers (nutpie, NUTS) compile it
    with the rest of the model.
:class:`~pm_joint.forward.harmonic.HarmonicBalanceGraph`
    Builds :func:`~pm_joint.forward.harmonic.harmonic_backbone_graph`, the
    single-harmonic backbone as a native pytensor graph from the catalogue's
    describing functions (pytensor differentiates it; NUTS works); points are
    an amplitude grid.
:class:`~pm_joint.forward.modal_harmonic.ModalHarmonicGraph`
    Builds :func:`~pm_joint.forward.modal_harmonic.modal_backbone_graph`, the
    phase-resonant backbone of one mode of an N-mode
    :class:`~identification.multimode.ModalModel` (first order in the coupling,
    one describing function per joint element) as a native pytensor graph;
    points are the locked mode's amplitude grid (``forward_model("modal_harmonic",
    ...)``, not yet a ``build_model`` choice).
:class:`~pm_joint.forward.pll.PLLOp`
    The time-domain PLL simulator as a black box (no gradient); points are its
    excitation levels (base-acceleration amplitudes of the holds, m/s²).

:func:`forward_model` picks one by name, so one PyMC model switches between
them with one argument.
"""

from __future__ import annotations

import os
from collections.abc import Sequence

from numpy.typing import ArrayLike

from identification.analytical.pll import PLLConfig
from identification.model import JointModel
from identification.multimode.model import ModalModel
from pm_joint.forward.base import BACKBONE_COLUMNS
from pm_joint.forward.harmonic import (
    HarmonicBalanceGraph,
    describing_graph,
    harmonic_backbone_graph,
)
from pm_joint.forward.modal_harmonic import ModalHarmonicGraph, modal_backbone_graph
from pm_joint.forward.pll import PLLOp
from pm_joint.forward.surrogate import SurrogateGraph, SurrogateOp, surrogate_graph
from surrogates.runtime import SurrogateRuntime

__all__ = [
    "BACKBONE_COLUMNS",
    "FORWARD_KINDS",
    "MODAL_FORWARD_KINDS",
    "HarmonicBalanceGraph",
    "ModalHarmonicGraph",
    "PLLOp",
    "SurrogateGraph",
    "SurrogateOp",
    "describing_graph",
    "forward_model",
    "harmonic_backbone_graph",
    "modal_backbone_graph",
    "surrogate_graph",
]

#: Names :func:`forward_model` accepts for a one-mode JointModel (``build_model``'s choices).
FORWARD_KINDS = ("surrogate", "harmonic", "pll")
#: Names :func:`forward_model` accepts for an N-mode ModalModel.
MODAL_FORWARD_KINDS = ("modal_harmonic",)


def forward_model(
    kind: str,
    model: JointModel | ModalModel | None,
    names: Sequence[str] | None = None,
    *,
    surrogate: SurrogateRuntime | str | os.PathLike | None = None,
    amplitudes_m: ArrayLike | None = None,
    levels: ArrayLike | None = None,
    config: PLLConfig | None = None,
    native_graph: bool = False,
    mode: int = 1,
) -> SurrogateOp | SurrogateGraph | HarmonicBalanceGraph | ModalHarmonicGraph | PLLOp:
    """The forward model called ``kind``, all with the same interface.

    Parameters
    ----------
    kind
        ``"surrogate"`` (needs ``surrogate``; ``model`` is not used),
        ``"harmonic"`` (needs ``amplitudes_m``), ``"pll"`` (needs ``levels``;
        ``config`` optional) or ``"modal_harmonic"`` (a ModalModel; needs
        ``amplitudes_m``, ``mode`` optional).
    model
        The joint model (template of the named parameters); a
        :class:`~identification.multimode.ModalModel` for ``"modal_harmonic"``.
    names
        Order of θ; default the surrogate's or the model's parameter names.
    amplitudes_m
        The harmonic balance's amplitude grid (m).
    levels
        The PLL holds' base-acceleration amplitudes (m/s²), in test order.
    native_graph
        The surrogate as :class:`SurrogateGraph` (its network in pytensor, for
        gradient samplers) rather than :class:`SurrogateOp` (onnxruntime).
    mode
        ``"modal_harmonic"``: the mode held at phase resonance, from 1.

    Returns
    -------
    SurrogateOp | SurrogateGraph | HarmonicBalanceGraph | ModalHarmonicGraph | PLLOp
        Call it on θ ``(..., n_params)`` for a ``(..., n_points, 3)`` backbone.
    """
    needs = {
        "surrogate": "surrogate",
        "harmonic": "amplitudes_m",
        "pll": "levels",
        "modal_harmonic": "amplitudes_m",
    }
    if kind not in needs:
        raise ValueError(f"kind must be one of {FORWARD_KINDS + MODAL_FORWARD_KINDS}, got {kind!r}")
    given = {"surrogate": surrogate, "amplitudes_m": amplitudes_m, "levels": levels}
    if given[needs[kind]] is None:
        raise ValueError(f"forward model {kind!r} needs {needs[kind]}=")
    if kind == "modal_harmonic":
        if not isinstance(model, ModalModel):
            raise ValueError(f"forward model {kind!r} needs a ModalModel, got {model!r}")
        return ModalHarmonicGraph(model, names, amplitudes_m, mode)
    if native_graph and kind == "pll":
        raise ValueError("the PLL simulator has no native pytensor graph (native_graph=True)")
    if kind == "surrogate":
        return SurrogateGraph(surrogate, names) if native_graph else SurrogateOp(surrogate, names)
    if not isinstance(model, JointModel):
        raise ValueError(f"forward model {kind!r} needs a JointModel, got {model!r}")
    if kind == "harmonic":
        return HarmonicBalanceGraph(model, names, amplitudes_m)
    return PLLOp(model, names, levels, config)
