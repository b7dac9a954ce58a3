"""Backbone curves: containers and their extraction from phase-resonance records.

A backbone point comes from one hold phase of a record (:mod:`identification.measurements.records`):
the last ``N`` excitation periods are fitted with a Fourier series whose phase
``φ(t) = 2π ∫ f(t) dt`` is the integral of the record's instantaneous-frequency
channel, so a slowly drifting PLL frequency is followed exactly and no
convention of the phase channel is assumed. With ``V_b`` and ``V`` the
fundamental-harmonic complex amplitudes of the base velocity and of the
centre-point velocity relative to the base (``v = Re(V e^{iφ})``), and
``ω = 2π f`` the mean frequency over the window:

* amplitude: ``|Q| = |V| / ω``, the relative-displacement fundamental (m);
* phase error: ``arg(V / V_b) + 90°``, zero at phase resonance, where the
  relative velocity lags the base velocity by 90°;
* damping ratio from the power balance of base excitation: the active power
  supplied per unit mass, ``½ Re(−iω V_b · conj(V))``, equals that of an
  equivalent viscous damper, ``½ · 2Dω · |V|²``, so
  ``D = |Q_b| cos(phase error) / (2 |Q|)`` — i.e. ``|Q_b| / (2|Q|)`` at
  phase resonance, with ``Q_b = V_b / (iω)`` the base-displacement fundamental.
"""

from __future__ import annotations

import dataclasses
import warnings
from collections.abc import Iterable, Iterator, Sequence
from dataclasses import dataclass
from functools import cached_property
from pathlib import Path

import numpy as np
import pandas as pd
from numpy.typing import ArrayLike
from scipy.integrate import cumulative_trapezoid
from scipy.interpolate import make_interp_spline

from identification.artifacts import atomic_write_text
from identification.measurements.records import Hold, Record

__all__ = [
    "TABLE_COLUMNS",
    "Backbone",
    "BackboneSet",
    "HoldPoint",
    "ShortHoldError",
    "extract_backbone",
    "extract_backbones",
    "hold_point",
]

#: Columns of :meth:`BackboneSet.to_table`, in order.
TABLE_COLUMNS = (
    "curve",
    "excitation_level",
    "amplitude_mm",
    "frequency_hz",
    "damping_ratio",
    "phase_error_deg",
    "source",
)
_REQUIRED_COLUMNS = ("curve", "amplitude_mm", "frequency_hz", "damping_ratio")


# ---------------------------------------------------------------------------
# Containers


@dataclass(frozen=True, eq=False)
class Backbone:
    """One backbone curve, a point per hold phase (or per model amplitude).

    Attributes
    ----------
    amplitude_m
        Fundamental-harmonic amplitude of the relative displacement (m), ≥ 0.
    frequency_hz
        Phase-resonance frequency (Hz), > 0.
    damping_ratio
        Power-balance damping ratio (1), signed.
    excitation_level
        Excitation level of each point (shaker voltage for test records), or None.
    phase_error_deg
        Deviation from phase resonance (deg), or None (model backbones).
    label
        Name of the curve (a record name for test records).
    source
        Where the curve comes from (a file, a model).

    The points are kept in the order given, so a test that steps up and down
    keeps both branches; interpolation (:meth:`frequency_at`,
    :meth:`damping_at`) works on the amplitude-sorted curve, see :attr:`branch`.
    """

    amplitude_m: np.ndarray
    frequency_hz: np.ndarray
    damping_ratio: np.ndarray
    excitation_level: np.ndarray | None = None
    phase_error_deg: np.ndarray | None = None
    label: str = ""
    source: str = ""

    def __post_init__(self) -> None:
        where = f"backbone {self.label!r}" if self.label else "backbone"
        n = None
        for name in ("amplitude_m", "frequency_hz", "damping_ratio", "excitation_level",
                     "phase_error_deg"):  # fmt: skip
            values = getattr(self, name)
            if values is None and name in ("excitation_level", "phase_error_deg"):
                continue
            try:
                array = np.array(values, dtype=float).reshape(-1)
            except (TypeError, ValueError):
                raise ValueError(f"{where}: {name} must be numbers, got {values!r}") from None
            n = array.size if n is None else n
            if array.size != n or n == 0:
                raise ValueError(
                    f"{where}: {name} has {array.size} values, expected {n} (one per point, ≥ 1)"
                )
            bad = np.flatnonzero(~np.isfinite(array))
            if bad.size:
                raise ValueError(f"{where}: {name}[{bad[0]}] is not finite ({array[bad[0]]})")
            array.setflags(write=False)
            object.__setattr__(self, name, array)
        if (self.amplitude_m < 0).any():
            i = int(np.argmax(self.amplitude_m < 0))
            raise ValueError(f"{where}: amplitude_m[{i}] is negative ({self.amplitude_m[i]})")
        if (self.frequency_hz <= 0).any():
            i = int(np.argmax(self.frequency_hz <= 0))
            raise ValueError(f"{where}: frequency_hz[{i}] is not positive ({self.frequency_hz[i]})")

    def __len__(self) -> int:
        return self.amplitude_m.size

    @property
    def amplitude_mm(self) -> np.ndarray:
        return 1e3 * self.amplitude_m

    @cached_property
    def branch(self) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """``(amplitude_m, frequency_hz, damping_ratio)`` sorted by amplitude.

        Points at the same amplitude (e.g. the same level stepped up and down)
        are averaged. A curve whose amplitudes are not monotonic warns once
        that it is interpolated on this sorted branch.
        """
        a = self.amplitude_m
        step = np.diff(a)
        if not ((step > 0).all() or (step < 0).all()):
            warnings.warn(
                f"{self.label or 'backbone'}: amplitudes are not monotonic (stepping up and "
                "down?); interpolating on the amplitude-sorted branch, equal amplitudes averaged",
                stacklevel=3,
            )
        unique, inverse = np.unique(a, return_inverse=True)
        counts = np.bincount(inverse)
        freq = np.bincount(inverse, weights=self.frequency_hz) / counts
        damp = np.bincount(inverse, weights=self.damping_ratio) / counts
        return unique, freq, damp

    @property
    def amplitude_range_m(self) -> tuple[float, float]:
        return float(self.amplitude_m.min()), float(self.amplitude_m.max())

    def frequency_at(self, amplitudes_m: ArrayLike, extrapolate: bool = False) -> np.ndarray:
        """Frequency (Hz) at the given amplitudes (m), linear between points.

        Outside the measured amplitude range a ValueError is raised unless
        ``extrapolate`` is True (then the end segments are extended).
        """
        return self._interpolate(1, amplitudes_m, extrapolate)

    def damping_at(self, amplitudes_m: ArrayLike, extrapolate: bool = False) -> np.ndarray:
        """Damping ratio at the given amplitudes (m); see :meth:`frequency_at`."""
        return self._interpolate(2, amplitudes_m, extrapolate)

    def _interpolate(self, which: int, amplitudes_m: ArrayLike, extrapolate: bool) -> np.ndarray:
        branch = self.branch
        a = np.asarray(amplitudes_m, dtype=float)
        if branch[0].size < 2:
            raise ValueError(f"{self.label or 'backbone'}: needs two distinct amplitudes")
        lo, hi = branch[0][0], branch[0][-1]
        if not np.isfinite(a).all():
            raise ValueError(f"{self.label or 'backbone'}: amplitudes_m must be finite")
        outside = (a < lo * (1 - 1e-12)) | (a > hi * (1 + 1e-12))
        if not extrapolate and outside.any():
            raise ValueError(
                f"{self.label or 'backbone'}: amplitude {1e3 * a[outside].flat[0]:.6g} mm is "
                f"outside the curve's range {1e3 * lo:.6g}–{1e3 * hi:.6g} mm "
                "(pass extrapolate=True to extend the end segments)"
            )
        return make_interp_spline(branch[0], branch[which], k=1)(a)

    def plot(self, ax=None):
        """Frequency and damping against amplitude (mm); see :meth:`BackboneSet.plot`."""
        return BackboneSet([self]).plot(ax)


class BackboneSet(Sequence[Backbone]):
    """Several backbones (e.g. one per assembly), with uniquely labelled curves.

    Unlabelled curves are named ``curve0``, ``curve1``, … by position.
    """

    def __init__(self, backbones: Iterable[Backbone]) -> None:
        curves = []
        for i, b in enumerate(backbones):
            if not isinstance(b, Backbone):
                raise ValueError(f"BackboneSet item {i} is a {type(b).__name__}, not a Backbone")
            curves.append(b if b.label else dataclasses.replace(b, label=f"curve{i}"))
        labels = [b.label for b in curves]
        duplicated = sorted({x for x in labels if labels.count(x) > 1})
        if duplicated:
            raise ValueError(f"BackboneSet: duplicated curve labels {duplicated}")
        self._curves: tuple[Backbone, ...] = tuple(curves)

    def __len__(self) -> int:
        return len(self._curves)

    def __getitem__(self, key):  # int, slice or label
        if isinstance(key, str):
            for b in self._curves:
                if b.label == key:
                    return b
            raise KeyError(f"no curve {key!r}; labels are {self.labels}")
        if isinstance(key, slice):
            return BackboneSet(self._curves[key])
        return self._curves[key]

    def __iter__(self) -> Iterator[Backbone]:
        return iter(self._curves)

    def __repr__(self) -> str:
        return f"<BackboneSet: {len(self)} curves>"

    @property
    def labels(self) -> list[str]:
        return [b.label for b in self._curves]

    def common_range(self) -> tuple[float, float]:
        """Amplitude interval (m) covered by every curve."""
        if not self._curves:
            raise ValueError("BackboneSet is empty")
        lo = max(b.amplitude_range_m[0] for b in self._curves)
        hi = min(b.amplitude_range_m[1] for b in self._curves)
        if lo >= hi:
            raise ValueError(
                f"the curves share no amplitude range (largest minimum {1e3 * lo:.6g} mm ≥ "
                f"smallest maximum {1e3 * hi:.6g} mm)"
            )
        return lo, hi

    def frequency_matrix(self, amplitudes_m: ArrayLike, extrapolate: bool = False) -> np.ndarray:
        """``(n_curves, n_amplitudes)`` frequencies (Hz) at common amplitudes (m)."""
        return np.array([b.frequency_at(amplitudes_m, extrapolate) for b in self._curves])

    def damping_matrix(self, amplitudes_m: ArrayLike, extrapolate: bool = False) -> np.ndarray:
        """``(n_curves, n_amplitudes)`` damping ratios at common amplitudes (m)."""
        return np.array([b.damping_at(amplitudes_m, extrapolate) for b in self._curves])

    # -------------------------------------------------------------- tables
    def to_table(self) -> pd.DataFrame:
        """Tidy table, one row per point, columns :data:`TABLE_COLUMNS` (NaN where absent)."""
        frames = []
        for b in self._curves:
            missing = np.full(len(b), np.nan)
            frames.append(
                pd.DataFrame(
                    {
                        "curve": b.label,
                        "excitation_level": missing
                        if b.excitation_level is None
                        else b.excitation_level,
                        "amplitude_mm": b.amplitude_mm,
                        "frequency_hz": b.frequency_hz,
                        "damping_ratio": b.damping_ratio,
                        "phase_error_deg": missing
                        if b.phase_error_deg is None
                        else b.phase_error_deg,
                        "source": b.source,
                    }
                )
            )
        if not frames:
            return pd.DataFrame(columns=list(TABLE_COLUMNS))
        return pd.concat(frames, ignore_index=True)

    @classmethod
    def from_table(cls, table: pd.DataFrame, source: str = "table") -> BackboneSet:
        """Inverse of :meth:`to_table`; ``excitation_level``, ``phase_error_deg`` and
        ``source`` are optional columns. Curves keep their order of first appearance."""
        missing = [c for c in _REQUIRED_COLUMNS if c not in table.columns]
        if missing:
            raise ValueError(f"{source}: missing column(s) {missing}; needs {_REQUIRED_COLUMNS}")
        curves = []
        for label, rows in table.groupby("curve", sort=False):
            fields = {}
            for column in ("excitation_level", "phase_error_deg"):
                values = rows.get(column)
                fields[column] = None if values is None or values.isna().all() else values
            try:
                curves.append(
                    Backbone(
                        amplitude_m=1e-3 * pd.to_numeric(rows["amplitude_mm"]).to_numpy(),
                        frequency_hz=pd.to_numeric(rows["frequency_hz"]).to_numpy(),
                        damping_ratio=pd.to_numeric(rows["damping_ratio"]).to_numpy(),
                        label=str(label),
                        source=str(rows["source"].iloc[0]) if "source" in rows else source,
                        **fields,
                    )
                )
            except ValueError as exc:
                raise ValueError(f"{source}: curve {label!r}: {exc}") from None
        return cls(curves)

    def to_csv(self, path: str | Path) -> Path:
        """Write :meth:`to_table` as CSV (atomically, full float precision)."""
        return atomic_write_text(path, self.to_table().to_csv(index=False))

    @classmethod
    def from_csv(cls, path: str | Path) -> BackboneSet:
        """Read a CSV written by :meth:`to_csv`."""
        path = Path(path)
        if not path.is_file():
            raise ValueError(f"{path}: backbone table not found")
        try:
            table = pd.read_csv(path, keep_default_na=True, dtype={"curve": str, "source": str})
        except (ValueError, pd.errors.ParserError) as exc:
            raise ValueError(f"{path}: not a readable CSV table ({exc})") from None
        table["source"] = table["source"].fillna("") if "source" in table else ""
        return cls.from_table(table, source=str(path))

    # ------------------------------------------------------------- figures
    def plot(self, ax=None):
        """Frequency (Hz) and damping ratio (%) against amplitude (mm).

        Parameters
        ----------
        ax
            Two matplotlib axes (frequency, damping); a new figure when None.

        Returns
        -------
        The two axes.
        """
        if ax is None:
            import matplotlib.pyplot as plt  # plotting is optional at import time

            _, ax = plt.subplots(1, 2, figsize=(10, 4), constrained_layout=True)
        freq_ax, damp_ax = ax
        for b in self._curves:
            (line,) = freq_ax.plot(b.amplitude_mm, b.frequency_hz, marker=".", label=b.label)
            damp_ax.plot(b.amplitude_mm, 100 * b.damping_ratio, marker=".", color=line.get_color())
        freq_ax.set(xlabel="amplitude (mm)", ylabel="frequency (Hz)")
        damp_ax.set(xlabel="amplitude (mm)", ylabel="damping ratio (%)")
        if 1 < len(self._curves) <= 12:
            freq_ax.legend(fontsize="small")
        return freq_ax, damp_ax


# ---------------------------------------------------------------------------
# Extraction


class ShortHoldError(ValueError):
    """A hold phase has fewer periods than asked for."""

    def __init__(self, periods: float, n_periods: int) -> None:
        super().__init__(f"holds {periods:.1f} periods, fewer than n_periods = {n_periods}")
        self.periods = periods


@dataclass(frozen=True)
class HoldPoint:
    """Backbone point of one hold phase (see the module notes for the definitions)."""

    amplitude_m: float
    frequency_hz: float
    damping_ratio: float
    phase_error_deg: float
    periods: int


def hold_window(
    time_s: np.ndarray, frequency_hz: np.ndarray, n_periods: int
) -> tuple[int, np.ndarray, float]:
    """The last ``n_periods`` periods of a hold: first sample, phase from 0, mean ω.

    The phase is ``2π ∫ f dt`` of the instantaneous-frequency channel, so the
    window spans whole periods of the excitation even while the PLL moves.

    Raises
    ------
    ValueError
        If the frequency channel is not positive; :class:`ShortHoldError` if the
        hold has fewer than ``n_periods`` periods.
    """
    if (frequency_hz <= 0).any():
        raise ValueError("the frequency channel is not positive")
    phase = 2 * np.pi * cumulative_trapezoid(frequency_hz, time_s, initial=0.0)
    periods = (phase[-1] - phase[0]) / (2 * np.pi)
    if periods < n_periods:
        raise ShortHoldError(periods, n_periods)
    start = int(np.searchsorted(phase, phase[-1] - 2 * np.pi * n_periods, side="right") - 1)
    phi = phase[start:] - phase[start]
    return start, phi, float(phi[-1] / (time_s[-1] - time_s[start]))


def fourier_basis(phi: np.ndarray, harmonics: int) -> np.ndarray:
    """Columns ``[1, cos kφ…, sin kφ…]`` for ``k = 1..harmonics``."""
    k = np.arange(1, harmonics + 1)
    return np.column_stack([np.ones_like(phi), np.cos(np.outer(phi, k)), np.sin(np.outer(phi, k))])


def hold_point(
    time_s: np.ndarray,
    excitation_velocity: np.ndarray,
    response_velocity: np.ndarray,
    frequency_hz: np.ndarray,
    n_periods: int = 70,
    harmonics: int = 3,
) -> HoldPoint:
    """Backbone point from the last ``n_periods`` periods of one hold phase.

    Parameters
    ----------
    time_s, excitation_velocity, response_velocity, frequency_hz
        Samples of the hold phase: time, base velocity, centre velocity relative
        to the base, instantaneous excitation frequency.
    n_periods
        Whole periods used, counted back from the end of the hold.
    harmonics
        Harmonics fitted along with the fundamental (and a constant) so that
        their leakage through a window of a non-integer number of samples per
        period does not bias the fundamental.

    Raises
    ------
    ValueError
        If the frequency channel is not positive or the hold holds fewer than
        ``n_periods`` periods.
    """
    start, phi, omega = hold_window(time_s, frequency_hz, n_periods)
    basis = fourier_basis(phi, harmonics)
    signals = np.column_stack([excitation_velocity[start:], response_velocity[start:]])
    coef = np.linalg.lstsq(basis, signals, rcond=None)[0]
    # v = a cos φ + b sin φ = Re((a − ib) e^{iφ})
    base, relative = coef[1] - 1j * coef[1 + harmonics]
    if relative == 0 or base == 0:
        raise ValueError("no measurable response (zero fundamental)")
    ratio = relative / base
    phase_error = np.degrees(np.angle(ratio * 1j))  # arg(V/V_b) + 90°, wrapped
    damping = np.real(-1j * base * np.conj(relative)) / (2 * abs(relative) ** 2)
    return HoldPoint(
        amplitude_m=abs(relative) / omega,
        frequency_hz=omega / (2 * np.pi),
        damping_ratio=float(damping),
        phase_error_deg=float(phase_error),
        periods=n_periods,
    )


def _hold_samples(record: Record, hold: Hold) -> slice:
    t = record.time_s
    return slice(np.searchsorted(t, hold.start_s, "left"), np.searchsorted(t, hold.end_s, "right"))


def extract_backbone(
    record: Record, n_periods: int = 70, harmonics: int = 3, strict: bool = True
) -> Backbone:
    """Backbone of a record: one point per hold phase of its step schedule.

    Parameters
    ----------
    record
        A phase-resonance record.
    n_periods
        Periods at the end of each hold phase used for its point (NLtest uses 70).
    harmonics
        Harmonics fitted besides the fundamental (see :func:`hold_point`).
    strict
        Hold phases shorter than ``n_periods`` periods raise a ValueError; when
        False they use their whole periods instead, with a warning.

    Raises
    ------
    ValueError
        Naming the record file and the level of a hold phase that is too short,
        has no data, a non-positive frequency channel, or a response that is not
        near phase quadrature with the excitation (|phase error| > 90°, i.e.
        negative power input: check the channel signs).
    """
    for name, value in (("n_periods", n_periods), ("harmonics", harmonics)):
        if not isinstance(value, int | np.integer) or value < 1:
            raise ValueError(f"{name} must be an integer ≥ 1, got {value!r}")
    holds = record.steps.holds()
    where = record.path or record.name
    if not holds:
        raise ValueError(
            f"{where}: the step schedule {record.steps.source} has no hold phase "
            "(no two consecutive rows with the same level)"
        )
    points, levels = [], []
    for hold in holds:
        rows = _hold_samples(record, hold)
        context = f"{where}: hold phase at level {hold.level:g} ({hold.start_s:g}–{hold.end_s:g} s)"
        if rows.stop - rows.start < 4 * (2 * harmonics + 1):
            raise ValueError(f"{context} has too few samples ({rows.stop - rows.start})")
        args = (
            record.time_s[rows],
            record.excitation_velocity[rows],
            record.response_velocity[rows],
            record.frequency_hz[rows],
        )
        try:
            point = hold_point(*args, n_periods=n_periods, harmonics=harmonics)
        except ShortHoldError as exc:
            whole = int(exc.periods)
            if strict or whole < 1:
                raise ValueError(f"{context} {exc}") from None
            warnings.warn(f"{context} {exc}; using its {whole} whole periods", stacklevel=2)
            point = hold_point(*args, n_periods=whole, harmonics=harmonics)
        except ValueError as exc:
            raise ValueError(f"{context}: {exc}") from None
        if not (np.isfinite(point.damping_ratio) and point.amplitude_m > 0):
            raise ValueError(f"{context}: no measurable response (zero fundamental)")
        if abs(point.phase_error_deg) > 90:
            raise ValueError(
                f"{context}: response is {point.phase_error_deg:+.1f}° from phase resonance "
                "(negative power input): check the signs of the velocity channels"
            )
        points.append(point)
        levels.append(hold.level)
    return Backbone(
        amplitude_m=[p.amplitude_m for p in points],
        frequency_hz=[p.frequency_hz for p in points],
        damping_ratio=[p.damping_ratio for p in points],
        excitation_level=levels,
        phase_error_deg=[p.phase_error_deg for p in points],
        label=record.name,
        source=str(where),
    )


def extract_backbones(
    records: Iterable[Record],
    n_periods: int = 70,
    harmonics: int = 3,
    strict: bool = True,
    progress: bool = False,
) -> BackboneSet:
    """Backbones of every record of a campaign (see :func:`extract_backbone`)."""
    if progress:
        from tqdm.auto import tqdm

        records = tqdm(records, desc="backbones", unit="record")
    return BackboneSet(
        extract_backbone(r, n_periods=n_periods, harmonics=harmonics, strict=strict)
        for r in records
    )
