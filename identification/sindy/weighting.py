"""How much each regression row counts: an error model of the records, and row weights from it.

**Why.** Ordinary least squares and a held-out mean square weigh every sample
alike. A free decay holds most of its squared force in its first tenth, so it
is fitted and cross-validated on its start alone: each fold's error is that of
whichever block holds the start, the folds' standard error equals their mean,
and the one-standard-error rule picks the sparsest admissible support however
wrong it is at the small amplitudes. Stepped levels of a resonance test over a
decade do the same in a milder way.

**The error model.** The residual of the regression has a part proportional to
the local force amplitude (gain errors of the filters and differences, physics
the library renders imperfectly: relative errors) and a part that is not
(sensor noise). With ``e(t)`` the local amplitude of the target ``y = ẍ + a_base``
(:func:`force_envelope`), its variance is modelled as
``σ²(t) = floor² + relative² · e(t)²`` (:class:`ErrorModel`), fitted to the
residual of a least-squares fit of a broad reference library
(:func:`fit_error_model`). Each row divided by ``σ(t)`` (feasible generalised
least squares, :func:`row_sigma`) makes every amplitude count by its accuracy:
where relative errors dominate, each amplitude counts alike (the error is
normalised by the block's own force scale); rows lost in the noise count as
little as the noise leaves them. A held-out mean square of the weighted residual
is then about 1 for a model as good as the reference, and larger where a model
fails at any amplitude.
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np
from scipy.optimize import nnls

from identification.measurements.signals import Kinematics, amplitude_envelope, lowpass

#: Amplitude bins (equal counts of samples) the squared residual is averaged over.
N_BINS = 16
#: Smallest floor, relative to the largest force amplitude (a noise-free record must not
#: give infinite weight to its decayed tail).
MIN_FLOOR = 1e-9


@dataclass(frozen=True)
class ErrorModel:
    """Residual standard deviation ``σ = sqrt(floor² + (relative · e)²)`` at force amplitude ``e``.

    Attributes
    ----------
    floor
        Amplitude-independent part (m/s²): sensor noise in the band.
    relative
        Part per unit force amplitude (dimensionless).
    """

    floor: float
    relative: float

    def sigma(self, envelope: np.ndarray) -> np.ndarray:
        """Residual standard deviation (m/s²) at force amplitudes ``envelope`` (m/s²)."""
        return np.sqrt(self.floor**2 + (self.relative * envelope) ** 2)

    def text(self) -> str:
        """One line for reports."""
        return f"noise floor {self.floor:.3g} m/s², relative error {self.relative:.3g}"


def force_envelope(kin: Kinematics) -> np.ndarray:
    """Local amplitude of ``y = ẍ + a_base`` (m/s²) over the valid samples.

    :func:`~identification.measurements.signals.amplitude_envelope` with its
    low-pass at a quarter of the band's lower edge (well below the fundamental).
    """
    y = kin.absolute_acceleration
    return amplitude_envelope(y, kin.sampling_rate_hz, kin.band_hz[0] / 4)[kin.valid]


def fit_error_model(
    kins: Sequence[Kinematics], residuals: Sequence[np.ndarray], envelopes: Sequence[np.ndarray]
) -> ErrorModel:
    """The error model of a reference fit's residuals (valid samples of each record).

    The squared residual is smoothed like the envelope (same low-pass), averaged
    over :data:`N_BINS` amplitude bins of equal sample counts, and fitted by
    ``floor² + relative² e²`` in relative terms: non-negative least squares
    reweighted by the inverse prediction (a few passes), so that the bins of
    small amplitude, whose squared residual is many decades smaller, count as
    much as the large ones.
    """
    squared, amplitude = [], []
    for kin, residual in zip(kins, residuals, strict=True):
        smooth = lowpass(np.square(residual), kin.sampling_rate_hz, kin.band_hz[0] / 4)
        squared.append(np.clip(smooth, 0.0, None))
    squared = np.concatenate(squared)
    amplitude = np.concatenate(envelopes)
    order = np.argsort(amplitude)
    bins = np.array_split(order, min(N_BINS, order.size))
    mean_squared = np.array([squared[b].mean() for b in bins])
    mean_e2 = np.array([np.mean(amplitude[b] ** 2) for b in bins])
    design = np.column_stack([np.ones_like(mean_e2), mean_e2])
    coefficients = nnls(design, mean_squared)[0]
    for _ in range(5):
        prediction = design @ coefficients
        if not np.all(prediction > 0):
            break
        coefficients = nnls(design / prediction[:, None], mean_squared / prediction)[0]
    floor_sq, relative_sq = coefficients
    floor = max(float(np.sqrt(floor_sq)), MIN_FLOOR * float(amplitude.max()))
    return ErrorModel(floor=floor, relative=float(np.sqrt(relative_sq)))


def row_sigma(error_model: ErrorModel, envelopes: Sequence[np.ndarray]) -> list[np.ndarray]:
    """Per record, the residual standard deviation (m/s²) at each valid sample."""
    return [error_model.sigma(e) for e in envelopes]
