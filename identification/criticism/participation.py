"""Where a second mode is, from its participation at the sensors (multi-point records).

One response point's backbone carries a second mode's product of coupling and detuning,
not where it is (``docs/criticism.md``, "A missing mode"). Multi-point records carry more:
the modal filter of the records' mode shapes (``pm-joint backbones --modes 2``,
:mod:`identification.measurements.modal_backbones`) gives the other mode's own coordinate
at every hold of the locked one — its harmonics ``P_k`` (m) against ``k`` times the locked
mode's fundamental. That coordinate is a mode's response to what drives it, at ``kω``:

``P_k(a) = a^k F_k(a) / D₂(kω(a))``, ``D₂(Ω) = ω₂² − Ω² + 2iζ₂ω₂Ω``,

with ``ω(a)``, ``ζ(a)`` the locked mode's measured backbone and ``F_k`` what drives the
other mode per unit ``a^k``. At ``k = 1`` a mode near the first is driven by the base (under
phase-locked control the drive balances the locked mode's damping force, ``∝ iζω²``) and by
the joint's force beyond rest (its change of the locked mode's stiffness, ``∝ ω² − ω₀²``);
what the modal filter leaks from the locked mode is a constant: per curve,
``F₁(a) = c₀ + c₁ (ω² − ω₀²)/ω₀² + c₂ iζω²/ω₀²`` with complex ``c``. At ``k = 2`` a mode
near ``2ω`` is driven by a quadratic coupling, ``∝ a²`` (``c₀ a²``; a drive that followed
the backbone's stiffness would mimic the detuning's first-order change and hide where the
mode is), and, as any linear mode, by the measured excitation's second harmonic ``E₂``
(a shaker's distortion); the filter leaks the locked mode's own second harmonic ``X₂``,
not divided by the detuning: ``P₂ = (c₀ a² + c_E E₂)/D₂(2ω) + c_X X₂``.
For a trial ``ω₂ = r ω₁`` the fit is linear: the
*profile* over ``r`` is the ``χ²`` it takes off against a mode too far to resonate (``D₂``
constant over the levels), in units of the best fit's residual variance; each assembly's
mode may lie within :data:`ALLOWANCE` of the campaign's (assemblies scatter). As the
backbone moves ``kω`` by a few per cent the detuning ``D₂(kω)`` changes by tens of per cent
where the mode is near: that change places it.

Two routes (:data:`ROUTES`): the fundamental near the first (ratios 0.8–1.25, the joint's
route) and the second harmonic near twice the first (1.6–2.4, the coupling's). A ratio whose
``kω₂``-resonance the backbone would cross (its range widened by half a half-power bandwidth)
is not tried. **Located** is the two-mode refit's rule
(:class:`~identification.criticism.mode_refit.RefitProfile`): solved neighbours on both
sides, nothing 5 % and more apart within :data:`~.config.SEPARATION`; and the resonance
takes at least ``SEPARATION`` off the far mode's fit and off both ends of its grid (a
profile that rises towards an end says a mode beyond it: a mode near 1:1 that a coupling
drives at ``2ω`` off resonance, tuning seeds 1–40 of the independent simulator). Of the
located routes the one that takes most is the answer.

**Exchange** (:attr:`ParticipationLocation.exchanges`). At ``2ω`` the coupling's column is
what a linear mode lacks: where the second harmonic is located, the ``χ²`` the coupling's
drive takes off beside the excitation's and the leak's (each curve's mode re-placed within
the allowance without it) must exceed the ``1 − EXCHANGE_LEVEL`` quantile of ``χ²`` with two
degrees per curve: then the participation *names* the mode (a second mode takes energy from
the locked one at twice its frequency). At the fundamental it cannot: the filter's leak
(a constant ratio) lies in the span of the basis over ``D₂`` (``Δk/D₂ = D₂₀/D₂ − 1``), so the
joint's drive cannot be told from it; and a linear mode's fit — the measured excitation
over the detuning, the leak beside it — left 700–2 700 χ² units to a joint's drive on the
rig with its second mode uncoupled (tuning seeds 1–3; which of the rig's artefacts does it
is not settled). There the participation *shows* the mode (:attr:`ParticipationLocation.shows`):
where the fundamental's route is located, a mode near the first responds at the sensors,
which a one-mode model does not hold — named as seen beside the first, no exchange claimed
(the independent simulator near 1:1, whose one-point backbone the catalogue explains or
finds nothing missing in, tuning seeds 1–3: placed at 110.6, 108.2 and 110.1 Hz, truth
108.1; on the 1:2 cases of the rig and the independent simulator the fundamental's route
was not located, seeds 1–3).
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass
from functools import cached_property

import numpy as np
import pandas as pd
from scipy.stats import chi2

from identification.criticism.config import SEPARATION
from identification.criticism.mode_refit import (
    COUPLING_ROUTE,
    CROSSING_BANDWIDTHS,
    JOINT_ROUTE,
    RefitProfile,
)

__all__ = [
    "ALLOWANCE",
    "EXCHANGE_LEVEL",
    "PARTICIPATION",
    "ROUTES",
    "ModeParticipation",
    "ParticipationCurve",
    "ParticipationLocation",
    "locate_by_participation",
    "locked_mode",
    "participation_profiles",
]

#: What placed a mode, in the words and the JSON (:attr:`RefitProfile.method`).
PARTICIPATION = "participation"
#: Route → (harmonic ``k``, ratios ``ω₂/ω₁`` tried).
ROUTES: dict[str, tuple[int, np.ndarray]] = {
    JOINT_ROUTE: (1, np.round(np.arange(0.8, 1.25 + 1e-9, 0.005), 4)),
    COUPLING_ROUTE: (2, np.round(np.arange(1.6, 2.4 + 1e-9, 0.005), 4)),
}
#: The level of the exchange's test at the second harmonic
#: (:attr:`ParticipationLocation.exchanges`).
EXCHANGE_LEVEL = 0.01
#: How far (relative) one assembly's second mode may lie from the campaign's: assemblies
#: scatter in frequency, a few tenths of a per cent to a per cent.
ALLOWANCE = 0.01


@dataclass(frozen=True, eq=False)
class ParticipationCurve:
    """One curve's holds: the locked mode's backbone and the other mode's harmonics.

    Attributes
    ----------
    amplitude_m, frequency_hz, damping_ratio
        ``(n,)`` the locked mode's amplitude, frequency and damping ratio at each hold.
    harmonics_m
        ``(n, K)`` complex: harmonic ``k`` = 1…K of the other mode's coordinate (m), its
        phase against ``k`` times the locked mode's fundamental.
    label
        The curve's label.
    drive
        ``(n, K)`` complex: the measured excitation's harmonics (its own unit; None: not
        measured) — what a linear mode answers at ``kω``.
    own_m
        ``(n, K)`` complex: the locked mode's own harmonics (m; None: not read) — what the
        modal filter leaks into the other mode's coordinate.
    """

    amplitude_m: np.ndarray
    frequency_hz: np.ndarray
    damping_ratio: np.ndarray
    harmonics_m: np.ndarray
    label: str = ""
    drive: np.ndarray | None = None
    own_m: np.ndarray | None = None


@dataclass(frozen=True, eq=False)
class ModeParticipation:
    """Another mode's participation in the holds of the criticised mode, curve by curve.

    Attributes
    ----------
    curves
        One :class:`ParticipationCurve` per measured curve.
    mode
        The other mode's number (1, 2, … in order of linear frequency).
    source
        Where the participation was read.
    """

    curves: tuple[ParticipationCurve, ...]
    mode: int = 2
    source: str = ""

    @classmethod
    def from_table(cls, table: pd.DataFrame, source: str = "table") -> ModeParticipation:
        """From a modal backbone table (``pm-joint backbones --modes N``,
        :meth:`~identification.measurements.modal_backbones.ModalBackboneSet.to_table`):
        the holds of the curves locked on :func:`locked_mode` and the next mode's
        ``mode{m}_h{k}`` columns (the first other mode above it, else below it).

        Raises
        ------
        ValueError
            The table has no ``mode`` column, or no other mode's harmonics.
        """
        mode = locked_mode(table, source)
        locked = table[(table["mode"] == mode) & table["frequency_hz"].notna()]
        modes = sorted(int(m) for m in table["mode"].unique() if int(m) != mode)
        if not modes:
            raise ValueError(f"{source}: no mode besides the locked one")
        other = min(modes, key=lambda m: (m < mode, abs(m - mode)))
        harmonics = sorted(
            int(c.split("_h")[1].split("_")[0])
            for c in table.columns
            if c.startswith(f"mode{other}_h") and c.endswith("_amplitude_mm")
        )
        curves = []
        for label, rows in locked.groupby("curve", sort=False):
            parts, own = (
                np.column_stack([_harmonic(rows, m, k) for k in harmonics]) for m in (other, mode)
            )
            curves.append(ParticipationCurve(
                1e-3 * rows["amplitude_mm"].to_numpy(float), rows["frequency_hz"].to_numpy(float),
                rows["damping_ratio"].to_numpy(float), parts, str(label),
                drive=_drive(rows, harmonics), own_m=own,
            ))  # fmt: skip
        return cls(tuple(curves), other, source)

    def words(self, harmonic: int) -> str:
        """The other mode's harmonic at the highest hold of all curves, in words."""
        curve = max(self.curves, key=lambda c: c.amplitude_m.max())
        top = int(np.argmax(curve.amplitude_m))
        a = float(curve.amplitude_m[top])
        share = abs(curve.harmonics_m[top, harmonic - 1]) / a
        return (f"measured at the sensors: the second mode's harmonic {harmonic} reaches "
                f"{100 * share:.2g} % of the response amplitude at {1e3 * a:.2g} mm")  # fmt: skip

    def reference(self) -> tuple[float, float]:
        """``(ω₁/2π, ζ₂)``: the frequency and damping ratio at each curve's lowest hold,
        median over the curves (the second mode damped like the first at rest, as the
        screen's)."""
        lowest = [int(np.argmin(c.amplitude_m)) for c in self.curves]
        f = np.median([c.frequency_hz[i] for c, i in zip(self.curves, lowest, strict=True)])
        z = np.median([c.damping_ratio[i] for c, i in zip(self.curves, lowest, strict=True)])
        return float(f), float(z)


def _harmonic(rows: pd.DataFrame, mode: int, k: int) -> np.ndarray:
    """Harmonic ``k`` of ``mode``'s coordinate at the rows (m, complex; 0 where not read)."""
    amplitude, phase = (f"mode{mode}_h{k}_amplitude_mm", f"mode{mode}_h{k}_phase_deg")
    if amplitude not in rows.columns:
        return np.zeros(len(rows), dtype=complex)
    value = (
        1e-3
        * rows[amplitude].to_numpy(float)
        * np.exp(1j * np.radians(rows[phase].to_numpy(float)))
    )
    return np.nan_to_num(value)


def _drive(rows: pd.DataFrame, harmonics: list[int]) -> np.ndarray | None:
    """The measured excitation's harmonics at the rows (its level times each harmonic's
    part of it), or None where the table carries no excitation."""
    if "excitation_level" not in rows.columns or rows["excitation_level"].isna().any():
        return None
    level = rows["excitation_level"].to_numpy(float)
    out = []
    for k in harmonics:
        cos, sin = f"excitation_harmonic{k}_cos", f"excitation_harmonic{k}_sin"
        if k == 1:
            out.append(level.astype(complex))
        elif cos in rows.columns:
            out.append(
                level * np.nan_to_num(rows[cos].to_numpy(float) - 1j * rows[sin].to_numpy(float))
            )
        else:
            out.append(np.zeros(level.size, dtype=complex))
    return np.column_stack(out)


def locked_mode(table: pd.DataFrame, source: str = "table") -> int:
    """The mode most holds of a modal backbone table are locked on (its rows carry the
    frequency).

    Raises
    ------
    ValueError
        No ``mode`` column, or no locked hold.
    """
    if "mode" not in table.columns:
        raise ValueError(f"{source}: not a modal backbone table (no 'mode' column)")
    locked = table.loc[table["frequency_hz"].notna(), "mode"]
    if locked.empty:
        raise ValueError(f"{source}: no hold carries a frequency")
    return int(locked.astype(int).mode().iloc[0])


def _linear_columns(
    curve: ParticipationCurve, omega_ref: float, harmonic: int
) -> tuple[np.ndarray, np.ndarray]:
    """What a linear mode that exchanges nothing answers at ``2ω``, in m (module notes):
    ``(n, p)`` columns a resonance divides — the measured excitation's second harmonic —
    and ``(n, q)`` columns it does not: the filter's leak of the locked mode's own."""
    n, k = curve.amplitude_m.size, harmonic
    drive = None if curve.drive is None or curve.drive.shape[1] < k else curve.drive[:, k - 1]
    own = None if curve.own_m is None or curve.own_m.shape[1] < k else curve.own_m[:, k - 1]
    resonant, plain = ([c] if c is not None and np.any(c) else [] for c in (drive, own))
    return _stack(resonant, n), _stack(plain, n)


def _exchange_columns(curve: ParticipationCurve, omega_ref: float, harmonic: int) -> np.ndarray:
    """``(n, 1)`` what the coupling adds to the drive at ``2ω``, over the detuning: ``a²``."""
    return curve.amplitude_m[:, None] ** 2


def _fundamental_columns(
    curve: ParticipationCurve, omega_ref: float, harmonic: int
) -> tuple[np.ndarray, np.ndarray]:
    """The columns that place a mode at the fundamental (module notes): ``a`` times a
    constant, the stiffness change and the damping force, all over the detuning."""
    a = curve.amplitude_m
    omega = 2 * np.pi * curve.frequency_hz
    resonant = a[:, None] * np.column_stack([
        np.ones(a.size), (omega**2 - omega_ref**2) / omega_ref**2,
        1j * curve.damping_ratio * omega**2 / omega_ref**2,
    ])  # fmt: skip
    return resonant, np.zeros((a.size, 0))


def _with_exchange(
    curve: ParticipationCurve, omega_ref: float, harmonic: int
) -> tuple[np.ndarray, np.ndarray]:
    """:func:`_linear_columns` with :func:`_exchange_columns` among the resonant ones."""
    resonant, plain = _linear_columns(curve, omega_ref, harmonic)
    return np.column_stack([_exchange_columns(curve, omega_ref, harmonic), resonant]), plain


def _stack(columns: list[np.ndarray], n: int) -> np.ndarray:
    return np.column_stack(columns) if columns else np.zeros((n, 0), dtype=complex)


#: A curve's fitted columns: ``(curve, ω_ref, k) → (over the detuning, beside it)``.
type Columns = Callable[[ParticipationCurve, float, int], tuple[np.ndarray, np.ndarray]]


def _residual(columns: np.ndarray, target: np.ndarray) -> float:
    """Residual sum of squares of the complex least squares ``columns c ≈ target``."""
    coefficients, *_ = np.linalg.lstsq(columns, target, rcond=None)
    return float(np.sum(np.abs(target - columns @ coefficients) ** 2))


class _Route:
    """One route's fits over its ratios (module notes)."""

    def __init__(self, participation: ModeParticipation, route: str) -> None:
        self.route = route
        self.harmonic, self.ratios = ROUTES[route]
        self.first_hz, self.zeta = participation.reference()
        self.omega_ref = 2 * np.pi * self.first_hz
        self.curves = [c for c in participation.curves if c.harmonics_m.shape[1] >= self.harmonic]
        span = np.concatenate([c.frequency_hz for c in self.curves])
        widen = 0.5 * CROSSING_BANDWIDTHS * 2 * self.zeta * self.first_hz
        at_hz = self.ratios * self.first_hz / self.harmonic
        self.crossed = (at_hz >= span.min() - widen) & (at_hz <= span.max() + widen)
        self._residuals: dict[Columns, np.ndarray] = {}

    @property
    def location_columns(self) -> Columns:
        """The columns that place the mode: the fundamental's, or at ``2ω`` the
        exchange's beside a linear mode's."""
        return _fundamental_columns if self.harmonic == 1 else _with_exchange

    def residuals(self, columns: Columns) -> np.ndarray:
        """``(R,)`` the residual sum of squares at each ratio of the fit of ``columns``
        (resonant ones over the detuning), each curve's mode where it fits best within
        :data:`ALLOWANCE` of the ratio (inf where not tried); each set fitted once."""
        if columns not in self._residuals:
            self._residuals[columns] = self._fit(columns)
        return self._residuals[columns]

    def _fit(self, columns: Columns) -> np.ndarray:
        k, omega_ref = self.harmonic, self.omega_ref
        total = np.zeros(self.ratios.size)
        for c in self.curves:
            drive = k * 2 * np.pi * c.frequency_hz
            resonant, plain = columns(c, omega_ref, k)
            own = np.full(self.ratios.size, np.inf)
            for i in np.flatnonzero(~self.crossed):
                omega2 = self.ratios[i] * omega_ref
                detuning = (omega2**2 - drive**2 + 2j * self.zeta * omega2 * drive) / omega_ref**2
                fitted = np.column_stack([resonant / detuning[:, None], plain])
                own[i] = _residual(fitted, c.harmonics_m[:, k - 1])
            total += [own[np.abs(self.ratios / r - 1) <= ALLOWANCE].min() for r in self.ratios]
        total[self.crossed] = np.inf
        return total

    def variance(self, columns: Columns, rss: float) -> float:
        """The residual variance per real number of a fit of ``columns`` whose sum of
        squares is ``rss``."""
        k = self.harmonic
        n_real = 2 * sum(c.amplitude_m.size for c in self.curves)
        n_columns = sum(sum(m.shape[1] for m in columns(c, self.omega_ref, k))
                        for c in self.curves)  # fmt: skip
        dof = max(n_real - 2 * n_columns - 1, 1)
        return max(rss / dof, np.finfo(float).tiny)

    @cached_property
    def profile(self) -> RefitProfile:
        """The χ² the resonance takes off a mode too far to resonate, at each ratio."""
        k, columns = self.harmonic, self.location_columns
        rss = self.residuals(columns)
        far = sum(
            _residual(np.column_stack(columns(c, self.omega_ref, k)), c.harmonics_m[:, k - 1])
            for c in self.curves
        )
        variance = self.variance(columns, float(np.min(rss)))
        gain = np.where(np.isfinite(rss), (far - rss) / variance, -np.inf)
        return RefitProfile(self.route, self.ratios, gain, np.zeros((self.ratios.size, 0)),
                            self.first_hz, method=PARTICIPATION)  # fmt: skip

    def exchange(self) -> float:
        """At ``2ω`` the χ² the coupling's drive (:func:`_exchange_columns`) takes off a
        linear mode's fit (:func:`_linear_columns`) at the best ratio, each curve's mode
        re-placed within the allowance, in units of the exchange's fit's residual variance;
        NaN at the fundamental (module notes)."""
        if self.harmonic != 2:
            return float("nan")
        best = self.profile.best
        with_exchange = float(self.residuals(_with_exchange)[best])
        linear = float(self.residuals(_linear_columns)[best])
        return (linear - with_exchange) / self.variance(_with_exchange, with_exchange)

    @property
    def exchange_threshold(self) -> float:
        """The ``1 − EXCHANGE_LEVEL`` quantile of χ² with two degrees per exchange column and
        curve (one complex coefficient each)."""
        n = _exchange_columns(self.curves[0], self.omega_ref, self.harmonic).shape[1]
        return float(chi2.ppf(1 - EXCHANGE_LEVEL, 2 * n * len(self.curves)))


def participation_profiles(participation: ModeParticipation) -> list[RefitProfile]:
    """Each route's profile over the second mode's frequency (:data:`ROUTES`)."""
    return [r.profile for r in _routes(participation)]


def _routes(participation: ModeParticipation) -> list[_Route]:
    harmonics = min(c.harmonics_m.shape[1] for c in participation.curves)
    return [_Route(participation, r) for r, (k, _) in ROUTES.items() if k <= harmonics]


@dataclass(frozen=True)
class ParticipationLocation:
    """Where the participation places the second mode.

    Attributes
    ----------
    profile
        The answering route's profile (the located route that takes most, else the route
        that takes most).
    why_not_located
        Empty where located; else why not.
    exchange, exchange_threshold
        The χ² the exchange's drive takes off at the located frequency (NaN where not
        located) and the threshold it must exceed to name the mode.
    """

    profile: RefitProfile
    why_not_located: str
    exchange: float = float("nan")
    exchange_threshold: float = float("nan")

    @property
    def located(self) -> bool:
        return not self.why_not_located

    @property
    def exchanges(self) -> bool:
        """Located, and the exchange's drive takes more than its threshold off: the mode
        takes energy from the locked one (module notes)."""
        return self.located and self.exchange > self.exchange_threshold

    @property
    def shows(self) -> bool:
        """Located at the fundamental (the joint's route): a mode near the first responds at
        the sensors, its coordinate shaped by its resonance as the backbone sweeps the
        detuning; whether it exchanges energy through the joint is not told there (module
        notes)."""
        return self.located and self.profile.route == JOINT_ROUTE


def locate_by_participation(participation: ModeParticipation) -> ParticipationLocation:
    """The second mode's frequency from its participation (module notes).

    Parameters
    ----------
    participation
        The other mode's harmonics at the locked mode's holds.

    Returns
    -------
    ParticipationLocation
        The answering route's profile and why it is not located (empty where it is).
    """
    answers = []
    for route in _routes(participation):
        profile = route.profile
        why = profile.why_not_located
        if not why and profile.gain < SEPARATION:
            why = (
                f"the {profile.route} route's participation is not shaped by a resonance: a "
                f"mode too far to resonate fits it within Δχ² {SEPARATION:g}"
            )
        solved = profile.profile[np.isfinite(profile.profile)]
        if not why and profile.gain - max(solved[0], solved[-1]) < SEPARATION:
            why = (
                f"the {profile.route} route's participation rises towards the end of its grid: "
                "a mode beyond it, not where"
            )
        exchange = route.exchange() if not why else float("nan")
        answers.append(ParticipationLocation(profile, why, exchange, route.exchange_threshold))
    located = [a for a in answers if a.located]
    return max(located or answers, key=lambda a: a.profile.gain)
