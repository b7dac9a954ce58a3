"""Several modes' backbone points from one sensor's free decay, and the 1:2 attribution.

Windows of ``window_periods`` periods of the lowest mode march along the decay, half a window
at a time, as the one-mode analysis's do (:func:`identification.measurements.decay.decay_points`);
each is fitted with every mode still above the noise at once
(:func:`identification.measurements.decay_components.fit_components`), each mode with its own
frequency, drift and decay rate and its harmonics. A mode whose fundamental's relative standard
error exceeds :data:`~identification.measurements.decay.NOISE_LIMIT`, or whose frequency leaves
its band, leaves the model from that window on.

**The locked content.** Where a lower mode's ``k``-th harmonic and a higher mode's fundamental
collide (near ``k``:1, e.g. 1:2), the window fits one component ``C`` there, and its content is
attributed afterwards, over the whole decay, by how it grows against the lower mode's amplitude:
a harmonic of mode 1 is locked to ``k`` times mode 1's phase and grows like ``a₁ᵏ`` (or faster),
so it vanishes with mode 1; a second mode's free content decays at its own rate, at its own
frequency, whatever mode 1 does. The window phasors ``C_w`` (at the window centres ``t_w``)
are fitted by

    C_w = h₁ P_wᵏ + h₂ P_wᵏ |P_w|² + A e^{(−σ + iω)(t_w − t₀)}

with ``P_w`` mode 1's fundamental phasor (the complex ``h₁, h₂, A`` by least squares for each
``(σ, ω)``, those two by nonlinear least squares from the windows' own). The harmonic part
``H_w = h₁P_wᵏ + h₂P_wᵏ|P_w|²`` becomes mode 1's ``k``-th harmonic, the rest ``F_w = C_w − H_w``
(not the fitted exponential: a nonlinear second mode keeps its own amplitude dependence) the
second mode's fundamental, its rate ``λ_F = (λ_C C_w − Ḣ_w) / F_w`` from the window's fitted
rate ``λ_C`` and ``Ḣ_w`` from mode 1's. The rule that decided is recorded
(:class:`Attribution`): only the harmonic part above the noise (no second mode there), only
the free part, or both; where the decay is too short to tell the two regressors apart (their
correlation above :data:`DEGENERATE_CORRELATION`: a detuning ``|ω₂ − kω₁|`` below the decay's
inverse length with ``σ₂ ≈ kσ₁``), all of it goes to the second mode and the rule says so.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from enum import StrEnum
from typing import Any

import numpy as np
from scipy import optimize
from scipy import signal as sps

from identification.measurements.decay import (
    MIN_POINTS,
    NOISE_LIMIT,
    DecayPoint,
    _point,
    decay_segments,
)
from identification.measurements.decay_components import (
    ComponentsFit,
    Lock,
    component_orders,
    fit_components,
)
from identification.measurements.local_fit import LocalFit

__all__ = [
    "DEGENERATE_CORRELATION",
    "Attribution",
    "LockAttribution",
    "SensorModes",
    "mode_bands_hz",
    "mode_frequencies_hz",
    "sensor_mode_points",
]

#: Correlation of the harmonic and free regressors above which a decay cannot tell them apart.
DEGENERATE_CORRELATION = 0.99
#: Fewest windows carrying both modes of a lock that the attribution fit takes.
MIN_WINDOWS = 6
#: Fundamentals closer than this many ``1/T`` (``T`` a window's length) cannot both be fitted.
LOCK_SEPARATION = 1.0
#: Widest band of a mode, as a factor about its frequency (narrower where modes are close).
BAND_FACTOR = 1.25


class Attribution(StrEnum):
    """Which rule separated the modes or attributed a locked content (printed by the CLI)."""

    MODAL_FILTER = "modal filter (least squares on the mode shapes at the sensors)"
    SEPARATE = "a joint local fit of every mode's band on one sensor"
    HARMONIC = "the lower mode's harmonic (grows with its amplitude, locked to its phase)"
    FREE = "the higher mode's free decay (its own rate and frequency, not the lower mode's)"
    SPLIT = "split: a harmonic part growing with the lower mode, the rest the higher mode's"
    UNDECIDED = "not separable over this decay: all of it given to the higher mode"


@dataclass(frozen=True)
class LockAttribution:
    """How one locked collision was attributed.

    ``harmonic_share``: share of the locked content's energy (Σ|·|² over the windows) given to
    the lower mode's harmonic; ``free_frequency_hz``, ``free_decay_rate_1_s``: the free part's
    exponential of the global fit; ``correlation``: between the harmonic and free regressors.
    """

    lock: Lock
    rule: Attribution
    harmonic_share: float
    free_frequency_hz: float
    free_decay_rate_1_s: float
    correlation: float

    def describe(self, frequencies_hz: np.ndarray) -> str:
        """One line: which content, the rule, what share (modes numbered from 1)."""
        low, up, k = self.lock.lower + 1, self.lock.upper + 1, self.lock.order
        return (
            f"content near {frequencies_hz[self.lock.upper]:.1f} Hz (mode {low}'s harmonic {k} "
            f"or mode {up}), attributed by its growth against mode {low}'s amplitude "
            f"(a harmonic grows like a{low}^{k} and keeps {k}× its phase): {self.rule.value}; "
            f"{100 * self.harmonic_share:.0f} % of it to mode {low}'s harmonic"
        )


@dataclass(frozen=True)
class SensorModes:
    """Per-mode backbone points of one sensor's decay (modes in order of frequency)."""

    points: tuple[tuple[DecayPoint, ...], ...]
    frequencies_hz: np.ndarray
    locks: tuple[LockAttribution, ...]
    stop_reasons: tuple[str, ...]


def mode_frequencies_hz(
    values: np.ndarray, sampling_rate_hz: float, n_modes: int, window_periods: float
) -> np.ndarray:
    """The ``n_modes`` highest peaks of the decay's Hann spectrum (Hz, increasing).

    Peaks with fewer than ``window_periods`` periods in the decay are left out; the others
    are taken from the highest down, each farther than a window's resolution
    (:data:`LOCK_SEPARATION` over a window of ``window_periods`` periods of the highest peak)
    from those already taken: the smeared peak of a mode whose frequency moves over the
    decay counts once. A mode's own harmonic can be taken, as can a mode near it: the
    windows' attribution tells them apart (see the module notes).
    """
    y = sps.detrend(np.asarray(values, dtype=float))
    n = y.size
    spectrum = np.abs(np.fft.rfft(y * np.hanning(n), 8 * n))
    freqs = np.fft.rfftfreq(8 * n, 1.0 / sampling_rate_hz)
    peaks, _ = sps.find_peaks(spectrum)
    # A mode whose window is longer than the decay has no point: lower peaks are the slow
    # mean of a displacement, not a mode.
    peaks = peaks[freqs[peaks] * n / sampling_rate_hz > window_periods]
    peaks = peaks[np.argsort(spectrum[peaks])[::-1]]
    if peaks.size == 0:
        raise ValueError("the record's spectrum shows no peak")
    resolution = LOCK_SEPARATION * freqs[peaks[0]] / window_periods
    taken: list[float] = []
    for i in peaks:
        if all(abs(freqs[i] - f) > resolution for f in taken):
            taken.append(float(freqs[i]))
            if len(taken) == n_modes:
                return np.sort(taken)
    raise ValueError(f"the record's spectrum shows {len(taken)} separate peak(s), {n_modes} "
                     "asked for")  # fmt: skip


def mode_bands_hz(frequencies_hz: np.ndarray) -> list[tuple[float, float]]:
    """Each mode's band (Hz; frequencies in increasing order): ``BAND_FACTOR`` about it, and
    no further than half-way (geometric) to its neighbours."""
    f = np.asarray(frequencies_hz, dtype=float)
    bands = []
    for m, fm in enumerate(f):
        low = fm / BAND_FACTOR if m == 0 else max(fm / BAND_FACTOR, math.sqrt(f[m - 1] * fm))
        high = (fm * BAND_FACTOR if m == f.size - 1
                else min(fm * BAND_FACTOR, math.sqrt(fm * f[m + 1])))  # fmt: skip
        bands.append((low, high))
    return bands


@dataclass
class _Window:
    """One window's fit and the modes it carried (indices into the record's modes)."""

    fit: ComponentsFit
    active: tuple[int, ...]

    def slot(self, mode: int) -> int:
        return self.active.index(mode)


def _march(t, y, segment, frequencies_hz, window_periods, harmonics, edge_periods):
    """Fit the windows along the segment; returns the windows and each mode's stop reason."""
    start, stop = segment
    f = np.asarray(frequencies_hz, dtype=float)
    window_s = window_periods / f[0]
    bands = mode_bands_hz(f)
    params = np.column_stack([2 * math.pi * f, np.zeros_like(f), np.zeros_like(f)])
    active = list(range(f.size))
    reasons = ["the decay's end"] * f.size
    centre = t[start] + (edge_periods + 0.5 * window_periods) / f[0]
    half = 0.5 * window_s
    windows: list[_Window] = []
    all_orders, locks = component_orders(f, harmonics, window_s)

    def orders_of(active):
        # A lower mode takes its locked order back once the higher mode has left; a higher
        # mode keeps its fundamental alone, so that its points carry the same orders.
        out = []
        for m in active:
            mine = set(all_orders[m]) | {
                lock.order for lock in locks if lock.lower == m and lock.upper not in active
            }
            out.append(tuple(sorted(mine)))
        return out

    while active:
        a = int(np.searchsorted(t, centre - half, "left"))
        b = int(np.searchsorted(t, centre + half, "right"))
        if a < start or centre + half > t[stop - 1]:
            break
        while active:
            try:
                fit = fit_components(t[a:b], y[a:b], centre, params[active], orders_of(active))
            except ValueError as exc:
                reasons = [f"a window fit failed at {centre:.4g} s ({exc})" if m in active
                           else r for m, r in enumerate(reasons)]  # fmt: skip
                active = []
                break
            failed = []
            for slot, m in enumerate(active):
                low, high = bands[m]
                relative = fit.phasor_standard_error[slot][0] / max(abs(fit.phasors[slot][0]),
                                                                    1e-300)  # fmt: skip
                if not (fit.converged and low <= fit.omega[slot] / (2 * math.pi) <= high):
                    failed.append((m, f"the window fit at {centre:.4g} s did not converge "
                                      "inside the band"))  # fmt: skip
                elif relative > NOISE_LIMIT:
                    failed.append((m, f"the noise floor at {centre:.4g} s"))
            if not failed:
                break
            for m, why in failed:
                reasons[m] = why
                active.remove(m)
        if not active:
            break
        windows.append(_Window(fit, tuple(active)))
        for slot, m in enumerate(active):
            params[m] = (fit.omega[slot] + fit.beta[slot] * half, fit.beta[slot], fit.sigma[slot])
        centre += half
    return windows, reasons


def _regressors(phasor, order, free_rate, times):
    """Columns of the attribution fit: ``Pᵏ``, ``Pᵏ|P|²`` and ``e^{λ(t − t₀)}``."""
    harmonic = phasor**order
    return np.column_stack([harmonic, harmonic * np.abs(phasor) ** 2,
                            np.exp(free_rate * (times - times[0]))])  # fmt: skip


def _solve(columns, target):
    """Complex least squares with the columns normalised; returns the coefficients."""
    norms = np.linalg.norm(columns, axis=0)
    norms[norms == 0] = 1.0
    return np.linalg.lstsq(columns / norms, target, rcond=1e-12)[0] / norms


def _attribute(windows: list[_Window], lock: Lock):
    """The global fit of the module notes over the windows that carry both modes.

    Returns the attribution, and per window (by index) the harmonic part ``H_w`` and its
    time derivative ``Ḣ_w``.
    """
    both = [i for i, w in enumerate(windows) if lock.lower in w.active and lock.upper in w.active]
    low = [windows[i].slot(lock.lower) for i in both]
    up = [windows[i].slot(lock.upper) for i in both]
    fits = [windows[i].fit for i in both]
    p = np.array([fit.phasors[s][0] for fit, s in zip(fits, low, strict=True)])
    c = np.array([fit.phasors[s][0] for fit, s in zip(fits, up, strict=True)])
    se = np.array([fit.phasor_standard_error[s][0] for fit, s in zip(fits, up, strict=True)])
    times = np.array([fit.centre_s for fit in fits])
    rate_p = np.array([-fit.sigma[s] + 1j * fit.omega[s] for fit, s in zip(fits, low, strict=True)])
    rate_c = np.array([-fit.sigma[s] + 1j * fit.omega[s] for fit, s in zip(fits, up, strict=True)])
    if len(both) < MIN_WINDOWS:
        nothing = {i: (0j, 0j) for i in both}
        return LockAttribution(lock, Attribution.UNDECIDED, 0.0, math.nan, math.nan,
                               math.nan), nothing  # fmt: skip
    sigma0, omega0 = float(np.median(-rate_c.real)), float(np.median(rate_c.imag))

    def residual(x):
        columns = _regressors(p, lock.order, -x[0] + 1j * x[1], times)
        r = columns @ _solve(columns, c) - c
        return np.concatenate([r.real, r.imag])

    span = max(times[-1] - times[0], 1e-9)
    best = optimize.least_squares(residual, [sigma0, omega0], x_scale=[1 / span, 1 / span],
                                  method="lm")  # fmt: skip
    sigma, omega = best.x
    columns = _regressors(p, lock.order, -sigma + 1j * omega, times)
    coef = _solve(columns, c)
    unit = columns / np.linalg.norm(columns, axis=0)
    harmonic_space = np.linalg.qr(unit[:, :2])[0]
    projection = harmonic_space @ (harmonic_space.conj().T @ unit[:, 2])
    correlation = float(np.linalg.norm(projection))
    h1, h2 = coef[0] * columns[:, 0], coef[1] * columns[:, 1]
    harmonic = h1 + h2
    # Ḣ: Pᵏ has rate kλ_P, Pᵏ|P|² has rate kλ_P + 2 Re λ_P.
    harmonic_rate = lock.order * rate_p * h1 + (lock.order * rate_p + 2 * rate_p.real) * h2
    # A part is there where it is above the noise as a backbone point must be, in enough
    # windows for a backbone.
    harmonic_on = np.sum(se <= NOISE_LIMIT * np.abs(harmonic)) >= MIN_POINTS
    free_on = np.sum(se <= NOISE_LIMIT * np.abs(c - harmonic)) >= MIN_POINTS
    if correlation > DEGENERATE_CORRELATION:
        rule = Attribution.UNDECIDED
    elif harmonic_on and free_on:
        rule = Attribution.SPLIT
    elif harmonic_on:
        rule = Attribution.HARMONIC
    else:
        rule = Attribution.FREE
    # The rule decides: the content goes where it says, all of it where one part is in the
    # noise.
    if rule is Attribution.HARMONIC:
        harmonic, harmonic_rate = c, rate_c * c
    elif rule is not Attribution.SPLIT:
        harmonic, harmonic_rate = 0 * c, 0 * c
    energy_h, energy_f = np.sum(np.abs(harmonic) ** 2), np.sum(np.abs(c - harmonic) ** 2)
    attribution = LockAttribution(
        lock=lock, rule=rule, harmonic_share=float(energy_h / max(energy_h + energy_f, 1e-300)),
        free_frequency_hz=float(omega / (2 * math.pi)), free_decay_rate_1_s=float(sigma),
        correlation=correlation,
    )  # fmt: skip
    parts = {i: (harmonic[n], harmonic_rate[n]) for n, i in enumerate(both)}
    return attribution, parts


def _local_fit(fit: ComponentsFit, slot: int, harmonics: int, phasors, se, omega, sigma, mean):
    """A one-mode :class:`LocalFit` of one mode of a window, orders ``1..len(phasors)``."""
    return LocalFit(
        centre_s=fit.centre_s,
        frequency_hz=float(omega / (2 * math.pi)),
        chirp_hz_s=float(fit.beta[slot] / (2 * math.pi)),
        decay_rate_1_s=float(sigma),
        phasors=np.asarray(phasors, dtype=complex),
        phasor_standard_error=np.asarray(se, dtype=float),
        mean=mean,
        mean_standard_error=fit.mean_standard_error,
        frequency_standard_error_hz=float(fit.nonlinear_standard_error[slot, 0] / (2 * math.pi)),
        chirp_standard_error_hz_s=float(fit.nonlinear_standard_error[slot, 1] / (2 * math.pi)),
        decay_rate_standard_error_1_s=float(fit.nonlinear_standard_error[slot, 2]),
        residual_rms=fit.residual_rms,
        n_samples=fit.n_samples,
        converged=fit.converged,
    )


def sensor_mode_points(
    time_s: np.ndarray,
    values: np.ndarray,
    quantity: str,
    sampling_rate_hz: float,
    n_modes: int,
    *,
    frequencies_hz: np.ndarray | None = None,
    window_periods: float = 6.0,
    harmonics: int = 3,
    edge_periods: float = 0.0,
    excitation: np.ndarray | None = None,
    steps: Any = None,
) -> SensorModes:
    """Each mode's backbone points from one sensor's free decay (see the module notes).

    ``frequencies_hz``: the modes' linear frequencies where known (else the spectrum's
    highest peaks, :func:`mode_frequencies_hz`); ``excitation``, ``steps``: where the
    record has them, to find its decay (:func:`~.decay.decay_segments`; its first).

    Raises
    ------
    ValueError
        No decay, modes a window cannot separate (closer than its resolution and not a
        harmonic collision), or a requested mode without a point above the noise.
    """
    t = np.asarray(time_s, dtype=float)
    y = np.asarray(values, dtype=float)
    segments = decay_segments(t, y, sampling_rate_hz, excitation=excitation, steps=steps)
    if not segments:
        raise ValueError("no free decay found")
    segment = segments[0]
    if frequencies_hz is None:
        head = y[segment[0] : segment[1]]
        f = mode_frequencies_hz(head, sampling_rate_hz, n_modes, window_periods)
    else:
        f = np.sort(np.asarray(frequencies_hz, dtype=float))
    window_s = window_periods / f[0]
    if np.any(np.diff(f) < LOCK_SEPARATION / window_s):
        raise ValueError(
            f"modes at {', '.join(f'{x:.5g}' for x in f)} Hz are closer than a window of "
            f"{window_periods:g} periods resolves; raise --window-periods"
        )
    _, locks = component_orders(f, harmonics, window_s)
    windows, reasons = _march(t, y, segment, f, window_periods, harmonics, edge_periods)
    attributions, parts = [], {}
    for lock in locks:
        attribution, found = _attribute(windows, lock)
        attributions.append(attribution)
        parts[lock] = found
    points: list[list[DecayPoint]] = [[] for _ in f]
    for i, window in enumerate(windows):
        fit = window.fit
        for slot, m in enumerate(window.active):
            phasor_list = fit.phasors[slot]
            order_list = fit.orders[slot]
            se_list = fit.phasor_standard_error[slot]
            omega, sigma = fit.omega[slot], fit.sigma[slot]
            full = np.zeros(max(order_list), complex)
            full_se = np.zeros(full.size)
            full[np.array(order_list) - 1], full_se[np.array(order_list) - 1] = phasor_list, se_list
            for lock in locks:
                if i not in parts[lock]:
                    continue
                harmonic, harmonic_rate = parts[lock][i]
                if m == lock.lower:
                    full = np.pad(full, (0, max(0, lock.order - full.size)))
                    full_se = np.pad(full_se, (0, max(0, lock.order - full_se.size)))
                    upper = window.slot(lock.upper)
                    full[lock.order - 1] = harmonic
                    full_se[lock.order - 1] = fit.phasor_standard_error[upper][0]
                elif m == lock.upper:
                    free = full[0] - harmonic
                    if free != 0:
                        rate = ((-sigma + 1j * omega) * full[0] - harmonic_rate) / free
                        omega, sigma = rate.imag, -rate.real
                    full[0] = free
            if not abs(full_se[0]) <= NOISE_LIMIT * abs(full[0]):
                continue  # a free part in the noise (or none): no point of this mode here
            mean = fit.mean if m == 0 else math.nan
            local = _local_fit(fit, slot, harmonics, full, full_se, omega, sigma, mean)
            points[m].append(_point(local, quantity))
    return SensorModes(
        points=tuple(tuple(p) for p in points),
        frequencies_hz=f,
        locks=tuple(attributions),
        stop_reasons=tuple(reasons),
    )
