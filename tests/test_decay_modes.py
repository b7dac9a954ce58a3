"""Backbones of several modes from free decays, against an independent two-mode ring-down.

The decays come from the independent simulator (:func:`independent.decays.modal_free_decay`:
scipy's DOP853 on modal equations of its own; nothing of pm-joint's kernels), read by one
sensor or by three through the mode shapes, with sensor noise, time stamps rounded to 7
significant digits. The truths are analytical:
the frequencies and damping ratios put in for linear modes; the first-order laws of a cubic
(``ω = ω₀ + 3k₃a²/(8ω₀)``) and of a quadratic (``ω = ω₀ − 5k₂²a²/(12ω₀³)``, 2nd harmonic
``k₂a/(6ω₀²)``) stiffness; and, for the ``κq₁²q₂`` coupling, the harmonic balance of mode 1
with mode 2 slaved, ``ω² = ω₁² − κ²a²(1/ω₂² + 1/(2(ω₂² − 4ω²)))``. Tolerances: the issue's
acceptance (0.05 % in frequency, 2 % in damping).
"""

import re

import numpy as np
import pandas as pd
import pytest
from independent_sim import free_decay
from two_modes import TwoModes, two_mode_decay

from identification.measurements.backbone import BackboneSet
from identification.measurements.columns import ColumnRecord
from identification.measurements.decay import extract_decay_backbone
from identification.measurements.decay_modes import (
    decay_backbones_by_mode,
    second_mode,
)
from identification.measurements.decay_sensor import Attribution
from pm_joint.cli import main

FREQUENCY_RTOL, DAMPING_RTOL = 5e-4, 0.02
SHAPES = np.array([[1.0, 0.5], [0.8, -0.9], [0.3, 1.0]])
#: Sensor noise (m): 10 nm, 1 % of the smallest amplitude a backbone point here needs.
NOISE_M = 1e-8
W1 = 2 * np.pi * 122.0
#: Quadratic stiffness of mode 1 whose 2nd harmonic is 2 % of a 1 mm fundamental.
K2 = 0.02 * 6 * W1**2 / 1e-3


def _noisy(decay, seed, key="displacement_m"):
    rng = np.random.default_rng(seed)
    return decay[key] + rng.normal(0.0, NOISE_M, decay[key].shape)


def _damped_hz(f_hz, zeta):
    return f_hz * np.sqrt(1 - zeta**2)


@pytest.fixture(scope="module")
def linear_pair():
    """Two linear modes near 1:2 (122 and 243 Hz), three sensors."""
    modes = TwoModes((122.0, 243.0), (0.004, 0.003))
    return modes, two_mode_decay(modes, (1e-3, 0.6e-3), SHAPES, duration_s=1.0)


@pytest.fixture(scope="module")
def harmonic_and_mode():
    """Mode 1 with a quadratic stiffness (a 2nd harmonic on mode 2's band), linear mode 2 near
    1:2, one sensor, 12 kHz so that rounded stamps jitter."""
    modes = TwoModes((122.0, 243.0), (0.004, 0.003), quadratic_mode1=K2)
    decay = two_mode_decay(modes, (1e-3, 0.6e-3), np.array([[1.0, 0.8]]), fs_hz=12_000.0,
                           duration_s=1.0)  # fmt: skip
    return modes, decay


def _check_linear(backbone, f_hz, zeta):
    np.testing.assert_allclose(backbone.frequency_hz, _damped_hz(f_hz, zeta), rtol=FREQUENCY_RTOL)
    np.testing.assert_allclose(backbone.damping_ratio, zeta, rtol=DAMPING_RTOL)


@pytest.mark.parametrize("sensors", ["three", "one"])
def test_uncoupled_linear_modes_give_what_was_put_in(linear_pair, sensors):
    modes, decay = linear_pair
    y = _noisy(decay, 0)
    shapes = SHAPES if sensors == "three" else None
    found = decay_backbones_by_mode(decay["time_s"], y if shapes is not None else y[:, 0],
                                    n_modes=2, quantity="displacement", shapes=shapes)  # fmt: skip
    assert found.n_modes == 2
    for backbone, f, zeta in zip(found.backbones, modes.frequency_hz, modes.damping_ratio,
                                 strict=True):  # fmt: skip
        assert len(backbone) >= 20
        _check_linear(backbone, f, zeta)
    if sensors == "three":
        assert found.method is Attribution.MODAL_FILTER
        assert found.reference_sensor == (0, 2)  # where each shape is largest
        # mode 1's amplitude at its reference sensor: the modal amplitude times 1.0
        assert found.backbones[0].amplitude_m[0] == pytest.approx(
            1e-3 * np.exp(-0.004 * W1 * found.backbones[0].time_s[0]), rel=1e-3
        )
        assert found.sensor_residual.max() < 1e-3
    else:
        # Mode 1 has no harmonic: the content near 2 × 122 Hz is mode 2's free decay.
        (lock,) = found.locks
        assert lock.rule is Attribution.FREE and lock.harmonic_share == 0
    # No exchange between uncoupled modes: each mode's energy decays at 2ζω.
    for backbone, energy, f, zeta in zip(found.backbones, found.energy, modes.frequency_hz,
                                         modes.damping_ratio, strict=True):  # fmt: skip
        slope = np.polyfit(backbone.time_s, np.log(energy), 1)[0]
        assert slope == pytest.approx(-2 * zeta * 2 * np.pi * f, rel=DAMPING_RTOL)


CUBIC_HZ = np.array([105.0, 260.0])
CUBIC_ZETA = np.array([0.004, 0.002])
#: 0.5 % hardening at 1 mm of modal amplitude
CUBIC_K3 = 0.005 * 8 * (2 * np.pi * CUBIC_HZ) ** 2 / 3 / 1e-6


@pytest.fixture(scope="module")
def cubic_pair():
    modes = TwoModes(tuple(CUBIC_HZ), tuple(CUBIC_ZETA), cubic=tuple(CUBIC_K3))
    return two_mode_decay(modes, (1e-3, 1e-3), SHAPES, duration_s=0.8)


@pytest.mark.parametrize("sensors", ["three", "one"])
def test_cubic_modes_follow_the_first_order_law(cubic_pair, sensors):
    w, zeta, k3 = 2 * np.pi * CUBIC_HZ, CUBIC_ZETA, CUBIC_K3
    y = _noisy(cubic_pair, 1)
    # one sensor: the second, where both shapes are large
    shapes, reading = (SHAPES, SHAPES) if sensors == "three" else (None, SHAPES[1:2])
    found = decay_backbones_by_mode(cubic_pair["time_s"], y if shapes is not None else y[:, 1],
                                    n_modes=2, quantity="displacement", shapes=shapes)  # fmt: skip
    for m, backbone in enumerate(found.backbones):
        a = backbone.amplitude_m / np.abs(reading[:, m]).max()  # the modal amplitude
        assert a.max() > 0.9e-3 and a.min() < 0.15e-3
        law = w[m] + 3 * k3[m] * a**2 / (8 * w[m])
        np.testing.assert_allclose(2 * np.pi * backbone.frequency_hz, law * np.sqrt(1 - zeta[m]**2),
                                   rtol=FREQUENCY_RTOL)  # fmt: skip
        # power balance: c⟨ẋ²⟩/(ω³a²) = ζω₀/ω (the 3rd harmonic's share is 1e-5 here)
        np.testing.assert_allclose(backbone.damping_ratio, zeta[m] * w[m] / law,
                                   rtol=DAMPING_RTOL)  # fmt: skip


#: Each quantity's key and the noise's scale (the displacement noise at mode 1).
QUANTITIES = {"displacement": ("displacement_m", 1.0), "velocity": ("velocity_m_s", W1),
              "acceleration": ("acceleration_m_s2", W1**2)}  # fmt: skip


@pytest.mark.parametrize("quantity", list(QUANTITIES))
def test_one_sensor_near_one_to_two_splits_harmonic_from_mode(harmonic_and_mode, quantity):
    _, decay = harmonic_and_mode
    key, scale = QUANTITIES[quantity]
    rng = np.random.default_rng(2)
    y = decay[key][:, 0] + rng.normal(0.0, NOISE_M * scale, decay["time_s"].size)
    found = decay_backbones_by_mode(decay["time_s"], y, n_modes=2, quantity=quantity)
    (lock,) = found.locks
    assert (lock.lock.lower, lock.lock.order, lock.lock.upper) == (0, 2, 1)
    assert lock.rule is Attribution.SPLIT
    first, second = found.backbones
    a = first.amplitude_m
    assert a.max() > 0.9e-3
    omega = W1 - 5 * K2**2 * a**2 / (12 * W1**3)
    np.testing.assert_allclose(2 * np.pi * first.frequency_hz, omega, rtol=FREQUENCY_RTOL)
    ratio = K2 * a / (6 * W1**2)
    large = ratio > 0.004
    np.testing.assert_allclose(np.abs(first.harmonics[large, 0]), ratio[large], rtol=0.05)
    np.testing.assert_allclose(first.damping_ratio, 0.004 * W1 / omega * (1 + 4 * ratio**2),
                               rtol=DAMPING_RTOL)  # fmt: skip
    _check_linear(second, 243.0, 0.003)


def test_a_harmonic_alone_is_no_second_mode():
    modes = TwoModes((122.0, 243.0), (0.004, 0.003), quadratic_mode1=2 * K2)
    decay = two_mode_decay(modes, (1e-3, 0.0), np.array([[1.0, 0.8]]), duration_s=0.8)
    y = _noisy(decay, 3)[:, 0]
    with pytest.raises(ValueError, match=r"no mode 2 found.*harmonic 2.*lower mode's harmonic"):
        decay_backbones_by_mode(decay["time_s"], y, n_modes=2, quantity="displacement")
    assert second_mode(decay["time_s"], y, quantity="displacement") is None


def test_coupled_one_to_two_modes_and_their_exchange():
    kappa = 2e6  # q₁²q₂ coupling: mode 2's slaved response is 5 % of it at 1 mm
    modes = TwoModes((122.0, 243.0), (0.004, 0.003), coupling=kappa)
    decay = two_mode_decay(modes, (1e-3, 0.3e-3), np.array([[1.0, 0.8]]), duration_s=1.0)
    t, y = decay["time_s"], _noisy(decay, 4)[:, 0]
    found = decay_backbones_by_mode(t, y, n_modes=2, quantity="displacement")
    first, second = found.backbones
    # Mode 2's equation is linear in q₂: its free part is the linear mode put in.
    _check_linear(second, 243.0, 0.003)
    w2 = 2 * np.pi * 243.0
    omega = np.full(len(first), W1)
    for _ in range(50):  # the fixed point of the two-harmonic balance
        omega = np.sqrt(W1**2 - kappa**2 * first.amplitude_m**2
                        * (1 / w2**2 + 1 / (2 * (w2**2 - 4 * omega**2))))  # fmt: skip
    np.testing.assert_allclose(2 * np.pi * first.frequency_hz, omega, rtol=FREQUENCY_RTOL)
    # What a one-mode reading does with it (the symptom): energy leaving for mode 2
    # reads as damping of mode 1, 20 % and more at the top.
    one = extract_decay_backbone(ColumnRecord(t, y, "displacement", "coupled", test="free-decay"))
    assert one.damping_ratio[0] > 1.2 * 0.004
    assert abs(first.damping_ratio[0] / 0.004 - 1) < 0.05
    line = second_mode(t, y, quantity="displacement")
    assert line is not None and line[0] == pytest.approx(243.0, abs=0.1)


def _csv(decay, folder, name):
    path = folder / f"{name}.csv"
    pd.DataFrame({"time": decay["time_s"], "displacement": _noisy(decay, 5)[:, 0]}).to_csv(
        path, index=False
    )
    return path


def _backbones(path, modes, out, capsys):
    options = ["--response", "displacement", "--quantity", "displacement"]
    code = main(["backbones", str(path), "--test", "free-decay", *options, "--modes", str(modes),
                 "--out", str(out)])  # fmt: skip
    captured = capsys.readouterr()
    assert code == 0, captured.err
    return captured


def test_the_command_line_reads_both_modes_and_warns_one_mode_readers(
    harmonic_and_mode, tmp_path, capsys
):
    _, decay = harmonic_and_mode
    assert np.ptp(np.diff(decay["time_s"])) > 0  # the rounded stamps jitter
    path = _csv(decay, tmp_path, "ring")
    captured = _backbones(path, 2, tmp_path / "two.csv", capsys)
    assert "attributed by its growth against mode 1's amplitude" in captured.out
    assert Attribution.SPLIT.value in captured.out
    table = pd.read_csv(tmp_path / "two.csv")
    assert sorted(table["mode"].unique()) == [1, 2]
    for m, f in ((1, 122.0), (2, 243.0)):
        rows = table[table["mode"] == m]
        assert len(rows) >= 20
        assert rows["frequency_hz"].iloc[-1] == pytest.approx(f, rel=FREQUENCY_RTOL)
        shares = rows[["mode1_energy_share", "mode2_energy_share"]].to_numpy()
        np.testing.assert_allclose(shares.sum(axis=1), 1.0)
    assert len(BackboneSet.from_csv(tmp_path / "two.csv")) == 2  # still a backbone table

    captured = _backbones(path, 1, tmp_path / "one.csv", capsys)
    warning = [line for line in captured.err.splitlines() if "second mode" in line]
    assert len(warning) == 1
    expected = (
        r"warning: the record \S+ring\.csv carries a second mode near 243\.0 Hz "
        r"\(\d+ % of the energy\); --modes 2 gives its backbone"
    )
    assert re.search(expected, warning[0])
    # the one-mode path is today's: the same table as the one-mode extraction
    record = ColumnRecord(decay["time_s"], pd.read_csv(path)["displacement"].to_numpy(),
                          "displacement", "ring", test="free-decay", path=path)  # fmt: skip
    expected = BackboneSet([extract_decay_backbone(record)]).to_table()
    written = pd.read_csv(tmp_path / "one.csv")
    np.testing.assert_array_equal(written["frequency_hz"], expected["frequency_hz"])


def test_a_one_mode_decay_gives_no_warning(tmp_path, capsys):
    omega = 2 * np.pi * 105.0

    def force(x, v):  # the asymmetric softening panel of test_decay: a 7 % 2nd harmonic
        return omega**2 * x + 2 * 0.004 * omega * v - 2.0e8 * x * x + 4.0e10 * x**3

    decay = free_decay(force, 1.2e-3, 0.0, duration_s=1.0)
    path = tmp_path / "panel.csv"
    values = decay["displacement_m"] + np.random.default_rng(6).normal(
        0, 1e-7, decay["time_s"].size
    )
    pd.DataFrame({"time": decay["time_s"], "displacement": values}).to_csv(path, index=False)
    captured = _backbones(path, 1, tmp_path / "one.csv", capsys)
    assert "second mode" not in captured.err


def test_complex_shapes_of_one_phase_are_normal_modes(linear_pair):
    modes, decay = linear_pair
    y = _noisy(decay, 0)
    turned = SHAPES * np.exp(1j * np.array([0.3, -1.1]))  # each mode's shape at one phase
    found = decay_backbones_by_mode(decay["time_s"], y, n_modes=2, quantity="displacement",
                                    shapes=turned)  # fmt: skip
    np.testing.assert_allclose(found.normal_mode_error, 0.0, atol=1e-12)
    for backbone, f, zeta in zip(found.backbones, modes.frequency_hz, modes.damping_ratio,
                                 strict=True):  # fmt: skip
        _check_linear(backbone, f, zeta)
    # a shape whose points are out of phase is no normal mode: its error is reported
    skewed = SHAPES.astype(complex)
    skewed[2, 1] *= np.exp(0.2j)
    found = decay_backbones_by_mode(decay["time_s"], y, n_modes=2, quantity="displacement",
                                    shapes=skewed)  # fmt: skip
    assert found.normal_mode_error[0] < 1e-12 < found.normal_mode_error[1]
