"""Phase-locked-loop (PLL) phase-resonance simulator.

A time-domain virtual phase-resonance test of a base-excited
:class:`~identification.model.JointModel`, ``ẍ + f(x, ẋ) = −a_base(t)``, as the
TRC rig and NLtest run it: an oscillator drives the shaker, a phase detector
measures the response's fundamental harmonic, a PI controller moves the
frequency until the response sits at phase resonance, and the excitation level
is stepped with smooth ramps; each hold phase gives one backbone point.

Conventions
-----------
Excitation
    ``a_base(t) = A(t) · sin θ(t)`` with ``θ̇ = ω(t)``, the PLL's frequency. The
    effective force on the relative coordinate is ``−a_base``.
Phase
    Phases are those of fundamental harmonics. Relative to the effective force
    ``−a_base``, phase resonance means the relative displacement lags by 90°,
    the relative velocity is in phase and the relative acceleration leads by
    90°. The real rig uses the **base velocity** as reference; it leads the
    force by 90°, so against it the relative displacement is at −180°, the
    relative velocity at −90° and the relative acceleration at 0°
    (:func:`target_phase_deg`). The choice of reference only changes the
    reported phases, not the point the loop locks on.
Phase detector
    The adaptive-filter Fourier estimator of Hippold et al. (2024): the sensed
    response is fitted online by ``c₀ + Σₖ aₖ sin kθ + bₖ cos kθ`` (k ≤
    ``harmonics``) with the LMS law ``ȧₖ = μ e sin kθ``, ``ḃₖ = μ e cos kθ``,
    ``e`` the fit residual. Averaged over a period this is a first-order low
    pass of bandwidth ``μ/2`` in the frame rotating with θ, with no phase delay
    at steady state, and because the harmonics are fitted too the fundamental's
    estimate carries no ripple from them (unlike multiply-and-low-pass
    demodulation). The excitation needs no detector: the oscillator synthesises
    it, so its phase is θ.
Controller
    ``ω = ω_I + K_p e_φ``, ``ω̇_I = K_i e_φ`` with ``e_φ`` the wrapped phase
    error (measured − target), clamped to ``frequency_limits`` with
    anti-windup. Near a resonance of modal bandwidth ``σ = ζω₀`` the phase of
    the response obeys ``δφ̇ = −σ δφ − δω`` (the slowly varying amplitude of a
    lightly damped mode, ``dφ/dω = −1/σ`` at steady state); with the detector's
    low pass ``ω_f`` the loop is third order, and :func:`design_gains` places
    its three poles at ``−p``: ``ω_f = 3p − σ``, ``K_p = 3p²/ω_f − σ``,
    ``K_i = p³/ω_f``, with ``p`` a multiple of ``σ`` (kept between ω₀/100 and
    ω₀/30 so that the averaged picture holds).
Level schedule
    Levels (base-acceleration amplitudes, m/s²) are approached by raised-cosine
    ramps of ``ramp_s`` (the first from rest, at the initial frequency with the
    controller off). A hold follows: at every completed oscillator period a lock
    detector checks that the phase error is within ``lock_tolerance_deg`` and
    that the response amplitude has settled: it approaches its steady state
    like ``exp(−ζωt)``, so a relative change ``δ`` per period means it is still
    ``δ / (2πζ)`` away, which must be below ``settling_tolerance`` (ζ estimated
    on line from the power balance); after ``lock_periods`` such periods
    in a row the last ``n_periods`` periods are measured (a lost lock restarts
    the settling). A hold that has not finished after ``max_hold_s`` is marked
    unlocked.
Backbone point
    Over exactly ``n_periods`` oscillator periods: fundamental harmonic ``Q`` of
    the relative displacement (amplitude, m), mean frequency, damping ratio
    from the power balance ``D = |Q_b| / (2|Q|)`` with ``Q_b = B/ω²`` the
    base-displacement fundamental (``B`` that of ``a_base``), and the phase
    error of the sensed response against the target.

Time integration is classical RK4 at the sampling step ``1/fs``, in numba.
Smoothed friction (slope ``F/v_reg``) and a stiff Jenkins spring make the
equation stiff, so the step is split into enough sub-steps to keep every
linearised eigenvalue inside RK4's stability region. The Jenkins element is
evaluated at each RK stage from the anchor state of the step start and the
anchor moves to the accepted state after the step.

A run that diverges (non-finite state or ``|x| > max_displacement_m``) marks
the current and all later levels unlocked, with NaN numbers; so does a model
with no positive linear stiffness when no initial frequency is given.
"""

from __future__ import annotations

import math
import numbers
from collections.abc import Sequence
from dataclasses import dataclass, field, fields
from typing import Any

import numba
import numpy as np
from numpy.typing import ArrayLike
from tqdm.auto import tqdm

from identification.analytical.harmonic import CoefficientTable, coefficient_table
from identification.checks import positive_vector
from identification.effects import CATALOGUE, jenkins_force, memoryless_force
from identification.model import JointModel

__all__ = [
    "PLLConfig",
    "PLLGains",
    "PLLResult",
    "PLLTimeSeries",
    "design_gains",
    "pll_backbones",
    "simulate_base_excitation",
    "simulate_pll",
    "stable_substeps",
    "target_phase_deg",
]

SENSING = ("displacement", "velocity", "acceleration")
REFERENCES = ("force", "base_velocity")

#: Phase of each response at phase resonance relative to the effective force −a_base (deg).
_RESONANT_PHASE_VS_FORCE_DEG = {"displacement": -90.0, "velocity": 0.0, "acceleration": 90.0}
#: Phase of each reference signal relative to the effective force −a_base (deg).
_REFERENCE_VS_FORCE_DEG = {"force": 0.0, "base_velocity": 90.0}
#: −a_base leads a_base = A sin θ (the detector's zero) by 180°.
_FORCE_VS_EXCITATION_DEG = 180.0

#: RK4 is stable for h·|λ| up to about 2.8 along both axes; keep a margin for nonlinearity.
_RK4_STABLE_STEP = 2.0
#: Closed-loop pole p of the PLL is kept within [ω₀/100, ω₀/30].
_POLE_LIMITS = (1.0 / 100.0, 1.0 / 30.0)
#: Default cap on RK4 sub-steps per sample.
_MAX_SUBSTEPS = 1000
#: Fewest samples per period at the highest frequency the oscillator may reach.
_MIN_SAMPLES_PER_PERIOD = 10


def target_phase_deg(sensing: str, reference: str = "force") -> float:
    """Phase of the sensed response at phase resonance relative to ``reference`` (deg).

    >>> target_phase_deg("displacement"), target_phase_deg("velocity", "base_velocity")
    (-90.0, -90.0)
    """
    if sensing not in SENSING:
        raise ValueError(f"sensing must be one of {SENSING}, got {sensing!r}")
    if reference not in REFERENCES:
        raise ValueError(f"reference must be one of {REFERENCES}, got {reference!r}")
    return _RESONANT_PHASE_VS_FORCE_DEG[sensing] - _REFERENCE_VS_FORCE_DEG[reference]


@dataclass(frozen=True)
class PLLGains:
    """PI gains and phase-detector bandwidth of the PLL.

    Attributes
    ----------
    kp
        Proportional gain (rad/s of frequency per rad of phase error, 1/s).
    ki
        Integral gain (1/s²).
    detector_bandwidth
        Bandwidth ``ω_f`` of the adaptive Fourier detector (rad/s); LMS step ``μ = 2ω_f``.
    """

    kp: float
    ki: float
    detector_bandwidth: float

    def __post_init__(self) -> None:
        for f in fields(self):
            value = getattr(self, f.name)
            _check_positive(f"PLLGains.{f.name}", value)


def design_gains(
    natural_frequency_hz: float, damping_ratio: float, bandwidth_ratio: float = 6.0
) -> PLLGains:
    """Closed-form PLL gains: the linearised loop's three poles at ``−p``.

    Parameters
    ----------
    natural_frequency_hz
        Resonance frequency ``ω₀/2π`` the loop will track.
    damping_ratio
        Linear modal damping ratio ζ (``σ = ζω₀``, may be ≤ 0).
    bandwidth_ratio
        ``p = bandwidth_ratio · σ``, kept within ``[ω₀/100, ω₀/30]``.
    """
    if not (math.isfinite(natural_frequency_hz) and natural_frequency_hz > 0):
        raise ValueError(f"natural_frequency_hz must be finite and > 0, got {natural_frequency_hz}")
    if not math.isfinite(damping_ratio):
        raise ValueError(f"damping_ratio must be finite, got {damping_ratio}")
    if not (math.isfinite(bandwidth_ratio) and bandwidth_ratio > 0):
        raise ValueError(f"bandwidth_ratio must be finite and > 0, got {bandwidth_ratio}")
    kp, ki, bandwidth = _pole_placement(
        2.0 * math.pi * natural_frequency_hz, damping_ratio, bandwidth_ratio
    )
    return PLLGains(float(kp), float(ki), float(bandwidth))


def _pole_placement(omega0, damping_ratio, bandwidth_ratio):
    """Vectorised core of :func:`design_gains` (rad/s inputs)."""
    sigma = damping_ratio * omega0
    p = np.clip(bandwidth_ratio * sigma, _POLE_LIMITS[0] * omega0, _POLE_LIMITS[1] * omega0)
    bandwidth = 3.0 * p - sigma
    return 3.0 * p**2 / bandwidth - sigma, p**3 / bandwidth, bandwidth


@dataclass(frozen=True)
class PLLConfig:
    """Settings of a virtual phase-resonance test.

    Attributes
    ----------
    fs
        Sampling (and controller) rate (Hz); the integrator step is ``1/fs``.
    sensing
        Response the detector sees: ``"displacement"``, ``"velocity"`` or
        ``"acceleration"`` (relative to the base).
    reference
        Signal the reported response phase is measured against: ``"force"``
        (−a_base) or ``"base_velocity"`` (as on the TRC rig).
    n_periods
        Periods measured at the end of each hold (NLtest uses 70 on test records).
    lock_tolerance_deg
        Largest phase error of a locked period.
    settling_tolerance
        Largest relative distance of the response amplitude from its steady
        state in a locked period, estimated as (relative change per period) /
        (2π·damping ratio); the damping ratio is biased by about as much.
    lock_periods
        Consecutive locked periods before the measurement starts.
    max_hold_s
        Longest hold (settling plus measurement) before a level is given up as
        unlocked; it must cover a few amplitude time constants ``1/(ζω)``
        (about 0.3 s for ζ = 0.5 % at 100 Hz).
    ramp_s
        Duration of the raised-cosine ramp between levels.
    initial_frequency_hz
        Oscillator start frequency; default the model's linear frequency.
    gains
        PI gains and detector bandwidth; default :func:`design_gains` from the
        model's linear frequency and viscous damping.
    bandwidth_ratio
        Closed-loop pole over modal bandwidth for the default gains.
    harmonics
        Harmonics fitted by the adaptive Fourier detector (≥ 1).
    frequency_limits
        Oscillator frequency range as multiples of the initial frequency.
    max_displacement_m
        ``|x|`` beyond this counts as divergence.
    max_substeps
        Most RK4 sub-steps per sample the stability check may ask for; a model
        needing more raises ValueError (raise ``v_reg`` or ``fs``).
    """

    fs: float = 10_000.0
    sensing: str = "displacement"
    reference: str = "force"
    n_periods: int = 20
    lock_tolerance_deg: float = 1.0
    settling_tolerance: float = 0.005
    lock_periods: int = 10
    max_hold_s: float = 10.0
    ramp_s: float = 0.1
    initial_frequency_hz: float | None = None
    gains: PLLGains | None = None
    bandwidth_ratio: float = 6.0
    harmonics: int = 3
    frequency_limits: tuple[float, float] = (0.5, 2.0)
    max_displacement_m: float = 0.05
    max_substeps: int = _MAX_SUBSTEPS

    def __post_init__(self) -> None:
        target_phase_deg(self.sensing, self.reference)  # validates both names
        for name in ("n_periods", "lock_periods", "harmonics", "max_substeps"):
            value = getattr(self, name)
            if not isinstance(value, int | np.integer) or isinstance(value, bool) or value < 1:
                raise ValueError(f"PLLConfig.{name} must be an integer ≥ 1, got {value!r}")
        positive = ("fs", "lock_tolerance_deg", "settling_tolerance", "max_hold_s")
        for name in (*positive, "bandwidth_ratio", "max_displacement_m"):
            _check_positive(f"PLLConfig.{name}", getattr(self, name))
        if not (math.isfinite(self.ramp_s) and self.ramp_s >= 0):
            raise ValueError(f"PLLConfig.ramp_s must be finite and ≥ 0, got {self.ramp_s!r}")
        if self.lock_tolerance_deg >= 90:
            raise ValueError(
                f"PLLConfig.lock_tolerance_deg must be < 90, got {self.lock_tolerance_deg}"
            )
        if self.initial_frequency_hz is not None:
            _check_positive("PLLConfig.initial_frequency_hz", self.initial_frequency_hz)
        if self.gains is not None and not isinstance(self.gains, PLLGains):
            raise ValueError(f"PLLConfig.gains must be a PLLGains or None, got {self.gains!r}")
        limits = self.frequency_limits
        if not (
            isinstance(limits, tuple | list)
            and len(limits) == 2
            and all(isinstance(v, numbers.Real) for v in limits)
            and 0 < limits[0] < 1 < limits[1] < math.inf
        ):
            raise ValueError(
                f"PLLConfig.frequency_limits must be (low, high) with 0 < low < 1 < high, "
                f"got {self.frequency_limits!r}"
            )


def _check_positive(name: str, value: Any) -> None:
    real = isinstance(value, numbers.Real) and not isinstance(value, bool)
    if not (real and math.isfinite(value) and value > 0):
        raise ValueError(f"{name} must be a finite number > 0, got {value!r}")


@dataclass(frozen=True, eq=False)
class PLLTimeSeries:
    """Samples of a virtual phase-resonance test (``fs`` Hz, SI units).

    ``x``, ``v``, ``a`` are the relative displacement, velocity, acceleration;
    ``base_velocity`` is the quasi-static integral ``−A cos θ / ω`` of the base
    acceleration (zero mean; exact while a level holds, off by ``Ȧ cos θ / ω``
    during ramps); ``frequency_hz`` and ``phase`` (θ, rad, unwrapped) are the
    oscillator's; ``response_phase_deg`` is the detector's phase of the sensed
    response against the configured reference; ``level`` the commanded
    amplitude ``A(t)`` (m/s²) and ``level_index`` the level being approached or held.
    ``holds[j] = (start, stop)`` are the sample ranges (stop exclusive) of the
    hold of level ``j``, where ``level`` is constant; ``measurements[j]`` the
    measured last periods. Rows of levels never reached are ``(-1, -1)``.
    """

    fs: float
    t: np.ndarray
    x: np.ndarray
    v: np.ndarray
    a: np.ndarray
    base_acceleration: np.ndarray
    base_velocity: np.ndarray
    frequency_hz: np.ndarray
    phase: np.ndarray
    response_phase_deg: np.ndarray
    level: np.ndarray
    level_index: np.ndarray
    holds: np.ndarray
    measurements: np.ndarray


@dataclass(frozen=True, eq=False)
class PLLResult:
    """Backbone points of virtual phase-resonance tests.

    Arrays have shape ``(n_levels,)`` for one model and ``(n_sets, n_levels)``
    for a batch; ``level`` is always ``(n_levels,)``. Unlocked levels have NaN
    amplitude, frequency and damping; their ``phase_error_deg`` is the
    detector's last error (NaN after divergence).

    Attributes
    ----------
    level
        Base-acceleration amplitude of each level (m/s²).
    amplitude_m
        Fundamental-harmonic amplitude of the relative displacement (m).
    frequency_hz
        Mean oscillator frequency over the measured periods (Hz).
    damping_ratio
        Power-balance damping ratio ``|Q_b| / (2|Q|)``.
    phase_error_deg
        Phase of the sensed response's fundamental minus its resonant target (deg).
    locked
        Whether the level locked and was measured.
    time_series
        The samples (single runs with ``record=True``), else None.
    """

    level: np.ndarray
    amplitude_m: np.ndarray
    frequency_hz: np.ndarray
    damping_ratio: np.ndarray
    phase_error_deg: np.ndarray
    locked: np.ndarray
    time_series: PLLTimeSeries | None = field(default=None, repr=False)


# --------------------------------------------------------------------------
# numba core: equation of motion and RK4.


@numba.njit(cache=True, inline="always")
def _acceleration(indices, coefficients, shapes, c_ms, k_t, f_s, x_anchor, f_anchor, x, v, a_base):
    """ẍ = −f(x, ẋ) − c_ms·Jenkins(x) − a_base, the Jenkins element from its anchor."""
    # The sum of `restoring_force` written out: calling that separately compiled
    # function from the hot loop costs atomic reference counts on its array
    # arguments, which doubled the time of a step.
    force = 0.0
    for i in range(indices.size):
        force += coefficients[i] * memoryless_force(indices[i], x, v, shapes[i, 0], shapes[i, 1])
    if c_ms != 0.0:
        force += c_ms * jenkins_force(x, x_anchor, f_anchor, k_t, f_s)
    return -force - a_base


@numba.njit(cache=True, inline="always")
def _advance(indices, coefficients, shapes, c_ms, k_t, f_s, x, v, xa, fa, acc0, h, forcing):
    """RK4 over ``len(forcing) // 2`` sub-steps of ``h``; returns ``(x, v, x_anchor, f_anchor)``.

    ``acc0`` is the acceleration at the start and ``forcing[j]`` the base
    acceleration at ``j·h/2``. Within a sub-step the Jenkins element is
    evaluated from its anchor at the sub-step start; the anchor then moves to
    the accepted state.
    """
    for j in range(forcing.size // 2):
        if j > 0:
            acc0 = _acceleration(
                indices, coefficients, shapes, c_ms, k_t, f_s, xa, fa, x, v, forcing[2 * j]
            )
        a_mid = forcing[2 * j + 1]
        x2 = x + 0.5 * h * v
        v2 = v + 0.5 * h * acc0
        acc2 = _acceleration(indices, coefficients, shapes, c_ms, k_t, f_s, xa, fa, x2, v2, a_mid)
        x3 = x + 0.5 * h * v2
        v3 = v + 0.5 * h * acc2
        acc3 = _acceleration(indices, coefficients, shapes, c_ms, k_t, f_s, xa, fa, x3, v3, a_mid)
        x4 = x + h * v3
        v4 = v + h * acc3
        acc4 = _acceleration(
            indices, coefficients, shapes, c_ms, k_t, f_s, xa, fa, x4, v4, forcing[2 * j + 2]
        )
        x = x + h / 6.0 * (v + 2.0 * v2 + 2.0 * v3 + v4)
        v = v + h / 6.0 * (acc0 + 2.0 * acc2 + 2.0 * acc3 + acc4)
        if c_ms != 0.0:
            fa = jenkins_force(x, xa, fa, k_t, f_s)
            xa = x
    return x, v, xa, fa


# --------------------------------------------------------------------------
# Open loop: prescribed base acceleration.


@numba.njit(cache=True)
def _interpolate(t, values, i, tau):
    """Cubic Lagrange interpolation at ``tau`` in ``[t[i], t[i+1]]`` (keeps RK4 4th order)."""
    n = t.size
    if n < 4:
        w = (tau - t[i]) / (t[i + 1] - t[i])
        return (1.0 - w) * values[i] + w * values[i + 1]
    first = min(max(i - 1, 0), n - 4)
    total = 0.0
    for j in range(first, first + 4):
        weight = 1.0
        for m in range(first, first + 4):
            if m != j:
                weight *= (tau - t[m]) / (t[j] - t[m])
        total += weight * values[j]
    return total


@numba.njit(cache=True)
def _open_loop(indices, coefficients, shapes, microslip, t, base_acceleration, x0, v0, n_sub):
    c_ms, k_t, f_s = microslip[0], microslip[1], microslip[2]
    n = t.size
    xs = np.full(n, np.nan)
    vs = np.full(n, np.nan)
    accs = np.full(n, np.nan)
    x, v = x0, v0
    xa = fa = 0.0  # the Jenkins element starts unstressed at x = 0
    forcing = np.empty(2 * n_sub + 1)
    for i in range(n):
        acc = _acceleration(
            indices, coefficients, shapes, c_ms, k_t, f_s, xa, fa, x, v, base_acceleration[i]
        )
        if not (np.isfinite(acc) and np.isfinite(x) and np.isfinite(v)):
            break
        xs[i], vs[i], accs[i] = x, v, acc
        if i == n - 1:
            break
        h = (t[i + 1] - t[i]) / n_sub
        forcing[0] = base_acceleration[i]
        forcing[-1] = base_acceleration[i + 1]
        for j in range(1, 2 * n_sub):
            forcing[j] = _interpolate(t, base_acceleration, i, t[i] + 0.5 * j * h)
        x, v, xa, fa = _advance(
            indices, coefficients, shapes, c_ms, k_t, f_s, x, v, xa, fa, acc, h, forcing
        )
    return xs, vs, accs


def simulate_base_excitation(
    model: JointModel,
    t: ArrayLike,
    base_acceleration: ArrayLike,
    x0: float = 0.0,
    v0: float = 0.0,
) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Response of ``model`` to a prescribed base acceleration (open loop).

    RK4 on the sample grid ``t`` (strictly increasing, need not be uniform),
    with the base acceleration interpolated cubically between samples and
    automatic sub-steps where the model is stiff (:func:`stable_substeps`).
    The microslip element starts unstressed.

    Parameters
    ----------
    model
        Joint model.
    t
        Sample times (s), 1-D.
    base_acceleration
        Base acceleration at ``t`` (m/s²).
    x0, v0
        Initial relative displacement (m) and velocity (m/s).

    Returns
    -------
    x, v, a
        Relative displacement, velocity and acceleration at ``t``; NaN from
        the first sample where the solution stops being finite.
    """
    t = _finite_vector("t", t)
    base_acceleration = _finite_vector("base_acceleration", base_acceleration)
    if t.size < 2:
        raise ValueError(f"t needs at least 2 samples, got {t.size}")
    if base_acceleration.size != t.size:
        raise ValueError(
            f"base_acceleration has {base_acceleration.size} samples but t has {t.size}"
        )
    steps = np.diff(t)
    if np.any(steps <= 0):
        raise ValueError(f"t must be strictly increasing (sample {np.argmax(steps <= 0) + 1})")
    for name, value in (("x0", x0), ("v0", v0)):
        if not math.isfinite(value):
            raise ValueError(f"{name} must be finite, got {value}")
    table = coefficient_table(model)
    n_sub = int(_substeps(table, float(steps.max()))[0])
    if n_sub > _MAX_SUBSTEPS:
        raise ValueError(_substep_message(model, n_sub, _MAX_SUBSTEPS))
    return _open_loop(
        table.indices, table.coefficients[0], table.shapes[0], table.microslip[0],
        t, base_acceleration, float(x0), float(v0), n_sub,
    )  # fmt: skip


def _finite_vector(name: str, values: ArrayLike) -> np.ndarray:
    array = np.ascontiguousarray(values, dtype=float)
    if array.ndim != 1:
        raise ValueError(f"{name} must be 1-D, got shape {array.shape}")
    bad = np.flatnonzero(~np.isfinite(array))
    if bad.size:
        raise ValueError(f"{name} is not finite at sample {bad[0]}")
    return array


# --------------------------------------------------------------------------
# Stability of the explicit step.


def _linear_coefficients(table: CoefficientTable) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Per-set small-amplitude stiffness, viscous damping and stiffest |damping| slope."""
    coefficients, shapes = table.coefficients, table.shapes
    by_effect = {e.index: e for e in CATALOGUE.values()}

    def total(effect: str) -> np.ndarray:
        return coefficients[:, table.indices == CATALOGUE[effect].index].sum(axis=1)

    stiffness = total("linear_stiffness") + table.microslip[:, 0] * table.microslip[:, 1]
    damping = total("viscous_damping")
    slope = np.abs(damping)
    for i, index in enumerate(table.indices):
        effect = by_effect[index]
        if "v_reg" in effect.shape:  # smoothed sign: slope c / v_reg at ẋ = 0
            v_reg = shapes[:, i, effect.shape.index("v_reg")]
            slope = slope + np.abs(coefficients[:, i]) / v_reg
    return stiffness, damping, slope


def _substeps(table: CoefficientTable, dt: float) -> np.ndarray:
    """Sub-steps per sample keeping the linearised eigenvalues in RK4's stability region."""
    stiffness, _, slope = _linear_coefficients(table)
    stiffness = np.abs(stiffness) + np.abs(table.microslip[:, 0] * table.microslip[:, 1])
    largest_eigenvalue = 0.5 * slope + np.sqrt(0.25 * slope**2 + stiffness)
    return np.maximum(1, np.ceil(largest_eigenvalue * dt / _RK4_STABLE_STEP)).astype(np.int64)


def stable_substeps(model: JointModel, fs: float) -> int:
    """RK4 sub-steps per sample at ``fs`` Hz that keep ``model``'s linearisation stable.

    The bound is the largest eigenvalue magnitude of the linearisation at rest,
    where the smoothed friction terms add their slope ``|c|/v_reg`` as viscous
    damping and the Jenkins spring its stiffness ``c·k_t``.
    """
    _check_positive("fs", fs)
    return int(_substeps(coefficient_table(model), 1.0 / fs)[0])


def _substep_message(model: JointModel, n_sub: int, limit: int) -> str:
    return (
        f"model {model.name or model.equation()!r} needs {n_sub} RK4 sub-steps per sample "
        f"(more than max_substeps = {limit}) to stay stable: a friction coefficient over its "
        "v_reg or a Jenkins stiffness is too stiff; raise v_reg or fs"
    )


# --------------------------------------------------------------------------
# PLL numba core.

# Layout of the per-run state vector.
_X, _V, _XA, _FA, _THETA, _OMEGA, _INTEGRAL, _CONTROL_ON, _DETECTOR = range(9)
# Layout of the settings vector (shared by all sets of a batch).
(
    _DT, _TARGET, _SENSING, _TOLERANCE, _LOCK_PERIODS, _SETTLING_TOLERANCE, _MAX_HOLD, _RAMP,
    _N_PERIODS, _X_MAX, _HARMONICS, _REFERENCE, _N_SETTINGS,
) = range(13)  # fmt: skip
# Layout of the per-set control vector.
_KP, _KI, _MU, _OMEGA_INITIAL, _OMEGA_LOW, _OMEGA_HIGH, _N_SUB, _N_CONTROL = range(8)
# Layout of a level's result row.
(
    _AMPLITUDE, _FREQUENCY, _DAMPING, _PHASE_ERROR, _LOCKED, _DIVERGED, _N_SAMPLES,
    _MEASURE_START, _N_RESULTS,
) = range(9)  # fmt: skip
# Recorded channels.
_CHANNELS = (
    "x", "v", "a", "base_acceleration", "base_velocity", "frequency_hz", "phase",
    "response_phase_deg", "level",
)  # fmt: skip


@numba.njit(cache=True)
def _wrap(angle):
    """Angle in (−π, π]."""
    return angle - 2.0 * np.pi * np.ceil((angle - np.pi) / (2.0 * np.pi))


@numba.njit(cache=True)
def _ramp(a_from, a_to, samples, ramp):
    """Raised-cosine ramp from ``a_from`` to ``a_to`` over ``ramp`` samples."""
    if samples >= ramp:
        return a_to
    return a_from + (a_to - a_from) * 0.5 * (1.0 - np.cos(np.pi * samples / ramp))


@numba.njit(cache=True)
def _initial_state(omega, harmonics):
    state = np.zeros(_DETECTOR + 1 + 2 * harmonics)
    state[_OMEGA] = omega
    state[_INTEGRAL] = omega
    return state


@numba.njit(cache=True)
def _run_level(
    indices, coefficients, shapes, microslip, control, settings, state, a_from, a_to, record,
    result,
):  # fmt: skip
    """Ramp to level ``a_to`` and hold it until measured or given up; advances ``state``.

    Writes the level's outcome into ``result`` and, when ``record`` has
    columns, its samples (one row per channel of ``_CHANNELS``).
    """
    dt = settings[_DT]
    target = settings[_TARGET]
    sensing = int(settings[_SENSING])
    tolerance = settings[_TOLERANCE]
    lock_periods = int(settings[_LOCK_PERIODS])
    settling_tolerance = settings[_SETTLING_TOLERANCE]
    max_hold = int(settings[_MAX_HOLD])
    ramp = int(settings[_RAMP])
    n_periods = int(settings[_N_PERIODS])
    x_max = settings[_X_MAX]
    harmonics = int(settings[_HARMONICS])
    kp, ki, mu_dt = control[_KP], control[_KI], control[_MU] * dt
    omega_low, omega_high = control[_OMEGA_LOW], control[_OMEGA_HIGH]
    n_sub = int(control[_N_SUB])
    c_ms, k_t, f_s = microslip[0], microslip[1], microslip[2]
    recording = record.shape[1] > 0

    x, v, xa, fa = state[_X], state[_V], state[_XA], state[_FA]
    theta, omega, integral = state[_THETA], state[_OMEGA], state[_INTEGRAL]
    control_on = state[_CONTROL_ON] > 0.0
    detector = state[_DETECTOR:]
    forcing = np.empty(2 * n_sub + 1)
    result[:] = np.nan
    result[_LOCKED] = 0.0
    result[_DIVERGED] = 0.0
    result[_MEASURE_START] = -1.0

    locked_count = 0
    measuring = False
    done = False
    next_boundary = np.inf
    magnitude_previous = -1.0
    remaining = 0.0
    duration = 0.0
    q_x = q_y = q_base = 0j
    error = np.nan
    n = 0
    while True:
        s, c = np.sin(theta), np.cos(theta)
        amplitude = _ramp(a_from, a_to, n, ramp)
        a_base = amplitude * s
        acc = _acceleration(indices, coefficients, shapes, c_ms, k_t, f_s, xa, fa, x, v, a_base)
        if not (abs(x) <= x_max and np.isfinite(v) and np.isfinite(acc)):
            result[_DIVERGED] = 1.0
            break
        if sensing == 0:
            y = x
        elif sensing == 1:
            y = v
        else:
            y = acc

        # Adaptive Fourier detector: LMS fit of the mean and `harmonics` harmonics in θ.
        fit = detector[0] + detector[1] * s + detector[2] * c
        sk, ck = s, c
        for k in range(3, 2 * harmonics + 1, 2):
            sk, ck = sk * c + ck * s, ck * c - sk * s
            fit += detector[k] * sk + detector[k + 1] * ck
        residual = mu_dt * (y - fit)
        detector[0] += 0.5 * residual  # the mean's gain halved: same time constant 2/μ
        detector[1] += residual * s
        detector[2] += residual * c
        sk, ck = s, c
        for k in range(3, 2 * harmonics + 1, 2):
            sk, ck = sk * c + ck * s, ck * c - sk * s
            detector[k] += residual * sk
            detector[k + 1] += residual * ck
        phase = np.arctan2(detector[2], detector[1])  # y₁ = |Y| sin(θ + phase)
        error = _wrap(phase - target)

        # PI controller with anti-windup at the frequency limits.
        if control_on:
            integral = min(max(integral + ki * error * dt, omega_low), omega_high)
            omega = min(max(integral + kp * error, omega_low), omega_high)

        if recording:
            record[0, n] = x
            record[1, n] = v
            record[2, n] = acc
            record[3, n] = a_base
            record[4, n] = -amplitude * c / omega
            record[5, n] = omega / (2.0 * np.pi)
            record[6, n] = theta
            record[7, n] = np.degrees(_wrap(phase - settings[_REFERENCE]))
            record[8, n] = amplitude

        if n == ramp:  # the hold starts; the first level's controller switches on here
            control_on = True
            next_boundary = theta + 2.0 * np.pi
        elif n > ramp and theta >= next_boundary:  # a period completed: lock detector
            next_boundary += 2.0 * np.pi
            magnitude = np.hypot(detector[1], detector[2])
            # Power-balance damping ratio from the detector: |Q_b| / (2|Q|), |Q| = |Y| / ω^k.
            damping = amplitude * omega**sensing / (2.0 * omega**2 * magnitude)
            change = abs(magnitude - magnitude_previous) / magnitude
            steady = change <= settling_tolerance * 2.0 * np.pi * damping
            ok = abs(error) <= tolerance and steady and omega_low < omega < omega_high
            magnitude_previous = magnitude
            if measuring and not ok:
                measuring = False
                locked_count = 0
            elif not measuring:
                locked_count = locked_count + 1 if ok else 0
                if locked_count >= lock_periods:
                    measuring = True
                    remaining = 2.0 * np.pi * n_periods
                    duration = 0.0
                    q_x = q_y = q_base = 0j
                    result[_MEASURE_START] = n
        if measuring:
            # Left Riemann sum in θ over exactly n_periods periods.
            weight = omega * dt
            if weight >= remaining:
                weight = remaining
                done = True
            remaining -= weight
            duration += weight / omega
            rotation = complex(c, -s) * weight
            q_x += x * rotation
            q_y += y * rotation
            q_base += a_base * rotation

        forcing[0] = a_base
        for j in range(1, 2 * n_sub + 1):
            fraction = j / (2.0 * n_sub)
            forcing[j] = _ramp(a_from, a_to, n + fraction, ramp) * np.sin(
                theta + omega * dt * fraction
            )
        x, v, xa, fa = _advance(
            indices, coefficients, shapes, c_ms, k_t, f_s, x, v, xa, fa, acc, dt / n_sub, forcing
        )
        theta = theta + omega * dt
        n += 1
        if done or n - ramp >= max_hold:
            break

    state[_X], state[_V], state[_XA], state[_FA] = x, v, xa, fa
    state[_THETA], state[_OMEGA], state[_INTEGRAL] = theta, omega, integral
    state[_CONTROL_ON] = 1.0 if control_on else 0.0
    result[_N_SAMPLES] = n
    if done:
        frequency = n_periods / duration
        amplitude_x = abs(q_x) / (np.pi * n_periods)
        amplitude_base = abs(q_base) / (np.pi * n_periods) / (2.0 * np.pi * frequency) ** 2
        result[_AMPLITUDE] = amplitude_x
        result[_FREQUENCY] = frequency
        result[_DAMPING] = amplitude_base / (2.0 * amplitude_x)
        phase_difference = np.arctan2(q_y.imag, q_y.real) - np.arctan2(q_base.imag, q_base.real)
        result[_PHASE_ERROR] = np.degrees(_wrap(phase_difference - target))
        result[_LOCKED] = 1.0
    elif result[_DIVERGED] == 0.0:
        result[_PHASE_ERROR] = np.degrees(error)


@numba.njit(cache=True)
def _backbone(indices, coefficients, shapes, microslip, control, settings, levels, out):
    """All levels of one parameter set; ``out`` is ``(n_levels, _N_RESULTS)``."""
    out[:] = np.nan
    out[:, _LOCKED] = 0.0
    if not (control[_OMEGA_INITIAL] > 0.0):
        return
    state = _initial_state(control[_OMEGA_INITIAL], int(settings[_HARMONICS]))
    record = np.empty((len(_CHANNELS), 0))
    a_from = 0.0
    for j in range(levels.size):
        _run_level(
            indices, coefficients, shapes, microslip, control, settings, state, a_from,
            levels[j], record, out[j],
        )  # fmt: skip
        if out[j, _DIVERGED] > 0.0:
            return
        a_from = levels[j]


@numba.njit(cache=True, parallel=True)
def _backbones_parallel(indices, coefficients, shapes, microslip, control, settings, levels, out):
    for i in numba.prange(coefficients.shape[0]):
        _backbone(
            indices, coefficients[i], shapes[i], microslip[i], control[i], settings, levels, out[i]
        )


# --------------------------------------------------------------------------
# Python side: inputs, per-set arrays, results.


def _settings(config: PLLConfig) -> np.ndarray:
    settings = np.zeros(_N_SETTINGS)
    excitation = _FORCE_VS_EXCITATION_DEG
    settings[_DT] = 1.0 / config.fs
    settings[_TARGET] = np.radians(
        _RESONANT_PHASE_VS_FORCE_DEG[config.sensing] + excitation
    )  # detector phases are against a_base = A sin θ
    settings[_SENSING] = SENSING.index(config.sensing)
    settings[_TOLERANCE] = np.radians(config.lock_tolerance_deg)
    settings[_LOCK_PERIODS] = config.lock_periods
    settings[_SETTLING_TOLERANCE] = config.settling_tolerance
    settings[_MAX_HOLD] = round(config.max_hold_s * config.fs)
    settings[_RAMP] = round(config.ramp_s * config.fs)
    settings[_N_PERIODS] = config.n_periods
    settings[_X_MAX] = config.max_displacement_m
    settings[_HARMONICS] = config.harmonics
    settings[_REFERENCE] = np.radians(_REFERENCE_VS_FORCE_DEG[config.reference] + excitation)
    return settings


def _control(table: CoefficientTable, config: PLLConfig, model: JointModel) -> np.ndarray:
    """Per-set gains, frequency range and sub-steps, ``(n_sets, _N_CONTROL)``."""
    stiffness, damping, _ = _linear_coefficients(table)
    with np.errstate(invalid="ignore"):
        omega_linear = np.where(stiffness > 0, np.sqrt(np.abs(stiffness)), np.nan)
    if config.initial_frequency_hz is not None:
        omega_initial = np.full(table.n_sets, 2.0 * np.pi * config.initial_frequency_hz)
    else:
        omega_initial = omega_linear
    control = np.zeros((table.n_sets, _N_CONTROL))
    if config.gains is None:
        # Design at the resonance the loop starts on; σ = c/2 from the viscous term.
        omega_design = np.where(np.isfinite(omega_linear), omega_linear, omega_initial)
        kp, ki, bandwidth = _pole_placement(
            omega_design, 0.5 * damping / omega_design, config.bandwidth_ratio
        )
    else:
        kp, ki, bandwidth = config.gains.kp, config.gains.ki, config.gains.detector_bandwidth
    control[:, _KP] = kp
    control[:, _KI] = ki
    control[:, _MU] = 2.0 * np.asarray(bandwidth)
    control[:, _OMEGA_INITIAL] = omega_initial
    control[:, _OMEGA_LOW] = config.frequency_limits[0] * omega_initial
    control[:, _OMEGA_HIGH] = config.frequency_limits[1] * omega_initial
    n_sub = _substeps(table, 1.0 / config.fs)
    worst = int(np.argmax(n_sub))
    if n_sub[worst] > config.max_substeps:
        raise ValueError(
            ("" if table.n_sets == 1 else f"parameter set {worst}: ")
            + _substep_message(model, int(n_sub[worst]), config.max_substeps)
        )
    control[:, _N_SUB] = n_sub
    if config.gains is None:
        # Sets with no resonance to design for have nothing to lock on.
        control[~np.isfinite(control[:, _KP]), _OMEGA_INITIAL] = np.nan
    return control


def _check_timing(config: PLLConfig, control: np.ndarray) -> None:
    """The hold must fit the lock and measurement periods, the sampling the frequencies."""
    omega = control[:, _OMEGA_INITIAL]
    omega = omega[np.isfinite(omega)]
    if omega.size == 0:
        return
    needed = (config.lock_periods + config.n_periods) * 2.0 * np.pi / omega.min()
    if config.max_hold_s < needed:
        raise ValueError(
            f"PLLConfig.max_hold_s = {config.max_hold_s} s is shorter than lock_periods + "
            f"n_periods = {config.lock_periods + config.n_periods} periods ({needed:.3g} s)"
        )
    highest_hz = config.frequency_limits[1] * omega.max() / (2.0 * np.pi)
    if config.fs < _MIN_SAMPLES_PER_PERIOD * highest_hz:
        raise ValueError(
            f"PLLConfig.fs = {config.fs} Hz gives fewer than {_MIN_SAMPLES_PER_PERIOD} samples "
            f"per period at {highest_hz:.4g} Hz (frequency_limits × initial frequency)"
        )


def _result(levels: np.ndarray, out: np.ndarray, time_series=None) -> PLLResult:
    return PLLResult(
        level=levels,
        amplitude_m=out[..., _AMPLITUDE].copy(),
        frequency_hz=out[..., _FREQUENCY].copy(),
        damping_ratio=out[..., _DAMPING].copy(),
        phase_error_deg=out[..., _PHASE_ERROR].copy(),
        locked=out[..., _LOCKED] > 0.0,
        time_series=time_series,
    )


def simulate_pll(
    model: JointModel,
    levels: ArrayLike,
    config: PLLConfig | None = None,
    record: bool = False,
) -> PLLResult:
    """Virtual phase-resonance test of ``model`` at stepped excitation levels.

    Parameters
    ----------
    model
        Joint model (mass-normalised, base-excited).
    levels
        Base-acceleration amplitudes of the holds (m/s²), in test order (e.g.
        up then down), each finite and > 0.
    config
        Test settings; default :class:`PLLConfig()`.
    record
        Keep the samples (:class:`PLLTimeSeries`) for virtual test records.

    Returns
    -------
    PLLResult
        One backbone point per level, arrays of shape ``(n_levels,)``.
    """
    config = PLLConfig() if config is None else config
    levels = positive_vector(levels, "levels")
    table = coefficient_table(model)
    control = _control(table, config, model)
    _check_timing(config, control)
    settings = _settings(config)
    arrays = (table.indices, table.coefficients[0], table.shapes[0], table.microslip[0])
    out = np.empty((levels.size, _N_RESULTS))
    if not record:
        _backbone(*arrays, control[0], settings, levels, out)
        return _result(levels, out)
    return _recorded_run(arrays, control[0], settings, levels, out, config.fs)


def _recorded_run(arrays, control, settings, levels, out, fs) -> PLLResult:
    """Level by level through the same kernel as :func:`_backbone`, keeping the samples."""
    out[:] = np.nan
    out[:, _LOCKED] = 0.0
    holds = np.full((levels.size, 2), -1, dtype=np.int64)
    measurements = np.full((levels.size, 2), -1, dtype=np.int64)
    pieces, indices = [], []
    ramp, max_hold = int(settings[_RAMP]), int(settings[_MAX_HOLD])
    if control[_OMEGA_INITIAL] > 0.0:
        state = _initial_state(control[_OMEGA_INITIAL], int(settings[_HARMONICS]))
        buffer = np.empty((len(_CHANNELS), ramp + max_hold + 1))
        start, a_from = 0, 0.0
        for j, level in enumerate(levels):
            _run_level(*arrays, control, settings, state, a_from, level, buffer, out[j])
            n = int(out[j, _N_SAMPLES])
            pieces.append(buffer[:, :n].copy())
            indices.append(np.full(n, j, dtype=np.int64))
            if n > ramp:
                holds[j] = start + ramp, start + n
            if out[j, _LOCKED] > 0:
                measurements[j] = start + int(out[j, _MEASURE_START]), start + n
            start += n
            if out[j, _DIVERGED] > 0:
                break
            a_from = level
    samples = np.concatenate(pieces, axis=1) if pieces else np.empty((len(_CHANNELS), 0))
    channels = dict(zip(_CHANNELS, samples, strict=True))
    series = PLLTimeSeries(
        fs=fs,
        t=np.arange(samples.shape[1]) / fs,
        level_index=np.concatenate(indices) if indices else np.empty(0, dtype=np.int64),
        holds=holds,
        measurements=measurements,
        **channels,
    )
    return _result(levels, out, series)


def _chunk_out(model, levels, parameters, names, config, parallel) -> np.ndarray:
    """Backbones of a chunk of parameter sets, ``(n_sets, n_levels, _N_RESULTS)``."""
    table = coefficient_table(model, parameters, names)
    control = _control(table, config, model)
    settings = _settings(config)
    out = np.empty((table.n_sets, levels.size, _N_RESULTS))
    arrays = (table.indices, table.coefficients, table.shapes, table.microslip)
    if parallel:
        _backbones_parallel(*arrays, control, settings, levels, out)
    else:  # the executor provides the parallelism; one set after another here
        for i in range(table.n_sets):
            _backbone(
                table.indices, table.coefficients[i], table.shapes[i], table.microslip[i],
                control[i], settings, levels, out[i],
            )  # fmt: skip
    return out


def _run_chunk(model, levels, parameters, names, config) -> np.ndarray:
    """Executor task: one chunk, serially (module-level so that it pickles)."""
    return _chunk_out(model, levels, parameters, names, config, parallel=False)


def pll_backbones(
    model: JointModel,
    levels: ArrayLike,
    parameters: ArrayLike,
    names: Sequence[str],
    config: PLLConfig | None = None,
    executor: Any = None,
    chunk_size: int | None = None,
    progress: bool | None = None,
) -> PLLResult:
    """PLL backbones of many parameter sets of one model structure.

    Parameters
    ----------
    model
        Template model; the named parameters are overridden per set.
    levels
        Base-acceleration amplitudes of the holds (m/s²), shared by all sets.
    parameters
        ``(n_sets, len(names))`` parameter values.
    names
        Parameter names as in :attr:`JointModel.parameter_names`.
    config
        Test settings (default gains are designed per set).
    executor
        Anything with ``submit(fn, *args)`` returning futures with ``.result()``
        (``concurrent.futures`` executors, a ``dask.distributed.Client``): the
        sets are split in chunks, submitted, and gathered in order. Without
        one, the chunks run here in numba threads (``prange`` over sets).
    chunk_size
        Sets per chunk; default about 8 chunks per worker thread (≥ 1 set).
    progress
        Show a tqdm bar; default when there is more than one chunk.

    Returns
    -------
    PLLResult
        Arrays of shape ``(n_sets, n_levels)``; the same numbers as
        :func:`simulate_pll` on each set.
    """
    config = PLLConfig() if config is None else config
    levels = positive_vector(levels, "levels")
    names = list(names)
    values = np.asarray(parameters, dtype=float)
    # Validates names and values and the stability of every set before any work is sent out.
    table = coefficient_table(model, values, names)
    _check_timing(config, _control(table, config, model))
    n_sets = table.n_sets
    if chunk_size is None:
        chunk_size = max(1, math.ceil(n_sets / (8 * numba.get_num_threads())))
    if not isinstance(chunk_size, int | np.integer) or chunk_size < 1:
        raise ValueError(f"chunk_size must be an integer ≥ 1, got {chunk_size!r}")
    starts = range(0, n_sets, chunk_size)
    chunks = [values[s : s + chunk_size] for s in starts]
    progress = len(chunks) > 1 if progress is None else progress
    bar = tqdm(total=n_sets, desc="PLL backbones", unit="set", disable=not progress)
    outs = []
    with bar:
        if executor is None:
            for chunk in chunks:
                outs.append(_chunk_out(model, levels, chunk, names, config, parallel=True))
                bar.update(len(chunk))
        else:
            futures = [
                executor.submit(_run_chunk, model, levels, chunk, names, config) for chunk in chunks
            ]
            for future, chunk in zip(futures, chunks, strict=True):
                outs.append(future.result())
                bar.update(len(chunk))
    return _result(levels, np.concatenate(outs, axis=0))
