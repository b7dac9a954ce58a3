"""The N-mode backbone as a recorded program (pm_joint.forward.modal_op) against the graph.

* One mode alone and beside an uncoupled mode: the one-mode closed-form graph
  (pm_joint.forward.harmonic, no loop, compiled in seconds), whose equations share nothing
  with the N-mode ones but the catalogue's describing functions (pandey2025's microslip
  exercises the recorded where/arccos/sin).
* The N-mode graph itself (pytensor, compiled): the same values to rounding on a coupled
  two-mode model, both modes, NaN where the graph gives NaN.
* numpy's evaluation of the same equations (modal_harmonic.modal_backbone_numpy): the same.
* What the program cannot record (a special function) is refused, and population matching
  keeps the graph for it and for gradient samplers.
"""

import numpy as np
import pytensor
import pytensor.tensor as pt
import pytest
from test_modal_graph import AMPLITUDES, NAMES, NOMINAL, one_mode_cases, two_mode

from identification.effects import CATALOGUE
from identification.multimode import JointElement, ModalModel, Mode
from pm_joint.forward import harmonic_backbone_graph, modal_backbone_graph
from pm_joint.forward.modal_harmonic import ModalHarmonicGraph, modal_backbone_numpy
from pm_joint.forward.modal_op import ModalHarmonicOp, Unrecordable


def _sets(seed: int, n: int = 40) -> np.ndarray:
    """Parameter sets ±10 % around the nominal, and two it cannot evaluate (f1 < 0, ζ1 < 0)."""
    sets = NOMINAL * np.random.default_rng(seed).uniform(0.9, 1.1, (n, NOMINAL.size))
    return np.vstack([sets, NOMINAL * [-1, 1, 1, 1, 1, 1, 1], NOMINAL * [1, 1, -1, 1, 1, 1, 1]])


def _same(got: np.ndarray, expected: np.ndarray, rtol: float) -> None:
    np.testing.assert_array_equal(np.isnan(got), np.isnan(expected))
    np.testing.assert_allclose(got, expected, rtol=rtol, atol=0.0)


def test_one_mode_is_the_one_mode_graph_alone_and_beside_an_uncoupled_mode():
    joint, names, sets, models, modal_names, modal_sets = one_mode_cases(3, 30)
    a = np.geomspace(1e-5, 2e-3, 21)
    theta = pt.dmatrix()
    expected = pytensor.function([theta], harmonic_backbone_graph(joint, theta, names, a))(sets)
    assert np.isfinite(expected[..., 1]).mean() > 0.9
    for model in models:
        got = ModalHarmonicOp(model, modal_names, a)._backbones(modal_sets)
        np.testing.assert_allclose(got, expected, rtol=1e-12, atol=1e-15)
        np.testing.assert_array_equal(np.isnan(got), np.isnan(expected))


@pytest.mark.slow  # the two-mode graph's scan compiles for minutes on a cold cache
@pytest.mark.parametrize("mode", [1, 2])
def test_the_program_gives_the_graphs_values(mode):
    theta = pt.dmatrix("theta")
    graph = pytensor.function(
        [theta], modal_backbone_graph(two_mode(), theta, NAMES, AMPLITUDES, mode=mode).backbone
    )
    sets = _sets(mode)
    expected = graph(sets)
    assert np.isfinite(expected[:-2]).all() and np.isnan(expected[-2:, :, 1:]).all()
    _same(ModalHarmonicOp(two_mode(), NAMES, AMPLITUDES, mode)._backbones(sets), expected, 1e-10)


@pytest.mark.parametrize("mode", [1, 2])
def test_the_program_gives_numpys_values_one_set_or_many(mode):
    sets = _sets(10 + mode)
    expected = modal_backbone_numpy(two_mode(), sets, NAMES, AMPLITUDES, mode=mode).backbone
    assert np.isfinite(expected[:-2]).all() and np.isnan(expected[-2:, :, 1:]).all()
    op = ModalHarmonicOp(two_mode(), NAMES, AMPLITUDES, mode)
    _same(op._backbones(sets), expected, 1e-12)
    single = np.array([op._backbones(s[None])[0] for s in sets])
    _same(single, expected, 1e-12)
    # Through pytensor, as a sampler calls it: leading axes kept, NaN rows counted.
    theta = pt.dmatrix()
    _same(pytensor.function([theta], op(theta))(sets), expected, 1e-12)
    assert op.n_failed >= 2


def test_a_special_function_is_refused_and_matching_keeps_the_graph_for_it():
    from pm_joint.inference.modal import _mode_forward

    saturating = ModalModel(
        modes=(Mode(100.0, 0.01, 1.0), Mode(230.0, 0.01, 1.0)),
        joint_shapes=((1.0, 0.5),),
        elements=(JointElement(CATALOGUE["tanh_saturation"].name, 1e4, {"x_s": 1e-4}),),
    )
    names = ["mode1.frequency_hz", "mode2.frequency_hz"]
    grid = np.geomspace(1e-5, 1e-3, 5)
    with pytest.raises(Unrecordable, match="tanh_gain"):
        ModalHarmonicOp(saturating, names, grid)
    for model, graph, expected in ((saturating, False, ModalHarmonicGraph),
                                   (two_mode(), False, ModalHarmonicOp),
                                   (two_mode(), True, ModalHarmonicGraph)):  # fmt: skip
        assert isinstance(_mode_forward(model, names, grid, grid[1:4], 1, graph), expected)
