"""Criticism that names a missing mode (#27 item 6).

* The second mode's signatures (``identification.criticism.second_mode``: the dynamic
  stiffness a second mode adds to the first through the joint or a 1:2 quadratic coupling,
  and the second harmonic it feeds) against the independent simulator's forced steady
  states (``independent.decays``: its own ODE integration, no library kernel): the
  first mode's complex dynamic stiffness ``F/X`` and the second mode's 2ω response.
* The lab rig's ``lab-second-mode`` (a mode 5 % above the first, coupled through the joint)
  criticised from its one-mode base model: the finding puts the mode within 5 % of the
  truth's frequency and names it ("explained by a second mode", #27's acceptance); a
  one-mode lab preset with a hidden catalogue effect names
  none. Seeds are tuning seeds (the held-out counts are the bench's,
  ``bench/criticism_second_mode.py``).
"""

from __future__ import annotations

import json
import math
import re

import numpy as np
import pytest
from scipy.optimize import lsq_linear

from identification.criticism.config import SEPARATION, VERDICTS, Verdict
from identification.criticism.criticism import criticize
from identification.criticism.mode_columns import (
    COUPLING,
    JOINT,
    SENSOR,
    added_stiffness,
    fed_harmonic,
    route_gains,
)
from identification.criticism.mode_refit import PARAMETERS, backbone_channels
from identification.effects import LINEAR_STIFFNESS, VISCOUS_DAMPING
from identification.model import JointModel
from identification.multimode.model import Coupling, JointElement, ModalModel, Mode
from independent.campaigns import OUT_OF_CATALOGUE_JOINTS, phase_resonance_campaign
from independent.decays import ModalSystem, PotentialTerm, modal_forced_steady_state
from independent.forces import CubicStiffness
from independent.modal_resonance import modal_phase_resonance
from studies.second_mode import TWO_MODE_CASES, campaign, passes, second_mode_campaign

F1_HZ, ZETA = 100.0, 0.02  # well damped, so the forced transient dies in a few hundred periods


def _operator(frequency_hz: float, zeta: float, at_hz: float) -> complex:
    w2, w = 2 * math.pi * frequency_hz, 2 * math.pi * at_hz
    return w2**2 - w**2 + 2j * zeta * w2 * w


def _steady(system: ModalSystem, drive_hz: float, base_m_s2: float) -> tuple[complex, complex]:
    """Mode 1's fundamental ``X`` and mode 2's second harmonic (complex, ``Re(· e^{ihωt})``)
    of the steady state under ``a_base = A sin ωt`` driving mode 1 alone."""
    w = 2 * math.pi * drive_hz
    period = 1 / drive_hz
    fs = 64 * drive_hz
    response = modal_forced_steady_state(
        system, lambda t: base_m_s2 * math.sin(w * t), period, (1.0, 0.0), fs_hz=fs,
        settle_periods=120, record_periods=4,
    )  # fmt: skip
    t = response.time_s
    q = response.modal_displacement
    x = 2 * np.mean(q[0] * np.exp(-1j * w * t))
    z = 2 * np.mean(q[1] * np.exp(-2j * w * t))
    # the recorded time restarts at 0 on a whole number of periods: phases are the drive's
    return complex(x), complex(z)


def _stiffness(x: complex, base_m_s2: float) -> complex:
    """``F/X``: mode 1 is forced by ``−A sin ωt = Re(iA e^{iωt})``."""
    return 1j * base_m_s2 / x


def test_a_quadratic_coupling_adds_what_the_column_says():
    """``κ q₁² q₂`` with mode 2 at 1.95× mode 1, driven at mode 1's frequency: the first mode's
    dynamic stiffness changes by ``−κ² a² [1/(2 D₂(2ω)) + 1/ω₂²]`` and mode 2 answers at 2ω with
    ``κ · fed_harmonic`` of the fundamental (phase-normalised), both within 5 % of the
    independent simulator's (the rest: higher orders in κ)."""
    f2, kappa, drive = 1.95 * F1_HZ, 1.2e7, F1_HZ
    base = 16.0  # about 1 mm of mode 1
    free = ModalSystem((F1_HZ, f2), (ZETA, ZETA))
    coupled = ModalSystem((F1_HZ, f2), (ZETA, ZETA), couplings=(PotentialTerm(kappa, (2, 1)),))
    x0, _ = _steady(free, drive, base)
    x, z = _steady(coupled, drive, base)
    a = abs(x)
    d2 = _operator(f2, ZETA, 2 * drive)
    measured = _stiffness(x, base) - _stiffness(x0, base)
    rest = np.array([_operator(f2, ZETA, 0.0)])
    expected = kappa**2 * added_stiffness(COUPLING, np.array([a]), np.array([d2]), at_rest=rest)[0]
    assert abs(measured) > 0.02 * abs(_stiffness(x0, base))  # the effect is not negligible
    assert abs(measured - expected) < 0.05 * abs(expected), (measured, expected)
    harmonic = z * a / x**2  # (C₂ − iS₂)/a with the fundamental's phase taken out
    expected_harmonic = kappa * fed_harmonic(np.array([a]), np.array([d2]))[0]
    assert abs(harmonic - expected_harmonic) < 0.05 * abs(expected_harmonic)


def test_a_mode_on_the_joint_adds_what_the_column_says():
    """A cubic joint ``k₃ u³`` on ``u = q₁ + b q₂``, mode 2 at 1.05× mode 1 (b = 0.3): the
    first mode's dynamic stiffness beyond its own cubic (measured with b = 0 and scaled to
    the amplitude as ``a²``) is ``b² Δ`` with ``N = ¾ k₃ a²``, ``a N′ = 2N``, within 10 %."""
    f2, b, k3, drive = 1.05 * F1_HZ, 0.3, 3e10, F1_HZ
    base = 16.0
    cubic = (CubicStiffness(k3),)
    alone = ModalSystem((F1_HZ, f2), (ZETA, ZETA), joint_shape=(1.0, 0.0), joint_terms=cubic)
    shared = ModalSystem((F1_HZ, f2), (ZETA, ZETA), joint_shape=(1.0, b), joint_terms=cubic)
    x0, _ = _steady(alone, drive, base)
    x, _ = _steady(shared, drive, base)
    k0 = _operator(F1_HZ, ZETA, drive)
    own = (_stiffness(x0, base) - k0) * (abs(x) / abs(x0)) ** 2  # the cubic at |x|
    measured = _stiffness(x, base) - k0 - own
    n = np.array([0.75 * k3 * abs(x) ** 2])
    expected = (
        b**2
        * added_stiffness(
            JOINT, np.array([abs(x)]), np.array([_operator(f2, ZETA, drive)]), n, 2 * n
        )[0]
    )
    assert abs(measured) > 0.02 * abs(k0)
    assert abs(measured - expected) < 0.1 * abs(expected), (measured, expected)


def test_a_modes_routes_are_fitted_together_as_bounded_least_squares_does():
    """Each mode's gain, its two routes fitted together with the exchange's coefficient
    ≥ 0 (and the other's too where it is one-sided), equals ``|z|² − min |z − Aθ|²`` from
    scipy's bounded least squares, over random columns of both signs of correlation, a
    silent column and a collinear pair."""
    rng = np.random.default_rng(7)
    p, m = 12, 8
    columns = rng.standard_normal((p, m))
    columns[:, 5] = 0.0  # silent (a crossed mode)
    columns[:, 7] = -2.0 * columns[:, 6]  # collinear with its partner
    one_sided = np.array([True, False, True, False, True, False, True, True])
    routes = np.array([[0, 1], [2, 3], [4, 5], [6, 7], [0, 2]])
    for _ in range(20):
        z = rng.standard_normal(p) + columns[:, rng.integers(m)] * rng.normal(0, 3)
        gains, coefficients = route_gains(columns, z, routes, one_sided)
        for k, pair in enumerate(routes):
            low = np.where(one_sided[pair], 0.0, -np.inf)
            fit = lsq_linear(columns[:, pair], z, bounds=(low, np.inf), tol=1e-12)
            expected = z @ z - np.sum((z - columns[:, pair] @ fit.x) ** 2)
            assert gains[k] == pytest.approx(expected, abs=1e-8 * (1 + z @ z))
            mine = z @ z - np.sum((z - columns[:, pair] @ coefficients[k]) ** 2)
            assert mine == pytest.approx(gains[k], abs=1e-8 * (1 + z @ z))
            assert np.all(coefficients[k][one_sided[pair]] >= 0)


def test_the_refits_backbone_is_the_independent_simulators():
    """The two-mode refit's prediction (a second mode near 1:1 sharing a cubic joint with
    shape 0.3, driven by the base with Γ₂ = 0.8, coupled by ``κ q₁² q₂``): frequency, power-
    balance damping ratio and second harmonic of mode 1 at phase resonance against the
    independent simulator's own harmonic balance (MINPACK on its own residual, six
    harmonics), within what three harmonics leave (0.01 % in frequency, 1 % in damping, 5 %
    of the second harmonic)."""
    k3, b, gamma2, kappa, f2 = -9e9, 0.3, 0.8, 1.2e7, 1.07 * F1_HZ
    levels = np.geomspace(5e-5, 2e-3, 6)
    template = ModalModel(
        modes=(Mode(F1_HZ, ZETA, 1.0), Mode(F1_HZ, ZETA, 0.0)), joint_shapes=((1.0, 0.0),),
        elements=(JointElement("cubic_stiffness", k3),),
        couplings=(Coupling(1, (1, 1), 0.0), Coupling(2, (2, 0), 0.0)),
    )  # fmt: skip
    values = dict(zip(PARAMETERS, (f2, b, 2 * kappa, kappa, gamma2), strict=True))
    channels = ("frequency_hz", "damping_ratio", "harmonic2_cos", "harmonic2_sin")
    mine = backbone_channels(
        template, levels, channels, np.array([[values[n] for n in PARAMETERS]])
    )[0]
    system = ModalSystem((F1_HZ, f2), (ZETA, ZETA), joint_shape=(1.0, b),
                         joint_terms=(CubicStiffness(k3),),
                         couplings=(PotentialTerm(kappa, (2, 1)),))  # fmt: skip
    theirs = modal_phase_resonance(system, 1, levels, participation=(1.0, gamma2))
    assert theirs.converged.all()
    assert np.allclose(mine[:, 0], theirs.frequency_hz, rtol=1e-4, atol=0)
    assert np.allclose(mine[:, 1], theirs.damping_ratio, rtol=1e-2, atol=0)
    second = theirs.participation[:, 0, 1] / levels  # (C₂ − iS₂)/a
    expected = np.column_stack([second.real, -second.imag])
    assert np.max(np.abs(second)) > 1e-4  # the coupling feeds a second harmonic to compare
    assert np.all(np.abs(mine[:, 2:] - expected) <= 0.05 * np.abs(second)[:, None] + 1e-7)


def test_the_verdict_joins_the_one_list():
    assert Verdict.SECOND_MODE == "explained by a second mode"
    assert Verdict.SECOND_MODE in VERDICTS
    assert [str(v) for v in VERDICTS][:5] == [
        "nothing missing", "drift", "explained", "partly explained",
        "not explained by the catalogue",
    ]  # fmt: skip


@pytest.fixture(scope="module")
def lab_second_mode():
    """``lab-second-mode`` (tuning seed 1) criticised from its one-mode base model, and the
    truth's second-mode frequency (1.05 × the first mode's)."""
    measured, model, truth, _ = campaign("lab-second-mode", 1)
    return criticize(model, measured), truth


def test_lab_second_mode_screens_the_second_mode(lab_second_mode):
    """The linear screen's best column puts the mode within 5 % of the truth's frequency (a
    diagnostic, :attr:`SecondMode.screen_frequency_hz`), with a share between 0 and 1, and
    ``criticism.json`` carries the finding (frequency where located, interval, ratio, share,
    where, why not located or not named)."""
    crit, truth = lab_second_mode
    report = json.loads(crit.to_json())
    mode = report["second_mode"]
    assert abs(mode["screen_frequency_hz"] - truth) <= 0.05 * truth, mode
    if mode["located"]:
        assert mode["ratio"] == pytest.approx(mode["frequency_hz"] / mode["first_frequency_hz"])
        assert mode["interval_hz"][0] <= mode["frequency_hz"] <= mode["interval_hz"][1]
    else:
        assert mode["frequency_hz"] is None, mode  # NaN, written as null
        assert "frequency not located" in mode["text"]
    assert 0 < mode["share"] < 1 and mode["mechanism"] == JOINT
    assert any("damping" in w for w in mode["where"])
    assert mode["named"] or mode["why"]
    assert "second mode" in crit.summary()


def test_lab_second_mode_is_explained_by_a_second_mode(lab_second_mode):
    """The mode's routes fitted together (joint and sensor) beat the catalogue's best
    (microslip, refitted) by more than the separation, and its calibrated threshold: named;
    a frequency it states is within 5 % of the truth's."""
    crit, truth = lab_second_mode
    assert crit.verdict == Verdict.SECOND_MODE, crit.summary()
    assert crit.second_mode.gain > crit.second_mode.catalogue_gain + SEPARATION
    mode = crit.second_mode
    assert not mode.located or abs(mode.frequency_hz - truth) <= 0.05 * truth, mode


@pytest.mark.parametrize("case", ["independent near 1:1"])
def test_near_one_to_one_states_no_wrong_frequency(case):
    """Near 1:1 (the independent simulator's system, 1.07 × the first mode; one response
    point: no participation) the linearised columns once named a mode at twice the first
    mode's frequency or below it. Whatever the finding names, a frequency it states is
    within 5 % of the truth's (the simulator's own parameters), and its words state no
    other: where the refit does not locate it, "frequency not located" and no "mode near
    … Hz" in the mode's words (tuning seed 1). The two-mode rig near 1:1, with its 15
    points' participation: ``tests/test_criticism_participation.py``."""
    measured, model, truth, _ = campaign(case, 1)
    assert TWO_MODE_CASES[case][1] in (1.06, 1.07)
    crit = criticize(model, measured)
    mode = crit.second_mode
    words = " ".join((mode.text, *mode.where))
    if mode.located:
        assert abs(mode.frequency_hz - truth) <= 0.05 * truth, words
        low, high = mode.interval_hz
        assert low <= mode.frequency_hz <= high
    else:
        assert math.isnan(mode.frequency_hz) and "frequency not located" in mode.text
        assert re.search(r"mode near [\d.]+ Hz", words) is None, words


def test_a_hidden_catalogue_effect_names_no_second_mode():
    """One-mode data (cubic damping hidden from a linear-viscous base): something is missing
    and the catalogue names it; no second mode."""
    row = second_mode_campaign("lab-hidden-cubic-damping", 1)
    assert row.verdict not in (Verdict.SECOND_MODE, "nothing missing"), row
    assert row.passed


@pytest.mark.parametrize("seed", [1, 10])
def test_an_out_of_catalogue_joint_is_not_named_a_second_mode(seed):
    """One-mode data from the independent simulator (its 12-slider Iwan joint, tuning seeds
    1 and 10) with the loop's first addition (ẋ|ẋ|, 93 % of the gain left on held-out
    seeds): the rest took a joint-route column's gain beyond the catalogue's (at seed 10
    the two-mode refit placed it near 94 Hz), but a free-form stiffness and damping gains
    far more beyond the column than the reference test's threshold, so no second mode is
    named (block 3 000 000 of bench/criticism_loop.py had named one on 5 of 5 such
    campaigns). Beside it ``lab-second-mode`` (a mode the column takes all of the
    free-form gain of) stays named:
    :func:`test_lab_second_mode_is_explained_by_a_second_mode`."""
    joint = OUT_OF_CATALOGUE_JOINTS["iwan"]
    measured = phase_resonance_campaign(joint, 3, seed)
    omega0 = float(joint.omega0_rad_s)
    model = JointModel({LINEAR_STIFFNESS: omega0**2, VISCOUS_DAMPING: 0.006 * omega0,
                        "quadratic_damping": 7.0})  # fmt: skip
    crit = criticize(model, measured)
    mode = crit.second_mode
    assert crit.significant and not mode.located
    assert not mode.named and "not told from joint physics outside the catalogue" in mode.why
    assert crit.verdict != Verdict.SECOND_MODE


@pytest.mark.parametrize(
    ("case", "named", "mechanism", "located", "frequency_hz", "passed"),
    [
        ("independent near 1:1", True, SENSOR, True, 108.07 * 1.049, True),
        ("independent near 1:1", True, SENSOR, True, 108.07 * 1.051, False),
        ("independent near 1:1", True, JOINT, False, float("nan"), False),
        ("independent near 1:1", False, "", False, float("nan"), False),
        ("uncoupled near 1:1", False, "", False, float("nan"), True),
        ("uncoupled near 1:1", True, SENSOR, True, 108.07 * 0.96, True),
        ("uncoupled near 1:1", True, JOINT, True, 108.07, False),
        ("uncoupled near 1:1", True, SENSOR, True, 108.07 * 0.94, False),
        ("lab-pure", True, SENSOR, True, 100.0, False),
        ("lab-pure", False, "", False, float("nan"), True),
    ],
)
def test_the_studys_outcome_rule_is_the_one_written_down(
    case, named, mechanism, located, frequency_hz, passed
):
    """The rule of docs/criticism.md ("A missing mode"), fixed before block 15 000 000: a
    two-mode row passes named and located within 5 % of the truth; an uncoupled row (a mode
    the sensors see that exchanges nothing) passes unnamed or named as seen beside the first
    within 5 %, and fails named as exchanging energy; a one-mode row passes unnamed."""
    truth = float("nan") if case == "lab-pure" else 108.07
    assert passes(case, named, mechanism, located, frequency_hz, truth) is passed
