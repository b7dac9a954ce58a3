"""Backbone curves: containers for what the hold fits of a test measured.

A :class:`Backbone` holds one point per hold phase (or per model amplitude): the
fundamental amplitude of the relative displacement, the phase-resonance
frequency and the power-balance damping ratio (their definitions are in
:mod:`identification.measurements.extraction`), and, where the points come from
hold fits, what else those fits measured:

* ``harmonics``: orders ``h = 2..H`` of the relative displacement
  ``x = a cos θ + Σ_h (C_h cos hθ + S_h sin hθ)``, as complex fractions of the
  fundamental in the frame where the fundamental is ``a cos θ``:
  ``(C_h − i S_h) / a``; ``harmonic_standard_error`` the standard error of
  each real component, from the fit residual;
* ``excitation_harmonics``: orders ``2..H`` of the base acceleration in the same
  form, relative to *its* fundamental (the forcing's distortion);
* ``mean_offset_m``: the mean of the relative displacement where the sensor
  observes it (NaN at points where it does not, e.g. velocity sensors);
* ``time_s``: when the point was measured (the centre of its hold window, s from
  the record's start), so drift in time can be told from amplitude dependence
  where levels were stepped up and down;
* ``settled``: whether the response amplitude had settled over the window, and
  ``dropped_samples``: samples the hold fit left out as sensor spikes.

:class:`BackboneSet` writes and reads them as a tidy table (:data:`TABLE_COLUMNS`).
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
from scipy.interpolate import make_interp_spline

from identification.artifacts import atomic_write_text

__all__ = ["TABLE_COLUMNS", "Backbone", "BackboneSet", "read_backbone_table"]

_BASE_COLUMNS = (
    "curve",
    "excitation_level",
    "amplitude_mm",
    "frequency_hz",
    "damping_ratio",
    "phase_error_deg",
    "source",
)
_REQUIRED_COLUMNS = ("curve", "amplitude_mm", "frequency_hz", "damping_ratio")


def _order_columns(h: int) -> tuple[str, ...]:
    """Columns of harmonic order ``h``: the response's parts, their standard error and
    the excitation's parts."""
    return (
        f"harmonic{h}_cos",
        f"harmonic{h}_sin",
        f"harmonic{h}_se",
        f"excitation_harmonic{h}_cos",
        f"excitation_harmonic{h}_sin",
    )


#: Columns of :meth:`BackboneSet.to_table`, in order, with harmonics of orders 2 and 3
#: (what :func:`~identification.measurements.extraction.extract_backbone` fits by
#: default); curves that carry higher orders add :func:`_order_columns` of each after
#: these.
TABLE_COLUMNS = (
    *_BASE_COLUMNS,
    *_order_columns(2),
    *_order_columns(3),
    "mean_offset_mm",
    "time_s",
    "settled",
    "dropped_samples",
)

# Optional per-point arrays: name → (dtype, one column per harmonic order).
_HARMONIC_FIELDS = {
    "harmonics": complex,
    "harmonic_standard_error": float,
    "excitation_harmonics": complex,
}


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
    harmonics
        ``(n_points, n_orders)`` complex harmonics ``h = 2, 3, …`` of the relative
        displacement, fractions of the fundamental (see the module notes), or None.
    harmonic_standard_error
        ``(n_points, n_orders)`` standard error of each real component of
        ``harmonics`` (fraction of the fundamental), or None (unknown).
    excitation_harmonics
        ``(n_points, n_orders)`` complex harmonics ``h = 2, 3, …`` of the base
        acceleration, fractions of its fundamental, or None.
    mean_offset_m
        Mean of the relative displacement (m) per point, NaN where the sensor does
        not observe it; None when no point does.
    time_s
        Time of each point (s from the start of its record: the centre of its hold
        window), or None.
    settled
        Whether each point's response amplitude had settled over its window, or None.
    dropped_samples
        Samples each point's hold fit dropped as sensor spikes, or None.

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
    harmonics: np.ndarray | None = None
    harmonic_standard_error: np.ndarray | None = None
    excitation_harmonics: np.ndarray | None = None
    mean_offset_m: np.ndarray | None = None
    time_s: np.ndarray | None = None
    settled: np.ndarray | None = None
    dropped_samples: np.ndarray | None = None

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
        self._check_hold_fit_arrays(where, n)

    def _check_hold_fit_arrays(self, where: str, n: int) -> None:
        """Validate and freeze the optional arrays of the hold fits."""
        for name, dtype in _HARMONIC_FIELDS.items():
            values = getattr(self, name)
            if values is None:
                continue
            try:
                array = np.array(values, dtype=dtype)
            except (TypeError, ValueError):
                raise ValueError(f"{where}: {name} must be numbers, got {values!r}") from None
            if array.ndim == 1:  # one order
                array = array.reshape(-1, 1)
            if array.ndim != 2 or array.shape[0] != n or array.shape[1] == 0:
                raise ValueError(
                    f"{where}: {name} has shape {array.shape}, expected ({n}, n_orders): one "
                    "row per point, a column per harmonic order from 2"
                )
            bad = np.argwhere(~np.isfinite(array))
            if bad.size:
                raise ValueError(f"{where}: {name}[{bad[0][0]}, {bad[0][1]}] is not finite")
            array.setflags(write=False)
            object.__setattr__(self, name, array)
        se = self.harmonic_standard_error
        if se is not None:
            if self.harmonics is None or se.shape != self.harmonics.shape:
                raise ValueError(
                    f"{where}: harmonic_standard_error needs harmonics of the same shape"
                    f" ({None if self.harmonics is None else self.harmonics.shape})"
                )
            if (se < 0).any():
                raise ValueError(f"{where}: harmonic_standard_error is negative")
        if self.mean_offset_m is not None:
            offset = np.array(self.mean_offset_m, dtype=float).reshape(-1)
            if offset.size != n or np.isinf(offset).any():
                raise ValueError(
                    f"{where}: mean_offset_m must have {n} values, finite or NaN (unobserved)"
                )
            offset.setflags(write=False)
            # A curve no point of which observes its mean is a curve without one.
            object.__setattr__(self, "mean_offset_m", None if np.isnan(offset).all() else offset)
        self._check_hold_flags(where, n)

    def _check_hold_flags(self, where: str, n: int) -> None:
        """Validate and freeze the time, settling and dropped-sample arrays."""
        for name, dtype in (("time_s", float), ("settled", bool), ("dropped_samples", int)):
            values = getattr(self, name)
            if values is None:
                continue
            raw = np.asarray(values).reshape(-1)
            array = raw.astype(dtype)
            if raw.size != n or (raw.dtype.kind == "f" and not np.isfinite(raw).all()):
                raise ValueError(f"{where}: {name} must have {n} finite values, got {values!r}")
            if dtype is not float and not (array == raw).all():
                raise ValueError(f"{where}: {name} must be {dtype.__name__} values, got {values!r}")
            if name == "dropped_samples" and (array < 0).any():
                raise ValueError(f"{where}: dropped_samples must be ≥ 0")
            array.setflags(write=False)
            object.__setattr__(self, name, array)

    def __len__(self) -> int:
        return self.amplitude_m.size

    @property
    def amplitude_mm(self) -> np.ndarray:
        return 1e3 * self.amplitude_m

    @property
    def harmonic_orders(self) -> tuple[int, ...]:
        """Orders of the columns of :attr:`harmonics` (empty without harmonics)."""
        return () if self.harmonics is None else tuple(range(2, 2 + self.harmonics.shape[1]))

    def without_harmonics(self) -> Backbone:
        """The curve without the response's and the excitation's harmonics."""
        return dataclasses.replace(
            self, harmonics=None, harmonic_standard_error=None, excitation_harmonics=None
        )

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

    def without_harmonics(self) -> BackboneSet:
        """The curves without their harmonics: what the backbones alone show."""
        return BackboneSet(b.without_harmonics() for b in self._curves)

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
        """Tidy table, one row per point, columns :data:`TABLE_COLUMNS` (NaN where absent).

        Harmonics are split into their cosine (real) and sine (minus imaginary)
        parts; orders above 3 that some curve carries add their columns.
        """
        n_orders = max([2, *(len(b.harmonic_orders) for b in self._curves)])
        orders = range(2, 2 + n_orders)
        columns = TABLE_COLUMNS + tuple(c for h in orders[2:] for c in _order_columns(h))
        frames = []
        for b in self._curves:
            missing = np.full(len(b), np.nan)
            frame = {
                "curve": b.label,
                "excitation_level": missing if b.excitation_level is None else b.excitation_level,
                "amplitude_mm": b.amplitude_mm,
                "frequency_hz": b.frequency_hz,
                "damping_ratio": b.damping_ratio,
                "phase_error_deg": missing if b.phase_error_deg is None else b.phase_error_deg,
                "source": b.source,
                "mean_offset_mm": missing if b.mean_offset_m is None else 1e3 * b.mean_offset_m,
                "time_s": missing if b.time_s is None else b.time_s,
                "settled": [None] * len(b) if b.settled is None else b.settled,
                "dropped_samples": missing if b.dropped_samples is None else b.dropped_samples,
            }
            for prefix, values in (("harmonic", b.harmonics),
                                   ("excitation_harmonic", b.excitation_harmonics)):  # fmt: skip
                for m, h in enumerate(orders):
                    inside = values is not None and m < values.shape[1]
                    frame[f"{prefix}{h}_cos"] = values[:, m].real if inside else missing
                    frame[f"{prefix}{h}_sin"] = -values[:, m].imag if inside else missing
            se = b.harmonic_standard_error
            for m, h in enumerate(orders):
                inside = se is not None and m < se.shape[1]
                frame[f"harmonic{h}_se"] = se[:, m] if inside else missing
            frames.append(pd.DataFrame(frame, columns=list(columns)))
        if not frames:
            return pd.DataFrame(columns=list(TABLE_COLUMNS))
        return pd.concat(frames, ignore_index=True)

    @classmethod
    def from_table(cls, table: pd.DataFrame, source: str = "table") -> BackboneSet:
        """Inverse of :meth:`to_table`; every column but :data:`_REQUIRED_COLUMNS` is
        optional (tables written before the harmonics were kept still read).
        Curves keep their order of first appearance."""
        missing = [c for c in _REQUIRED_COLUMNS if c not in table.columns]
        if missing:
            raise ValueError(f"{source}: missing column(s) {missing}; needs {_REQUIRED_COLUMNS}")
        curves = []
        for label, rows in table.groupby("curve", sort=False):
            fields = {}
            for column in ("excitation_level", "phase_error_deg"):
                values = rows.get(column)
                fields[column] = None if values is None or values.isna().all() else values
            fields |= _hold_fit_fields(rows)
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
        return cls.from_table(read_backbone_table(path), source=str(path))

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


def _hold_fit_fields(rows: pd.DataFrame) -> dict[str, np.ndarray | None]:
    """The harmonics, their standard errors and the mean offset of one curve's rows.

    A curve carries the orders ``2..H`` whose cosine column it fills; columns a
    table lacks, or a curve leaves empty, give None.
    """

    def numbers(column: str) -> np.ndarray | None:
        if column not in rows:
            return None
        values = pd.to_numeric(rows[column]).to_numpy(dtype=float)
        return None if np.isnan(values).all() else values

    def orders(prefix: str) -> list[int]:
        found, h = [], 2
        while numbers(f"{prefix}{h}_cos") is not None:
            found.append(h)
            h += 1
        return found

    def complex_parts(prefix: str, hs: list[int]) -> np.ndarray | None:
        if not hs:
            return None
        values = np.full((len(rows), len(hs)), np.nan, dtype=complex)
        for m, h in enumerate(hs):
            values.real[:, m] = numbers(f"{prefix}{h}_cos")
            sine = numbers(f"{prefix}{h}_sin")
            if sine is not None:  # else NaN: the Backbone names the hole
                values.imag[:, m] = -sine
        return values

    response = orders("harmonic")
    errors = [numbers(f"harmonic{h}_se") for h in response]
    offset = numbers("mean_offset_mm")
    dropped = numbers("dropped_samples")
    settled = None
    if "settled" in rows and not rows["settled"].isna().all():
        words = {True: True, False: False, "True": True, "False": False}
        settled = rows["settled"].map(words).to_numpy()  # a hole stays NaN: the Backbone names it
    return {
        "time_s": numbers("time_s"),
        "settled": settled,
        "dropped_samples": dropped,
        "harmonics": complex_parts("harmonic", response),
        "harmonic_standard_error": None
        if not errors or any(e is None for e in errors)
        else np.column_stack(errors),
        "excitation_harmonics": complex_parts("excitation_harmonic", orders("excitation_harmonic")),
        "mean_offset_m": None if offset is None else 1e-3 * offset,
    }


def read_backbone_table(path: str | Path) -> pd.DataFrame:
    """The table of a backbone CSV (:meth:`BackboneSet.to_csv`, or the modal table of
    ``pm-joint backbones --modes N``), curves and sources as text.

    Raises
    ------
    ValueError
        No such file, or not a readable CSV table.
    """
    path = Path(path)
    if not path.is_file():
        raise ValueError(f"{path}: backbone table not found")
    try:
        table = pd.read_csv(path, keep_default_na=True, dtype={"curve": str, "source": str})
    except (ValueError, pd.errors.ParserError) as exc:
        raise ValueError(f"{path}: not a readable CSV table ({exc})") from None
    table["source"] = table["source"].fillna("") if "source" in table else ""
    return table
