"""The N-mode backbone graph (pm_joint.forward.modal_harmonic) against independent answers.

* identification.multimode's phase resonance (multi-harmonic balance with AFT,
  Newton and natural continuation: a different method) on a two-mode model away
  from internal resonance, within the single-harmonic truncation error of its
  joint element, written out here in closed form;
* the one-mode graph (pm_joint.forward.harmonic, closed-form describing
  functions) when the second mode is absent or uncoupled;
* central differences of its gradient (pytensor's verify_grad);
* a batch of 1000 parameter sets against a loop over the sets.
"""

import numpy as np
import pytensor
import pytensor.tensor as pt
import pytest
from pytensor.gradient import verify_grad

from identification.effects import CATALOGUE, LINEAR_STIFFNESS, VISCOUS_DAMPING
from identification.model import JointModel
from identification.multimode import (
    Coupling,
    HarmonicSettings,
    JointElement,
    ModalModel,
    Mode,
    phase_resonance,
)
from pm_joint.forward import (
    BACKBONE_COLUMNS,
    ModalHarmonicGraph,
    forward_model,
    harmonic_backbone_graph,
    modal_backbone_graph,
)

CUBIC = CATALOGUE["cubic_stiffness"].name

# The two-mode system of tests/test_multimode.py: f1 = 1 Hz, f2 = 2.45 Hz (away from
# 1:2 and 1:3), a cubic joint element on q = η1 + 0.6 η2, the coupling potential
# κ η1² η2 (forces 2κ η1η2 on mode 1, κ η1² on mode 2).
F1, F2, SHAPE2, K3, KAPPA, ZETA = 1.0, 2.45, 0.6, 300.0, 15.0, 0.01
AMPLITUDES = np.geomspace(0.005, 0.12, 8)
NAMES = [
    "mode1.frequency_hz",
    "mode2.frequency_hz",
    "mode1.damping_ratio",
    "joint1.mode2",
    f"joint1.{CUBIC}",
    "coupling1",
    "coupling2",
]
NOMINAL = np.array([F1, F2, ZETA, SHAPE2, K3, 2 * KAPPA, KAPPA])


def two_mode(f2: float = F2) -> ModalModel:
    return ModalModel(
        modes=(Mode(F1, ZETA, 1.0), Mode(f2, ZETA, 0.5)),
        joint_shapes=((1.0, SHAPE2),),
        elements=(JointElement(CUBIC, K3),),
        couplings=(Coupling(1, (1, 1), 2 * KAPPA), Coupling(2, (2, 0), KAPPA)),
    )


@pytest.fixture(scope="module")
def two_mode_graph():
    """The compiled graph of the two-mode model on a matrix of parameter sets."""
    theta = pt.dmatrix("theta")
    out = modal_backbone_graph(two_mode(), theta, NAMES, AMPLITUDES)
    return pytensor.function(
        [theta], [out.backbone, out.energy_share, out.converged, out.harmonic_amplitude_m]
    )


def test_matches_the_multi_harmonic_balance_within_the_truncation_error(two_mode_graph):
    backbone, share, converged, harmonics = (x[0] for x in two_mode_graph(NOMINAL[None]))
    reference = phase_resonance(two_mode(), AMPLITUDES, settings=HarmonicSettings(harmonics=7))
    assert converged.all() and reference.converged.all()
    np.testing.assert_array_equal(backbone[:, 0], AMPLITUDES)
    gap = backbone[:, 1] / reference.frequency_hz - 1
    # What the graph leaves out, to leading order: the joint element's 3rd harmonic.
    # k₃q³ on q = a cos θ forces mode m at 3ω with φ_m k₃a³/4; that response feeds
    # back through 3k₃q²: Δ(ω²) = −(3/16)(k₃a²)² Σ_m φ_m² / (ω_m² − 9ω²) (one mode:
    # the Duffing single-harmonic error (3/256)(k₃a²/ω²)² of Lindstedt–Poincaré).
    # The 25 % beyond it covers the next terms (the coupling's own 3ω, the element
    # acting on the driven harmonics), smaller by mode 2's energy share (< 1 % here).
    omega = 2 * np.pi * reference.frequency_hz
    shapes_over_detuning = 1 / ((2 * np.pi * F1) ** 2 - 9 * omega**2) + SHAPE2**2 / (
        (2 * np.pi * F2) ** 2 - 9 * omega**2
    )
    truncation = -0.5 * (3 / 16) * (K3 * AMPLITUDES**2) ** 2 * shapes_over_detuning / omega**2
    assert np.all(np.abs(gap) <= 1.25 * np.abs(truncation) + 1e-12), (gap, truncation)
    assert abs(gap[-1]) > 1e-4  # the comparison is not vacuous: the nonlinearity shows
    # Damping (power balance) and mode 2's participation.
    np.testing.assert_allclose(backbone[:, 2], reference.damping_ratio, rtol=2e-3)
    assert np.all(share[:, 1] < 0.01)
    np.testing.assert_allclose(share[:, 1], reference.energy_share[:, 1], rtol=0.1, atol=1e-6)
    # Mode 2's fundamental and its 2ω response driven by the quadratic coupling.
    c = reference.coefficients[-1, 1]
    np.testing.assert_allclose(harmonics[-1, 1, 1], np.hypot(c[1], c[2]), rtol=0.02)
    np.testing.assert_allclose(harmonics[-1, 1, 2], np.hypot(c[3], c[4]), rtol=0.05)


def one_mode_cases(seed: int, n_sets: int) -> tuple:
    """pandey2025 as a JointModel and as N-mode models, alone and beside an uncoupled mode,
    with ``n_sets`` parameter sets ±10 % of each's: ``(joint, names, sets, (alone, beside),
    modal_names, modal_sets)``."""
    joint = JointModel.preset("pandey2025")
    names = joint.parameter_names
    nominal = np.array([joint.parameters[n] for n in names])
    sets = nominal * np.random.default_rng(seed).uniform(0.9, 1.1, (n_sets, nominal.size))
    k, c = sets[:, names.index(LINEAR_STIFFNESS)], sets[:, names.index(VISCOUS_DAMPING)]
    others = [n for n in names if n not in (LINEAR_STIFFNESS, VISCOUS_DAMPING)]
    modal_sets = np.column_stack(
        [np.sqrt(k) / (2 * np.pi), c / (2 * np.sqrt(k))] + [sets[:, names.index(n)] for n in others]
    )
    alone = ModalModel.from_joint_model(joint)
    modal_names = ["mode1.frequency_hz", "mode1.damping_ratio"] + [f"joint1.{n}" for n in others]
    # A second mode on no joint and without couplings; it takes base excitation.
    beside = ModalModel(
        modes=(*alone.modes, Mode(3.1 * alone.modes[0].frequency_hz, 0.02, 0.7)),
        joint_shapes=((1.0, 0.0),),
        elements=alone.elements,
    )
    return joint, names, sets, (alone, beside), modal_names, modal_sets


# Slow: the scan compiles for ~20 s; CI checks the same claim on the recorded program
# (tests/test_modal_op.py, the same equations) and the scan itself against the balance above.
@pytest.mark.slow
def test_one_mode_is_the_one_mode_graph_alone_and_beside_an_uncoupled_mode():
    joint, names, sets, (alone, beside), modal_names, modal_sets = one_mode_cases(0, 50)
    a = np.geomspace(1e-5, 2e-3, 21)
    theta_joint, theta_modal = pt.dmatrix(), pt.dmatrix()
    evaluate = pytensor.function(
        [theta_joint, theta_modal],
        [
            harmonic_backbone_graph(joint, theta_joint, names, a),
            modal_backbone_graph(alone, theta_modal, modal_names, a).backbone,
            modal_backbone_graph(beside, theta_modal, modal_names, a).backbone,
        ],
    )
    expected, one, two = evaluate(sets, modal_sets)
    assert np.isfinite(expected[..., 1]).mean() > 0.9
    for got in (one, two):
        np.testing.assert_allclose(got, expected, rtol=1e-12, atol=1e-15)
        np.testing.assert_array_equal(np.isnan(got), np.isnan(expected))


@pytest.mark.slow  # compiling the gradient graph takes minutes
def test_gradient_equals_central_differences():
    model = two_mode()

    def frequency_and_damping(scaled):
        backbone = modal_backbone_graph(model, scaled * NOMINAL, NAMES, AMPLITUDES[::3]).backbone
        return backbone[:, 1:]

    verify_grad(
        frequency_and_damping,
        [np.array([1.0, 1.01, 0.98, 1.02, 0.97, 1.03, 0.99])],
        rng=np.random.default_rng(1),
        eps=1e-6,
        abs_tol=1e-6,
        rel_tol=1e-5,
    )


def test_a_batch_of_1000_sets_equals_the_loop_over_them(two_mode_graph):
    sets = NOMINAL * np.random.default_rng(2).uniform(0.9, 1.1, (1000, NOMINAL.size))
    batch = two_mode_graph(sets)
    for i in range(sets.shape[0]):
        single = two_mode_graph(sets[i : i + 1])
        for b, s in zip(batch, single, strict=True):
            # a batch sums in another order than one set: rounding, relative to the array's scale
            scale = np.nanmax(np.abs(s[0])) if np.isfinite(s[0]).any() else 0.0
            np.testing.assert_allclose(b[i], s[0], rtol=1e-12, atol=1e-12 * scale)


def test_a_set_it_cannot_evaluate_gives_nan_not_an_error(two_mode_graph):
    bad = np.array([NOMINAL, NOMINAL * [-1, 1, 1, 1, 1, 1, 1], NOMINAL * [1, 1, -1, 1, 1, 1, 1]])
    backbone, _, converged, _ = two_mode_graph(bad)
    assert converged[0].all() and not converged[1:].any()
    assert np.isfinite(backbone[0]).all() and np.isnan(backbone[1:, :, 1:]).all()


def test_forward_model_registration_and_its_contract():
    model = two_mode()
    op = forward_model("modal_harmonic", model, NAMES[:2], amplitudes_m=AMPLITUDES, mode=1)
    assert isinstance(op, ModalHarmonicGraph)
    assert op.parameter_names == tuple(NAMES[:2]) and op.n_points == AMPLITUDES.size
    out = op(pt.tensor3())
    assert out.ndim == 4 and out.type.shape[-2:] == (AMPLITUDES.size, len(BACKBONE_COLUMNS))
    with pytest.raises(ValueError, match="ModalModel"):
        forward_model("modal_harmonic", JointModel.preset("pandey2025"), None, amplitudes_m=[1e-3])
    with pytest.raises(ValueError, match=r"mode must be 1\.\.2"):
        modal_backbone_graph(model, np.ones(1), NAMES[:1], AMPLITUDES, mode=3)
