"""Which parameters the hierarchical model lets vary (pm_joint.inference.varying)."""

import numpy as np
from oscillators import duffing

from identification.analytical.harmonic import backbone
from identification.measurements.backbone import Backbone, BackboneSet
from pm_joint.inference.varying import varying_parameters

#: A Duffing panel with an even spring: over a symmetric orbit x² averages out of the
#: fundamental, so its describing function is zero and a single-harmonic backbone
#: cannot see it at all.
TEMPLATE = duffing(quadratic_stiffness=3e7)
NAMES = ["linear_stiffness", "viscous_damping", "cubic_stiffness", "quadratic_stiffness"]


def _assemblies(n=8, seed=0):
    """Backbones of ``n`` assemblies that differ by 0.5 % in k, 10 % in c and 20 % in k3."""
    rng = np.random.default_rng(seed)
    spread = np.array([0.005, 0.1, 0.2, 0.2])
    values = np.array([TEMPLATE.parameters[n] for n in NAMES]) * np.exp(
        spread * rng.standard_normal((n, len(NAMES)))
    )
    amplitudes = 1e-3 * np.geomspace(0.1, 1.5, 12)
    hb = backbone(TEMPLATE, amplitudes, parameters=values, names=NAMES)
    return BackboneSet(
        Backbone(amplitudes, f, d, label=f"a{i}")
        for i, (f, d) in enumerate(zip(hb.frequency_hz, hb.damping_ratio, strict=True))
    )


def test_a_term_the_backbone_cannot_see_is_held_and_the_stiffness_varies():
    choice = varying_parameters(TEMPLATE, _assemblies(), NAMES)
    assert "quadratic_stiffness" in choice.held
    assert choice.reach["quadratic_stiffness"] < 1e-6
    # 20 % of the stiffness is about 10 % of the frequency: thousands of scatters.
    assert {"linear_stiffness", "viscous_damping", "cubic_stiffness"} <= set(choice.varying)
    assert "quadratic_stiffness" in choice.text()


def test_a_parameter_the_other_one_imitates_is_held():
    # k3 at 1e4 N/m³·kg⁻¹ shifts 1.5 mm by 1e-8 of the stiffness: far below the scatter,
    # which comes from k alone here, so only k varies.
    weak = TEMPLATE.replace(cubic_stiffness=1e4)
    rng = np.random.default_rng(1)
    amplitudes = 1e-3 * np.geomspace(0.1, 1.5, 12)
    values = np.column_stack(
        [
            TEMPLATE.parameters["linear_stiffness"] * np.exp(0.005 * rng.standard_normal(6)),
            np.full(6, 1e4),
        ]
    )
    hb = backbone(
        weak, amplitudes, parameters=values, names=["linear_stiffness", "cubic_stiffness"]
    )
    curves = BackboneSet(
        Backbone(amplitudes, f, d, label=f"a{i}")
        for i, (f, d) in enumerate(zip(hb.frequency_hz, hb.damping_ratio, strict=True))
    )
    choice = varying_parameters(
        weak, curves, ["linear_stiffness", "cubic_stiffness"], channels=("frequency_hz",)
    )
    assert choice.varying == ["linear_stiffness"]
    assert choice.held == ["cubic_stiffness"]
