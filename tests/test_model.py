import json

import numpy as np
import pytest
from scipy import integrate

from identification.model import JointModel, Term, parameter_bounds
from identification.rig import RIG_PRESETS

PAPER_EQ3 = dict(
    k1=4.49e5, k2=1.85, k3=2.60e7, k4=2.95e4, k5=60.5, k6=3.32e9,
    k7=2.33e4, k8=9.50, k9=3.35e7, k10=11.6, k11=5.66, k12=5.10e5,
)  # fmt: skip


def paper_eq3_force(x, v):
    """Restoring force of the paper's Eq. 3, written as printed in the paper."""
    k = PAPER_EQ3
    return (
        k["k1"] * x + k["k2"] * v - k["k3"] * x**2 - k["k4"] * x * v + k["k5"] * v**2
        - k["k6"] * x**3 - k["k7"] * x * v**2 - k["k8"] * v**3 - k["k9"] * x * abs(x)
        + k["k10"] * v * abs(v) + k["k11"] * (1 - k["k12"] * x**2) * v
    )  # fmt: skip


def test_pandey2025_preset_reproduces_eq3():
    model = JointModel.preset("pandey2025")
    rng = np.random.default_rng(0)
    x = rng.uniform(-1e-3, 1e-3, 200)
    v = rng.uniform(-0.7, 0.7, 200)
    np.testing.assert_allclose(model.restoring_force(x, v), paper_eq3_force(x, v), rtol=1e-12)
    assert model.linear_frequency_hz == pytest.approx(106.6, abs=0.05)


def test_rhs_integrates_a_linear_oscillator():
    omega0, zeta = 2 * np.pi * 100, 0.01
    model = JointModel({"linear_stiffness": omega0**2, "viscous_damping": 2 * zeta * omega0})
    sol = integrate.solve_ivp(
        lambda t, y: model.rhs(t, y, 0.0), (0, 0.02), [1e-3, 0.0], rtol=1e-10, atol=1e-14
    )
    wd = omega0 * np.sqrt(1 - zeta**2)
    t = sol.t[-1]
    exact = (
        1e-3 * np.exp(-zeta * omega0 * t) * (np.cos(wd * t) + zeta * omega0 / wd * np.sin(wd * t))
    )
    assert sol.y[0, -1] == pytest.approx(exact, rel=1e-6)


def test_rhs_microslip_state_follows_the_jenkins_element():
    model = JointModel(
        {"linear_stiffness": 4e5, "microslip": {"coefficient": 1.0, "k_t": 4e4, "F_s": 2.0}}
    )
    assert model.state_size == 3
    assert model.linear_stiffness == pytest.approx(4.4e5)
    # sticking: ż = k_t ẋ; slipping in the direction of the force: ż = 0
    assert model.rhs(0, np.array([0.0, 0.1, 0.0]), 0.0)[2] == pytest.approx(4e3)
    assert model.rhs(0, np.array([0.0, 0.1, 2.0]), 0.0)[2] == 0.0
    assert model.rhs(0, np.array([0.0, -0.1, 2.0]), 0.0)[2] == pytest.approx(-4e3)


def test_equation_text_reads_like_the_model():
    model = JointModel({"linear_stiffness": 4.0e5, "cubic_stiffness": -3e9, "viscous_damping": 2})
    assert model.equation() == "ẍ + 4e+05·x + 2·ẋ − 3e+09·x³ = −a_base(t)"


def test_json_round_trip(tmp_path):
    model = JointModel.preset("pandey2025").with_effect("microslip", 1.0, k_t=3e4, F_s=0.8)
    model = model.with_effect("tanh_saturation", 5.0, x_s=2e-4)
    path = model.to_json(tmp_path / "model.json")
    back = JointModel.from_json(path)
    assert back == model
    assert back.name == "pandey2025"
    assert back.parameters == model.parameters


def test_parameters_are_named_and_settable():
    model = JointModel(
        {"linear_stiffness": 4e5, "microslip": {"coefficient": 1, "k_t": 1e4, "F_s": 1}}
    )
    assert model.parameter_names == [
        "linear_stiffness",
        "microslip",
        "microslip.k_t",
        "microslip.F_s",
    ]
    changed = model.with_parameters({"microslip.k_t": 2e4, "linear_stiffness": 3e5})
    assert changed["microslip"].shape["k_t"] == 2e4
    assert changed.coefficient("linear_stiffness") == 3e5
    assert model.replace(microslip__F_s=3.0)["microslip"].shape["F_s"] == 3.0


def test_unknown_effect_raises_naming_it():
    with pytest.raises(ValueError, match="unknown effect 'cubic_stifness'"):
        JointModel({"cubic_stifness": 1.0})


@pytest.mark.parametrize("bad", [np.nan, np.inf, -np.inf])
def test_non_finite_coefficient_raises_naming_the_effect(bad):
    with pytest.raises(ValueError, match="coefficient of 'viscous_damping' is not finite"):
        Term("viscous_damping", bad)


def test_adding_an_effect_twice_raises():
    model = JointModel({"linear_stiffness": 1.0})
    with pytest.raises(ValueError, match="'linear_stiffness' is already in the model"):
        model.with_effect("linear_stiffness", 2.0)


@pytest.mark.parametrize(
    ("payload", "message"),
    [
        ({"format": "pm-joint/JointModel"}, "missing field 'terms'"),
        ({"terms": [{"coefficient": 1.0}]}, r"terms\[0\]: missing field 'effect'"),
        ({"terms": [{"effect": "linear_stiffness"}]}, r"terms\[0\]: missing field 'coefficient'"),
        ({"terms": [{"effect": "linear_stiffness", "coefficient": "NaN"}]}, "not finite"),
        ({"terms": [{"effect": "nope", "coefficient": 1}]}, "unknown effect 'nope'"),
    ],
)
def test_bad_json_raises_naming_the_item(tmp_path, payload, message):
    path = tmp_path / "bad.json"
    path.write_text(json.dumps(payload))
    with pytest.raises(ValueError, match=message) as info:
        JointModel.from_json(path)
    assert str(path) in str(info.value)


def test_unknown_preset_lists_the_available_ones():
    with pytest.raises(ValueError, match="pandey2025"):
        JointModel.preset("nope")


def test_parameter_bounds_are_sign_aware():
    model = JointModel.preset("pandey2025")  # has negative coefficients
    names = ["linear_stiffness", "cubic_stiffness", "van_der_pol"]
    box = parameter_bounds(model, names, {"linear_stiffness": 0.1, "cubic_stiffness": 0.5,
                                        "van_der_pol": 0.2})  # fmt: skip
    values = np.array([model.parameters[n] for n in names])
    np.testing.assert_allclose(box[0], [0.9 * values[0], 1.1 * values[0]])
    np.testing.assert_allclose(box[1], [1.5 * values[1], 0.5 * values[1]])  # negative
    assert np.all(box[:, 0] < values) and np.all(values < box[:, 1])
    with pytest.raises(ValueError, match=r"shape parameter .microslip\.F_s. must stay > 0"):
        parameter_bounds(RIG_PRESETS["trc-like"].model, ["microslip.F_s"], 1.5)
    with pytest.raises(ValueError, match="unknown parameter 'k9'"):
        parameter_bounds(RIG_PRESETS["trc-like"].model, ["k9"])


def test_the_hysteretic_term_is_found_by_its_flag_not_its_name():
    plain = JointModel({"linear_stiffness": 4e5, "cubic_stiffness": 1e9})
    assert plain.hysteretic_term is None and plain.stateful_terms == ()
    assert not plain.has_microslip and plain.state_size == 2
    assert plain.microslip_arrays() == (0.0, 0.0, 0.0)
    model = plain.with_effect("microslip", 0.5, k_t=3e4, F_s=0.8)
    assert model.hysteretic_term == model["microslip"] and model.stateful_terms == (
        model["microslip"],
    )
    assert model.has_microslip and model.state_size == 3
    assert model.microslip_arrays() == (0.5, 3e4, 0.8)
    # Stuck, the Jenkins spring adds to the small-amplitude stiffness; the kernels leave it out.
    assert model.linear_stiffness == 4e5 + 0.5 * 3e4
    indices, _, _ = model.kernel_arrays()
    assert len(indices) == 2
    assert model["microslip"].text(3) == "0.5·Jenkins(x; k_t=3e+04, F_s=0.8)"
