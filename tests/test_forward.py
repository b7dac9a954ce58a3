"""Forward models: native harmonic-balance graph, ONNX surrogate Op, PLL Op.

Independent expectations: the numpy single- and multi-harmonic backbones of
``identification.analytical.harmonic``, central finite differences, onnxruntime itself,
torch autograd on the trained network (in float64), and the time-domain PLL.
"""

from __future__ import annotations

import pickle
import warnings

import numpy as np
import pymc as pm
import pytensor
import pytensor.tensor as pt
import pytest
import torch
from pytensor.graph.replace import vectorize_graph

from identification.analytical.harmonic import backbone
from identification.analytical.pll import pll_backbones
from identification.model import JointModel
from pm_joint.forward import (
    BACKBONE_COLUMNS,
    HarmonicBalanceGraph,
    PLLOp,
    SurrogateGraph,
    SurrogateOp,
    forward_model,
    harmonic_backbone_graph,
    surrogate_graph,
)
from pm_joint.inference import sample
from surrogates.export import export_surrogate
from surrogates.nets import NetConfig
from surrogates.runtime import SurrogateRuntime, SurrogateSpec
from surrogates.train import TrainingConfig, train_surrogate

torch.set_num_threads(1)
# Python-perform Ops run in numba object mode; pytensor says so on every compile.
pytestmark = pytest.mark.filterwarnings("ignore:Numba will use object mode:UserWarning")

OMEGA_100HZ_SQUARED = (2 * np.pi * 100) ** 2
DUFFING = JointModel(
    {"linear_stiffness": OMEGA_100HZ_SQUARED, "viscous_damping": 6.0, "cubic_stiffness": 2e10}
)
DUFFING_FRICTION = DUFFING.with_effect("microslip", 1.0, k_t=5e4, F_s=2.0).with_effect(
    "coulomb_friction", 0.3
)
#: Every odd (and the mixed) catalogue effect at once, with a positive stiffness throughout.
EVERY_EFFECT = JointModel(
    {
        "linear_stiffness": 4e5,
        "viscous_damping": 5.0,
        "quadratic_stiffness": -2e7,
        "cubic_stiffness": 1e10,
        "abs_stiffness": -1e6,
        "quadratic_damping": 10.0,
        "cubic_damping": -5.0,
        "displacement_velocity_squared": -2e4,
        "van_der_pol": -1e6,
        "coulomb_friction": 0.3,
        "stribeck_friction": {"coefficient": 0.2, "v_s": 0.02},
        "tanh_saturation": {"coefficient": 50.0, "x_s": 1e-3},
        "exponential": {"coefficient": 10.0, "x_s": 1.5e-3},
        "microslip": {"coefficient": 1.0, "k_t": 5e4, "F_s": 2.0},
    }
)
MODELS = {
    "pandey2025": JointModel.preset("pandey2025"),
    "duffing_friction": DUFFING_FRICTION,
    "every_effect": EVERY_EFFECT,
}
AMPLITUDES_M = np.geomspace(1e-5, 2e-3, 9)
#: Mode of the exactness checks: the math, not the backend, is under test there (and
#: numba's first compile of every graph would take minutes); the NUTS and Op tests
#: run pytensor's default (numba) mode.
MATH = "FAST_COMPILE"


def _compiled(model, names, amplitudes=AMPLITUDES_M):
    theta = pt.matrix("theta")
    return theta, pytensor.function(
        [theta], harmonic_backbone_graph(model, theta, names, amplitudes)
    )


# -- harmonic balance as a pytensor graph --------------------------------------


@pytest.mark.parametrize("name", list(MODELS))
def test_graph_equals_the_single_harmonic_backbone(name):
    model = MODELS[name]
    names = model.parameter_names
    values = np.array([list(model.parameters.values())] * 3)
    values[1] *= 1.05  # every parameter moved, shapes included
    values[2, names.index("linear_stiffness")] *= 0.9
    _, function = _compiled(model, names)
    out = function(values)
    expected = backbone(model, AMPLITUDES_M, parameters=values, names=names, method="single")
    assert out.shape == (3, AMPLITUDES_M.size, len(BACKBONE_COLUMNS))
    assert expected.converged.all()
    np.testing.assert_array_equal(out[..., 0], np.broadcast_to(AMPLITUDES_M, (3, 9)))
    np.testing.assert_allclose(out[..., 1], expected.frequency_hz, rtol=1e-10)
    np.testing.assert_allclose(out[..., 2], expected.damping_ratio, rtol=1e-10)


@pytest.mark.parametrize("name", list(MODELS))
def test_pointwise_graph_pairs_each_row_with_its_amplitude(name):
    # The hierarchical model's mode: row i of θ at amplitude i only.
    model = MODELS[name]
    names = model.parameter_names
    rng = np.random.default_rng(3)
    values = np.array(list(model.parameters.values())) * (
        1 + 0.03 * rng.standard_normal((AMPLITUDES_M.size, len(names)))
    )
    theta = pt.matrix("theta")
    function = pytensor.function(
        [theta], harmonic_backbone_graph(model, theta, names, AMPLITUDES_M, pointwise=True)
    )
    out = function(values)
    expected = backbone(model, AMPLITUDES_M, parameters=values, names=names, method="single")
    rows = np.arange(AMPLITUDES_M.size)
    assert out.shape == (AMPLITUDES_M.size, len(BACKBONE_COLUMNS))
    np.testing.assert_allclose(out[:, 1], expected.frequency_hz[rows, rows], rtol=1e-10)
    np.testing.assert_allclose(out[:, 2], expected.damping_ratio[rows, rows], rtol=1e-10)


@pytest.mark.parametrize("name", list(MODELS))
def test_graph_gradient_equals_central_differences(name):
    model = MODELS[name]
    names = model.parameter_names
    point = np.array(list(model.parameters.values()))
    theta = pt.vector("theta")
    graph = harmonic_backbone_graph(model, theta, names, AMPLITUDES_M)
    # One weighted sum per channel: its gradient checks every parameter at once.
    weights = np.linspace(0.5, 1.5, AMPLITUDES_M.size)
    costs = [pt.sum(weights * graph[:, column]) for column in (1, 2)]
    function = pytensor.function([theta], costs, mode=MATH)
    gradient = pytensor.function([theta], [pytensor.grad(c, theta) for c in costs], mode=MATH)
    actual = np.array(gradient(point))
    for j, value in enumerate(point):
        step = 1e-6 * abs(value)
        up, down = point.copy(), point.copy()
        up[j] += step
        down[j] -= step
        expected = (np.array(function(up)) - np.array(function(down))) / (2 * step)
        # Even terms have exactly zero gradient; elsewhere relative agreement.
        np.testing.assert_allclose(actual[:, j], expected, rtol=1e-5, atol=1e-300, err_msg=names[j])


def test_graph_broadcasts_over_leading_axes_and_parameter_subsets():
    names = ["cubic_stiffness", "microslip.F_s"]  # any order, any subset
    values = np.array([[[2e10, 2.0], [1e10, 3.0]], [[3e10, 1.0], [2.5e10, 2.5]]])
    op = HarmonicBalanceGraph(DUFFING_FRICTION, names, AMPLITUDES_M)
    out = op(pt.as_tensor(values)).eval(mode=MATH)
    expected = backbone(
        DUFFING_FRICTION, AMPLITUDES_M, parameters=values.reshape(-1, 2), names=names
    )
    assert (op.parameter_names, op.n_points) == (tuple(names), AMPLITUDES_M.size)
    np.testing.assert_allclose(out[..., 1].reshape(4, -1), expected.frequency_hz, rtol=1e-10)


def test_graph_gives_nan_not_errors_where_there_is_no_backbone():
    softening = DUFFING.replace(cubic_stiffness=-2e11)  # stiffness < 0 above ≈ 1.6 mm
    names = ["linear_stiffness", "cubic_stiffness"]
    theta = pt.vector("theta")
    graph = harmonic_backbone_graph(softening, theta, names, AMPLITUDES_M)
    point = np.array([OMEGA_100HZ_SQUARED, -2e11])
    out = graph.eval({theta: point}, mode=MATH)
    lost = ~np.isfinite(out[:, 1])
    assert lost.any() and not lost.all()
    assert np.all(AMPLITUDES_M[lost] > 1.5e-3) and np.isnan(out[lost, 2]).all()
    # The lost points must not poison the gradient of the others.
    cost = pt.sum(pt.switch(pt.isnan(graph[:, 1]), 0.0, graph[:, 1]))
    assert np.isfinite(pytensor.grad(cost, theta).eval({theta: point}, mode=MATH)).all()
    # A shape parameter ≤ 0 makes the whole row NaN instead of raising.
    bad = HarmonicBalanceGraph(DUFFING_FRICTION, ["microslip.k_t"], AMPLITUDES_M)
    assert np.isnan(bad(pt.as_tensor([-1.0])).eval(mode=MATH)[:, 1:]).all()


def test_nuts_samples_through_the_graph():
    op = HarmonicBalanceGraph(
        DUFFING_FRICTION, ["linear_stiffness", "cubic_stiffness"], AMPLITUDES_M
    )
    truth = backbone(DUFFING_FRICTION, AMPLITUDES_M).frequency_hz
    with pm.Model() as model:
        k = pm.Uniform("k", 3.5e5, 4.5e5)
        k3 = pm.Uniform("k3", 1e10, 3e10)
        pm.Normal("f", mu=op(pt.stack([k, k3]))[:, 1], sigma=0.5, observed=truth)
    gradient = model.compile_dlogp()(model.initial_point())
    assert np.isfinite(gradient).all() and np.all(gradient != 0)
    with model, warnings.catch_warnings():
        warnings.simplefilter("ignore", UserWarning)  # "only 20 samples" and the like
        draws = pm.sample(
            step=pm.NUTS(), draws=20, tune=20, chains=1, random_seed=3,
            progressbar=False, compute_convergence_checks=False,
        )  # fmt: skip
    k_draws = draws.posterior["k"].values.ravel()
    assert np.isfinite(k_draws).all() and np.unique(k_draws).size > 1
    assert int(draws.sample_stats["diverging"].sum()) < 20


# -- ONNX surrogate ------------------------------------------------------------

SURROGATE_NAMES = ("linear_stiffness", "cubic_stiffness")
SURROGATE_BOUNDS = np.array([[3.6e5, 4.4e5], [1e10, 3e10]])
SURROGATE_LEVELS = np.linspace(0.5, 10.0, 8)  # base acceleration, m/s²


def level_backbones(model, parameters, levels=SURROGATE_LEVELS):
    """Single-harmonic backbones at base-acceleration levels: A(a) inverted on a fine grid."""
    grid = np.geomspace(1e-6, 6e-3, 2000)
    result = backbone(model, grid, parameters=parameters, names=SURROGATE_NAMES)
    assert np.all(np.diff(result.base_acceleration, axis=1) > 0)  # A(a) invertible
    amplitude = np.array([np.interp(levels, A, grid) for A in result.base_acceleration])
    frequency = np.array(
        [
            np.interp(levels, A, f)
            for A, f in zip(result.base_acceleration, result.frequency_hz, strict=True)
        ]
    )
    return np.stack([amplitude, frequency], axis=-1)


def _trained(tmp_path_factory, n, net, epochs):
    rng = np.random.default_rng(0)
    x = SURROGATE_BOUNDS[:, 0] + rng.random((n, 2)) * np.ptp(SURROGATE_BOUNDS, axis=1)
    spec = SurrogateSpec(SURROGATE_NAMES, SURROGATE_BOUNDS, SURROGATE_LEVELS)
    config = TrainingConfig(net=net, max_epochs=epochs, finetune_epochs=epochs, progress=False)
    surrogate = train_surrogate(x, level_backbones(DUFFING, x), spec, config)
    folder = export_surrogate(surrogate, tmp_path_factory.mktemp("surrogate"))
    return surrogate, SurrogateRuntime.load(folder)


@pytest.fixture(scope="module")
def tiny(tmp_path_factory):
    net = NetConfig(latent_dim=8, conv_filters=(8, 4), ffnn_width=32, ffnn_depth=2)
    return _trained(tmp_path_factory, 40, net, epochs=20)


def _inside(runtime, shape, seed=1):
    rng = np.random.default_rng(seed)
    return runtime.bounds[:, 0] + rng.random((*shape, 2)) * np.ptp(runtime.bounds, axis=1)


def test_surrogate_op_equals_the_runtime_over_leading_axes(tiny):
    _, runtime = tiny
    op = SurrogateOp(runtime)
    values = _inside(runtime, (2, 3))
    theta = pt.tensor3("theta")
    out = pytensor.function([theta], op(theta))(values)
    assert out.shape == (2, 3, SURROGATE_LEVELS.size, 3) and op.n_points == SURROGATE_LEVELS.size
    expected = runtime.predict(values.reshape(-1, 2)).reshape(2, 3, -1, 2)
    np.testing.assert_array_equal(out[..., :2], expected)
    assert np.isnan(out[..., 2]).all()  # trained without damping
    # vectorize_graph (PyMC's batching) keeps the Op and its native batch axes.
    vector = pt.vector("vector")
    batched = vectorize_graph(op(vector), {vector: theta})
    assert batched.owner.op is op
    np.testing.assert_array_equal(pytensor.function([theta], batched)(values), out)


def test_surrogate_op_reorders_names_and_refuses_others(tiny):
    _, runtime = tiny
    values = _inside(runtime, (4,))
    swapped = SurrogateOp(runtime, names=SURROGATE_NAMES[::-1])
    assert swapped.parameter_names == SURROGATE_NAMES[::-1]
    np.testing.assert_array_equal(
        swapped(pt.as_tensor(values[:, ::-1])).eval(),
        SurrogateOp(runtime)(pt.as_tensor(values)).eval(),
    )
    with pytest.raises(ValueError, match=r"missing \['cubic_stiffness'\].*\['k3'\]"):
        SurrogateOp(runtime, names=["linear_stiffness", "k3"])


def test_surrogate_op_gives_nan_outside_its_box(tiny):
    _, runtime = tiny
    op = SurrogateOp(runtime)
    values = _inside(runtime, (4,))
    values[1, 1] = 2 * SURROGATE_BOUNDS[1, 1]
    values[2, 0] = np.nan
    out = op(pt.as_tensor(values)).eval()
    assert np.isnan(out[[1, 2]]).all()
    np.testing.assert_array_equal(out[[0, 3], :, :2], runtime.predict(values[[0, 3]]))
    assert (op.n_evaluated, op.n_failed) == (4, 2)


def test_surrogate_op_survives_pickling(tiny):
    _, runtime = tiny
    op = SurrogateOp(runtime, names=SURROGATE_NAMES[::-1])
    values = pt.as_tensor(_inside(runtime, (5,)))
    copy = pickle.loads(pickle.dumps(op))
    np.testing.assert_array_equal(copy(values).eval(), op(values).eval())


def test_surrogate_graph_equals_onnxruntime(tiny):
    _, runtime = tiny
    values = _inside(runtime, (3, 4))
    graph = surrogate_graph(runtime, pt.as_tensor(values)).eval(mode=MATH)
    expected = runtime.predict(values.reshape(-1, 2)).reshape(3, 4, -1, 2)
    np.testing.assert_allclose(graph[..., :2], expected, rtol=1e-5)
    assert np.isnan(graph[..., 2]).all()


@pytest.mark.slow  # 50 s, mostly nutpie's compile
def test_surrogate_graph_forward_model_equals_the_onnxruntime_op_and_nutpie_runs_on_it(tiny):
    """The native graph is what gradient samplers compile: same values as the Op (float32
    rounding apart), same parameter order, and nutpie's numba backend samples through it."""
    _, runtime = tiny
    names = SURROGATE_NAMES[::-1]
    native = forward_model("surrogate", None, names, surrogate=runtime, native_graph=True)
    assert isinstance(native, SurrogateGraph) and native.parameter_names == tuple(names)
    values = pt.as_tensor(_inside(runtime, (2, 5))[..., ::-1])
    expected = SurrogateOp(runtime, names=names)(values).eval()
    graph = native(values).eval(mode=MATH)
    np.testing.assert_allclose(graph[..., :2], expected[..., :2], rtol=1e-5)
    assert np.isnan(graph[..., 2]).all()
    with pytest.raises(ValueError, match="no native pytensor graph"):
        forward_model("pll", DUFFING, PLL_NAMES, levels=PLL_LEVELS, native_graph=True)
    # A posterior of the frequency at the top level around the value at the box's centre.
    centre = runtime.bounds.mean(axis=1)[::-1]
    target = SurrogateOp(runtime, names=names)(pt.as_tensor(centre)).eval()[-1, 1]
    with pm.Model() as model:
        theta = pt.stack([pm.Uniform(n, *runtime.bounds[SURROGATE_NAMES.index(n)]) for n in names])
        pm.Normal("f", native(theta)[-1, 1], 0.05 * target, observed=target)
    idata = sample(model, sampler="nutpie", draws=200, tune=200, chains=2, progressbar=False)
    assert int(idata.sample_stats["diverging"].sum()) == 0
    assert idata.posterior["linear_stiffness"].std() > 0


def test_surrogate_gradient_equals_torch_autograd(tiny):
    surrogate, runtime = tiny
    op = SurrogateOp(runtime, names=SURROGATE_NAMES[::-1])
    point = _inside(runtime, (2,))[0]
    weights = np.linspace(0.5, 1.5, SURROGATE_LEVELS.size)
    theta = pt.vector("theta")
    cost = pt.sum(op(theta)[:, 1] * weights) + 1e3 * pt.sum(op(theta)[:, 0])
    gradient = pytensor.function([theta], pytensor.grad(cost, theta), mode=MATH)(point[::-1])
    network = surrogate.model.double()
    x = torch.tensor(point, requires_grad=True)
    y = network(x[None])[0]
    (y[:, 1] @ torch.tensor(weights) + 1e3 * y[:, 0].sum()).backward()
    surrogate.model.float()
    np.testing.assert_allclose(gradient, x.grad.numpy()[::-1], rtol=1e-8)


# -- PLL -----------------------------------------------------------------------

PLL_LEVELS = np.array([1.0, 4.0, 8.0])
PLL_NAMES = ["linear_stiffness", "cubic_stiffness"]


@pytest.fixture(scope="module")
def pll_run():
    op = PLLOp(DUFFING, PLL_NAMES, PLL_LEVELS)
    values = np.array([[OMEGA_100HZ_SQUARED, 2e10], [(2 * np.pi * 95) ** 2, 1e10]])
    return op, values, op(pt.as_tensor(values)).eval()


def test_pll_op_agrees_with_multi_harmonic_balance(pll_run):
    op, values, out = pll_run
    assert out.shape == (2, 3, 3) and op.parameter_names == tuple(PLL_NAMES)
    assert np.isfinite(out).all()
    for row, value in enumerate(values):
        multi = backbone(
            DUFFING, out[row, :, 0], parameters=value[None], names=PLL_NAMES, method="multi"
        )
        np.testing.assert_allclose(out[row, :, 1], multi.frequency_hz[0], rtol=3e-3)


def test_pll_op_is_the_batch_simulator(pll_run):
    _, values, out = pll_run
    result = pll_backbones(DUFFING, PLL_LEVELS, values, PLL_NAMES, progress=False)
    np.testing.assert_array_equal(out[..., 1], result.frequency_hz)
    np.testing.assert_array_equal(out[..., 2], result.damping_ratio)


def test_pll_op_gives_nan_for_sets_it_cannot_run():
    op = PLLOp(DUFFING_FRICTION, ["linear_stiffness", "microslip.k_t"], PLL_LEVELS[:1])
    values = np.array(
        [
            [OMEGA_100HZ_SQUARED, 5e4],
            [-OMEGA_100HZ_SQUARED, 5e4],  # no positive stiffness: nothing to lock on
            [OMEGA_100HZ_SQUARED, -5e4],  # shape parameter ≤ 0
            [1e16, 5e4],  # too stiff for the sub-step limit (the simulator raises)
        ]
    )
    out = op(pt.as_tensor(values)).eval()
    assert np.isfinite(out[0]).all() and np.isnan(out[1:]).all()
    assert (op.n_evaluated, op.n_failed) == (4, 3)


# -- one switch ----------------------------------------------------------------


def test_forward_model_switches_and_the_models_agree(tiny, pll_run):
    _, runtime = tiny
    _, values, pll_out = pll_run
    kinds = {
        "harmonic": forward_model("harmonic", DUFFING, PLL_NAMES, amplitudes_m=AMPLITUDES_M),
        "pll": forward_model("pll", DUFFING, PLL_NAMES, levels=PLL_LEVELS),
        "surrogate": forward_model("surrogate", None, PLL_NAMES, surrogate=runtime),
    }
    assert {k: type(v) for k, v in kinds.items()} == {
        "harmonic": HarmonicBalanceGraph, "pll": PLLOp, "surrogate": SurrogateOp
    }  # fmt: skip
    for op in kinds.values():
        assert op.parameter_names == tuple(PLL_NAMES)
    # Harmonic balance at the PLL's own amplitudes: the two analytical backbones agree.
    for row, value in enumerate(values):
        graph = harmonic_backbone_graph(DUFFING, pt.as_tensor(value), PLL_NAMES, pll_out[row, :, 0])
        np.testing.assert_allclose(graph.eval(mode=MATH)[:, 1], pll_out[row, :, 1], rtol=3e-3)
    with pytest.raises(ValueError, match="needs levels="):
        forward_model("pll", DUFFING, PLL_NAMES)
    with pytest.raises(ValueError, match="kind must be one of"):
        forward_model("simulink", DUFFING, PLL_NAMES)


@pytest.mark.slow
def test_surrogate_agrees_with_harmonic_balance_within_its_accuracy(tmp_path_factory):
    surrogate, runtime = _trained(tmp_path_factory, 300, NetConfig(ffnn_width=128), epochs=400)
    op = SurrogateOp(runtime)
    values = _inside(runtime, (20,), seed=5)
    out = op(pt.as_tensor(values)).eval()
    stated = surrogate.metrics["channels"]["frequency_hz"]["max_ape_pct"] / 100
    assert stated < 0.01
    for row, value in enumerate(values):
        graph = harmonic_backbone_graph(
            DUFFING, pt.as_tensor(value), SURROGATE_NAMES, out[row, :, 0]
        )
        np.testing.assert_allclose(out[row, :, 1], graph.eval(mode=MATH)[:, 1], rtol=2 * stated)
