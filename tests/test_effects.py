"""The effects catalogue against independent calculations.

Closed-form describing functions are checked against adaptive quadrature
(scipy.integrate.quad) of the same numba force kernels, i.e. against the
definition k_eq = (1/πa)∫f cos θ dθ, c_eq = −(1/πaω)∫f sin θ dθ; the pytensor
graphs against the numpy describing functions (both come from one source per
effect, with per-backend special functions); the declared parity and polynomial
flags against the force kernels themselves. Tests parametrised over the
catalogue cover a new effect module without being edited.
"""

import numpy as np
import pytensor.tensor as pt
import pytest
from scipy import integrate, special

from identification.effects import (
    CATALOGUE,
    HYSTERETIC,
    LINEAR_STIFFNESS,
    VISCOUS_DAMPING,
    jenkins_force,
    jenkins_path,
    memoryless_force,
    restoring_force,
)
from identification.effects.base import (
    KEY_CHANNELS,
    NUMPY,
    ArrayNamespace,
    Effect,
    FitScale,
    pytensor_namespace,
)
from identification.effects.special import TANH_QUADRATURE_POINTS
from pm_joint.forward import describing_graph

#: Mode of the graph checks: the math, not the backend, is under test.
MATH = "FAST_COMPILE"
MEMORYLESS = [name for name, effect in CATALOGUE.items() if not effect.hysteretic]
HYSTERETIC_EFFECTS = [name for name, effect in CATALOGUE.items() if effect.hysteretic]

CATALOGUE_NAMES = [
    "linear_stiffness",
    "viscous_damping",
    "quadratic_stiffness",
    "cubic_stiffness",
    "abs_stiffness",
    "quadratic_damping",
    "cubic_damping",
    "velocity_squared",
    "stiffness_damping_coupling",
    "displacement_velocity_squared",
    "van_der_pol",
    "coulomb_friction",
    "stribeck_friction",
    "tanh_saturation",
    "exponential",
    "microslip",
]


def test_catalogue_has_exactly_the_design_names():
    assert list(CATALOGUE) == CATALOGUE_NAMES
    for effect in CATALOGUE.values():
        assert effect.units and effect.reading and effect.term
        assert set(effect.defaults) == set(effect.shape) == set(effect.shape_units)


def _quad_describing(kernel, a, omega, p0, p1, breakpoints=()):
    def f(theta):
        return kernel(a * np.cos(theta), -a * omega * np.sin(theta), p0, p1)

    opts = dict(points=breakpoints or None, limit=400, epsabs=0, epsrel=1e-12)
    cos_part = integrate.quad(lambda t: f(t) * np.cos(t), 0, 2 * np.pi, **opts)[0]
    sin_part = integrate.quad(lambda t: f(t) * np.sin(t), 0, 2 * np.pi, **opts)[0]
    return cos_part / (np.pi * a), -sin_part / (np.pi * a * omega)


SHAPES = {
    "coulomb_friction": {"v_reg": 1e-9},
    "stribeck_friction": {"v_s": 0.02, "v_reg": 1e-9},
    "tanh_saturation": {"x_s": 4e-4},
    "exponential": {"x_s": 8e-4},
}


@pytest.mark.filterwarnings("ignore::scipy.integrate.IntegrationWarning")  # zero integrands
@pytest.mark.parametrize("name", MEMORYLESS)
@pytest.mark.parametrize("a", [2e-5, 3e-4, 1.5e-3])
def test_describing_function_matches_quadrature_of_the_force(name, a):
    effect = CATALOGUE[name]
    omega = 2 * np.pi * 104.0
    shape = SHAPES.get(name, {})
    p0, p1 = effect.shape_values(**shape)
    k_eq, c_eq = effect.describing(a, omega, **shape)
    # velocity reversals (θ = 0, π) are where the friction kernels jump
    k_ref, c_ref = _quad_describing(effect.force.py_func, a, omega, p0, p1, (np.pi,))
    # even terms have no first harmonic: compare against the force's own scale
    theta = np.linspace(0, 2 * np.pi, 721)
    force_scale = max(
        abs(effect.force(a * np.cos(t), -a * omega * np.sin(t), p0, p1)) for t in theta
    )
    tol = 1e-6 if name in ("coulomb_friction", "stribeck_friction") else 1e-9
    assert k_eq == pytest.approx(k_ref, rel=tol, abs=1e-12 * force_scale / a)
    assert c_eq == pytest.approx(c_ref, rel=tol, abs=1e-12 * force_scale / (a * omega))


def test_coulomb_equivalent_damping_is_4F_over_pi_a_omega():
    a, omega = 5e-4, 650.0
    _, c_eq = CATALOGUE["coulomb_friction"].describing(a, omega)
    assert c_eq == pytest.approx(4 / (np.pi * a * omega), rel=1e-14)


def _jenkins_loop(a, k_t, f_s, n=100_000):
    theta = np.linspace(0, 4 * np.pi, 2 * n + 1)
    x = a * np.cos(theta)
    # load up to the extreme, then two cycles: the second one is the steady loop
    f = jenkins_path(np.concatenate([np.linspace(0, a, 2001), x]), k_t, f_s)[2001:]
    return theta[n:], x[n:], f[n:]


@pytest.mark.parametrize("ratio", [0.5, 1.0, 1.3, 3.0, 30.0])
def test_microslip_describing_function_matches_the_hysteresis_loop(ratio):
    k_t, f_s = 2e4, 1.5
    a = ratio * f_s / k_t
    omega = 600.0
    theta, x, f = _jenkins_loop(a, k_t, f_s)
    k_loop = integrate.trapezoid(f * np.cos(theta), theta) / (np.pi * a)
    energy = -integrate.trapezoid(f, x)  # x runs a → −a → a, the loop area
    k_eq, c_eq = CATALOGUE["microslip"].describing(a, omega, k_t=k_t, F_s=f_s)
    assert k_eq == pytest.approx(k_loop, rel=2e-6)
    # dissipated energy per cycle = π c_eq ω a² (Masing: 4 F_s (a − a_s))
    assert np.pi * c_eq * omega * a**2 == pytest.approx(abs(energy), rel=2e-6, abs=1e-15)
    if ratio > 1:
        assert abs(energy) == pytest.approx(4 * f_s * (a - f_s / k_t), rel=2e-6)


def test_jenkins_force_sticks_then_slips():
    k_t, f_s = 1e4, 1.0
    assert jenkins_force(5e-5, 0.0, 0.0, k_t, f_s) == pytest.approx(0.5)
    assert jenkins_force(5e-4, 0.0, 0.0, k_t, f_s) == 1.0
    # unloading from the slip limit is elastic again
    assert jenkins_force(4e-4, 5e-4, 1.0, k_t, f_s) == pytest.approx(0.0)


def test_numba_kernels_agree_with_vectorised_features():
    rng = np.random.default_rng(1)
    x = rng.normal(scale=1e-3, size=50)
    v = rng.normal(scale=0.3, size=50)
    for effect in CATALOGUE.values():
        if effect.hysteretic:
            continue
        p0, p1 = effect.shape_values()
        feature = effect.feature(x, v, **effect.defaults)
        dispatched = [
            memoryless_force(effect.index, xi, vi, p0, p1) for xi, vi in zip(x, v, strict=True)
        ]
        np.testing.assert_allclose(dispatched, feature, rtol=1e-14, err_msg=effect.name)
        direct = [effect.force(xi, vi, p0, p1) for xi, vi in zip(x, v, strict=True)]
        np.testing.assert_allclose(direct, feature, rtol=1e-14, err_msg=effect.name)


def test_restoring_force_sums_terms():
    idx = np.array([CATALOGUE["linear_stiffness"].index, CATALOGUE["cubic_stiffness"].index])
    coef = np.array([4e5, -2e9])
    shapes = np.zeros((2, 2))
    x, v = 1e-3, 0.2
    assert restoring_force(idx, coef, shapes, x, v) == pytest.approx(4e5 * x - 2e9 * x**3)


def test_shape_parameter_validation_names_the_parameter():
    with pytest.raises(ValueError, match=r"tanh_saturation.x_s"):
        CATALOGUE["tanh_saturation"].shape_values(x_s=-1.0)
    with pytest.raises(ValueError, match=r"no shape parameter.*'width'"):
        CATALOGUE["microslip"].shape_values(width=1.0)


@pytest.mark.parametrize("ratio", [1e-4, 2e-3, 0.7, 40.0, 900.0, 5e3])
def test_tanh_describing_function_across_its_table_and_limits(ratio):
    # tanh's gain is tabulated once with a series below and an asymptote above:
    # each range against adaptive quadrature split at and around the zero
    # crossings, where tanh(u cos θ) turns within ~1/u of θ = π/2, 3π/2.
    x_s, omega = 1e-3, 650.0
    a = ratio * x_s
    k_eq, c_eq = CATALOGUE["tanh_saturation"].describing(a, omega, x_s=x_s)
    width = min(10.0 / ratio, 0.5)
    crossings = [c + d for c in (np.pi / 2, 3 * np.pi / 2) for d in (-width, 0.0, width)]
    k_ref, _ = _quad_describing(
        CATALOGUE["tanh_saturation"].force.py_func, a, omega, x_s, 0.0, crossings
    )
    assert k_eq == pytest.approx(k_ref, rel=1e-10)
    assert c_eq == 0.0


# -- one source, two backends ---------------------------------------------------


@pytest.mark.parametrize("effect", list(CATALOGUE))
def test_describing_graph_matches_the_catalogue(effect):
    a = np.geomspace(1e-6, 5e-3, 9)[:, None]
    omega = np.array([250.0, 630.0, 1100.0])
    shape = {n: 1.7 * v for n, v in CATALOGUE[effect].defaults.items()}  # not the defaults
    k_want, c_want = CATALOGUE[effect].describing(a, omega, **shape)
    k_got, c_got = (v.eval(mode=MATH) for v in describing_graph(effect, a, omega, **shape))
    # Damping compared as the force it gives (c·ω, a stiffness), on the effect's scale.
    scale = np.abs(k_want).max() + np.abs(c_want * omega).max()
    np.testing.assert_allclose(k_got, k_want, rtol=1e-12, atol=1e-14 * scale)
    np.testing.assert_allclose(c_got * omega, c_want * omega, rtol=1e-12, atol=1e-14 * scale)


def _tanh_quadrature_error(u):
    """Bound on the relative error of the periodic trapezoid sum of the tanh gain.

    tanh(u cos θ) has its nearest complex singularity at Im θ = asinh(π/(2u)), so N
    points are accurate to about exp(−N asinh(π/(2u))) (Trefethen & Weideman 2014).
    """
    return np.exp(-TANH_QUADRATURE_POINTS * np.arcsinh(np.pi / (2 * u)))


@pytest.mark.parametrize("name", list(CATALOGUE))
def test_numpy_and_pytensor_describing_agree_at_random_points(name):
    effect = CATALOGUE[name]
    rng = np.random.default_rng(list(CATALOGUE).index(name))
    n = 400
    a = np.exp(rng.uniform(np.log(1e-6), np.log(5e-3), n))
    omega = 2 * np.pi * np.exp(rng.uniform(np.log(20.0), np.log(400.0), n))
    # Shapes from a fifth to five times the defaults, one per point (the graph
    # broadcasts shape arrays the way the backbone graph's parameter rows do).
    shape = {
        p: d * np.exp(rng.uniform(np.log(0.2), np.log(5.0), n)) for p, d in effect.defaults.items()
    }
    k_want, c_want = effect.describing(a, omega, **shape)
    k_got, c_got = (v.eval(mode=MATH) for v in describing_graph(name, a, omega, **shape))
    rtol = 1e-10
    if name == "tanh_saturation":
        rtol = rtol + _tanh_quadrature_error(a / shape["x_s"])
    scale = np.abs(k_want) + np.abs(c_want * omega)  # both parts as stiffnesses
    assert np.all(np.abs(k_got - k_want) <= rtol * scale), name
    assert np.all(np.abs(c_got - c_want) * omega <= rtol * scale), name


def test_array_namespaces_agree():
    rng = np.random.default_rng(7)
    x = rng.uniform(-0.99, 0.99, 50)  # inside the domain of arccos
    positive = np.exp(rng.uniform(np.log(1e-3), np.log(30.0), 50))
    xp = pytensor_namespace()
    for field in ArrayNamespace.__dataclass_fields__:
        if field == "name":
            continue
        if field == "where":
            want = NUMPY.where(x > 0, x, -2 * x)
            got = xp.where(x > 0, x, -2 * x).eval(mode=MATH)
        else:
            argument = positive if field in ("sqrt", "tanh_gain") else x
            want = getattr(NUMPY, field)(argument)
            got = getattr(xp, field)(pt.as_tensor(argument)).eval(mode=MATH)
        rtol = 1e-12 + (_tanh_quadrature_error(positive) if field == "tanh_gain" else 0.0)
        assert np.all(np.abs(got - want) <= rtol * np.abs(want)), field
    # Dawson's integral against its definition D(x) = exp(−x²)∫₀ˣ exp(t²) dt.
    for value in (0.3, 1.5, 4.0):
        integral = integrate.quad(lambda t, v=value: np.exp(t * t - v * v), 0, value)[0]
        assert NUMPY.dawsn(value) == pytest.approx(integral, rel=1e-12)
    assert special.dawsn is NUMPY.dawsn


def test_dawson_gradient_is_analytic():
    x = pt.vector("x")
    gradient = pt.grad(pt.sum(pytensor_namespace().dawsn(x)), x)
    points = np.array([-2.0, 0.1, 0.9, 3.0])
    step = 1e-6
    expected = (special.dawsn(points + step) - special.dawsn(points - step)) / (2 * step)
    np.testing.assert_allclose(gradient.eval({x: points}, mode=MATH), expected, rtol=1e-8)


# -- the declared flags against the force -----------------------------------------


@pytest.mark.parametrize("name", MEMORYLESS)
def test_parity_is_that_of_the_force(name):
    effect = CATALOGUE[name]
    rng = np.random.default_rng(3)
    x = rng.uniform(-2e-3, 2e-3, 200)
    v = rng.uniform(-0.5, 0.5, 200)
    f, f_mirrored = effect.feature(x, v), effect.feature(-x, -v)
    scale = np.max(np.abs(f))
    odd = np.max(np.abs(f_mirrored + f)) <= 1e-12 * scale
    even = np.max(np.abs(f_mirrored - f)) <= 1e-12 * scale
    assert (odd, even) == {"odd": (True, False), "even": (False, True), "mixed": (False, False)}[
        effect.parity
    ]


@pytest.mark.parametrize("name", MEMORYLESS)
def test_polynomial_flag_is_that_of_the_force(name):
    # A force of degree ≤ 3 in (x, ẋ) is reproduced exactly by the 10 monomials.
    effect = CATALOGUE[name]
    rng = np.random.default_rng(4)
    x = rng.uniform(-1.0, 1.0, 400)
    v = rng.uniform(-1.0, 1.0, 400)
    shape = {p: 0.3 for p in effect.shape}  # friction and saturation well inside the box
    f = effect.feature(x, v, **shape)
    monomials = np.stack([x**i * v**j for i in range(4) for j in range(4 - i)], axis=1)
    coefficients = np.linalg.lstsq(monomials, f, rcond=None)[0]
    misfit = np.max(np.abs(monomials @ coefficients - f)) / np.max(np.abs(f))
    if effect.polynomial:
        assert misfit < 1e-12
    else:
        assert misfit > 1e-4


def test_dispatch_gives_nothing_for_the_hysteretic_element_and_nan_beyond_the_catalogue():
    microslip = CATALOGUE["microslip"]
    assert microslip.force(1e-5, 0.0, 1e5, 1.0) == pytest.approx(1.0)  # virgin curve
    assert memoryless_force(microslip.index, 1e-5, 0.0, 1e5, 1.0) == 0.0
    assert np.isnan(memoryless_force(len(CATALOGUE), 1e-5, 0.0, 0.0, 0.0))


# -- what the fits and the criticism take from an effect ---------------------------------


def test_fit_grids_lie_inside_the_bounds_and_name_shape_parameters():
    scale = FitScale.from_measurements([5e-5, 2e-4, 1.6e-3], [101.0, 99.5, 96.0], 4e5)
    for effect in CATALOGUE.values():
        grid, bounds = effect.shape_grid(scale), effect.shape_bounds(scale)
        assert set(grid) <= set(bounds) <= set(effect.shape), effect.name
        for shape, values in grid.items():
            low, high = bounds[shape]
            assert 0 < low < high
            assert np.all((values > low) & (values < high)), f"{effect.name}.{shape}"
        assert isinstance(effect.fitted_reading(1.0, effect.defaults, scale), str)


# -- what the rest of the library takes from an effect instead of its name ---------------


def test_the_kernels_carry_the_one_hysteretic_effect():
    assert HYSTERETIC_EFFECTS == [HYSTERETIC.name] == ["microslip"]
    assert (LINEAR_STIFFNESS, VISCOUS_DAMPING) == ("linear_stiffness", "viscous_damping")


@pytest.mark.parametrize("name", HYSTERETIC_EFFECTS)
def test_stuck_stiffness_is_the_describing_stiffness_before_slip(name):
    effect = CATALOGUE[name]
    shape = {"k_t": 3e4, "F_s": 0.8}  # slips from 27 µm
    k_eq, c_eq = effect.describing(1e-9, 600.0, **shape)
    assert c_eq == 0.0
    assert effect.stuck_stiffness(2.5, shape) == pytest.approx(2.5 * k_eq, rel=1e-15)
    # Arrays in, arrays out (the harmonic balance's parameter sets).
    coefficients = np.array([1.0, 2.0])
    shapes = {"k_t": np.array([3e4, 4e4]), "F_s": np.array([0.8, 0.9])}
    np.testing.assert_array_equal(effect.stuck_stiffness(coefficients, shapes), [3e4, 8e4])


def test_a_hysteretic_effect_must_say_what_it_adds_while_stuck():
    fields = dict(name="sticky", term="S(x)", units="1", reading="r", force=lambda x, v, p, q: 0.0)
    with pytest.raises(ValueError, match="stuck stiffness if and only if hysteretic"):
        Effect(**fields, hysteretic=True, path_feature=lambda x, v: x)
    with pytest.raises(ValueError, match="stuck stiffness if and only if hysteretic"):
        Effect(**fields, stuck_stiffness=lambda c, shape: c)


def test_term_text_writes_the_shape_values_in():
    assert CATALOGUE["cubic_stiffness"].term_text({}) == "x³"
    assert CATALOGUE["tanh_saturation"].term_text({"x_s": 2.5e-4}, 3) == (
        CATALOGUE["tanh_saturation"].term.replace("x_s", "0.00025")
    )
    # The regularising velocity is a numerical device: equations leave it out.
    stribeck = CATALOGUE["stribeck_friction"]
    v_s = stribeck.defaults["v_s"]
    assert stribeck.term_text(stribeck.defaults, 3) == stribeck.term.replace("v_s", f"{v_s:.3g}")
    assert HYSTERETIC.term_text({"k_t": 3e4, "F_s": 0.8}, 3) == "Jenkins(x; k_t=3e+04, F_s=0.8)"


@pytest.mark.parametrize("name", [n for n, e in CATALOGUE.items() if e.hidden_scenario])
def test_hidden_scenario_gives_a_term_the_catalogue_takes(name):
    effect = CATALOGUE[name]
    scenario = effect.hidden_scenario
    truth = scenario.truth((2 * np.pi * 101.0) ** 2)
    terms = dict(truth) if isinstance(truth, dict) else {"coefficient": truth}
    assert set(terms) - {"coefficient"} <= set(effect.shape)
    assert np.isfinite(terms["coefficient"]) and terms["coefficient"] != 0
    effect.shape_values(**{k: v for k, v in terms.items() if k != "coefficient"})
    assert scenario.key_channel in KEY_CHANNELS and scenario.description


def test_every_effect_but_the_linear_pair_can_be_hidden():
    hidden = {name for name, effect in CATALOGUE.items() if effect.hidden_scenario is not None}
    assert hidden == set(CATALOGUE) - {LINEAR_STIFFNESS, VISCOUS_DAMPING}
