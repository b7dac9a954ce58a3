"""Identify a joint model from test records: input checks, weights, shapes, mean-offset iterations.

**Data.** Whole records, ramps and PLL transients included: the equation of
motion holds at every instant, not only in steady state, so no sample needs to
be thrown away; only ``edge_periods`` periods at each end, where the zero-phase
filters ring, are left out. As in the paper, the acceleration comes from the
velocity channel by central differences and the displacement by the trapezoidal
rule (:func:`~identification.measurements.signals.kinematics`); both are
zero-phase, so their small gain errors (``(ωh)²/6`` and ``(ωh)²/12``, 7e-4 and
3e-4 at 100 Hz and 10 kHz) act on the stiffness and never leak into the
damping. Displacement and acceleration sensors, and free decays without a base
channel, come through :func:`.kinematics.sensor_kinematics` and
:func:`identify_kinematics`. Several records (assemblies, runs) are fitted
jointly: the model is then their population model.

**Weights.** A least-squares fit of a broad reference library (the polynomials
up to cubic in ``(x, ẋ)`` and the library's columns of fixed shape) gives the
records' error model (:mod:`.weighting`); every fit and every held-out error of
the identification weighs the rows by it, so that each amplitude counts.

**Shapes.** Shape parameters the caller does not fix are scanned over the
records' range (:mod:`.shapes`); lists the caller gives are a grid
(:func:`.library.library_grid`) of which each library is fitted: an admissible
model beats any inadmissible one, then the held-out error decides.

**Mean offset.** A measured displacement brings its slow mean
(``Kinematics.mean_offset``). Otherwise, after each fit the slow offset implied
by the model's quasi-static balance (:func:`.library.mean_offset`) is added back
to the displacement and the fit repeated with the same support
(``offset_iterations``); the iterate with the lowest cross-validated error is
kept and its support chosen again (:func:`_fit_with_offsets`).

**What the report says.** A warning names a support with a clearly better
held-out error than the model's (:func:`.selection.better_support`); the
:class:`~.report.Identification` keeps the error model, the shape scans and
the admissibility verdict of the model.
"""

from __future__ import annotations

import math
import warnings
from collections.abc import Mapping, Sequence
from typing import Any

import numpy as np
from numpy.typing import ArrayLike

from identification.effects import CATALOGUE
from identification.measurements.signals import Kinematics, kinematics
from identification.sindy.admissibility import Admissibility, tested_amplitudes
from identification.sindy.design import Design, build_design
from identification.sindy.kinematics import sensor_kinematics
from identification.sindy.library import (
    POLYNOMIAL_LIBRARY,
    Columns,
    LibraryTerm,
    RankDeficientLibraryError,
    library_grid,
    library_model,
    mean_offset,
    shape_text,
)
from identification.sindy.regression import bagged_coefficients, gram_factor, least_squares
from identification.sindy.report import Identification
from identification.sindy.selection import Fit, better_support, refit, sparse_fit
from identification.sindy.shapes import ShapeScan, fit_scale, scan_shapes, scanned_parameters
from identification.sindy.weighting import ErrorModel, fit_error_model, force_envelope


class BetterSupportWarning(UserWarning):
    """Another support of the library has a clearly better held-out error than the model's."""


class DriveFrequencyWarning(UserWarning):
    """Records without an excitation hold one frequency and the model's linear frequency is it."""


#: Relative spread of the frequency channels (over all records) below which they hold one
#: frequency: a PLL's frequency moves with the amplitude by far more.
SINGLE_FREQUENCY_SPREAD = 1e-3
#: Relative distance of the model's linear frequency from that one frequency within which it
#: is taken for the drive's.
DRIVE_FREQUENCY_MATCH = 1e-2


def record_kinematics(record: Any, **options: Any) -> Kinematics:
    """Band-limited kinematics of a record (:class:`~identification.measurements.records.Record`
    or :class:`~identification.measurements.columns.ColumnRecord`).

    A free decay (``record.test == "free-decay"``) goes through
    :func:`.kinematics.sensor_kinematics` on the quantity as measured: filters padded by
    prediction (it starts in motion), the band from its own spectrum, and a measured
    displacement's slow mean kept (``Kinematics.mean_offset``). Driven records go
    through the velocity chain of the paper
    (:func:`~identification.measurements.signals.kinematics`). ``options`` are
    ``n_harmonics``, ``edge_periods`` and ``band_hz``.
    """
    if getattr(record, "test", "phase-resonance") == "free-decay":
        return sensor_kinematics(record.time_s, record.response, record.quantity, **options)
    return kinematics(record.time_s, record.response_velocity, record.excitation_velocity,
                      record.frequency_hz, record.sampling_rate_hz, **options)  # fmt: skip


def identify(records: Any, effects: Sequence[str], **options: Any) -> Identification:
    """Identify a joint model from test records (:class:`~.measurements.records.Record`).

    ``records`` is one record or a sequence of them, fitted jointly; all must
    share one sampling rate. ``options`` are those of :func:`identify_arrays`.
    """
    records = [records] if hasattr(records, "response_velocity") else list(records)
    if not records:
        raise ValueError("no records given")
    if any(getattr(r, "test", None) == "free-decay" for r in records):
        preprocessing = {k: options.pop(k) for k in ("n_harmonics", "edge_periods", "band_hz")
                         if k in options}  # fmt: skip
        labels = [str(r.path or r.name) for r in records]
        kins = []
        for record, label in zip(records, labels, strict=True):
            try:
                kins.append(record_kinematics(record, **preprocessing))
            except ValueError as exc:
                raise ValueError(f"{label}: {exc}") from None
        return identify_kinematics(kins, effects, labels=labels, **options)
    return identify_arrays(
        [r.time_s for r in records],
        [r.response_velocity for r in records],
        [r.excitation_velocity for r in records],
        [r.frequency_hz for r in records],
        effects,
        labels=[str(r.path or r.name) for r in records],
        **options,
    )


def identify_arrays(
    t: ArrayLike | Sequence[ArrayLike],
    response_velocity: ArrayLike | Sequence[ArrayLike],
    base_velocity: ArrayLike | Sequence[ArrayLike],
    frequency_hz: ArrayLike | Sequence[ArrayLike],
    effects: Sequence[str],
    *,
    n_harmonics: int = 3,
    edge_periods: float = 20.0,
    band_hz: tuple[float, float] | None = None,
    labels: Sequence[str] | None = None,
    **options: Any,
) -> Identification:
    """Identify a joint model from velocity arrays of one or several records.

    Each data argument is one 1-D array, or a list with one array per record
    (as in pysindy's multiple trajectories); records are fitted jointly.

    Parameters
    ----------
    t
        Sample times (s), uniformly sampled, one rate for all records.
    response_velocity
        Response-point velocity relative to the base (m/s).
    base_velocity
        Base (excitation) velocity (m/s).
    frequency_hz
        Instantaneous excitation frequency (Hz); sets the pass band.
    effects
        Catalogue names of the library columns (e.g. :data:`.library.PAPER_LIBRARY`).
    n_harmonics, edge_periods, band_hz
        Preprocessing (:func:`~identification.measurements.signals.kinematics`).
    labels
        Names of the records for error messages (file paths).
    options
        Those of :func:`identify_kinematics`.

    Returns
    -------
    Identification

    Raises
    ------
    ValueError
        Unknown effect or shape, records with different sampling rates or
        non-uniform sampling, records too short, or a rank-deficient library
        (naming the dependent columns).

    Warns
    -----
    DriveFrequencyWarning
        Records without an excitation hold one frequency and the model's linear
        frequency is it.
    """
    channels = [_as_list(c) for c in (t, response_velocity, base_velocity, frequency_hz)]
    n_records = len(channels[0])
    if any(len(c) != n_records for c in channels):
        raise ValueError(
            "t, response_velocity, base_velocity and frequency_hz must hold the same number "
            f"of records, got {[len(c) for c in channels]}"
        )
    labels = list(labels) if labels is not None else [f"record {i}" for i in range(n_records)]
    library_grid(effects, options.get("shapes"))  # bad libraries are refused before any work
    rates = [_sampling_rate(np.asarray(ti, dtype=float), label)
             for ti, label in zip(channels[0], labels, strict=True)]  # fmt: skip
    if max(rates) - min(rates) > 1e-6 * max(rates):
        listing = ", ".join(
            f"{label}: {rate:.6g} Hz" for label, rate in zip(labels, rates, strict=True)
        )
        raise ValueError(f"records have different sampling rates ({listing}); resample first")
    kins = []
    for (ti, vi, bi, fi), rate, label in zip(zip(*channels, strict=True), rates, labels,
                                             strict=True):  # fmt: skip
        try:
            kins.append(kinematics(ti, vi, bi, fi, rate, n_harmonics=n_harmonics,
                                   edge_periods=edge_periods, band_hz=band_hz))  # fmt: skip
        except ValueError as exc:
            raise ValueError(f"{label}: {exc}") from None
    result = identify_kinematics(kins, effects, labels=labels, **options)
    if not any(np.any(k.base_acceleration[k.valid]) for k in kins):
        held = [np.broadcast_to(np.asarray(f, dtype=float), k.t.shape)[k.valid]
                for f, k in zip(channels[3], kins, strict=True)]  # fmt: skip
        _warn_drive_frequency(result, held)
    return result


def _warn_drive_frequency(result: Identification, frequency_hz: Sequence[np.ndarray]) -> None:
    """:class:`DriveFrequencyWarning` when records without an excitation hold one frequency
    and the model's linear frequency is that frequency.

    At one frequency ``ω`` the band-limited response has ``ẍ = −ω² x``. With the
    excitation measured the target ``ẍ + a_base`` still pins the inertia; without it
    (a shaker whose force was not recorded) inertia and linear stiffness act through
    the same column, so a fit of steady holds gives ``ω`` as the "natural" frequency
    whatever the structure (a shaker test of a bolted beam at one frequency came out
    with R² = 0.9999).
    """
    values = np.concatenate(frequency_hz)
    if values.size == 0:
        return
    drive = float(np.median(values))
    if np.ptp(values) > SINGLE_FREQUENCY_SPREAD * drive:
        return
    model = result.model
    if model.linear_stiffness <= 0:
        return
    linear = model.linear_frequency_hz
    if abs(linear / drive - 1) <= DRIVE_FREQUENCY_MATCH:
        warnings.warn(
            f"the records hold one excitation frequency ({drive:.6g} Hz) and carry no "
            f"excitation, and the model's linear frequency ({linear:.6g} Hz) is that "
            "frequency: at one frequency and without the excitation inertia and linear "
            "stiffness cannot be told apart, so the natural frequency is not measured; "
            "give the excitation channel, or identify from a free decay",
            DriveFrequencyWarning,
            stacklevel=3,
        )


def identify_kinematics(
    kins: Sequence[Kinematics],
    effects: Sequence[str],
    *,
    shapes: Mapping[str, Mapping[str, float | Sequence[float]]] | None = None,
    threshold: float | Sequence[float] | str | None = "cv",
    ensemble: bool = False,
    n_models: int = 20,
    seed: int = 0,
    n_folds: int = 5,
    min_threshold: float = 1e-3,
    offset_iterations: int = 3,
    labels: Sequence[str] | None = None,
) -> Identification:
    """Identify a joint model from the kinematics of one or several records.

    The entry point for any sensor and test: velocity records of a resonance
    test (:func:`identify_arrays`), or displacement, velocity or acceleration of
    free decays and base-driven tests (:func:`.kinematics.sensor_kinematics`).

    Parameters
    ----------
    kins
        Band-limited kinematics of each record, one sampling rate for all.
    effects
        Catalogue names of the library columns (e.g. :data:`.library.PAPER_LIBRARY`).
    shapes
        Shape parameters per effect, ``{"tanh_saturation": {"x_s": 5e-4}}``; a
        list of values is scanned and the best-scoring combination kept
        (``{"microslip": {"k_t": [...], "F_s": [...]}}`` scans a grid). Shape
        parameters not given are scanned over the effect's own grid for the
        records' range (:mod:`.shapes`).
    threshold
        ``"cv"``, ``"bic"`` (see :mod:`.selection`), a fixed group-share
        threshold (one for both groups, or a ``(conservative, dissipative)``
        pair), or None for plain least squares on the whole library.
    ensemble
        Also bag ``n_models`` STLSQ fits (``pysindy.EnsembleOptimizer``, time
        samples drawn with replacement, ``seed``) at the chosen thresholds and
        report per-term inclusion probabilities. Consecutive samples are
        correlated, so these probabilities are optimistic; the backward
        elimination after the threshold paths is not repeated per bag.
    n_folds
        Cross-validation folds (:func:`.design.deal_blocks`).
    min_threshold
        Lowest threshold tried (a group share).
    offset_iterations
        Mean-offset reconstructions (:func:`.library.mean_offset`) after the
        first fit, for records without a measured offset; 0 disables.
    labels
        Names of the records for messages.

    Returns
    -------
    Identification

    Raises
    ------
    ValueError
        Unknown effect or shape, records with different sampling rates, or a
        rank-deficient library (naming the dependent columns).

    Warns
    -----
    BetterSupportWarning
        Another support of the library has a clearly better held-out error.
    """
    kins = list(kins)
    if not kins:
        raise ValueError("no records given")
    labels = list(labels) if labels is not None else [f"record {i}" for i in range(len(kins))]
    rates = [k.sampling_rate_hz for k in kins]
    if max(rates) - min(rates) > 1e-6 * max(rates):
        listing = ", ".join(f"{label}: {k.sampling_rate_hz:.6g} Hz"
                            for label, k in zip(labels, kins, strict=True))  # fmt: skip
        raise ValueError(f"records have different sampling rates ({listing}); resample first")
    grid = library_grid(effects, shapes)
    if n_folds < 2:
        raise ValueError(f"n_folds must be >= 2, got {n_folds}")
    if not (math.isfinite(min_threshold) and 0 < min_threshold < 1):
        raise ValueError(f"min_threshold must be in (0, 1), got {min_threshold}")
    n_effective = sum(2 * (k.band_hz[1] - k.band_hz[0]) * (k.valid.stop - k.valid.start)
                      / k.sampling_rate_hz for k in kins)  # fmt: skip
    amplitudes_m = tested_amplitudes(kins)
    scanned = scanned_parameters(effects, shapes, fit_scale(kins, amplitudes_m))
    offsets = [k.mean_offset for k in kins]
    columns = Columns(kins, offsets)
    error_model, sigma = _error_model(kins, grid[0], scanned, offsets, n_folds, columns)
    fixed = dict(kins=kins, n_folds=n_folds, sigma=sigma, amplitudes_m=amplitudes_m,
                 selection=dict(threshold=threshold, n_effective=n_effective,
                                min_threshold=min_threshold),
                 offset_iterations=offset_iterations)  # fmt: skip
    best, refused = None, []
    for terms in grid:
        try:
            terms, scans = _scan(kins, terms, scanned, offsets, n_folds, sigma, columns)
            fitted_shapes = [len(scanned.get(t.effect, ())) for t in terms]
            candidate = _fit_with_offsets(terms, columns, fitted_shapes=fitted_shapes, **fixed)
        except RankDeficientLibraryError as exc:
            if len(grid) == 1:
                raise
            refused.append(f"{shape_text(terms)} ({exc})")
            continue
        fit, admissibility = candidate[1], candidate[4]
        # An admissible model beats any inadmissible one, then the held-out error decides.
        rank = (not admissibility(library_model(terms, fit.coefficients)), fit.held_out)
        if best is None or rank < best[0]:
            best = (rank, candidate, scans)
    if best is None:
        raise RankDeficientLibraryError("every shape of the grid gives a rank-deficient library: "
                                        + "; ".join(refused))  # fmt: skip
    if refused:
        warnings.warn("shape grid points skipped: " + "; ".join(refused), stacklevel=2)
    (terms, fit, offsets, iterations, admissibility), scans = best[1], best[2]
    _warn_better_support(fit, terms, admissibility)
    bagged = _bagged(fit, [t.effect for t in terms], n_models, seed) if ensemble else None
    return Identification.from_fit(kins, terms, fit, offsets, iterations, threshold, bagged,
                                   error_model=error_model, shape_scans=tuple(scans),
                                   admissibility=admissibility)  # fmt: skip


def _as_list(values: Any) -> list[np.ndarray]:
    """One array per record, from one record's array or a list of records' arrays."""
    if isinstance(values, np.ndarray) and values.ndim == 1:
        return [values]
    values = list(values)
    if values and np.ndim(values[0]) == 0:  # one record given as a plain list of numbers
        return [np.asarray(values, dtype=float)]
    return [np.asarray(v, dtype=float) for v in values]


def _sampling_rate(t: np.ndarray, label: str) -> float:
    """Sampling rate (Hz) of a time axis; ValueError if it is not uniformly sampled."""
    if t.ndim != 1 or t.size < 3:
        raise ValueError(f"{label}: t must be 1-D with at least 3 samples")
    steps = np.diff(t)
    rate = (t.size - 1) / (t[-1] - t[0])
    if not np.all(np.isfinite(steps)) or np.any(np.abs(steps * rate - 1) > 1e-3):
        raise ValueError(f"{label}: t is not uniformly sampled (steps {steps.min():.6g} to "
                         f"{steps.max():.6g} s)")  # fmt: skip
    return float(rate)


def _error_model(
    kins: Sequence[Kinematics],
    terms: Sequence[LibraryTerm],
    scanned: Mapping[str, Any],
    offsets: Sequence[np.ndarray | None],
    n_folds: int,
    columns: Columns,
) -> tuple[ErrorModel, list[np.ndarray]]:
    """The records' error model, and the residual standard deviation at each valid sample.

    From the least-squares residual of the reference library: the polynomials
    up to cubic in ``(x, ẋ)`` and the library's columns that are not scanned.
    """
    reference = {t.effect: t for t in terms if t.effect not in scanned}
    for name in POLYNOMIAL_LIBRARY:
        reference.setdefault(name, LibraryTerm(name))
    design = build_design(kins, list(reference.values()), offsets, n_folds, columns=columns)
    residuals = design.residuals(least_squares(gram_factor(design.gram)))
    envelopes = [force_envelope(k) for k in kins]
    error_model = fit_error_model(kins, residuals, envelopes)
    return error_model, [error_model.sigma(e) for e in envelopes]


def _scan(
    kins: Sequence[Kinematics],
    terms: tuple[LibraryTerm, ...],
    scanned: Mapping[str, Mapping[str, np.ndarray]],
    offsets: Sequence[np.ndarray | None],
    n_folds: int,
    sigma: Sequence[np.ndarray],
    columns: Columns,
) -> tuple[tuple[LibraryTerm, ...], list[ShapeScan]]:
    """The library with the scanned shapes chosen (:func:`.shapes.scan_shapes`), and the scans."""
    if not any(t.effect in scanned for t in terms):
        return terms, []
    fixed = [t for t in terms if t.effect not in scanned]
    design = build_design(kins, fixed, offsets, n_folds, sigma, columns)
    chosen, scans = scan_shapes(kins, design, terms, scanned, offsets)
    kept = [t for t in terms if t.effect not in scanned or t.effect in chosen]
    return tuple(LibraryTerm(t.effect, {**t.shape, **chosen.get(t.effect, {})})
                 for t in kept), scans  # fmt: skip


def _fit_with_offsets(
    terms: tuple[LibraryTerm, ...],
    columns: Columns,
    *,
    kins: Sequence[Kinematics],
    n_folds: int,
    sigma: Sequence[np.ndarray],
    amplitudes_m: np.ndarray,
    selection: dict[str, Any],
    offset_iterations: int,
    fitted_shapes: Sequence[int],
) -> tuple[tuple[LibraryTerm, ...], Fit, list[np.ndarray | None], int, Admissibility]:
    """Fit, then refit with the mean offset each fit implies; keep the best iterate.

    Records with a measured offset keep it. The support is chosen on the first
    fit and held while the offset is iterated, and chosen again on the kept
    design. Iterates are compared by their cross-validated error: the in-sample
    residual would favour spurious terms that mimic the missing offset. The
    iteration stops early when the model has no even term (nothing shifts the
    mean) or its coefficients settle.
    """
    offsets = list(columns.offsets)

    def design_of(columns: Columns) -> Design:
        return build_design(kins, terms, columns.offsets, n_folds, sigma, columns)

    admissibility = Admissibility.of(kins, offsets, amplitudes_m)
    fit = first = sparse_fit(design_of(columns), terms, admissibility=admissibility,
                             fitted_shapes=fitted_shapes, **selection)  # fmt: skip
    best = (fit, offsets, 0, admissibility)
    unmeasured = [k.mean_offset is None for k in kins]
    for iteration in range(1, offset_iterations + 1):
        model = library_model(terms, fit.coefficients)
        if (not any(unmeasured) or model.linear_stiffness <= 0
                or all(CATALOGUE[e].parity == "odd" for e in model.effects)):  # fmt: skip
            break
        offsets = [mean_offset(model, k) if u else o
                   for k, u, o in zip(kins, unmeasured, offsets, strict=True)]  # fmt: skip
        columns = columns.with_offsets(offsets)
        previous, fit = fit, refit(design_of(columns), first)
        if fit.held_out < best[0].held_out:
            best = (fit, offsets, iteration, None)
        if np.allclose(fit.coefficients, previous.coefficients, rtol=1e-3, atol=0):
            break
    fit, offsets, iteration, admissibility = best
    if iteration:
        admissibility = Admissibility.of(kins, offsets, amplitudes_m)
        fit = sparse_fit(fit.design, terms, admissibility=admissibility,
                         fitted_shapes=fitted_shapes, **selection)  # fmt: skip
    return terms, fit, offsets, iteration, admissibility


def _warn_better_support(
    fit: Fit, terms: Sequence[LibraryTerm], admissibility: Admissibility
) -> None:
    """:class:`BetterSupportWarning` naming a clearly better support, if there is one."""
    found = better_support(fit, terms, admissibility)
    if found is None:
        return
    support, error = found

    def names(mask: np.ndarray) -> str:
        return "{" + ", ".join(t.effect for t, m in zip(terms, mask, strict=True) if m) + "}"

    warnings.warn(
        f"support {names(support)} has a clearly better held-out error "
        f"({math.sqrt(error):.3g}) than the identified model's {names(fit.support)} "
        f"({math.sqrt(fit.held_out):.3g}; normalised RMS, 1 = the reference fit's error): "
        "the model may be missing a term or carrying an imitation of one",
        BetterSupportWarning,
        stacklevel=3,  # the caller of identify_kinematics
    )


def _bagged(
    fit: Fit, names: Sequence[str], n_models: int, seed: int
) -> tuple[dict[str, float], dict[str, float]]:
    """Inclusion probability and median SI coefficient per term of bagged STLSQ fits."""
    rows = np.hstack(fit.design.weighted_rows())
    bagged = bagged_coefficients(rows[:-1].T, rows[-1], fit.design.thresholds(fit.threshold),
                                 n_models, seed)  # fmt: skip
    inclusion = dict(zip(names, np.mean(bagged != 0, axis=0).tolist(), strict=True))
    median = fit.design.model_coefficients(np.median(bagged, axis=0))
    return inclusion, dict(zip(names, median.tolist(), strict=True))
