"""The N-mode harmonic balance (identification.multimode) against independent answers.

* a time integration written here (scipy ``solve_ivp``, forces written out by hand,
  no package kernel) of a two-mode system with a cubic joint element and a
  quadratic modal coupling: the forced steady state, and the conservative
  nonlinear mode found by shooting;
* a published internal resonance: the saturation of Nayfeh & Mook's 1:2
  quadratically coupled oscillators, first-order multiple scales in closed form;
* the one-mode case against the package's own one-mode harmonic balance.
"""

import json

import numpy as np
import pytest
from scipy.integrate import solve_ivp
from scipy.optimize import brentq, fsolve

from identification.analytical.harmonic import backbone
from identification.effects import CATALOGUE, LINEAR_STIFFNESS, VISCOUS_DAMPING
from identification.model import JointModel
from identification.multimode import (
    Coupling,
    HarmonicSettings,
    JointElement,
    ModalModel,
    Mode,
    forced_response,
    nonlinear_modes,
    phase_resonance,
)
from identification.multimode.balance import StateLayout, evaluate, harmonic_grid, modal_arrays
from identification.multimode.continuation import continue_nonlinear_mode

CUBIC = CATALOGUE["cubic_stiffness"].name
QUADRATIC = CATALOGUE["quadratic_stiffness"].name
CUBIC_DAMPING = CATALOGUE["cubic_damping"].name
JENKINS = next(e.name for e in CATALOGUE.values() if e.hysteretic)

# The two-mode test system: f1 = 1 Hz, f2 = 2.45 Hz, a cubic joint element on
# q = η1 + 0.6 η2 and the coupling potential V = κ η1² η2 (forces 2κ η1η2 on
# mode 1, κ η1² on mode 2).
F1, F2, SHAPE2, K3, KAPPA = 1.0, 2.45, 0.6, 300.0, 15.0
GAMMA = (1.0, 0.5)


def two_mode(zeta: float) -> ModalModel:
    return ModalModel(
        modes=(Mode(F1, zeta, GAMMA[0]), Mode(F2, zeta, GAMMA[1])),
        joint_shapes=((1.0, SHAPE2),),
        elements=(JointElement(CUBIC, K3),),
        couplings=(Coupling(1, (1, 1), 2 * KAPPA), Coupling(2, (2, 0), KAPPA)),
    )


def two_mode_rhs(zeta: float, base):
    """The two-mode equations written out by hand (base: t -> base acceleration)."""
    w1, w2 = 2 * np.pi * F1, 2 * np.pi * F2

    def rhs(t, s):
        e1, e2, v1, v2 = s[:4]
        q = e1 + SHAPE2 * e2
        g = K3 * q**3
        a = base(t)
        d1 = -2 * zeta * w1 * v1 - w1**2 * e1 - g - 2 * KAPPA * e1 * e2 - GAMMA[0] * a
        d2 = -2 * zeta * w2 * v2 - w2**2 * e2 - SHAPE2 * g - KAPPA * e1**2 - GAMMA[1] * a
        return [v1, v2, d1, d2]

    return rhs


def integrated_steady_state(rhs, period: float, n_periods: int = 60, n_last: int = 4) -> np.ndarray:
    """Fourier spectrum of η1, η2 over the last ``n_last`` periods of a run from rest.

    Harmonic ``h`` of the period sits at bin ``n_last · h`` (whole periods sampled).
    """
    n_per = 128
    t_end = n_periods * period
    t_eval = t_end - n_last * period + np.arange(n_last * n_per) * period / n_per
    run = solve_ivp(
        rhs, (0, t_end), [0, 0, 0, 0], method="DOP853", rtol=1e-11, atol=1e-13, t_eval=t_eval
    )
    assert run.success
    return np.fft.rfft(run.y[:2], axis=-1) / t_eval.size


def test_forced_steady_state_matches_time_integration():
    zeta, level, f_exc = 0.05, 1.0, 0.9
    sol = forced_response(two_mode(zeta), [f_exc], level, settings=HarmonicSettings(harmonics=9))
    assert sol.converged[0]
    omega = 2 * np.pi * f_exc
    n_last = 4
    spectrum = integrated_steady_state(
        two_mode_rhs(zeta, lambda t: level * np.cos(omega * t)), 1 / f_exc, n_last=n_last
    )
    for m in range(2):
        integrated = 2 * abs(spectrum[m, n_last])
        balanced = np.hypot(*sol.coefficients[0, m, 1:3])
        assert balanced == pytest.approx(integrated, rel=1e-4)
        # the phase too: the fundamental's cos and sin parts, relative to its amplitude
        cos_sin = np.array([2 * spectrum[m, n_last].real, -2 * spectrum[m, n_last].imag])
        assert np.max(np.abs(sol.coefficients[0, m, 1:3] - cos_sin)) <= 1e-4 * integrated
        # the mean and second harmonic the quadratic coupling makes, to 1e-4 of the fundamental
        second = np.array([2 * spectrum[m, 2 * n_last].real, -2 * spectrum[m, 2 * n_last].imag])
        assert abs(sol.coefficients[0, m, 0] - spectrum[m, 0].real) <= 1e-4 * integrated
        assert np.max(np.abs(sol.coefficients[0, m, 3:5] - second)) <= 1e-4 * integrated


def test_conservative_nonlinear_mode_matches_shooting():
    """Zero damping: the EPMC point is the periodic orbit with the same fundamental amplitude.

    The forces depend on positions only, so an orbit through zero velocity at t = 0
    and again at T/2 is periodic with period T (time reversal). Shooting solves for
    η(0) and T with the fundamental's cosine part of η1 over the period equal to
    the prescribed amplitude (an integral carried by the integrator).
    """
    amplitude = 0.12
    sol = nonlinear_modes(
        two_mode(0.0), [0.04, 0.08, amplitude], settings=HarmonicSettings(harmonics=11)
    )
    assert sol.converged.all()
    assert np.max(np.abs(sol.damping_ratio)) < 1e-10
    assert sol.frequency_hz[-1] > 1.01 * F1  # the cubic element hardens it
    rhs = two_mode_rhs(0.0, lambda t: 0.0)

    def conditions(unknowns):
        e1, e2, period = unknowns

        def augmented(t, s):
            return [*rhs(t, s), s[0] * np.cos(2 * np.pi * t / period)]

        end = solve_ivp(
            augmented, (0, period / 2), [e1, e2, 0, 0, 0], method="DOP853", rtol=1e-12, atol=1e-14
        ).y[:, -1]
        return [end[2], end[3], 4 * end[4] / period - amplitude]

    c = sol.coefficients[-1]
    start = c[:, 0] + c[:, 1::2].sum(axis=1)  # η(0) = C0 + Σ C_h
    guess = [start[0], start[1], 1 / sol.frequency_hz[-1]]
    e1, e2, period = fsolve(conditions, guess, xtol=1e-13)
    assert np.max(np.abs(conditions([e1, e2, period]))) < 1e-10
    assert sol.frequency_hz[-1] == pytest.approx(1 / period, rel=1e-4)
    assert start[0] == pytest.approx(e1, rel=1e-4)
    assert start[1] == pytest.approx(e2, rel=1e-4, abs=1e-4 * abs(e1))


def _saturation_closed_form(w1, w2, mu1, mu2, alpha1, alpha2, force, big_omega):
    """First-order multiple-scales steady state of Nayfeh & Mook's 1:2 system.

    Nayfeh, A. H. and Mook, D. T. (1979; Wiley Classics 1995), *Nonlinear
    Oscillations*, Wiley, §6.5 (quadratic nonlinearities, 1:2 internal resonance)
    and §6.5.1 "The saturation phenomenon": ü1 + ω1² u1 + 2μ1 u̇1 = α1 u1 u2,
    ü2 + ω2² u2 + 2μ2 u̇2 = α2 u1² + F cos Ωt, with ω2 = 2ω1 + σ1 and Ω = ω2 + σ2
    (the book's ε absorbed into μ, σ, F). On the coupled branch u2's amplitude is
    a2 = (2ω1/α1)·[4μ1² + (σ1 + σ2)²]^½ whatever F (the saturation), and a1² solves
    the quadratic the second solvability condition gives. Returns (a1, a2, γ1, γ2):
    u1 = a1 cos(Ωt/2 − (γ1 + γ2)/2), u2 = a2 cos(Ωt − γ2).
    """
    nu = (big_omega - 2 * w1) / 2
    sigma2 = big_omega - w2
    a2 = 4 * w1 * np.hypot(mu1, nu) / abs(alpha1)
    e1 = 4 * w1 * (-nu + 1j * mu1) / (alpha1 * a2)
    z = w2 * a2 * (-sigma2 + 1j * mu2)
    w = alpha2 * w1 * (-nu - 1j * mu1) / (alpha1 * a2)
    qa, qb, qc = abs(w) ** 2, -2 * np.real(z * np.conj(w)), abs(z) ** 2 - force**2 / 4
    s = (-qb + np.sqrt(qb * qb - 4 * qa * qc)) / (2 * qa)
    return np.sqrt(s), a2, np.angle(e1), np.angle((z - s * w) / (force / 2))


def _saturation_case(eps: float, factor: float) -> tuple[np.ndarray, np.ndarray]:
    """Balanced and closed-form amplitudes ``(a1, a2)`` of the 1:2 case at ``eps``.

    Mode 2 (ω2 = 2 + ε) is driven near its resonance (Ω = ω2 + ε/2) with
    μ1 = μ2 = ε, α1 = α2 = 1, at ``factor`` times the force where its linear
    response would reach the saturation amplitude. Newton starts from the closed
    form (the uncoupled branch a1 = 0 is a solution too).
    """
    w1, mu, alpha, harmonics = 1.0, eps, 1.0, 4
    w2 = 2 + eps
    big_omega = w2 + 0.5 * eps
    model = ModalModel(
        modes=(Mode(w1 / (2 * np.pi), mu / w1, 0.0), Mode(w2 / (2 * np.pi), mu / w2, 1.0)),
        joint_shapes=(),
        couplings=(Coupling(1, (1, 1), -alpha), Coupling(2, (2, 0), -alpha)),
    )
    saturation = 4 * w1 * np.hypot(mu, (big_omega - 2 * w1) / 2)
    force = factor * saturation * 2 * w2 * np.hypot(mu, big_omega - w2)
    a1, a2, g1, g2 = _saturation_closed_form(w1, w2, mu, mu, alpha, alpha, force, big_omega)
    start = np.zeros((2, 2 * harmonics + 1))
    start[0, 1:3] = a1 * np.cos((g1 + g2) / 2), a1 * np.sin((g1 + g2) / 2)
    start[1, 3:5] = a2 * np.cos(g2), a2 * np.sin(g2)
    # u1 answers at Ω/2: the balance's fundamental is Ω/2, the forcing its 2nd harmonic;
    # F cos Ωt on mode 2 alone is a base acceleration −F with participations (0, 1).
    sol = forced_response(model, [big_omega / (2 * np.pi)], -force, forcing_harmonic=2,
                          start=start, settings=HarmonicSettings(harmonics, tol=1e-12))  # fmt: skip
    assert sol.converged[0]
    c = sol.coefficients[0]
    return np.array([np.hypot(*c[0, 1:3]), np.hypot(*c[1, 3:5])]), np.array([a1, a2])


@pytest.mark.parametrize("eps", [0.005, 0.0025])
def test_nayfeh_mook_saturation(eps):
    """Published 1:2 internal resonance: the saturation of the directly excited mode.

    At 2 and 4 times the saturation force, first-order multiple scales leaves
    errors of order ε relative (the next order): the balance must agree within 6ε
    on both amplitudes; and doubling the force moves mode 2 by O(ε), not by a
    factor 2 (the saturation).
    """
    balanced, closed = zip(*(_saturation_case(eps, factor) for factor in (2.0, 4.0)), strict=True)
    for b, c in zip(balanced, closed, strict=True):
        np.testing.assert_allclose(b, c, rtol=6 * eps)
    assert balanced[1][1] / balanced[0][1] - 1 < 4 * eps


def test_saturation_error_is_first_order():
    """The disagreement with the closed form falls like ε (the perturbation's next order)."""
    errors = []
    for eps in (0.01, 0.005, 0.0025):
        balanced, closed = _saturation_case(eps, 2.0)
        errors.append(abs(balanced[1] / closed[1] - 1))
    ratios = np.array(errors[1:]) / np.array(errors[:-1])
    assert np.all((ratios > 0.4) & (ratios < 0.6))


def _joint_model() -> JointModel:
    w0 = 2 * np.pi * 100
    return JointModel(
        {
            LINEAR_STIFFNESS: w0**2,
            VISCOUS_DAMPING: 2 * 0.003 * w0,
            CUBIC: 1e11,
            QUADRATIC: 3e6,
            CUBIC_DAMPING: 1e3,
        }
    )


@pytest.mark.parametrize("with_jenkins", [False, True])
def test_one_mode_equals_the_one_mode_balance(with_jenkins):
    model = _joint_model()
    n_time = 80
    if with_jenkins:
        k_t = 0.06 * model.linear_stiffness
        model = model.with_effect(JENKINS, 1.0, k_t=k_t, F_s=k_t * 2e-4)
        n_time = 160
    a = np.linspace(0.05e-3, 2e-3, 7)
    ref = backbone(model, a, method="multi", harmonics=5, n_time=n_time, tol=1e-13)
    sol = phase_resonance(
        ModalModel.from_joint_model(model),
        a,
        settings=HarmonicSettings(5, n_time=n_time, tol=1e-13),
    )
    assert ref.converged.all() and sol.converged.all()
    np.testing.assert_allclose(sol.frequency_hz, ref.frequency_hz, rtol=1e-10)
    np.testing.assert_allclose(sol.base_acceleration[:, 1], ref.base_acceleration, rtol=1e-10)
    np.testing.assert_allclose(sol.damping_ratio, ref.damping_ratio, rtol=1e-10)
    c = sol.coefficients[:, 0]
    scale = a[:, None]
    np.testing.assert_allclose(c[:, :1] / scale, ref.harmonics_cos_m[:, :1] / scale, atol=1e-10)
    np.testing.assert_allclose(c[:, 3::2] / scale, ref.harmonics_cos_m[:, 2:] / scale, atol=1e-10)
    np.testing.assert_allclose(c[:, 4::2] / scale, ref.harmonics_sin_m[:, 2:] / scale, atol=1e-10)


def test_internal_resonance_1_3_is_found_and_placed():
    """A hardening mode 1 meets mode 2 at 3:1; the branch names mode 2, harmonic 3.

    The joint element couples the modes; where 3 f(a) crosses f2 = 3.15 Hz mode 2
    takes energy through the third harmonic. Without mode 2 at the joint (shape 0)
    nothing is reported.
    """

    def model(shape2: float) -> ModalModel:
        return ModalModel(
            modes=(Mode(1.0, 0.01), Mode(3.15, 0.01)),
            joint_shapes=((1.0, shape2),),
            elements=(JointElement(CUBIC, 40.0),),
        )

    branch = continue_nonlinear_mode(model(0.5), 0.01, 0.5, settings=HarmonicSettings(7))
    assert branch.stopped == "end amplitude"
    (found,) = branch.internal_resonances
    assert (found.mode, found.harmonic) == (2, 3)
    peak = np.argmax(branch.energy_share[:, 1])
    assert 3 * branch.frequency_hz[peak] == pytest.approx(3.15, rel=0.02)
    assert branch.amplitude_m[0] < found.amplitude_m < branch.amplitude_m[peak] + 1e-12
    assert "1:3" in found.describe()
    alone = continue_nonlinear_mode(model(0.0), 0.01, 0.5, settings=HarmonicSettings(7))
    assert alone.internal_resonances == ()
    assert alone.energy_share[:, 1].max() < 1e-20


def test_batch_equals_single_sets():
    model = two_mode(0.02)
    names = ["mode1.frequency_hz", f"joint1.{CUBIC}", "coupling2"]
    values = np.array([[1.0, 300.0, 15.0], [1.1, 200.0, 5.0], [0.95, 350.0, 25.0]])
    a = np.array([0.02, 0.06, 0.1])
    batch = nonlinear_modes(model, a, parameters=values, names=names)
    for row, v in enumerate(values):
        single = ModalModel(
            modes=(Mode(v[0], 0.02, GAMMA[0]), Mode(F2, 0.02, GAMMA[1])),
            joint_shapes=((1.0, SHAPE2),),
            elements=(JointElement(CUBIC, v[1]),),
            couplings=(Coupling(1, (1, 1), 2 * KAPPA), Coupling(2, (2, 0), v[2])),
        )
        assert model.with_parameters(dict(zip(names, v, strict=True))) == single
        alone = nonlinear_modes(single, a)
        np.testing.assert_allclose(batch.frequency_hz[row], alone.frequency_hz, rtol=1e-12)
        np.testing.assert_allclose(batch.damping_ratio[row], alone.damping_ratio, rtol=1e-8)
    with pytest.raises(ValueError, match="unknown parameters"):
        model.with_parameters({"mode3.frequency_hz": 1.0})


def test_json_round_trip_and_validation(tmp_path):
    model = two_mode(0.02)
    assert "η1·η2" in model.equation(1) and "at x = q1" in model.equation(2)
    path = model.to_json(tmp_path / "m.json")
    assert ModalModel.from_json(path) == model
    data = json.loads(path.read_text())
    assert (data["format"], data["version"]) == ("pm-joint/ModalModel", 1)
    data["modes"][0]["frequency_hz"] = 2.0
    with pytest.raises(ValueError, match="hash mismatch"):
        ModalModel.from_dict(data)
    del data["content_sha256"]
    assert ModalModel.from_dict(data).modes[0].frequency_hz == 2.0
    data["elements"][0]["effect"] = "no_such_effect"
    with pytest.raises(ValueError, match="unknown effect"):
        ModalModel.from_dict(data)
    with pytest.raises(ValueError, match="degree"):
        Coupling(1, (1, 0), 1.0)
    with pytest.raises(ValueError, match="one entry per mode"):
        ModalModel(modes=(Mode(1.0),), joint_shapes=((1.0, 0.5),))
    with pytest.raises(ValueError, match="joint 2"):
        ModalModel(
            modes=(Mode(1.0),),
            joint_shapes=((1.0,),),
            elements=(JointElement(CUBIC, 1.0, joint=2),),
        )
    with pytest.raises(ValueError, match=r"modes are 1\.\.1"):
        ModalModel(modes=(Mode(1.0),), joint_shapes=(), couplings=(Coupling(2, (2,), 1.0),))
    with pytest.raises(ValueError, match="no base participation"):
        phase_resonance(ModalModel(modes=(Mode(1.0, 0.01, 0.0),), joint_shapes=()), [0.1])


def test_internal_resonance_1_2_captures_the_branch():
    """Near 1:2 with the coupling potential κ η1² η2: mode 2 takes over the branch.

    Mode 1 hardens (cubic element on q = η1) until twice its frequency meets
    f2 = 2.1 Hz; from there the branch's frequency locks at f2 / 2 while mode 2
    takes nearly all the energy through the second harmonic.
    """
    model = ModalModel(
        modes=(Mode(1.0, 0.005), Mode(2.1, 0.005)),
        joint_shapes=((1.0, 0.0),),
        elements=(JointElement(CUBIC, 40.0),),
        couplings=(Coupling(1, (1, 1), 6.0), Coupling(2, (2, 0), 3.0)),
    )
    branch = continue_nonlinear_mode(model, 0.01, 0.6, settings=HarmonicSettings(4))
    assert branch.stopped == "end amplitude"
    (found,) = branch.internal_resonances
    assert (found.mode, found.harmonic) == (2, 2)
    assert 2 * found.frequency_hz == pytest.approx(2.1, rel=0.02)
    assert found.peak_share > 0.9
    assert 2 * branch.frequency_hz[-1] == pytest.approx(2.1, rel=0.005)


def test_phase_resonance_matches_time_integration():
    """The two-mode phase-resonant backbone: the base A sin ωt it finds holds η1 = a cos ωt.

    Integrated at the balance's ω and A, the steady η1 must have the prescribed
    fundamental amplitude and no sine part; a frequency off by δ would turn the
    phase by about δ / (ζ ω), so the 1e-4 phase check also checks ω to ~ζ·1e-4.
    """
    zeta = 0.05
    sol = phase_resonance(two_mode(zeta), [0.02, 0.06, 0.1], settings=HarmonicSettings(9))
    assert sol.converged.all()
    omega = 2 * np.pi * sol.frequency_hz[-1]
    level = sol.base_acceleration[-1, 1]
    n_last = 4
    spectrum = integrated_steady_state(
        two_mode_rhs(zeta, lambda t: level * np.sin(omega * t)), 2 * np.pi / omega, n_last=n_last
    )
    fundamental = 2 * spectrum[0, n_last]
    # η1 = a cos ωt: amplitude a, no sine part (the 90° of phase resonance)
    assert fundamental.real == pytest.approx(0.1, rel=1e-4)
    assert abs(fundamental.imag) <= 1e-4 * 0.1


def test_jacobian_matches_finite_differences():
    """The AFT Jacobian, every column (coefficients, ω, ξ, A_c, A_s), against central differences.

    A model with a velocity term (cubic damping), a stiffness term, a Jenkins
    element on a second joint coordinate and both couplings; a state where the
    Jenkins element slips part of the period.
    """
    model = ModalModel(
        modes=(Mode(1.0, 0.02, 1.0), Mode(2.3, 0.01, 0.4)),
        joint_shapes=((1.0, 0.6), (0.5, -1.0)),
        elements=(
            JointElement(CUBIC, 300.0),
            JointElement(CUBIC_DAMPING, 5.0),
            JointElement(JENKINS, 1.0, {"k_t": 10.0, "F_s": 0.5}, joint=2),
        ),
        couplings=(Coupling(1, (1, 1), 30.0), Coupling(2, (2, 0), 15.0)),
    )
    grid = harmonic_grid(3, 64)
    layout = StateLayout(2, grid.size)
    rng = np.random.default_rng(3)
    y = np.zeros((1, layout.n_state))
    y[0, : layout.n_coefficients] = 0.1 * rng.standard_normal(layout.n_coefficients)
    y[0, layout.omega], y[0, layout.xi] = 6.5, 0.3
    y[0, layout.forcing_cos], y[0, layout.forcing_sin] = 0.7, -0.2
    arrays = modal_arrays(model)
    for harmonic in (1, 2):
        _, jacobian = evaluate(arrays, grid, y, harmonic)
        numeric = np.empty_like(jacobian[0])
        for j in range(layout.n_state):
            h = 1e-7 * max(1.0, abs(y[0, j]))
            up, down = y.copy(), y.copy()
            up[0, j] += h
            down[0, j] -= h
            numeric[:, j] = (evaluate(arrays, grid, up, harmonic)[0][0]
                             - evaluate(arrays, grid, down, harmonic)[0][0]) / (2 * h)  # fmt: skip
        scale = np.abs(numeric).max()
        assert np.max(np.abs(jacobian[0] - numeric)) <= 1e-5 * scale


def test_uncoupled_second_mode_leaves_the_first_as_alone():
    """Mode 2 absent from the joint and uncoupled: mode 1's backbone is the one-mode one,
    Jenkins history included, and mode 2 answers the base as a linear oscillator."""
    k_t = 0.06 * _joint_model().linear_stiffness
    joint = _joint_model().with_effect(JENKINS, 1.0, k_t=k_t, F_s=k_t * 2e-4)
    alone = ModalModel.from_joint_model(joint)
    pair = ModalModel(
        modes=(*alone.modes, Mode(230.0, 0.01, 0.7)),
        joint_shapes=((1.0, 0.0),),
        elements=alone.elements,
    )
    a = np.array([0.1e-3, 0.5e-3, 1.5e-3])
    settings = HarmonicSettings(5, n_time=160, tol=1e-13)
    one = phase_resonance(alone, a, settings=settings)
    two = phase_resonance(pair, a, settings=settings)
    np.testing.assert_allclose(two.frequency_hz, one.frequency_hz, rtol=1e-10)
    np.testing.assert_allclose(two.damping_ratio, one.damping_ratio, rtol=1e-10)
    # mode 2 answers the base (participation 0.7) linearly, at the fundamental only
    w2, w = 2 * np.pi * 230.0, 2 * np.pi * two.frequency_hz
    expected = 0.7 * two.base_acceleration[:, 1] / np.abs(w2**2 - w**2 + 2j * 0.01 * w2 * w)
    np.testing.assert_allclose(np.hypot(*two.coefficients[:, 1, 1:3].T), expected, rtol=1e-8)


def test_light_damping_nonlinear_mode_matches_a_free_decay():
    """ζ = 0.2 %: the free decay from the EPMC orbit follows its frequency and damping.

    The decay's instantaneous frequency (one period between successive maxima of
    η1) at the cycle's fundamental amplitude matches the EPMC branch to 1e-4. The
    energy the decay loses over that cycle (the system's energy, written here)
    matches the EPMC damping's, ``ξ T Σ_m ⟨η̇_m²⟩ = 4π D Σ_m ⟨η̇_m²⟩``, to 0.5 % (the
    amplitude falls by 2πζ ≈ 1.3 % over a cycle, and EPMC's error for light
    damping is of order ζ relative). The amplitude's log decrement is not D here:
    the hardening makes the energy grow faster than a².
    """
    zeta = 0.002
    amplitudes = np.linspace(0.01, 0.14, 27)
    sol = nonlinear_modes(two_mode(zeta), amplitudes, settings=HarmonicSettings(9))
    assert sol.converged.all()
    c, omega = sol.coefficients[-1], 2 * np.pi * sol.frequency_hz[-1]
    orders = np.arange(1, 10)
    start = c[:, 0] + c[:, 1::2].sum(axis=1)
    speed = omega * (c[:, 2::2] * orders).sum(axis=1)
    t_end = 42.0
    run = solve_ivp(two_mode_rhs(zeta, lambda t: 0.0), (0, t_end), [*start, *speed],
                    method="DOP853", rtol=1e-11, atol=1e-13, dense_output=True)  # fmt: skip
    grid = np.linspace(0, t_end, int(t_end * 400))
    v1 = run.sol(grid)[2]
    crossings = np.flatnonzero((v1[:-1] > 0) & (v1[1:] <= 0))
    maxima = np.array([brentq(lambda t: run.sol(t)[2], grid[i], grid[i + 1], xtol=1e-14)
                       for i in crossings])  # fmt: skip
    w1, w2 = 2 * np.pi * F1, 2 * np.pi * F2

    def energy(t: float) -> float:
        e1, e2, v1, v2 = run.sol(t)
        q = e1 + SHAPE2 * e2
        return (0.5 * (v1**2 + v2**2 + w1**2 * e1**2 + w2**2 * e2**2) + K3 * q**4 / 4
                + KAPPA * e1**2 * e2)  # fmt: skip

    # Σ_m ⟨η̇_m²⟩ along the branch: ½ Σ_h (hω)² (C² + S²)
    power = sol.coefficients[:, :, 1::2] ** 2 + sol.coefficients[:, :, 2::2] ** 2
    mean_square_speed = 0.5 * np.sum(
        (2 * np.pi * sol.frequency_hz[:, None, None] * orders) ** 2 * power, axis=(1, 2)
    )
    for k in (0, 15, 30):
        period = maxima[k + 1] - maxima[k]
        phase = 2 * np.pi * np.arange(256) / 256
        eta1 = run.sol(maxima[k] + phase * period / (2 * np.pi))[0]
        amplitude = np.hypot(2 * np.mean(eta1 * np.cos(phase)), 2 * np.mean(eta1 * np.sin(phase)))
        branch = np.interp(amplitude, sol.amplitude_m, sol.frequency_hz)
        assert 1 / period == pytest.approx(branch, rel=1e-4)
        lost = energy(maxima[k]) - energy(maxima[k + 1])
        predicted = (
            4 * np.pi * np.interp(amplitude, sol.amplitude_m, sol.damping_ratio * mean_square_speed)
        )
        assert lost == pytest.approx(predicted, rel=5e-3)


def _scenario_terms(effect, k0: float) -> dict:
    truth = effect.hidden_scenario.truth(k0)
    return dict(truth) if isinstance(truth, dict) else {"coefficient": truth}


@pytest.mark.parametrize(
    "effect", [e for e in CATALOGUE.values() if e.hidden_scenario is not None], ids=lambda e: e.name
)
def test_every_catalogue_effect_is_a_joint_element(effect):
    """Each catalogue effect as the joint element of a one-mode model (at its lab scenario's
    size) gives the one-mode balance's backbone to 1e-9."""
    w0 = 2 * np.pi * 100
    entry = _scenario_terms(effect, w0**2)
    model = JointModel({LINEAR_STIFFNESS: w0**2, VISCOUS_DAMPING: 2 * 0.003 * w0,
                        effect.name: entry})  # fmt: skip
    a = np.array([0.1e-3, 0.6e-3, 1.5e-3])
    ref = backbone(model, a, method="multi", harmonics=3, n_time=128, tol=1e-13)
    sol = phase_resonance(ModalModel.from_joint_model(model), a,
                          settings=HarmonicSettings(3, n_time=128, tol=1e-13))  # fmt: skip
    both = ref.converged & sol.converged
    assert both.sum() >= 2
    np.testing.assert_allclose(sol.frequency_hz[both], ref.frequency_hz[both], rtol=1e-9)
    np.testing.assert_allclose(sol.damping_ratio[both], ref.damping_ratio[both], rtol=1e-9)
