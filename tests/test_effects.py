"""The effects catalogue against independent calculations.

Closed-form describing functions are checked against adaptive quadrature
(scipy.integrate.quad) of the same numba force kernels, i.e. against the
definition k_eq = (1/πa)∫f cos θ dθ, c_eq = −(1/πaω)∫f sin θ dθ.
"""

import numpy as np
import pytest
from scipy import integrate

from identification.effects import (
    CATALOGUE,
    jenkins_force,
    jenkins_path,
    memoryless_force,
    restoring_force,
)

DESIGN_NAMES = [
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
    assert list(CATALOGUE) == DESIGN_NAMES
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
@pytest.mark.parametrize("name", [n for n in DESIGN_NAMES if n != "microslip"])
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
