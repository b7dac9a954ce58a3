"""How well an identified model holds: against the record, the measured backbone, a reference.

:func:`validate` simulates the model under the record's measured base
excitation and compares velocity and acceleration (the paper's section 4.1.3);
:func:`backbone_error` compares its harmonic-balance backbone with measured
backbone points; :func:`comparison_table` sets its coefficients beside a
reference model's.
"""

from __future__ import annotations

from collections.abc import Mapping
from dataclasses import dataclass

import numpy as np
from numpy.typing import ArrayLike

from identification.analytical import harmonic, pll
from identification.measurements.signals import Kinematics, bandpass
from identification.model import JointModel
from identification.sindy.report import Identification


@dataclass(frozen=True)
class ErrorStatistics:
    """Error of a predicted signal against the measured one (paper section 4.1.3)."""

    mean: float
    max_abs: float
    rmse: float
    relative_rmse: float  # rmse / RMS of the measured signal

    @classmethod
    def of(cls, measured: np.ndarray, predicted: np.ndarray) -> ErrorStatistics:
        """Statistics of ``predicted − measured``."""
        error = predicted - measured
        rmse = float(np.sqrt(np.mean(error**2)))
        return cls(float(np.mean(error)), float(np.max(np.abs(error))), rmse,
                   rmse / float(np.sqrt(np.mean(measured**2))))  # fmt: skip


@dataclass(frozen=True, eq=False)
class Validation:
    """Open-loop simulation of a model under the measured base excitation, against the record."""

    t: np.ndarray
    measured_velocity: np.ndarray
    predicted_velocity: np.ndarray
    measured_acceleration: np.ndarray
    predicted_acceleration: np.ndarray
    velocity: ErrorStatistics
    acceleration: ErrorStatistics


def validate(model: JointModel, kin: Kinematics) -> Validation:
    """Simulate ``model`` under the record's base acceleration and compare.

    The simulation (:func:`identification.analytical.pll.simulate_base_excitation`)
    starts from the record's first displacement and velocity; its velocity and
    acceleration pass the record's band-pass, so that both sides are compared
    in the same band, and are compared over the valid samples.
    """
    _, v, a = pll.simulate_base_excitation(
        model, kin.t, kin.base_acceleration, x0=kin.displacement[0], v0=kin.velocity[0]
    )
    if not np.all(np.isfinite(v)):
        raise ValueError("the model's response to the measured base excitation diverges")
    predicted = bandpass(np.column_stack([v, a]), kin.sampling_rate_hz, kin.band_hz)[kin.valid]
    measured_v, measured_a = kin.velocity[kin.valid], kin.acceleration[kin.valid]
    return Validation(
        t=kin.t[kin.valid],
        measured_velocity=measured_v,
        predicted_velocity=predicted[:, 0],
        measured_acceleration=measured_a,
        predicted_acceleration=predicted[:, 1],
        velocity=ErrorStatistics.of(measured_v, predicted[:, 0]),
        acceleration=ErrorStatistics.of(measured_a, predicted[:, 1]),
    )


def backbone_error(
    model: JointModel,
    amplitude_m: ArrayLike,
    frequency_hz: ArrayLike,
    *,
    method: str = "single",
) -> np.ndarray:
    """Relative frequency error of the model's harmonic-balance backbone at measured points.

    ``harmonic.backbone(model, amplitude_m).frequency_hz / frequency_hz − 1``
    (NaN where the harmonic balance found no phase-resonant solution).
    """
    amplitude_m = np.asarray(amplitude_m, dtype=float)
    frequency_hz = np.asarray(frequency_hz, dtype=float)
    if amplitude_m.shape != frequency_hz.shape:
        raise ValueError(f"amplitude_m {amplitude_m.shape} and frequency_hz "
                         f"{frequency_hz.shape} must have the same shape")  # fmt: skip
    predicted = harmonic.backbone(model, amplitude_m, method=method).frequency_hz
    return predicted / frequency_hz - 1.0


def comparison_table(
    identification: Identification,
    reference: JointModel,
    labels: Mapping[str, str] | None = None,
) -> str:
    """Identified coefficients beside a reference model's (e.g. the paper's Eq. 3).

    One row per effect of the library or the reference: its label (``labels``,
    e.g. :data:`.library.EQ3_SYMBOLS`), reference and identified coefficients
    (model convention, SI) and the relative error ("spurious" for a term the
    reference does not have).
    """
    labels = labels or {}
    names = list(dict.fromkeys([*identification.effects, *reference.effects]))
    lines = [f"{'effect':<30}{'symbol':>10}{'reference':>13}{'identified':>13}{'error':>9}"]
    for name in names:
        ref = reference.coefficient(name)
        got = identification.coefficients.get(name, 0.0)
        error = f"{got / ref - 1:+.1%}" if ref else ("" if got == 0 else "spurious")
        lines.append(f"{name:<30}{labels.get(name, ''):>10}{ref:>13.4g}{got:>13.4g}{error:>9}")
    return "\n".join(lines)
