"""What an identification reports: the model, how it was found, and what the data could not tell.

:class:`Identification` is the result of :func:`.identify.identify`; it is
assembled from the selected fit by :meth:`Identification.from_fit`, which also
warns (:class:`.library.CollinearityWarning`) about library columns the data
cannot tell apart.
"""

from __future__ import annotations

import itertools
import math
import warnings
from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np

from identification.effects import CATALOGUE
from identification.measurements.signals import Kinematics
from identification.model import JointModel
from identification.sindy.admissibility import Admissibility
from identification.sindy.library import (
    COLLINEARITY_WARNING,
    GROUPS,
    CollinearityWarning,
    LibraryTerm,
    column_correlation,
    library_model,
)
from identification.sindy.selection import Fit, ThresholdPath
from identification.sindy.shapes import ShapeScan
from identification.sindy.weighting import ErrorModel


@dataclass(frozen=True, eq=False)
class Identification:
    """Result of :func:`.identify.identify`: the model and how it was found.

    Attributes
    ----------
    model
        Identified :class:`~identification.model.JointModel` (SI units).
    library
        The library columns, with the shape parameters chosen.
    coefficients
        SI coefficient of every library term in the model convention
        (``ẍ + Σ c_i φ_i = −a_base``), 0 where the term was dropped.
    normalised_coefficients
        Group share ``c_i max|φ_i| / max|f_group|`` (signed): the term's peak
        over the peak force of its group (``groups``), the scale the threshold
        applies to.
    groups
        ``"conservative"`` or ``"dissipative"`` per library term (:data:`.library.GROUPS`).
    threshold
        The STLSQ thresholds used, (conservative, dissipative) group shares
        (NaN for a group the library lacks).
    threshold_method
        ``"cv"``, ``"bic"``, ``"fixed"`` or ``"none"`` (plain least squares).
    path
        Candidates along the threshold paths and their scores (``"cv"``,
        ``"bic"``), else None.
    r2
        Coefficient of determination of ``ẍ + a_base`` over the regression samples.
    residual_rms
        RMS of the regression residual (m/s²).
    held_out_error
        RMS of the cross-validated (held-out blocks) residual, each sample divided by
        the error model's standard deviation there: about 1 for a model as good as the
        reference fit at every amplitude.
    error_model
        The records' error model (:class:`.weighting.ErrorModel`) the rows are weighted by.
    shape_scans
        The scans of the shape parameters the caller did not fix (:class:`.shapes.ShapeScan`).
    inadmissible
        Why the model is not admissible (:class:`.admissibility.Admissibility`), "" if it is.
    condition_number
        Of the scaled library matrix.
    correlation
        ``(n_terms, n_terms)`` correlations between the library columns.
    peak_contribution
        Per kept term, ``max|c_i φ_i| / max|Σ c_j φ_j|`` over the data.
    inclusion_probability, ensemble_coefficients
        With ``ensemble=True``: share of bagged models that keep each term,
        and their median coefficients (SI); else None.
    offset_iterations
        Mean-offset reconstructions of the kept fit (0: none).
    band_hz
        Pass band of each record.
    n_samples
        Regression rows (all records).
    """

    model: JointModel
    library: tuple[LibraryTerm, ...]
    coefficients: dict[str, float]
    normalised_coefficients: dict[str, float]
    groups: dict[str, str]
    threshold: tuple[float, float]
    threshold_method: str
    path: ThresholdPath | None
    r2: float
    residual_rms: float
    held_out_error: float
    error_model: ErrorModel
    shape_scans: tuple[ShapeScan, ...]
    inadmissible: str
    condition_number: float
    correlation: np.ndarray
    peak_contribution: dict[str, float]
    inclusion_probability: dict[str, float] | None
    ensemble_coefficients: dict[str, float] | None
    offset_iterations: int
    band_hz: tuple[tuple[float, float], ...]
    n_samples: int

    @classmethod
    def from_fit(
        cls,
        kins: Sequence[Kinematics],
        terms: Sequence[LibraryTerm],
        fit: Fit,
        offsets: Sequence[np.ndarray | None],
        iterations: int,
        threshold: float | Sequence[float] | str | None,
        ensemble: tuple[dict[str, float], dict[str, float]] | None,
        *,
        error_model: ErrorModel,
        shape_scans: tuple[ShapeScan, ...],
        admissibility: Admissibility,
    ) -> Identification:
        """The report of the selected fit, warning about nearly collinear library columns.

        Parameters
        ----------
        kins
            Kinematics of the records fitted.
        terms
            Library columns, with the shapes chosen.
        fit
            The selected fit.
        offsets
            Per record, the mean offset of the fit (None: none).
        iterations
            Mean-offset reconstructions of the fit.
        threshold
            The ``threshold`` argument of the identification (names the method).
        ensemble
            Inclusion probabilities and median coefficients of bagged fits, or None.
        error_model, shape_scans
            The records' error model and the scans of the unfixed shapes.
        admissibility
            The checks of the records, to state whether the model passes them.
        """
        names = [t.effect for t in terms]
        correlation, condition = column_correlation(fit.design.gram)
        for i, j in itertools.combinations(range(len(names)), 2):
            if abs(correlation[i, j]) > COLLINEARITY_WARNING:
                warnings.warn(
                    f"library columns {names[i]!r} and {names[j]!r} are nearly collinear on these "
                    f"records (r = {correlation[i, j]:+.5f}): only their combination is identified",
                    CollinearityWarning,
                    stacklevel=3,  # the caller of identify_arrays
                )
        model = library_model(terms, fit.coefficients)
        inclusion, ensemble_coefficients = ensemble or (None, None)
        if threshold is None:
            method = "none"
        else:
            method = threshold if isinstance(threshold, str) else "fixed"
        dissipative = fit.design.dissipative.tolist()
        return cls(
            model=model,
            library=tuple(terms),
            coefficients=dict(zip(names, fit.coefficients.tolist(), strict=True)),
            normalised_coefficients=dict(zip(names, (-fit.xi).tolist(), strict=True)),
            groups={n: GROUPS[d] for n, d in zip(names, dissipative, strict=True)},
            threshold=(float(fit.threshold[0]), float(fit.threshold[1])),
            threshold_method=method,
            path=fit.path,
            r2=1.0 - fit.rss / fit.design.tss,
            residual_rms=math.sqrt(fit.rss / fit.design.n_rows),
            held_out_error=math.sqrt(fit.held_out),
            error_model=error_model,
            shape_scans=shape_scans,
            inadmissible=admissibility.reason(model),
            condition_number=condition,
            correlation=correlation,
            peak_contribution=_peak_contribution(model, kins, offsets),
            inclusion_probability=inclusion,
            ensemble_coefficients=ensemble_coefficients,
            offset_iterations=iterations,
            band_hz=tuple(k.band_hz for k in kins),
            n_samples=fit.design.n_rows,
        )

    @property
    def effects(self) -> list[str]:
        """Library effect names in library order."""
        return [term.effect for term in self.library]

    def collinear_pairs(self, limit: float = 0.95) -> list[tuple[str, str, float]]:
        """Pairs of library columns with ``|r| > limit``, most collinear first."""
        names = self.effects
        pairs = [(names[i], names[j], float(self.correlation[i, j]))
                 for i, j in itertools.combinations(range(len(names)), 2)
                 if abs(self.correlation[i, j]) > limit]  # fmt: skip
        return sorted(pairs, key=lambda p: -abs(p[2]))

    def summary(self) -> str:
        """Plain-text report: coefficients, shares, inclusion, fit quality, collinearity."""
        lines = [
            f"SINDy identification: {self.n_samples} samples, thresholds "
            f"{self.threshold[0]:.3g} (conservative) / {self.threshold[1]:.3g} (dissipative) "
            f"({self.threshold_method}), R² = {self.r2:.6f}, residual RMS "
            f"{self.residual_rms:.4g} m/s², held-out error {self.held_out_error:.3g} "
            f"(normalised; {self.error_model.text()}), condition number "
            f"{self.condition_number:.3g}",
            f"{'effect':<30}{'group':>13}{'coefficient':>13}{'ξ':>11}{'peak share':>12}"
            f"{'P(incl.)':>10}",
        ]
        for name in self.effects:
            share = self.peak_contribution.get(name)
            incl = None if self.inclusion_probability is None else self.inclusion_probability[name]
            lines.append(
                f"{name:<30}{self.groups[name]:>13}{self.coefficients[name]:>13.4g}"
                f"{self.normalised_coefficients[name]:>11.2e}"
                f"{'' if share is None else f'{share:.2%}':>12}"
                f"{'' if incl is None else f'{incl:.2f}':>10}"
            )
        for scan in self.shape_scans:
            lines.append("shape scanned: " + scan.text())
        if self.inadmissible:
            lines.append(f"NOT ADMISSIBLE: the model {self.inadmissible}")
        pairs = self.collinear_pairs()
        if pairs:
            lines.append("nearly collinear columns (|r| > 0.95): " + ", ".join(
                f"{a} ~ {b} (r = {r:+.4f})" for a, b, r in pairs))  # fmt: skip
        lines.append(self.model.equation())
        return "\n".join(lines)

    def __str__(self) -> str:
        return self.summary()


def _peak_contribution(
    model: JointModel, kins: Sequence[Kinematics], offsets: Sequence[np.ndarray | None]
) -> dict[str, float]:
    """Per term of ``model``, its peak force over the peak restoring force along the records."""
    peaks = {t.effect: 0.0 for t in model.terms}
    total = 0.0
    for kin, offset in zip(kins, offsets, strict=True):
        x = kin.displacement if offset is None else kin.displacement + offset
        x, v = x[kin.valid], kin.velocity[kin.valid]
        total = max(total, float(np.max(np.abs(model.restoring_force(x, v)))))
        for t in model.terms:
            peaks[t.effect] = max(peaks[t.effect], float(np.max(np.abs(
                t.coefficient * CATALOGUE[t.effect].feature(x, v, **t.shape)))))  # fmt: skip
    return {name: peak / total for name, peak in peaks.items()} if total else peaks
