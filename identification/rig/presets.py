"""Named rig scenarios: a ground truth, the model a user would start from, and what is hidden.

Each preset of :data:`RIG_PRESETS` gives :meth:`identification.rig.Rig.preset` its
nominal model and reassembly spread; the ``hidden-*`` scenarios (and the control
``hidden-none``) hide one or two catalogue effects at a level that shows clearly in
the backbone over 0.05–2 mm, for the model-criticism studies.

The ``lab-*`` scenarios run on the lab rig (:class:`identification.rig.lab.LabRig`,
101 Hz, 0.3 % damping at rest) and come in three groups, for the criticism studies
that must survive real measurements:

* :data:`LAB_NULL_SCENARIOS` — the truth is the base model's structure; only the
  lab differs: ``lab-pure`` (a clean lock-in PLL), ``lab-distorted`` (4 %/3 % of 2nd/3rd
  harmonic in the base acceleration, shaker-structure interaction), ``lab-ripple``
  (about 3 Hz of 2ω ripple on the frequency channel), ``lab-lock`` (a 3° phase offset
  and holds that end before the amplitude settles), ``lab-drift`` (natural frequency
  +0.3 % and response-sensor gain +4 % over the campaign, levels up then down),
  ``lab-dropouts`` (vibrometer spikes, per-channel noise, a decoder offset),
  ``lab-all`` and ``lab-all-hardening`` (everything at once, linear and hardening truths).
  Nothing should be proposed.
* :data:`LAB_HIDDEN_SCENARIOS` — ``lab-hidden-<effect>``: every catalogue effect but the
  linear ones hidden in turn, its signature clear over 0.05–2 mm, under mild artefacts
  of every kind (:data:`_LAB`).
* :data:`LAB_OUT_OF_CATALOGUE_SCENARIOS` — physics no catalogue term is: an Iwan joint,
  a symmetric clearance, a preloaded one-sided contact, power-law damping, a second
  mode nearby coupled through the joint; under the same mild artefacts. The base model
  is the truth's catalogue part; the right answer is "not (fully) explained by the
  catalogue".

:data:`MODAL_RIG_PRESETS` holds the truths of several modes for
:class:`identification.rig.modal_rig.ModalRig`: ``two-mode``, bending and torsion near
1:2 coupled through the joint and a quadratic modal coupling.
"""

from __future__ import annotations

import dataclasses
import math
from collections.abc import Callable, Mapping, Sequence
from dataclasses import dataclass, field
from typing import Any

from identification.effects import CATALOGUE
from identification.model import JointModel
from identification.multimode.model import Coupling, JointElement, ModalModel, Mode
from identification.rig.conditions import Controller, Drift, Sensors, Shaker
from identification.rig.joints import (
    Clearance,
    IwanJoint,
    Joint,
    PowerLawDamping,
    PreloadedContact,
    SecondMode,
)

__all__ = [
    "HIDDEN_EFFECT_SCENARIOS",
    "LAB_HIDDEN_SCENARIOS",
    "LAB_NULL_SCENARIOS",
    "LAB_OUT_OF_CATALOGUE_SCENARIOS",
    "MODAL_RIG_PRESETS",
    "RIG_PRESETS",
    "TWO_MODE_RATIO",
    "ModalRigPreset",
    "RigPreset",
    "lab_hidden_scenario",
]


@dataclass(frozen=True)
class RigPreset:
    """A ground truth, the model a user would start from, and what is hidden.

    ``lab`` holds the :class:`~identification.rig.lab.LabRig` settings of a lab
    scenario (artefacts, out-of-catalogue joints, a second mode, the level
    schedule); None for the ideal rig's scenarios.
    """

    model: JointModel
    base_model: JointModel
    hidden_effects: tuple[str, ...]
    description: str
    variability: Mapping[str, float] = field(default_factory=dict)
    lab: Mapping[str, Any] | None = None


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


# --------------------------------------------------------------------------
# Lab scenarios: the lab rig (identification.rig.lab) with its artefacts.


def _lab_model(name: str, terms: Mapping[str, Any], joints: Sequence[Joint] = ()) -> JointModel:
    """A catalogue model whose stiffness at rest, joints included, is the 101 Hz one.

    Terms that stiffen the structure at rest (a stuck Jenkins element, tanh and
    exp, a stuck Iwan joint, a closed contact) take their share off the linear term.
    """
    terms = dict(terms)
    at_rest = sum(j.small_amplitude_stiffness for j in joints)
    if "microslip" in terms:
        at_rest += terms["microslip"]["k_t"]
    for effect in ("tanh_saturation", "exponential"):
        if effect in terms:
            at_rest += terms[effect]["coefficient"] / terms[effect]["x_s"]
    terms["linear_stiffness"] -= at_rest
    return JointModel(terms, name=name)


#: Shaker distortion: 4 % 2nd and 3 % 3rd harmonic of the base acceleration.
_DISTORTION = {"distortion": {2: 0.04, 3: 0.03}, "distortion_phase_deg": {2: 30.0, 3: -60.0}}
#: The distortion and a light shaker-structure interaction (modal over armature mass 0.2 %).
_DISTORTED = Shaker(**_DISTORTION, interaction=0.002)
#: A first-order 15 Hz detector behind a hot proportional gain: about 3 Hz of 2ω ripple on
#: the frequency channel at 101 Hz.
_RIPPLING = Controller(
    detector_cutoff_hz=15.0,
    detector_order=1,
    proportional_gain_hz_per_deg=0.35,
    integral_gain_hz_per_deg_s=4.0,
)
#: Noise that differs per channel: the centre point on reflective tape, the others less
#: well placed; accelerometer-grade base channels.
_CHANNEL_NOISE = tuple(1e-4 * f for f in (2, 1.5, 3, 1, 2, 1, 1.5, 1, 2, 1, 2, 1, 3, 1.5, 2))
_SPECKLE = Sensors(
    panel_noise_m_s=_CHANNEL_NOISE,
    base_noise_m_s=3e-5,
    dropout_rate_hz=0.5,
    dropout_spike_m_s=0.5,
    panel_offset_m_s=2e-3,
)
_DRIFTING = Drift(frequency_over_campaign=0.003, frequency_over_run=0.002, gain_over_campaign=0.04)
#: Everything at once: what a lab campaign looks like.
_ALL = {
    # No interaction here: with the hot loop of _RIPPLING it makes the lock oscillate
    # (frequency swings of ±10 Hz), a failure, not an artefact to calibrate against.
    "shaker": Shaker(**_DISTORTION),
    "controller": dataclasses.replace(_RIPPLING, phase_offset_deg=2.0),
    "drift": _DRIFTING,
    "sensors": _SPECKLE,
    "schedule": "up-down",
}
#: The conditions of the lab hidden-effect and out-of-catalogue scenarios: milder artefacts
#: of every kind.
_LAB = {
    "shaker": Shaker(distortion={2: 0.02, 3: 0.015}, interaction=0.001),
    "controller": Controller(
        detector_cutoff_hz=40.0, detector_order=1, loop_pole_hz=2.0, phase_offset_deg=1.0
    ),
    "drift": Drift(
        frequency_over_campaign=0.002, frequency_over_run=0.001, gain_over_campaign=0.02
    ),
    "sensors": Sensors(panel_noise_m_s=_CHANNEL_NOISE, base_noise_m_s=3e-5, dropout_rate_hz=0.2),
    "schedule": "up-down",
}


def _lab_scenario(
    name: str,
    base: Mapping[str, Any],
    hidden: Mapping[str, Any],
    text: str,
    conditions: Mapping[str, Any],
    joints: Sequence[Joint] = (),
    second_mode: SecondMode | None = None,
    variability: Mapping[str, float] = _REASSEMBLY,
) -> RigPreset:
    physics = {"joints": tuple(joints), "second_mode": second_mode}
    return RigPreset(
        model=_lab_model(name, {**base, **hidden}, joints),
        base_model=_lab_model(f"{name} (base)", base, joints),
        hidden_effects=tuple(hidden),
        description=text,
        variability=variability,
        lab={**conditions, **physics},
    )


_LINEAR = _linear()
_ARTEFACT_SCENARIOS = {
    "lab-pure": (
        {},
        "pure-sine lab: a clean lock-in PLL (4th-order detector), no distortion, "
        "no drift, 1e-4 m/s noise; the truth is linear-viscous",
    ),
    "lab-distorted": (
        {"shaker": _DISTORTED},
        "shaker distortion: 4 % 2nd and 3 % 3rd harmonic in the base acceleration "
        "and a light shaker-structure interaction; linear-viscous truth",
    ),
    "lab-ripple": (
        {"controller": _RIPPLING},
        "controller ripple: a first-order 15 Hz detector behind a hot proportional "
        "gain puts about 3 Hz of 2ω ripple on the frequency channel; "
        "linear-viscous truth",
    ),
    "lab-lock": (
        {"controller": Controller(loop_pole_hz=0.7, phase_offset_deg=3.0), "hold_s": 1.5},
        "imperfect lock: a 3° uncompensated phase and short holds that end before the "
        "amplitude has settled; linear-viscous truth",
    ),
    "lab-drift": (
        {"drift": _DRIFTING, "schedule": "up-down"},
        "drift: natural frequency +0.3 % over the campaign and +0.2 % within each run, "
        "response-sensor gain +4 % over the campaign, levels stepped up then down; "
        "linear-viscous truth",
    ),
    "lab-dropouts": (
        {"sensors": _SPECKLE},
        "vibrometer dropouts (0.5 per second per channel, spikes to ±0.5 m/s), "
        "a 2 mm/s offset and noise that differs per channel; linear-viscous truth",
    ),
    "lab-all": (
        _ALL,
        "all artefacts together (distortion, ripple, 2° phase offset, drift, "
        "dropouts, up-down levels); linear-viscous truth",
    ),
}
for _name, (_conditions, _text) in _ARTEFACT_SCENARIOS.items():
    RIG_PRESETS[_name] = _lab_scenario(_name, _LINEAR, {}, _text, _conditions)
RIG_PRESETS["lab-all-hardening"] = _lab_scenario(
    "lab-all-hardening",
    {**_LINEAR, **_HARDENING},
    {},
    "all artefacts together on a nonlinear truth the catalogue holds (linear, viscous, cubic "
    "hardening +5 % at 2 mm); the base model is the truth's structure",
    _ALL,
)


def lab_hidden_scenario(effect: str) -> str:
    """Name of the lab preset that hides the catalogue ``effect`` from its base model."""
    return "lab-hidden-" + effect.replace("_", "-")


#: One catalogue effect hidden at a time under the lab conditions, from each effect's own
#: :class:`~identification.effects.base.HiddenScenario`: preset name → (its terms, the base
#: it hides from beyond the linear pair, what it does over 0.05–2 mm).
_LAB_HIDDEN = {
    lab_hidden_scenario(name): (
        {name: effect.hidden_scenario.truth(_K0)},
        _HARDENING if effect.hidden_scenario.on_hardening_base else {},
        effect.hidden_scenario.description,
    )
    for name, effect in CATALOGUE.items()
    if effect.hidden_scenario is not None
}

for _name, (_hidden, _extra, _text) in _LAB_HIDDEN.items():
    RIG_PRESETS[_name] = _lab_scenario(
        _name,
        {**_LINEAR, **_extra},
        _hidden,
        f"{_text}, hidden from a {'linear-viscous-cubic' if _extra else 'linear-viscous'} base "
        "model, under mild lab artefacts of every kind",
        _LAB,
    )

#: Out-of-catalogue physics under the lab conditions: no catalogue effect is the truth.
_K_IWAN = 0.1 * _K0
_LAB_OUT_OF_CATALOGUE = {
    "iwan": (
        {
            "joints": (
                IwanJoint(
                    stiffness=_K_IWAN, macroslip_force=_K_IWAN * 3e-3 / 3, chi=-0.5, n_sliders=12
                ),
            )
        },
        {**_REASSEMBLY, "iwan.macroslip_force": 0.1},
        "an Iwan joint of 12 sliders (10 % of the stiffness at rest, power-law density χ = −0.5, "
        "macroslip at 3 mm): damping rising as amplitude^0.5 from 0.4 % to 1 % and softening",
    ),
    "clearance": (
        {"joints": (Clearance(gap_m=3e-4, contact_stiffness=0.15 * _K0),)},
        {**_REASSEMBLY, "clearance.gap_m": 0.05},
        "a symmetric clearance of ±0.3 mm closing on a spring of 15 % of the stiffness: "
        "hardening from 0.3 mm to +6 % at 2 mm",
    ),
    "contact": (
        {"joints": (PreloadedContact(contact_stiffness=0.2 * _K0, preload=0.2 * _K0 * 3e-4),)},
        {**_REASSEMBLY, "preloaded_contact.preload": 0.1},
        "a one-sided contact (20 % of the stiffness at rest) preloaded to lift off at 0.3 mm: "
        "softening by about 5 % at 2 mm with a mean shift and even harmonics",
    ),
    "power-law-damping": (
        {"joints": (PowerLawDamping(coefficient=6.2, exponent=1.5),)},
        {**_REASSEMBLY, "power_law_damping.coefficient": 0.05},
        "power-law damping c·|v|^1.5: the damping ratio rises as amplitude^0.5 from 0.3 % to "
        "about 0.8 % at 2 mm",
    ),
    "second-mode": (
        {
            "second_mode": SecondMode(
                frequency_ratio=1.05,
                damping_ratio=0.003,
                participation=0.3,
                centre_shape=0.3,
                joint_shape=0.5,
            )
        },
        _REASSEMBLY,
        "a second mode 5 % above the first (106 Hz), coupled through the joint (half the joint "
        "displacement) and seen at the centre point: as the cubic hardening brings the first "
        "mode towards it, energy goes to the second mode, the backbone flattens near 103 Hz "
        "at 1.5 mm and the damping rises from 0.3 % to 0.4 %",
    ),
}
for _kind, (_physics, _spread, _text) in _LAB_OUT_OF_CATALOGUE.items():
    _name = f"lab-{_kind}"
    _base = {**_LINEAR, **(_HARDENING if _kind == "second-mode" else {})}
    RIG_PRESETS[_name] = _lab_scenario(
        _name,
        _base,
        {},
        f"{_text}; out of the catalogue, under mild lab artefacts",
        _LAB,
        variability=_spread,
        **_physics,
    )

#: Lab scenarios whose truth is the base model's structure: nothing should be proposed.
LAB_NULL_SCENARIOS: tuple[str, ...] = (*_ARTEFACT_SCENARIOS, "lab-all-hardening")
#: Lab scenarios hiding one catalogue effect.
LAB_HIDDEN_SCENARIOS: tuple[str, ...] = tuple(_LAB_HIDDEN)
#: Lab scenarios whose missing physics is not in the catalogue.
LAB_OUT_OF_CATALOGUE_SCENARIOS: tuple[str, ...] = tuple(f"lab-{k}" for k in _LAB_OUT_OF_CATALOGUE)


# --------------------------------------------------------------------------
# Several modes: the two-mode virtual TRC (identification.rig.modal_rig).


@dataclass(frozen=True)
class ModalRigPreset:
    """A ground truth of several modes for :class:`~identification.rig.modal_rig.ModalRig`.

    ``model`` builds the truth for a frequency ratio (None: the preset's own);
    ``amplitude_range_mm`` is the range of each mode's PLL campaign at its reference
    point; ``lab`` the rig's artefact settings.
    """

    model: Callable[[float | None], ModalModel]
    description: str
    amplitude_range_mm: tuple[tuple[float, float], ...]
    variability: Mapping[str, float] = field(default_factory=dict)
    lab: Mapping[str, Any] = field(default_factory=dict)


#: Torsion over bending frequency of the two-mode preset: near 1:2, below it by enough that
#: twice the bending backbone (softened to 99.9 Hz by microslip at 0.5 mm) stays 2 % above the
#: torsion frequency, as on the TRC panel (about 105–111 and 198–200 Hz).
TWO_MODE_RATIO = 1.94
_TWO_MODE_JOINT_SHAPES = ((1.0, 0.3),)
#: The 1:2 coupling: a modal potential κ η₁² η₂ (forces 2κ η₁ η₂ on bending, κ η₁² on
#: torsion), sized so that torsion's second-harmonic participation reaches a few per cent of
#: the bending amplitude near 1 mm.
_QUADRATIC_COUPLING = 1.2e7


def _two_mode_model(ratio: float | None = None) -> ModalModel:
    """Bending at 101 Hz and torsion at ``ratio`` × 101 Hz at rest, both with unit base
    participation at their reference points, a joint that moves with both (microslip and
    membrane hardening on it) and the 1:2 quadratic coupling."""
    ratio = TWO_MODE_RATIO if ratio is None else float(ratio)
    if not (math.isfinite(ratio) and ratio > 1):
        raise ValueError(f"the two-mode ratio must be finite and > 1, got {ratio}")
    slip = _microslip(0.06, 2e-4)
    k_t = slip["k_t"]
    # The stuck Jenkins element adds φ_j² k_t to each mode's stiffness at rest.
    shapes = _TWO_MODE_JOINT_SHAPES[0]
    omega = [
        math.sqrt(_K0 - shapes[0] ** 2 * k_t),
        math.sqrt(ratio**2 * _K0 - shapes[1] ** 2 * k_t),
    ]
    kappa = _QUADRATIC_COUPLING
    return ModalModel(
        modes=(
            Mode(omega[0] / (2 * math.pi), 0.0025 * 2 * math.pi * _F0_HZ / omega[0], 1.0),
            Mode(omega[1] / (2 * math.pi), 0.003 * 2 * math.pi * ratio * _F0_HZ / omega[1], 1.0),
        ),
        joint_shapes=_TWO_MODE_JOINT_SHAPES,
        elements=(
            JointElement("microslip", 1.0, {"k_t": k_t, "F_s": slip["F_s"]}),
            JointElement("cubic_stiffness", _HARDENING["cubic_stiffness"]),
        ),
        couplings=(Coupling(1, (1, 1), 2 * kappa), Coupling(2, (2, 0), kappa)),
        name="two-mode",
    )


#: The lab conditions of the two-mode rig: those of the lab scenarios without the
#: shaker-structure interaction (not modelled for several modes).
_TWO_MODE_LAB = {**_LAB, "shaker": dataclasses.replace(_LAB["shaker"], interaction=0.0)}

MODAL_RIG_PRESETS: dict[str, ModalRigPreset] = {
    "two-mode": ModalRigPreset(
        model=_two_mode_model,
        description=(
            "two-mode TRC panel: bending at 101 Hz (damping 0.25 %) and torsion near 1:2 "
            "(196 Hz, 0.3 %), a joint moving with both (microslip from 0.2 mm, hardening +5 % "
            "at 2 mm) and a 1:2 quadratic modal coupling: the bending backbone carries "
            "torsion at twice its frequency; 15-point sensors, mild lab artefacts of every kind"
        ),
        amplitude_range_mm=((0.05, 2.0), (0.02, 0.5)),
        variability={
            "mode1.frequency_hz": 0.0025,
            "mode1.damping_ratio": 0.05,
            "mode2.frequency_hz": 0.0025,
            "mode2.damping_ratio": 0.05,
        },
        lab=_TWO_MODE_LAB,
    ),
}
