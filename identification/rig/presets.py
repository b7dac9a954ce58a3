"""Named rig scenarios: a ground truth, the model a user would start from, and what is hidden.

Each preset of :data:`RIG_PRESETS` gives :meth:`identification.rig.Rig.preset` its
nominal model and reassembly spread; the ``hidden-*`` scenarios (and the control
``hidden-none``) hide one or two catalogue effects at a level that shows clearly in
the backbone over 0.05–2 mm, for the model-criticism studies.
"""

from __future__ import annotations

import math
from collections.abc import Mapping
from dataclasses import dataclass, field
from typing import Any

from identification.model import JointModel

__all__ = ["HIDDEN_EFFECT_SCENARIOS", "RIG_PRESETS", "RigPreset"]


@dataclass(frozen=True)
class RigPreset:
    """A ground truth, the model a user would start from, and what is hidden."""

    model: JointModel
    base_model: JointModel
    hidden_effects: tuple[str, ...]
    description: str
    variability: Mapping[str, float] = field(default_factory=dict)


_F0_HZ = 101.0
_K0 = (2 * math.pi * _F0_HZ) ** 2
_ZETA = 0.003


def _linear(zeta: float = _ZETA) -> dict[str, float]:
    """101 Hz with viscous damping ratio ``zeta``."""
    return {"linear_stiffness": _K0, "viscous_damping": 2 * zeta * math.sqrt(_K0)}


def _microslip(stiffness_share: float, slip_amplitude_m: float) -> dict[str, Any]:
    """A Jenkins element carrying ``stiffness_share`` of the 101 Hz stiffness while stuck."""
    k_t = stiffness_share * _K0
    return {"coefficient": 1.0, "k_t": k_t, "F_s": k_t * slip_amplitude_m}


def _model(name: str, terms: Mapping[str, Any]) -> JointModel:
    terms = dict(terms)
    if "microslip" in terms:  # the stuck joint keeps the 101 Hz small-amplitude frequency
        terms["linear_stiffness"] -= terms["microslip"]["k_t"]
    return JointModel(terms, name=name)


def _scenario(
    name: str, base: Mapping[str, Any], hidden: Mapping[str, Any], text: str
) -> RigPreset:
    return RigPreset(
        model=_model(name, {**base, **hidden}),
        base_model=_model(f"{name} (base)", base),
        hidden_effects=tuple(hidden),
        description=text,
        variability=_REASSEMBLY,
    )


#: Reassembly spread of the presets: joint stiffness and friction vary most.
_REASSEMBLY = {"linear_stiffness": 0.005, "viscous_damping": 0.05}
_HARDENING = {"cubic_stiffness": 1.4e10}  # +5 % at 2 mm

#: Microslip from 0.2 mm (6 % of the stiffness) and membrane hardening to 110 Hz at 2 mm.
_TRC_JOINT = {"cubic_stiffness": 3.26e10, "microslip": _microslip(0.06, 2e-4)}
_TRC = {**_linear(0.0025), **_TRC_JOINT}

#: Named rig scenarios. Frequencies and damping are quoted for 0.05–2 mm.
RIG_PRESETS: dict[str, RigPreset] = {
    "trc-like": RigPreset(
        model=_model("trc-like", _TRC),
        base_model=_model("trc-like (base)", _linear(0.0025)),
        hidden_effects=("cubic_stiffness", "microslip"),
        description=(
            "TRC-like panel: 101 Hz at small amplitude, microslip from 0.2 mm softens it to "
            "about 99.9 Hz at 0.5 mm and lifts the damping from 0.25 % to 1.2 %, then membrane "
            "stretching (cubic) hardens it to 110 Hz at 2 mm (damping back to 0.5 %)"
        ),
        variability={**_REASSEMBLY, "microslip.F_s": 0.1, "cubic_stiffness": 0.03},
    ),
    "hidden-none": _scenario(
        "hidden-none", {**_linear(), **_HARDENING}, {},
        "control: the base model (linear, viscous, cubic hardening +5 % at 2 mm) is the truth",
    ),
    "hidden-cubic": _scenario(
        "hidden-cubic", _linear(), _HARDENING,
        "membrane stretching missing: cubic stiffness raises the frequency by 5 % at 2 mm "
        "over a linear-viscous base model",
    ),
    "hidden-quadratic": _scenario(
        "hidden-quadratic", {**_linear(), **_HARDENING}, {"quadratic_stiffness": -5e7},
        "arch asymmetry missing: quadratic stiffness (a multi-harmonic, softening effect) takes "
        "about 2 % off the 2 mm frequency of a linear-viscous-cubic base model",
    ),
    "hidden-quadratic-damping": _scenario(
        "hidden-quadratic-damping", _linear(), {"quadratic_damping": 5.0},
        "fluid damping missing: ẋ|ẋ| raises the damping from 0.3 % to about 0.7 % at 2 mm "
        "over a linear-viscous base model",
    ),
    "hidden-coulomb": _scenario(
        "hidden-coulomb", _linear(), {"coulomb_friction": 0.2},
        "macroslip friction missing: Coulomb friction triples the damping at 0.05 mm "
        "(0.3 % → 0.9 %, fading as 1/amplitude to 0.32 % at 2 mm) over a linear-viscous base model",
    ),
    "hidden-microslip": _scenario(
        "hidden-microslip", {**_linear(), **_HARDENING}, {"microslip": _microslip(0.06, 2e-4)},
        "joint microslip missing: from 0.2 mm a Jenkins element softens the panel by up to "
        "2.6 % and lifts the damping from 0.3 % to 1.25 %, over a linear-viscous-cubic base",
    ),
    "hidden-two": _scenario(
        "hidden-two", _linear(0.0025), _TRC_JOINT,
        "two effects missing at once (the trc-like truth): microslip softening and damping, "
        "then cubic hardening to 110 Hz, over a linear-viscous base model",
    ),
}  # fmt: skip

#: The hidden-effect scenarios (and the control, ``hidden-none``) of the criticism studies.
HIDDEN_EFFECT_SCENARIOS: tuple[str, ...] = tuple(n for n in RIG_PRESETS if n.startswith("hidden-"))
