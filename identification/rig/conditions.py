"""What a laboratory adds to a phase-resonance test: the lab rig's artefact settings.

Each class is one source of the imperfections real records carry (docs/science.md §6),
with its units, what it models and what a lab would see. The lab engine
(:mod:`identification.rig.lab`) puts them into the simulation; the settings and
what they imply (gains, predicted ripple, drift at a time) live here.

* :class:`Shaker` — the base motion is not the commanded sine. The coil drives an
  armature of its own: ``a_base = a_coil + μ·f₁(x, ẋ) − ω_c·v_base``, with
  ``a_coil = A (sin θ + Σₖ dₖ sin(kθ + ψₖ))`` (harmonic distortion dₖ of the
  acceleration, typically 2–5 % of 2nd and 3rd), ``μ`` the modal mass over the
  armature mass (shaker–structure interaction: the structure's restoring force
  ``f₁`` pushes the armature back, so the base acceleration drops at resonance
  and carries the structure's harmonics) and ``ω_c`` the centring of the
  suspension (keeps the base velocity free of drift; a lead of ``ω_c/ω`` rad).
  The base sensors measure all of it.
* :class:`Controller` — the phase-locked loop as a lab builds it: the response
  (and the reference) multiplied by ``sin θ`` and ``cos θ`` of the oscillator and
  low-passed (``detector_order`` first-order stages), the phase ``atan2(Q, I)``,
  and a PI controller on the phase error. The low pass lets part of the 2ω
  product through: the recorded frequency channel carries a ripple at 2ω of
  about ``|K_p + K_i/(2iω)|·|H(2iω)|/2π`` Hz (twice that when the phase is taken
  against the measured base, itself in quadrature with the response), and any
  2nd harmonic or offset adds a ripple at 1ω. Lock quality: ``loop_pole_hz``
  (tracking speed; with short holds the amplitude has not settled when the
  measurement starts) and ``phase_offset_deg`` (an uncompensated phase of the
  sensing chain: the loop locks that far from phase resonance).
* :class:`Drift` — slow changes over a campaign and within a run: the natural
  frequency (temperature; a few tenths of a per cent) and a sensor's gain (a few
  per cent). Up- and down-stepped levels show drift as hysteresis in time.
* :class:`Sensors` — per-channel white noise (m/s RMS), a decoder offset, and laser-vibrometer
  dropouts: at random times (``dropout_rate_hz`` per channel) a few samples are
  replaced by spikes uniform within ``±dropout_spike_m_s`` (speckle: the signal
  level drops and the demodulator outputs nonsense). The controller sees the
  measured centre channel, spikes included.
"""

from __future__ import annotations

import math
from collections.abc import Mapping
from dataclasses import dataclass, field, fields
from typing import Any

import numpy as np

__all__ = ["REFERENCES", "Controller", "Drift", "LoopGains", "Sensors", "Shaker"]

#: What the phase detector measures the response's phase against.
REFERENCES = ("base", "command")


def _finite(where: str, value: Any, low: float | None = None, strict: bool = False) -> float:
    value = float(value)
    if not math.isfinite(value) or (low is not None and (value <= low if strict else value < low)):
        bound = "" if low is None else f" and {'>' if strict else '≥'} {low}"
        raise ValueError(f"{where} must be finite{bound}, got {value}")
    return value


def _as_dict(obj: Any) -> dict[str, Any]:
    out = {}
    for f in fields(obj):
        value = getattr(obj, f.name)
        if isinstance(value, Mapping):
            value = {str(k): v for k, v in value.items()}
        elif isinstance(value, tuple):
            value = list(value)
        out[f.name] = value
    return out


@dataclass(frozen=True)
class Shaker:
    """The shaker: harmonic distortion, interaction with the structure, centring.

    Attributes
    ----------
    distortion
        ``{k: d_k}``: amplitude of harmonic ``k`` ≥ 2 of the coil acceleration relative
        to the fundamental (0.03 is 3 %).
    distortion_phase_deg
        ``{k: ψ_k}``: its phase against ``kθ`` (deg; default 0).
    interaction
        ``μ`` ≥ 0: modal mass of the structure over the armature's mass (1).
    centring_hz
        Corner of the suspension's centring of the base velocity (Hz, ≥ 0).
    """

    distortion: Mapping[int, float] = field(default_factory=dict)
    distortion_phase_deg: Mapping[int, float] = field(default_factory=dict)
    interaction: float = 0.0
    centring_hz: float = 1.0

    def __post_init__(self) -> None:
        distortion = {}
        for k, d in dict(self.distortion).items():
            if int(k) != float(k) or int(k) < 2:
                raise ValueError(f"Shaker.distortion: harmonic orders are integers ≥ 2, got {k!r}")
            distortion[int(k)] = _finite(f"Shaker.distortion[{k}]", d, 0.0)
        phases = {
            int(k): _finite("Shaker.distortion_phase_deg", v)
            for k, v in dict(self.distortion_phase_deg).items()
        }
        if set(phases) - set(distortion):
            raise ValueError(
                f"Shaker.distortion_phase_deg names harmonics without distortion: "
                f"{sorted(set(phases) - set(distortion))}"
            )
        object.__setattr__(self, "distortion", distortion)
        object.__setattr__(self, "distortion_phase_deg", phases)
        object.__setattr__(self, "interaction", _finite("Shaker.interaction", self.interaction, 0))
        object.__setattr__(self, "centring_hz", _finite("Shaker.centring_hz", self.centring_hz, 0))

    def harmonics_table(self) -> np.ndarray:
        """``(n, 3)`` rows ``(order, ratio, phase rad)`` for the engine."""
        rows = [
            (k, d, math.radians(self.distortion_phase_deg.get(k, 0.0)))
            for k, d in sorted(self.distortion.items())
        ]
        return np.array(rows, dtype=float).reshape(-1, 3)

    def coil_per_base(self, damping_ratio: float) -> float:
        """``|a_coil| / |a_base|`` of the fundamental at phase resonance.

        With ``a_base = a_coil + μ f₁`` and the response at phase resonance,
        ``a_coil = a_base ((1 + μ) − iμ/(2ζ))``: the interaction costs the
        shaker more drive where the structure is lightly damped.
        """
        mu = self.interaction
        return abs(complex(1 + mu, -mu / (2 * damping_ratio)))

    def to_dict(self) -> dict[str, Any]:
        return _as_dict(self)


@dataclass(frozen=True)
class LoopGains:
    """PI gains and detector filter of the lab PLL (rad/s units)."""

    kp: float
    ki: float
    detector_bandwidth: float
    stage_bandwidth: float


@dataclass(frozen=True)
class Controller:
    """A multiply-and-low-pass phase-locked loop with a PI controller.

    Attributes
    ----------
    detector_cutoff_hz
        Bandwidth of the detector's low pass (Hz): the DC group delay of its
        ``detector_order`` stages equals that of one first-order stage of this
        corner (each stage's corner is ``detector_order`` times higher). A wide
        first-order low pass is a fast but rippling detector.
    detector_order
        First-order stages of the low pass (≥ 1); 4 is a clean lock-in amplifier.
    loop_pole_hz
        Closed-loop tracking pole ``p/2π`` (Hz) of the designed gains: the
        linearised loop has a double pole at ``−p`` and a third at ``−(σ + ω_f − 2p)``.
    proportional_gain_hz_per_deg, integral_gain_hz_per_deg_s
        Hand-tuned PI gains instead (frequency step per degree of phase error, and
        its rate), as a test engineer sets them; both or neither. A hot
        proportional gain behind a narrow detector is how a lab loop tracks fast
        and ripples.
    reference
        ``"base"``: the phase against the measured base velocity (both demodulated
        alike); ``"command"``: against the oscillator's own sine.
    phase_offset_deg
        Uncompensated phase of the response chain (deg): the loop locks this far
        from phase resonance.
    initial_frequency_hz
        Oscillator start frequency; default the structure's small-amplitude frequency.
    frequency_limits
        Oscillator range as multiples of the start frequency.
    """

    detector_cutoff_hz: float = 10.0
    detector_order: int = 4
    loop_pole_hz: float = 2.0
    proportional_gain_hz_per_deg: float | None = None
    integral_gain_hz_per_deg_s: float | None = None
    reference: str = "base"
    phase_offset_deg: float = 0.0
    initial_frequency_hz: float | None = None
    frequency_limits: tuple[float, float] = (0.5, 2.0)

    def __post_init__(self) -> None:
        _finite("Controller.detector_cutoff_hz", self.detector_cutoff_hz, 0, strict=True)
        _finite("Controller.loop_pole_hz", self.loop_pole_hz, 0, strict=True)
        _finite("Controller.phase_offset_deg", self.phase_offset_deg)
        order = self.detector_order
        if not isinstance(order, int | np.integer) or isinstance(order, bool) or order < 1:
            raise ValueError(f"Controller.detector_order must be an integer ≥ 1, got {order!r}")
        if self.reference not in REFERENCES:
            raise ValueError(
                f"Controller.reference must be one of {REFERENCES}, got {self.reference!r}"
            )
        hand = (self.proportional_gain_hz_per_deg, self.integral_gain_hz_per_deg_s)
        if (hand[0] is None) != (hand[1] is None):
            raise ValueError("Controller: give both hand-tuned gains or neither")
        if hand[0] is not None:
            _finite("Controller.proportional_gain_hz_per_deg", hand[0], 0, strict=True)
            _finite("Controller.integral_gain_hz_per_deg_s", hand[1], 0, strict=True)
        if self.initial_frequency_hz is not None:
            _finite("Controller.initial_frequency_hz", self.initial_frequency_hz, 0, strict=True)
        low, high = self.frequency_limits
        if not (0 < low < 1 < high < math.inf):
            raise ValueError(
                f"Controller.frequency_limits must be (low, high) with 0 < low < 1 < high, "
                f"got {self.frequency_limits}"
            )
        object.__setattr__(self, "frequency_limits", (float(low), float(high)))

    def gains(self, natural_frequency_hz: float, damping_ratio: float) -> LoopGains:
        """PI gains for a mode of this frequency and damping ratio.

        Near resonance the response phase obeys ``δφ̇ = −σ δφ − δω`` (σ = ζω₀); with
        the detector ``ω_f/(s + ω_f)`` and ``δω = K_p e + K_i ∫e`` the loop's
        characteristic polynomial is ``s³ + (σ + ω_f)s² + ω_f(σ + K_p)s + ω_f K_i``.
        Matching ``(s + p)²(s + r)`` gives ``r = σ + ω_f − 2p``,
        ``K_p = (p² + 2pr)/ω_f − σ`` and ``K_i = p² r/ω_f``; ``ω_f`` is free, so the
        detector bandwidth (ripple) and the tracking speed are set apart.
        Hand-tuned gains are used as given (the loop's stability is then the
        tuner's business, as in a lab).
        """
        omega0 = 2 * math.pi * natural_frequency_hz
        sigma = damping_ratio * omega0
        omega_f = 2 * math.pi * self.detector_cutoff_hz
        stage = self.detector_order * omega_f
        if self.proportional_gain_hz_per_deg is not None:
            per_deg = 2 * math.pi * 180 / math.pi  # (rad/s per rad) per (Hz per deg)
            kp = self.proportional_gain_hz_per_deg * per_deg
            return LoopGains(kp, self.integral_gain_hz_per_deg_s * per_deg, omega_f, stage)
        p = 2 * math.pi * self.loop_pole_hz
        r = sigma + omega_f - 2 * p
        kp = (p * p + 2 * p * r) / omega_f - sigma
        ki = p * p * r / omega_f
        if not (r > 0 and kp > 0 and ki > 0):
            raise ValueError(
                f"Controller: a loop pole of {self.loop_pole_hz} Hz needs a wider detector than "
                f"{self.detector_cutoff_hz} Hz at damping ratio {damping_ratio:.3g} "
                "(detector_cutoff_hz > about twice loop_pole_hz)"
            )
        return LoopGains(kp, ki, omega_f, stage)

    def predicted_ripple_hz(
        self, frequency_hz: float, natural_frequency_hz: float, damping_ratio: float
    ) -> float:
        """Amplitude of the 2ω ripple of the frequency channel (Hz), first-order estimate.

        The products ``y sin θ``, ``y cos θ`` of a response ``Y sin(θ + φ)`` carry
        ``(Y/2) cos(2θ + φ)`` terms; through the low pass ``H`` they move the phase
        estimate by ``|H(2iω)| sin(2θ + 2φ + arg H)`` rad, and the PI controller turns
        that into ``|K_p + K_i/(2iω)|`` times as much frequency. Against the measured
        base, in quadrature with the response, the two phase estimates' ripples add.
        """
        gains = self.gains(natural_frequency_hz, damping_ratio)
        omega2 = 2 * 2 * math.pi * frequency_hz
        stage = gains.stage_bandwidth / complex(gains.stage_bandwidth, omega2)
        detector = abs(stage) ** self.detector_order
        controller = abs(complex(gains.kp, -gains.ki / omega2))
        both = 2.0 if self.reference == "base" else 1.0
        return both * controller * detector / (2 * math.pi)

    def to_dict(self) -> dict[str, Any]:
        return _as_dict(self)


@dataclass(frozen=True)
class Drift:
    """Slow drift of the natural frequency and of a sensor's gain.

    Values are relative changes (0.003 is +0.3 %): ``*_over_campaign`` from the
    start of the first record of a campaign to the start of its last (records in
    the order they are written: assembly by assembly, run by run), ``*_over_run``
    from the start to the end of each record. Both are linear in time.

    Attributes
    ----------
    frequency_over_campaign, frequency_over_run
        Natural-frequency drift of the first mode (temperature): its linear
        stiffness is scaled by ``(1 + δ)²``.
    gain_over_campaign, gain_over_run
        Gain drift of the sensors named by ``gain_channels``.
    gain_channels
        ``"panel"`` (the response vibrometer: all 15 panel points) or ``"base"``.
    """

    frequency_over_campaign: float = 0.0
    frequency_over_run: float = 0.0
    gain_over_campaign: float = 0.0
    gain_over_run: float = 0.0
    gain_channels: str = "panel"

    def __post_init__(self) -> None:
        for f in fields(self):
            if f.name != "gain_channels":
                value = _finite(f"Drift.{f.name}", getattr(self, f.name))
                if value <= -0.5:
                    raise ValueError(f"Drift.{f.name} must be > −0.5, got {value}")
        if self.gain_channels not in ("panel", "base"):
            raise ValueError(
                f"Drift.gain_channels must be 'panel' or 'base', got {self.gain_channels!r}"
            )

    def frequency(self, position: float) -> tuple[float, float]:
        """Relative frequency change at the start and end of a record at ``position`` (0…1)."""
        start = self.frequency_over_campaign * position
        return start, start + self.frequency_over_run

    def gain(self, position: float) -> tuple[float, float]:
        """Sensor gain (1 = nominal) at the start and end of a record at ``position`` (0…1)."""
        start = 1.0 + self.gain_over_campaign * position
        return start, start + self.gain_over_run

    @property
    def any(self) -> bool:
        return any(getattr(self, f.name) for f in fields(self) if f.name != "gain_channels")

    def to_dict(self) -> dict[str, Any]:
        return _as_dict(self)


@dataclass(frozen=True)
class Sensors:
    """Noise per channel and laser-vibrometer dropouts.

    Attributes
    ----------
    panel_noise_m_s
        White-noise RMS of the panel channels (m/s): one value or 15 (per point);
        None takes the rig's ``noise_m_s``.
    base_noise_m_s
        White-noise RMS of each base channel (m/s); None takes the rig's ``noise_m_s``.
    dropout_rate_hz
        Mean number of dropouts per second on each vibrometer channel.
    dropout_samples
        Mean length of a dropout (samples, ≥ 1; geometric).
    dropout_spike_m_s
        Dropout samples are uniform within ± this (m/s).
    dropouts_on_base
        Whether the base channels are vibrometers with dropouts too.
    panel_offset_m_s
        DC offset of the panel channels' velocity decoder (m/s): invisible to a
        backbone fit with a constant term, it leaves a 1ω ripple in the PLL's
        products and so on its frequency channel.
    """

    panel_noise_m_s: float | tuple[float, ...] | None = None
    base_noise_m_s: float | None = None
    dropout_rate_hz: float = 0.0
    dropout_samples: float = 2.0
    dropout_spike_m_s: float = 0.5
    dropouts_on_base: bool = False
    panel_offset_m_s: float = 0.0

    def __post_init__(self) -> None:
        if self.panel_noise_m_s is not None:
            noise = np.atleast_1d(np.asarray(self.panel_noise_m_s, dtype=float))
            if noise.size not in (1, 15) or not np.all(np.isfinite(noise) & (noise >= 0)):
                raise ValueError("Sensors.panel_noise_m_s must be one or 15 finite values ≥ 0")
            value = float(noise[0]) if noise.size == 1 else tuple(float(v) for v in noise)
            object.__setattr__(self, "panel_noise_m_s", value)
        if self.base_noise_m_s is not None:
            _finite("Sensors.base_noise_m_s", self.base_noise_m_s, 0)
        _finite("Sensors.dropout_rate_hz", self.dropout_rate_hz, 0)
        _finite("Sensors.dropout_samples", self.dropout_samples, 1)
        _finite("Sensors.dropout_spike_m_s", self.dropout_spike_m_s, 0)
        _finite("Sensors.panel_offset_m_s", self.panel_offset_m_s)

    def channel_noise(self, default_m_s: float) -> np.ndarray:
        """RMS noise of the 17 velocity channels (15 panel points, 2 base points), m/s."""
        panel = default_m_s if self.panel_noise_m_s is None else self.panel_noise_m_s
        base = default_m_s if self.base_noise_m_s is None else self.base_noise_m_s
        return np.concatenate([np.broadcast_to(panel, 15), [base, base]]).astype(float)

    def dropouts(
        self, rng: np.random.Generator, n_samples: int, fs: float
    ) -> list[tuple[int, int, int]]:
        """``(channel, first sample, length)`` of every dropout of one record (channels 0–16)."""
        channels = 17 if self.dropouts_on_base else 15
        if self.dropout_rate_hz == 0:
            return []
        out = []
        p = 1.0 / self.dropout_samples
        for channel in range(channels):
            count = rng.poisson(self.dropout_rate_hz * n_samples / fs)
            starts = np.sort(rng.integers(0, n_samples, count))
            lengths = rng.geometric(p, count)
            out += [
                (channel, int(s), int(min(n, n_samples - s)))
                for s, n in zip(starts, lengths, strict=True)
            ]
        return out

    def to_dict(self) -> dict[str, Any]:
        return _as_dict(self)
