"""Modal coordinates of multi-point records: the modal filter and the shapes it uses.

A record with sensors ``s = 1..S`` whose responses ``y_s(t)`` (relative to the
base, in one quantity) are a sum of ``N ≤ S`` modes, ``y_s = Σ_m φ_sm η_m``, has
its modal coordinates ``η`` by least squares on the mode shapes at the sensors,
``η = Φ⁺ y`` (:class:`ModalFilter`). What the ``N`` modes do not explain is
reported per sensor: the RMS of ``y_s − Σ_m φ_sm η_m`` over the RMS of ``y_s``
(:meth:`ModalFilter.reconstruction_error`).

Shapes:

* **Complex shapes** (a modes file's ``a+bj`` entries) are made real by aligning
  their phase (the normal-mode approximation, :func:`real_shapes`): each shape is
  turned by the angle that makes its imaginary part smallest in the least-squares
  sense, ``θ = ½ arg Σ_s φ_s²``, and its real part kept, the largest entry
  positive. The error of the approximation is the part left out,
  ``‖Im(φ e^{−iθ})‖ / ‖φ‖`` (0 for a shape with one phase throughout).
* **Estimated shapes** (:func:`estimate_shapes`), for column files without a
  mode-shape file: the sensors' cross-spectral matrix (Welch averages of
  Hann-windowed segments) is decomposed at every frequency; its first singular
  value's peaks are the modes' narrow bands and the first singular vector at a
  peak the mode's shape (frequency-domain decomposition). Only peaks where one
  shape dominates (the first singular value :data:`DOMINANCE` times the second
  or more) and that stand out of their surroundings by as much (prominence)
  count, the most prominent first: over noise the singular values are alike,
  and a ripple on another mode's skirt does not stand out as a mode does. A peak whose shape is
  one already taken (MAC above :data:`SAME_SHAPE_MAC`: a harmonic, or the same
  mode at another hold's frequency) is passed over.

Each mode's amplitude is reported at its **reference sensor**, the sensor where
its shape is largest: the mode's coordinate times that shape entry, i.e. the
mode's own contribution to that sensor (independent of how the shapes are
scaled). Energy shares of the modes are those of these scaled coordinates
``x_m``: ``E_m = ⟨½ ẋ_m² + ½ ω_m² x_m²⟩`` with ``ω_m`` the mode's linear
frequency (:func:`identification.multimode.solve.energy_shares`); with
mass-normalised shapes and unit participation at the reference sensors they are
the modes' shares of the structure's vibration energy.

:func:`second_mode_warning` is the one wording of the warning that a one-mode
reading misses a mode carrying more than a stated share of the energy
(:data:`SECOND_MODE_SHARE`), for PLL holds and free decays alike.
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np
from numpy.typing import ArrayLike

from identification.measurements.series import frozen_array

__all__ = [
    "DOMINANCE",
    "SAME_SHAPE_MAC",
    "SECOND_MODE_SHARE",
    "ModalFilter",
    "RealShapes",
    "estimate_shapes",
    "mac",
    "real_shapes",
    "second_mode_warning",
]

#: Energy share of a mode left out of a one-mode reading above which it is warned of.
SECOND_MODE_SHARE = 0.05
#: Modal assurance criterion above which two estimated shapes are one mode's.
SAME_SHAPE_MAC = 0.9
#: Ratio of the first to the second singular value of the cross-spectral matrix at a peak
#: above which one shape dominates it: a mode's band, not noise.
DOMINANCE = 10.0
#: Condition number of the sensors' shape matrix beyond which the modes cannot be told apart.
_MAX_CONDITION = 1e6
#: Frequency resolution of the spectra the shapes are estimated from (Hz): fine enough to
#: part modes a few per cent apart at 100 Hz, coarse enough to average ~ 10 segments/s.
_RESOLUTION_HZ = 0.5


def second_mode_warning(
    where: str, frequency_hz: float, share: float, threshold: float = SECOND_MODE_SHARE
) -> str | None:
    """The one-line warning that a one-mode reading leaves out a mode, or None below ``threshold``.

    Parameters
    ----------
    where
        The record (file or name) the line is about.
    frequency_hz
        The other mode's frequency (Hz).
    share
        Its largest share of the energy over the record (a fraction).
    threshold
        Share above which it is said.
    """
    if not share > threshold:
        return None
    return (
        f"{where}: a second mode near {frequency_hz:.4g} Hz carries {100 * share:.3g} % of the "
        f"energy (more than {100 * threshold:g} %); one mode was read: read several with "
        "--modes 2"
    )


def mac(a: ArrayLike, b: ArrayLike) -> float:
    """Modal assurance criterion of two shapes: ``|aᴴb|² / (‖a‖² ‖b‖²)`` (1: the same shape)."""
    a, b = np.asarray(a), np.asarray(b)
    return float(abs(np.vdot(a, b)) ** 2 / (np.vdot(a, a).real * np.vdot(b, b).real))


@dataclass(frozen=True, eq=False)
class RealShapes:
    """Complex shapes made real by aligning their phase (see the module notes).

    Attributes
    ----------
    shapes
        ``(S, N)`` real shapes, the largest entry of each positive.
    rotation_deg
        ``(N,)`` angle each complex shape was turned by (deg).
    error
        ``(N,)`` part of each shape the approximation leaves out, ``‖Im‖ / ‖φ‖``.
    """

    shapes: np.ndarray
    rotation_deg: np.ndarray
    error: np.ndarray


def real_shapes(shapes: ArrayLike) -> RealShapes:
    """Real shapes of complex ones by phase alignment (the normal-mode approximation).

    ``shapes`` is ``(S, N)`` (one column per mode) or ``(S,)``; see the module notes.
    """
    phi = np.asarray(shapes, dtype=complex)
    if phi.ndim == 1:
        phi = phi[:, None]
    norms = np.linalg.norm(phi, axis=0)
    if phi.ndim != 2 or not np.isfinite(phi).all() or not (norms > 0).all():
        raise ValueError(f"mode shapes must be finite, non-zero (S, N) columns, got {phi.shape}")
    # The angle that makes Σ Im(φ e^{-iθ})² least: half the angle of Σ φ².
    theta = 0.5 * np.angle(np.sum(phi**2, axis=0))
    turned = phi * np.exp(-1j * theta)
    real = turned.real.copy()
    largest = real[np.argmax(np.abs(real), axis=0), np.arange(real.shape[1])]
    real *= np.where(largest < 0, -1.0, 1.0)
    theta = np.where(largest < 0, theta + np.pi, theta)
    return RealShapes(
        shapes=frozen_array(real),
        rotation_deg=frozen_array(np.degrees(np.angle(np.exp(1j * theta)))),
        error=frozen_array(np.linalg.norm(turned.imag, axis=0) / norms),
    )


@dataclass(frozen=True, eq=False)
class ModalFilter:
    """Least-squares modal filter of ``N`` modes on ``S ≥ N`` sensors (see the module notes).

    Attributes
    ----------
    shapes
        ``(S, N)`` real mode shapes at the sensors, modes in order of frequency.
    frequencies_hz
        ``(N,)`` linear frequencies, increasing.
    sensor_names
        One name per sensor.
    source
        Where the shapes come from (a file, or how they were estimated).
    alignment_error
        ``(N,)`` error of making complex shapes real (:func:`real_shapes`), 0 for real ones.

    Raises
    ------
    ValueError
        Fewer sensors than modes, shapes the sensors cannot tell apart (condition
        number above 1e6), frequencies not positive and increasing.
    """

    shapes: np.ndarray
    frequencies_hz: np.ndarray
    sensor_names: tuple[str, ...]
    source: str = ""
    alignment_error: np.ndarray | None = None

    def __post_init__(self) -> None:
        where = self.source or "mode shapes"
        shapes = np.asarray(self.shapes, dtype=float)
        if shapes.ndim == 1:
            shapes = shapes[:, None]
        freqs = np.asarray(self.frequencies_hz, dtype=float).reshape(-1)
        names = tuple(str(n) for n in self.sensor_names)
        n_sensors, n_modes = shapes.shape
        if freqs.size != n_modes or len(names) != n_sensors:
            raise ValueError(
                f"{where}: {n_modes} shape(s) at {n_sensors} sensor(s) need as many frequencies "
                f"and sensor names, got {freqs.size} and {len(names)}"
            )
        if n_sensors < n_modes:
            raise ValueError(
                f"{where}: {n_modes} modes cannot be told apart by {n_sensors} sensor(s); "
                "a modal filter needs at least one sensor per mode"
            )
        if not (np.isfinite(shapes).all() and np.isfinite(freqs).all() and (freqs > 0).all()):
            raise ValueError(f"{where}: shapes must be finite and frequencies > 0")
        if np.any(np.diff(freqs) <= 0):
            raise ValueError(f"{where}: modes must be in increasing frequency, got {freqs}")
        condition = np.linalg.cond(shapes)
        if not condition < _MAX_CONDITION:
            raise ValueError(
                f"{where}: the sensors cannot tell the {n_modes} modes apart (the shapes at the "
                f"sensors are nearly dependent, condition number {condition:.3g})"
            )
        error = np.zeros(n_modes) if self.alignment_error is None else self.alignment_error
        object.__setattr__(self, "shapes", frozen_array(shapes))
        object.__setattr__(self, "frequencies_hz", frozen_array(freqs))
        object.__setattr__(self, "sensor_names", names)
        object.__setattr__(self, "alignment_error", frozen_array(np.asarray(error, float)))

    @classmethod
    def from_complex(
        cls,
        shapes: ArrayLike,
        frequencies_hz: ArrayLike,
        sensor_names: Sequence[str],
        source: str = "",
        n_modes: int | None = None,
    ) -> ModalFilter:
        """The filter of (possibly complex) shapes: made real by :func:`real_shapes`, sorted
        by frequency, the first ``n_modes`` of them kept (default all)."""
        aligned = real_shapes(shapes)
        freqs = np.asarray(frequencies_hz, dtype=float).reshape(-1)
        order = np.argsort(freqs, kind="stable")[: n_modes or freqs.size]
        if n_modes is not None and order.size < n_modes:
            raise ValueError(
                f"{source or 'mode shapes'}: {n_modes} modes asked for, {order.size} given"
            )
        return cls(aligned.shapes[:, order], freqs[order], tuple(sensor_names), source,
                   aligned.error[order])  # fmt: skip

    @property
    def n_modes(self) -> int:
        return self.shapes.shape[1]

    @property
    def reference_sensor(self) -> np.ndarray:
        """``(N,)`` index of the sensor where each mode's shape is largest."""
        return np.argmax(np.abs(self.shapes), axis=0)

    @property
    def reference_shape(self) -> np.ndarray:
        """``(N,)`` each mode's shape at its reference sensor."""
        return self.shapes[self.reference_sensor, np.arange(self.n_modes)]

    def coordinates(self, responses: ArrayLike) -> np.ndarray:
        """``(n, N)`` modal coordinates of ``(n, S)`` sensor responses (least squares)."""
        y = self._check(responses)
        return np.linalg.lstsq(self.shapes, y.T, rcond=None)[0].T

    def scaled_coordinates(self, responses: ArrayLike) -> np.ndarray:
        """``(n, N)`` each mode's contribution at its reference sensor: η_m times its shape."""
        return self.coordinates(responses) * self.reference_shape

    def reconstruction_error(self, responses: ArrayLike) -> np.ndarray:
        """``(S,)`` RMS of what the modes leave unexplained at each sensor over its RMS."""
        y = self._check(responses)
        residual = y - self.coordinates(y) @ self.shapes.T
        rms = np.sqrt(np.mean(y**2, axis=0))
        with np.errstate(invalid="ignore", divide="ignore"):
            return np.where(rms > 0, np.sqrt(np.mean(residual**2, axis=0)) / rms, 0.0)

    def _check(self, responses: ArrayLike) -> np.ndarray:
        y = np.asarray(responses, dtype=float)
        if y.ndim != 2 or y.shape[1] != self.shapes.shape[0]:
            raise ValueError(
                f"responses must be (n_samples, {self.shapes.shape[0]}) (one column per "
                f"sensor), got {y.shape}"
            )
        return y


def estimate_shapes(
    time_s: ArrayLike,
    responses: ArrayLike,
    n_modes: int,
    sensor_names: Sequence[str],
    band_hz: tuple[float, float] | None = None,
) -> ModalFilter:
    """Shapes and frequencies of ``n_modes`` modes from the sensors' spectra (module notes).

    Parameters
    ----------
    time_s
        Uniform sample times (s).
    responses
        ``(n, S)`` sensor responses.
    n_modes
        Modes to find.
    sensor_names
        One name per sensor.
    band_hz
        Where the modes are looked for (Hz); default everything below 0.4 × the
        sampling rate.

    Raises
    ------
    ValueError
        Fewer than ``n_modes`` distinct modes in the spectra.
    """
    from scipy.signal import find_peaks, stft

    t = np.asarray(time_s, dtype=float)
    y = np.asarray(responses, dtype=float)
    fs = (t.size - 1) / (t[-1] - t[0])
    segment = int(2 ** np.ceil(np.log2(fs / _RESOLUTION_HZ)))
    segment = min(segment, int(2 ** np.floor(np.log2(y.shape[0]))))
    freqs, _, spectra = stft(y.T, fs=fs, window="hann", nperseg=segment, noverlap=segment // 2,
                             detrend="linear", boundary=None, padded=False)  # fmt: skip
    low, high = band_hz or (0.0, 0.4 * fs)
    inside = np.flatnonzero((freqs > max(low, 0.0)) & (freqs < high))
    # (S, F, T) → cross-spectral matrices (F, S, S), averaged over the segments
    z = spectra[:, inside, :].transpose(1, 0, 2)
    density = np.einsum("fst,fut->fsu", z, z.conj()) / z.shape[-1]
    vectors, values, _ = np.linalg.svd(density)
    first = values[:, 0]
    # A mode's band stands out of its surroundings; a ripple on another's skirt does not.
    peaks, found = find_peaks(np.log(first + first.max() * 1e-30), prominence=np.log(DOMINANCE))
    chosen: list[tuple[float, np.ndarray]] = []
    # Most prominent first: a strong mode's leakage skirt holds higher but flatter bumps than
    # a weak mode's own peak.
    for p in peaks[np.argsort(found["prominences"], kind="stable")[::-1]]:
        shape = vectors[p, :, 0]
        if values.shape[1] > 1 and first[p] < DOMINANCE * values[p, 1]:
            continue
        if any(mac(shape, other) > SAME_SHAPE_MAC for _, other in chosen):
            continue
        chosen.append((_peak_frequency(freqs[inside], np.log(first), p), shape))
        if len(chosen) == n_modes:
            break
    where = "spectra of the sensors"
    if len(chosen) < n_modes:
        raise ValueError(
            f"{where}: found {len(chosen)} distinct mode shape(s) of the {n_modes} asked for "
            "(a mode the record does not excite cannot be estimated); give them with "
            "--mode-shapes FILE"
        )
    chosen.sort(key=lambda pair: pair[0])
    return ModalFilter.from_complex(
        np.column_stack([s for _, s in chosen]), [f for f, _ in chosen], sensor_names,
        source="estimated from the records (first singular vectors of the sensors' "
        "narrow-band cross-spectra)",
    )  # fmt: skip


def _peak_frequency(freqs: np.ndarray, values: np.ndarray, p: int) -> float:
    """A spectral peak's frequency, refined by a parabola through it and its neighbours."""
    if not 0 < p < freqs.size - 1:
        return float(freqs[p])
    a, b, c = values[p - 1 : p + 2]
    curvature = a - 2 * b + c
    offset = 0.5 * (a - c) / curvature if curvature < 0 else 0.0
    return float(freqs[p] + offset * (freqs[1] - freqs[0]))
