"""Drift against physics: what the up- and down-stepped branches of a run say.

A backbone is a steady state: at equal amplitude, a joint's frequency and damping
do not depend on whether the level was reached stepping up or down (a hysteretic
joint's *hold* is hysteretic, its backbone point is not). A difference between
the branches at equal amplitude is therefore something else, and when it grows
with the *time* between the two visits to a level — largest at the lowest level,
visited first and last — it is drift (temperature, a sensor's gain), not joint
physics. The likelihood averages the branches (:mod:`identification.fitting.data`),
which cancels a drift linear in time, so drift is reported here and never
proposed as physics.

:func:`branch_drift` regresses the branch difference on the time between the
visits, per curve through the origin; the curves' rates are the independent
units of the test (levels within a run share their run's drift), so the rate is
their mean with a t-test across curves (with one or two curves, across levels,
and said so).
"""

from __future__ import annotations

import warnings
from dataclasses import dataclass

import numpy as np
from scipy import stats

from identification.fitting.data import FitData

__all__ = ["Drift", "branch_drift"]

_UNITS = {"frequency_hz": ("Hz", 1.0), "damping_ratio": ("%-points", 100.0)}


@dataclass(frozen=True)
class Drift:
    """The drift of a channel seen between the branches of the runs.

    Attributes
    ----------
    channel
        ``"frequency_hz"`` or ``"damping_ratio"``.
    rate, standard_error
        Change per unit time (channel unit per ``time_unit``) and its standard error.
    time_unit
        ``"hour"`` (the backbones carry hold times) or ``"hold"`` (positions in the run).
    p_value
        Two-sided, of the rate against zero.
    units
        Independent units of the test: curves, or (with fewer than three) levels.
    largest_difference
        Largest mean difference down − up between the branches at a level (channel unit).
    significant
        ``p_value`` below the criticism's level.
    """

    channel: str
    rate: float
    standard_error: float
    time_unit: str
    p_value: float
    units: str
    largest_difference: float
    significant: bool

    @property
    def text(self) -> str:
        unit, factor = _UNITS[self.channel]
        name = "frequency" if self.channel == "frequency_hz" else "damping"
        verdict = "drift, not joint physics" if self.significant else "no drift beyond the noise"
        return (
            f"{name}: the down-stepped branch differs from the up-stepped one by up to "
            f"{factor * self.largest_difference:+.2g} {unit}, following the time between the "
            f"visits: {factor * self.rate:+.2g} ± {factor * self.standard_error:.2g} {unit} per "
            f"{self.time_unit} (p = {self.p_value:.2g}, {self.units}) — {verdict}"
        )

    def to_dict(self) -> dict:
        return {
            "channel": self.channel,
            "rate_per_time_unit": self.rate,
            "standard_error": self.standard_error,
            "time_unit": self.time_unit,
            "p_value": self.p_value,
            "units": self.units,
            "largest_difference": self.largest_difference,
            "significant": self.significant,
            "text": self.text,
        }


def branch_drift(data: FitData, alpha: float) -> list[Drift]:
    """Drift of frequency and damping from runs stepped up and down (empty without them)."""
    branches = data.branch_values(data.values)
    if branches.shape[1] < 2:
        return []
    times = data.branch_values(data.time[:, None])[..., 0]
    scale = 3600.0 if data.time_unit == "s" else 1.0
    difference = branches[:, 1] - branches[:, 0]
    gap = (times[:, 1] - times[:, 0]) / scale
    out = []
    for channel in ("frequency_hz", "damping_ratio"):
        j = data.column(channel)
        d, t = difference[:, :, j], gap
        both = np.isfinite(d) & np.isfinite(t) & (t > 0)
        rates, pooled_d, pooled_t = [], [], []
        for i in range(d.shape[0]):
            rows = both[i]
            if rows.sum() >= 2:
                rates.append(np.sum(d[i, rows] * t[i, rows]) / np.sum(t[i, rows] ** 2))
                pooled_d.append(d[i, rows])
                pooled_t.append(t[i, rows])
        if not rates:
            continue
        if len(rates) >= 3:
            rate = float(np.mean(rates))
            se = float(np.std(rates, ddof=1) / np.sqrt(len(rates)))
            df, units = len(rates) - 1, f"{len(rates)} runs"
        else:
            dd, tt = np.concatenate(pooled_d), np.concatenate(pooled_t)
            rate = float(np.sum(dd * tt) / np.sum(tt**2))
            df = dd.size - 1
            se = float(np.sqrt(np.sum((dd - rate * tt) ** 2) / max(df, 1) / np.sum(tt**2)))
            units = f"{dd.size} levels of {len(rates)} run(s), assumed independent"
        p = float(2 * stats.t.sf(abs(rate) / se, df)) if se > 0 and df > 0 else 1.0
        with warnings.catch_warnings():
            warnings.simplefilter("ignore", RuntimeWarning)  # levels only one branch reaches
            level_mean = np.nanmean(np.where(both, d, np.nan), axis=0)
        largest = float(level_mean[np.nanargmax(np.abs(level_mean))])
        out.append(
            Drift(channel, rate, se, "hour" if scale > 1 else "hold", p, units, largest, p < alpha)
        )
    return out
