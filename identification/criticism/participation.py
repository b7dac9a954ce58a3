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
``F₁(a) = c₀ + c₁ (ω² − ω₀²)/ω₀² + c₂ iζω²/ω₀²`` with complex ``c`` (:data:`BASIS`). At
``k = 2`` a mode near ``2ω`` is driven by a quadratic coupling, ``∝ a²``: ``F₂ = c₀``
(a drive that followed the backbone's stiffness would mimic the detuning's first-order
change and hide where the mode is). For a trial ``ω₂ = r ω₁`` the fit is linear: the
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
takes at least ``SEPARATION`` off the far mode's fit. Of the located routes the one that
takes most is the answer.


What the participation cannot say is whether the mode *exchanges* energy with the locked one:
the modal filter's leak of the locked mode (a constant ratio) lies in the span of the
basis over ``D₂`` (``Δk/D₂ = D₂₀/D₂ − 1``), so the joint's drive cannot be told from it, and
a shaker's distortion drives a linear mode at ``2ω`` as a coupling does (on the rig with its
second mode uncoupled, tuning seed 1, the second harmonic located a resonance). It places a
mode that the criticism names (:mod:`~identification.criticism.second_mode`); it names none.
"""

from __future__ import annotations

from dataclasses import dataclass
from functools import cached_property

import numpy as np
import pandas as pd

from identification.criticism.config import SEPARATION
from identification.criticism.mode_refit import (
    COUPLING_ROUTE,
    CROSSING_BANDWIDTHS,
    JOINT_ROUTE,
    RefitProfile,
)

__all__ = [
    "ALLOWANCE",
    "BASIS",
    "ROUTES",
    "ModeParticipation",
    "ParticipationCurve",
    "ParticipationLocation",
    "locate_by_participation",
    "locked_mode",
    "participation_profiles",
]

#: Route → (harmonic ``k``, ratios ``ω₂/ω₁`` tried).
ROUTES: dict[str, tuple[int, np.ndarray]] = {
    JOINT_ROUTE: (1, np.round(np.arange(0.8, 1.25 + 1e-9, 0.005), 4)),
    COUPLING_ROUTE: (2, np.round(np.arange(1.6, 2.4 + 1e-9, 0.005), 4)),
}
#: How far (relative) one assembly's second mode may lie from the campaign's: assemblies
#: scatter in frequency, a few tenths of a per cent to a per cent.
ALLOWANCE = 0.01
#: What drives the other mode, per curve (module notes): a constant (the filter's leak, a
#: quadratic coupling), the locked mode's stiffness change (the joint) and its damping force
#: (the base under phase-locked control).
BASIS = ("constant", "stiffness change", "damping force")


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
    """

    amplitude_m: np.ndarray
    frequency_hz: np.ndarray
    damping_ratio: np.ndarray
    harmonics_m: np.ndarray
    label: str = ""


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
            parts = [
                1e-3 * rows[f"mode{other}_h{k}_amplitude_mm"].to_numpy(float)
                * np.exp(1j * np.radians(rows[f"mode{other}_h{k}_phase_deg"].to_numpy(float)))
                for k in harmonics
            ]  # fmt: skip
            curves.append(ParticipationCurve(
                1e-3 * rows["amplitude_mm"].to_numpy(float), rows["frequency_hz"].to_numpy(float),
                rows["damping_ratio"].to_numpy(float), np.column_stack(parts), str(label),
            ))  # fmt: skip
        return cls(tuple(curves), other, source)

    def reference(self) -> tuple[float, float]:
        """``(ω₁/2π, ζ₂)``: the frequency and damping ratio at each curve's lowest hold,
        median over the curves (the second mode damped like the first at rest, as the
        screen's)."""
        lowest = [int(np.argmin(c.amplitude_m)) for c in self.curves]
        f = np.median([c.frequency_hz[i] for c, i in zip(self.curves, lowest, strict=True)])
        z = np.median([c.damping_ratio[i] for c, i in zip(self.curves, lowest, strict=True)])
        return float(f), float(z)


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


def _basis(curve: ParticipationCurve, omega_ref: float, harmonic: int) -> np.ndarray:
    """``(n, 3)`` :data:`BASIS` at the curve's holds (``(n, 1)``, the constant, at the
    second harmonic: what feeds it per ``a²``)."""
    omega = 2 * np.pi * curve.frequency_hz
    if harmonic == 2:
        return np.ones((omega.size, 1))
    return np.column_stack([
        np.ones(omega.size), (omega**2 - omega_ref**2) / omega_ref**2,
        1j * curve.damping_ratio * omega**2 / omega_ref**2,
    ])  # fmt: skip


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

    @cached_property
    def rss(self) -> np.ndarray:
        """``(R,)`` the residual sum of squares at each ratio, each curve's mode where it
        fits best within :data:`ALLOWANCE` of the ratio (inf where not tried)."""
        k, omega_ref = self.harmonic, self.omega_ref
        total = np.zeros(self.ratios.size)
        for c in self.curves:
            drive = k * 2 * np.pi * c.frequency_hz
            columns = (c.amplitude_m**k)[:, None] * _basis(c, omega_ref, k)
            own = np.full(self.ratios.size, np.inf)
            for i in np.flatnonzero(~self.crossed):
                omega2 = self.ratios[i] * omega_ref
                detuning = (omega2**2 - drive**2 + 2j * self.zeta * omega2 * drive) / omega_ref**2
                own[i] = _residual(columns / detuning[:, None], c.harmonics_m[:, k - 1])
            total += [own[np.abs(self.ratios / r - 1) <= ALLOWANCE].min() for r in self.ratios]
        total[self.crossed] = np.inf
        return total

    @cached_property
    def variance(self) -> float:
        """The best fit's residual variance per real number."""
        k = self.harmonic
        n_real = 2 * sum(c.amplitude_m.size for c in self.curves)
        n_basis = _basis(self.curves[0], self.omega_ref, k).shape[1]
        dof = max(n_real - 2 * n_basis * len(self.curves) - 1, 1)
        return max(float(np.min(self.rss)) / dof, np.finfo(float).tiny)

    @cached_property
    def profile(self) -> RefitProfile:
        """The χ² the resonance takes off a mode too far to resonate, at each ratio."""
        k = self.harmonic
        far = sum(
            _residual((c.amplitude_m**k)[:, None] * _basis(c, self.omega_ref, k),
                      c.harmonics_m[:, k - 1])
            for c in self.curves
        )  # fmt: skip
        gain = np.where(np.isfinite(self.rss), (far - self.rss) / self.variance, -np.inf)
        return RefitProfile(self.route, self.ratios, gain, np.zeros((self.ratios.size, 0)),
                            self.first_hz, method="participation")  # fmt: skip


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
    """

    profile: RefitProfile
    why_not_located: str

    @property
    def located(self) -> bool:
        return not self.why_not_located


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
        answers.append(ParticipationLocation(profile, why))
    located = [a for a in answers if a.located]
    return max(located or answers, key=lambda a: a.profile.gain)
