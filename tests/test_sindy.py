"""SINDy identification against known ground truths.

Test data: known JointModels under base excitation, integrated with
``scipy.integrate.solve_ivp`` (DOP853, rtol 1e-9), an integrator independent
of the package's own, sampled at 10 kHz. Each data set is three 3 s linear
sine sweeps of the base acceleration through resonance at rising levels, so
the records cover small to large amplitudes. "Vibrometer-like noise" is white
noise of 1e-4 m/s RMS added to both velocity channels.
"""

import math
import warnings

import numpy as np
import pytest
from scipy import integrate

from identification import harmonic
from identification.effects import CATALOGUE, restoring_force
from identification.model import JointModel
from identification.records import DATA_COLUMNS, Record, StepSchedule
from identification.signals import kinematics
from identification.sindy import (
    EQ3_SYMBOLS,
    PAPER_LIBRARY,
    POLYNOMIAL_LIBRARY,
    CollinearityWarning,
    backbone_error,
    comparison_table,
    identify,
    identify_arrays,
    plot_validation,
    validate,
)

FS = 10_000.0
NOISE_M_S = 1e-4
OMEGA = 2 * np.pi * 100.0

#: ~100 Hz, ζ = 0.5 %, cubic hardening of ~3 % in frequency at 1 mm, Coulomb friction
#: dissipating as much as the viscous damper at 0.5 mm (4 F / (π a ω) = 2 ζ ω).
TRUTH = JointModel(
    {
        "linear_stiffness": OMEGA**2,
        "viscous_damping": 2 * 0.005 * OMEGA,
        "quadratic_stiffness": 8e6,
        "cubic_stiffness": 3e10,
        "coulomb_friction": 1.5,
    }
)
#: Polynomial terms (all but ẋ², see the x²/ẋ² test) and the joint terms x|x|, ẋ|ẋ|, Coulomb.
LARGER_LIBRARY = [e for e in POLYNOMIAL_LIBRARY if e != "velocity_squared"] + [
    "abs_stiffness",
    "quadratic_damping",
    "coulomb_friction",
]


def sweep(f0_hz, f1_hz, duration_s, level):
    """Linear sweep: base acceleration function, and sampled base velocity and frequency."""
    rate = (f1_hz - f0_hz) / duration_s

    def acceleration(t):
        omega = 2 * np.pi * (f0_hz + rate * t)
        phase = 2 * np.pi * (f0_hz * t + 0.5 * rate * t * t)
        return level * np.sin(phase) + level * 2 * np.pi * rate / omega**2 * np.cos(phase)

    t = np.arange(0.0, duration_s, 1 / FS)
    frequency = f0_hz + rate * t
    phase = 2 * np.pi * (f0_hz * t + 0.5 * rate * t * t)
    # Base velocity −A/ω cos φ: `acceleration` is its exact time derivative.
    return t, acceleration, -level / (2 * np.pi * frequency) * np.cos(phase), frequency


def simulate(model, sweeps, noise=0.0, seed=0):
    """Records ``(t, response v, base v, frequency)`` and the true ``(x, v)`` per record."""
    indices, coefficients, shapes = model.kernel_arrays()
    rng = np.random.default_rng(seed)
    records, states = [], []
    for spec in sweeps:
        t, base_acceleration, base_velocity, frequency = spec

        def rhs(time, y, base_acceleration=base_acceleration):
            force = restoring_force(indices, coefficients, shapes, y[0], y[1])
            return (y[1], -force - base_acceleration(time))

        solution = integrate.solve_ivp(
            rhs, (t[0], t[-1]), [0.0, 0.0], t_eval=t, method="DOP853", rtol=1e-9, atol=1e-13
        )
        x, v = solution.y
        records.append((
            t,
            v + noise * rng.standard_normal(t.size),
            base_velocity + noise * rng.standard_normal(t.size),
            frequency,
        ))  # fmt: skip
        states.append((x, v))
    return records, states


def columns(records):
    return [list(c) for c in zip(*records, strict=True)]


@pytest.fixture(scope="module")
def truth_data():
    sweeps = [sweep(92, 110, 3.0, 3.0), sweep(90, 108, 3.0, 6.0), sweep(88, 106, 3.0, 10.0)]
    clean, states = simulate(TRUTH, sweeps)
    rng = np.random.default_rng(1)
    noisy = [
        (
            t,
            v + NOISE_M_S * rng.standard_normal(t.size),
            b + NOISE_M_S * rng.standard_normal(t.size),
            f,
        )
        for t, v, b, f in clean
    ]
    return clean, noisy, states


@pytest.fixture(scope="module")
def truth_fit(truth_data):
    _, noisy, _ = truth_data
    return identify_arrays(*columns(noisy), LARGER_LIBRARY)


@pytest.fixture(scope="module")
def pandey_data():
    model = JointModel.preset("pandey2025")
    sweeps = [sweep(98, 114, 3.0, 1.5), sweep(96, 112, 3.0, 5.0), sweep(94, 110, 3.0, 12.0)]
    return simulate(model, sweeps, noise=NOISE_M_S, seed=2)


def assert_identified(identification, truth, rtol):
    kept = {t.effect for t in identification.model.terms}
    assert kept == set(truth.effects), identification.summary()
    for effect in truth.effects:
        assert identification.coefficients[effect] == pytest.approx(
            truth.coefficient(effect), rel=rtol
        ), f"{effect}\n{identification.summary()}"


def test_truth_identified_within_2_percent_without_noise(truth_data):
    clean, _, states = truth_data
    assert 1e-3 < max(np.max(np.abs(x)) for x, _ in states) < 2e-3  # the range asked for
    identification = identify_arrays(*columns(clean), LARGER_LIBRARY)
    assert_identified(identification, TRUTH, rtol=0.02)
    assert identification.r2 > 0.99999


def test_truth_identified_within_10_percent_with_vibrometer_noise(truth_fit):
    assert_identified(truth_fit, TRUTH, rtol=0.10)
    assert truth_fit.threshold_method == "cv"
    assert truth_fit.path.score_se is not None
    assert truth_fit.threshold in truth_fit.path.thresholds


def test_identified_backbone_matches_truth(truth_fit):
    # Single-harmonic backbone of the truth in closed form: even terms and damping do not
    # move it, so ω² = k₁ + ¾ k₃ a².
    amplitude_m = np.linspace(1e-4, 1.5e-3, 15)
    truth_hz = np.sqrt(OMEGA**2 + 0.75 * 3e10 * amplitude_m**2) / (2 * np.pi)
    error = backbone_error(truth_fit.model, amplitude_m, truth_hz)
    assert np.max(np.abs(error)) <= 0.005


def test_quadratic_stiffness_and_velocity_squared_cannot_be_told_apart(truth_data):
    # Band-limited, both act only through the 2nd harmonic with the ratio −ω², and the mean
    # that would separate them is not in velocity data: their columns are collinear.
    clean, _, _ = truth_data
    library = [*LARGER_LIBRARY, "velocity_squared"]
    with pytest.warns(CollinearityWarning, match="'quadratic_stiffness' and 'velocity_squared'"):
        identification = identify_arrays(*columns(clean), library)
    i, j = library.index("quadratic_stiffness"), library.index("velocity_squared")
    assert abs(identification.correlation[i, j]) > 0.99
    assert ("quadratic_stiffness", "velocity_squared") in {
        (a, b) for a, b, _ in identification.collinear_pairs(0.99)
    }
    # The odd terms, which set the backbone and the damping, are still right.
    for effect in ("linear_stiffness", "cubic_stiffness", "viscous_damping", "coulomb_friction"):
        assert identification.coefficients[effect] == pytest.approx(
            TRUTH.coefficient(effect), rel=0.02
        )


@pytest.mark.parametrize("threshold", ["bic", 2e-3])
def test_other_threshold_rules_find_the_same_model(truth_data, threshold):
    clean, _, _ = truth_data
    identification = identify_arrays(*columns(clean), LARGER_LIBRARY, threshold=threshold)
    assert_identified(identification, TRUTH, rtol=0.02)
    assert identification.threshold_method == ("bic" if threshold == "bic" else "fixed")


def test_plain_least_squares_keeps_every_term(truth_data):
    clean, _, _ = truth_data
    identification = identify_arrays(*columns(clean), LARGER_LIBRARY, threshold=None)
    assert identification.threshold_method == "none"
    assert len(identification.model.terms) == len(LARGER_LIBRARY)


def test_ensemble_reports_inclusion_probabilities(truth_data):
    clean, _, _ = truth_data
    identification = identify_arrays(*columns(clean), LARGER_LIBRARY, ensemble=True, n_models=10)
    for effect in LARGER_LIBRARY:
        expected = 1.0 if effect in TRUTH else 0.0
        assert identification.inclusion_probability[effect] == expected
    for effect in TRUTH.effects:
        assert identification.ensemble_coefficients[effect] == pytest.approx(
            TRUTH.coefficient(effect), rel=0.02
        )


def test_validation_against_the_record(truth_data, truth_fit):
    _, noisy, _ = truth_data
    t, v, b, f = noisy[-1]
    result = validate(truth_fit.model, kinematics(t, v, b, f, FS))
    assert result.velocity.relative_rmse < 0.02
    assert result.acceleration.relative_rmse < 0.02
    assert abs(result.velocity.mean) < 1e-3 * np.max(np.abs(result.measured_velocity))
    assert result.velocity.max_abs >= result.velocity.rmse

    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    figure, axes = plt.subplots(3, 1)
    plot_validation(result, axes, channel="acceleration")
    assert len(axes[0].lines) == 2 and len(axes[2].lines) == 1
    plt.close(figure)


def test_pandey2025_identified_with_the_paper_library(pandey_data):
    truth = JointModel.preset("pandey2025")
    records, states = pandey_data
    peak_m = max(np.max(np.abs(x)) for x, _ in states)
    assert 1e-3 < peak_m < 1.5e-3
    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always", CollinearityWarning)
        identification = identify_arrays(*columns(records), PAPER_LIBRARY)
    # Peak share of each true term in the true restoring force over the tested range.
    total = max(np.max(np.abs(truth.restoring_force(x, v))) for x, v in states)
    share = {
        term.effect: max(
            np.max(np.abs(term.coefficient * CATALOGUE[term.effect].feature(x, v, **term.shape)))
            for x, v in states
        )
        / total
        for term in truth.terms
    }
    print(f"\npandey2025 under base excitation, 0.2–{peak_m * 1e3:.2f} mm, noise {NOISE_M_S} m/s")
    print(comparison_table(identification, truth, EQ3_SYMBOLS))
    print(identification.summary())
    print("true peak shares: " + ", ".join(f"{k} {v:.2%}" for k, v in share.items()))
    for effect, fraction in share.items():
        if fraction > 0.01:
            assert identification.coefficients[effect] == pytest.approx(
                truth.coefficient(effect), rel=0.10
            ), effect
    # Its multi-harmonic backbone (even terms included) is the truth's over the tested range.
    amplitude_m = np.linspace(1e-4, peak_m, 12)
    truth_hz = harmonic.backbone(truth, amplitude_m, method="multi").frequency_hz
    error = backbone_error(identification.model, amplitude_m, truth_hz, method="multi")
    assert np.max(np.abs(error)) <= 0.005
    # What the data cannot separate is said: x² vs ẋ² and the tanh/exp columns vs x.
    pairs = {(a, b) for a, b, _ in identification.collinear_pairs(0.98)}
    assert ("quadratic_stiffness", "velocity_squared") in pairs
    assert ("linear_stiffness", "tanh_saturation") in pairs
    assert any("tanh_saturation" in str(w.message) for w in caught)
    assert 100 < identification.condition_number < 1e5


def make_record(arrays, name):
    t, v, b, f = arrays
    data = np.zeros((t.size, len(DATA_COLUMNS)))
    data[:, 0] = t
    data[:, 8] = v + b  # panel point 8, the centre, in absolute terms
    data[:, 16] = b + 1e-3  # two base points whose mean is the base velocity
    data[:, 17] = b - 1e-3
    data[:, 18] = f
    steps = StepSchedule(np.array([t[0], t[-1]]), np.array([1.0, 1.0]))
    return Record(data, steps, name)


def test_identify_from_records_equals_arrays(truth_data, truth_fit):
    _, noisy, _ = truth_data
    records = [make_record(r, f"Config1_PRT_Assemb{i}") for i, r in enumerate(noisy)]
    identification = identify(records, LARGER_LIBRARY)
    for effect in LARGER_LIBRARY:
        assert identification.coefficients[effect] == pytest.approx(
            truth_fit.coefficients[effect], rel=1e-9, abs=1e-12
        )


def test_records_with_different_sampling_rates_are_refused(truth_data):
    _, noisy, _ = truth_data
    t, v, b, f = noisy[0]
    slow = (t[::2], v[::2], b[::2], f[::2])
    records = [
        make_record(noisy[0], "Config1_PRT_Assemb1"),
        make_record(slow, "Config1_PRT_Assemb2"),
    ]
    with pytest.raises(ValueError, match=r"different sampling rates.*Assemb1.*Assemb2"):
        identify(records, LARGER_LIBRARY)


def test_bad_libraries_are_refused(truth_data):
    clean, _, _ = truth_data
    data = columns(clean[:1])
    with pytest.raises(ValueError, match="unknown effect 'cubic_stifness'"):
        identify_arrays(*data, ["linear_stiffness", "cubic_stifness"])
    with pytest.raises(ValueError, match=r"\['linear_stiffness'\] appear more than once"):
        identify_arrays(*data, ["linear_stiffness", "viscous_damping", "linear_stiffness"])
    with pytest.raises(ValueError, match="not in the library"):
        identify_arrays(*data, ["linear_stiffness"], shapes={"tanh_saturation": {"x_s": 1e-3}})
    with pytest.raises(ValueError, match="no shape parameter"):
        identify_arrays(*data, ["tanh_saturation"], shapes={"tanh_saturation": {"v_s": 1e-3}})
    with pytest.raises(ValueError, match="threshold must be"):
        identify_arrays(*data, ["linear_stiffness"], threshold="aic")
    # tanh(x/x_s) with x_s ≫ x is x/x_s to 1e-12: the library is rank-deficient.
    with pytest.raises(
        ValueError, match=r"rank-deficient.*\['linear_stiffness', 'tanh_saturation'\]"
    ):
        identify_arrays(
            *data,
            ["linear_stiffness", "viscous_damping", "tanh_saturation"],
            shapes={"tanh_saturation": {"x_s": 1e3}},
        )


def test_bad_time_axis_is_refused(truth_data):
    clean, _, _ = truth_data
    t, v, b, f = clean[0]
    jittered = t.copy()
    jittered[100] += 0.5 / FS
    with pytest.raises(ValueError, match="record 0: t is not uniformly sampled"):
        identify_arrays(jittered, v, b, f, LARGER_LIBRARY)
    with pytest.raises(ValueError, match="same number of records"):
        identify_arrays([t, t], [v], [b], [f], LARGER_LIBRARY)


@pytest.mark.slow
def test_microslip_shape_is_found_by_scanning():
    # Linear spring-damper plus a Jenkins element slipping at a_s = F_s / k_t = 0.25 mm.
    truth = JointModel(
        {
            "linear_stiffness": 0.8 * OMEGA**2,
            "viscous_damping": 2 * 0.003 * OMEGA,
            "microslip": {"coefficient": 1.0, "k_t": 0.2 * OMEGA**2, "F_s": 20.0},
        }
    )
    sweeps = [sweep(88, 106, 3.0, 4.0), sweep(86, 104, 3.0, 10.0)]
    records = []
    for t, base_acceleration, base_velocity, frequency in sweeps:
        solution = integrate.solve_ivp(
            lambda time, y, a=base_acceleration: truth.rhs(time, y, a(time)),
            (t[0], t[-1]), [0.0, 0.0, 0.0], t_eval=t, method="DOP853", rtol=1e-9, atol=1e-13,
        )  # fmt: skip
        records.append((t, solution.y[1], base_velocity, frequency))
    k_t = truth["microslip"].shape["k_t"]
    # F_s = 40 m/s² never slips at these amplitudes (a_s = 0.5 mm): Jenkins ≡ k_t x there.
    with pytest.warns(UserWarning, match=r"skipped: microslip.k_t=[\d.]+, microslip.F_s=40 "):
        identification = identify_arrays(
            *columns(records),
            ["linear_stiffness", "viscous_damping", "cubic_stiffness", "microslip"],
            shapes={"microslip": {"k_t": k_t, "F_s": [10.0, 20.0, 40.0]}},
        )
    print(identification.summary())
    term = identification.model["microslip"]
    assert term.shape["F_s"] == 20.0
    assert term.coefficient == pytest.approx(1.0, rel=0.05)
    assert identification.coefficients["linear_stiffness"] == pytest.approx(
        truth.coefficient("linear_stiffness"), rel=0.02
    )
    assert math.isclose(identification.model.linear_frequency_hz, 100.0, rel_tol=0.01)
