import numpy as np
import pytest
from scipy import signal

from identification.measurements.signals import (
    amplitude_envelope,
    bandpass,
    central_difference,
    displacement_from_velocity,
    harmonic_band_hz,
    kinematics,
    lowpass,
    scale_by_maximum,
    trapezoid_integral,
    unscale_coefficients,
)

FS = 10_000.0


def zero_phase_gain(band, frequencies_hz, order=8):
    """|H|² of the Butterworth band-pass: the gain of sosfiltfilt, from scipy's own response."""
    sos = signal.butter(order, band, btype="bandpass", fs=FS, output="sos")
    _, h = signal.sosfreqz(sos, worN=np.asarray(frequencies_hz, float), fs=FS)
    return np.abs(h) ** 2


@pytest.mark.parametrize("tracked_hz", [(95.0, 105.0), (100.0, 100.0), (60.0, 110.0)])
@pytest.mark.parametrize("tolerance", [1e-3, 1e-2])
def test_band_loses_exactly_tolerance_at_the_protected_harmonics(tracked_hz, tolerance):
    f_min, f_max = tracked_hz
    band = harmonic_band_hz(np.linspace(f_min, f_max, 50), FS, tolerance=tolerance)
    loss = 1 - zero_phase_gain(band, [f_min, 3 * f_max])
    np.testing.assert_allclose(loss, tolerance, rtol=1e-3)
    # In between (fundamentals, 2nd and 3rd harmonics of the tracked range) it loses less.
    inside = np.concatenate([np.linspace(f_min, f_max, 5), 2 * np.linspace(f_min, f_max, 5),
                             3 * np.linspace(f_min, f_max, 5)])  # fmt: skip
    assert np.all(1 - zero_phase_gain(band, inside) <= tolerance * (1 + 1e-3))
    # Far outside it rejects: slow drift and the 8th harmonic.
    assert np.all(zero_phase_gain(band, [0.2 * f_min, 8 * f_max]) < 1e-3)


def test_band_must_stay_below_nyquist():
    with pytest.raises(ValueError, match="Nyquist"):
        harmonic_band_hz([900.0, 1000.0], 5_000.0)
    with pytest.raises(ValueError, match="too close to the Nyquist"):
        harmonic_band_hz([1550.0, 1650.0], 10_000.0)


def test_band_rejects_bad_frequency_channel():
    with pytest.raises(ValueError, match="frequency_hz"):
        harmonic_band_hz([100.0, 0.0], FS)
    with pytest.raises(ValueError, match="frequency_hz"):
        harmonic_band_hz([100.0, np.nan], FS)
    with pytest.raises(ValueError, match="n_harmonics"):
        harmonic_band_hz([100.0], FS, n_harmonics=0)


def test_bandpass_keeps_three_harmonics_and_removes_drift_and_high_harmonics():
    t = np.arange(0, 2.0, 1 / FS)
    f = 100.0
    harmonics = sum(np.cos(2 * np.pi * h * f * t + h) / h for h in (1, 2, 3))
    polluted = harmonics + 0.5 + 3.0 * t + 0.3 * np.sin(2 * np.pi * 7 * f * t)
    band = harmonic_band_hz([f], FS)
    out = bandpass(polluted, FS, band)
    middle = slice(2000, -2000)
    np.testing.assert_allclose(out[middle], harmonics[middle], atol=2e-3)


def test_bandpass_rejects_bad_band():
    with pytest.raises(ValueError, match="band_hz"):
        bandpass(np.zeros(100), FS, (500.0, 100.0))


def test_lowpass_keeps_slow_part_only():
    t = np.arange(0, 2.0, 1 / FS)
    slow = 1e-5 * np.sin(2 * np.pi * 2 * t)
    out = lowpass(slow + 1e-3 * np.cos(2 * np.pi * 100 * t), FS, 20.0)
    # The local mean of an oscillation is ill-defined near the ends: compare inside.
    np.testing.assert_allclose(out[5000:-5000], slow[5000:-5000], atol=1e-7)


def test_amplitude_envelope_follows_a_stepped_level():
    # 100 Hz at 0.1 mm, then a 0.1 s raised-cosine ramp to 0.5 mm: the envelope is the
    # amplitude away from the ramp (a hold phase of a resonance test), monotone across it.
    t = np.arange(0, 2.0, 1 / FS)
    ramp = np.clip((t - 1.0) / 0.1, 0.0, 1.0)
    amplitude = 1e-4 + 4e-4 * 0.5 * (1 - np.cos(np.pi * ramp))
    envelope = amplitude_envelope(amplitude * np.cos(2 * np.pi * 100 * t + 0.4), FS, 20.0)
    hold = (np.abs(t - 0.5) < 0.3) | (np.abs(t - 1.6) < 0.2)
    np.testing.assert_allclose(envelope[hold], amplitude[hold], rtol=2e-3)
    inside = (t > 1.0) & (t < 1.1)
    assert np.all(np.diff(envelope[inside]) > 0)


def test_central_difference_has_the_textbook_error():
    # Central differences see sin(ωΔt)/(ωΔt) of the true derivative of a sinusoid.
    t = np.arange(0, 0.1, 1 / FS)
    omega = 2 * np.pi * 300.0
    derivative = central_difference(np.sin(omega * t), FS)
    gain = np.sin(omega / FS) / (omega / FS)
    np.testing.assert_allclose(derivative[1:-1], gain * omega * np.cos(omega * t[1:-1]),
                               atol=1e-9 * omega)  # fmt: skip


def test_trapezoid_integral_has_the_textbook_error():
    # The trapezoidal rule integrates cos ωt with gain (ωΔt/2)/tan(ωΔt/2).
    t = np.arange(0, 0.1, 1 / FS)
    omega = 2 * np.pi * 300.0
    integral = trapezoid_integral(np.cos(omega * t), FS)
    half = omega / FS / 2
    np.testing.assert_allclose(integral, (half / np.tan(half)) * np.sin(omega * t) / omega,
                               atol=1e-12)  # fmt: skip


def test_displacement_from_velocity_has_no_drift():
    rng = np.random.default_rng(0)
    t = np.arange(0, 4.0, 1 / FS)
    omega = 2 * np.pi * 100.0
    x = 1e-3 * np.sin(omega * t)
    # A sensor offset and white noise: integrated, both would drift.
    velocity = np.gradient(x, t) + 2e-3 + 1e-4 * rng.standard_normal(t.size)
    band = harmonic_band_hz([100.0], FS)
    displacement = displacement_from_velocity(velocity, FS, band)
    middle = slice(3000, -3000)
    error = displacement[middle] - x[middle]
    assert np.max(np.abs(error)) < 1e-5  # 1 % of the amplitude, everywhere, to the very end
    assert abs(np.mean(error[-5000:])) < 1e-6


def test_scaling_and_unscaling_give_the_raw_regression():
    rng = np.random.default_rng(1)
    theta = rng.standard_normal((500, 3)) * np.array([1e-3, 1.0, 1e4])
    y = theta @ np.array([2e5, -3.0, 1e-4]) + 1e-3 * rng.standard_normal(500)
    raw = np.linalg.lstsq(theta, y, rcond=None)[0]
    theta_s, feature_scale = scale_by_maximum(theta)
    y_s, target_scale = scale_by_maximum(y)
    assert np.max(np.abs(theta_s)) == pytest.approx(1.0)
    scaled = np.linalg.lstsq(theta_s, y_s, rcond=None)[0]
    np.testing.assert_allclose(unscale_coefficients(scaled, feature_scale, target_scale), raw,
                               rtol=1e-10)  # fmt: skip


def test_scaling_a_zero_column_is_an_error():
    with pytest.raises(ValueError, match=r"column\(s\) \[1\]"):
        scale_by_maximum(np.array([[1.0, 0.0], [2.0, 0.0]]))


def test_kinematics_of_a_two_harmonic_response():
    t = np.arange(0, 3.0, 1 / FS)
    omega = 2 * np.pi * 100.0
    x = 1e-3 * np.cos(omega * t) + 5e-5 * np.sin(3 * omega * t)
    v = -1e-3 * omega * np.sin(omega * t) + 1.5e-4 * omega * np.cos(3 * omega * t)
    # What central differences make of the true acceleration, harmonic by harmonic.
    gain = [np.sin(h * omega / FS) / (h * omega / FS) for h in (1, 3)]
    a = -1e-3 * omega**2 * gain[0] * np.cos(omega * t) - 4.5e-4 * omega**2 * gain[1] * np.sin(
        3 * omega * t
    )
    base_v = 0.01 * np.sin(omega * t)
    kin = kinematics(t, v, base_v, np.full(t.size, 100.0), FS)
    valid = kin.valid
    # The band-pass loses at most 0.1 % at the kept harmonics; the trapezoidal rule is good
    # to (ωΔt)²/12 ≈ 0.03 % at the fundamental.
    np.testing.assert_allclose(kin.displacement[valid], x[valid], atol=1.5e-3 * 1e-3)
    np.testing.assert_allclose(kin.velocity[valid], v[valid], atol=1e-3 * np.max(np.abs(v)))
    np.testing.assert_allclose(kin.acceleration[valid], a[valid], atol=1e-3 * np.max(np.abs(a)))
    base_a = 0.01 * omega * gain[0] * np.cos(omega * t)
    np.testing.assert_allclose(
        kin.base_acceleration[valid], base_a[valid], atol=1e-3 * 0.01 * omega
    )
    assert valid.start == pytest.approx(20 * FS / kin.band_hz[0], abs=1)


def test_kinematics_rejects_bad_records():
    t = np.arange(0, 3.0, 1 / FS)
    ok = np.sin(2 * np.pi * 100 * t)
    f = np.full(t.size, 100.0)
    with pytest.raises(ValueError, match="too short"):
        kinematics(t[:500], ok[:500], ok[:500], f[:500], FS)
    bad = ok.copy()
    bad[10] = np.nan
    with pytest.raises(ValueError, match="base_velocity contains NaN"):
        kinematics(t, ok, bad, f, FS)
    with pytest.raises(ValueError, match="response_velocity has shape"):
        kinematics(t, ok[:-1], ok, f, FS)
