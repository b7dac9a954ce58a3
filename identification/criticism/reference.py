"""The free-form reference: the shape of what is missing, whatever it is.

The reference model is the refitted base model plus a smooth correction of every
channel against log-amplitude (:func:`identification.criticism.directions.reference_directions`),
fitted to the same data with the same likelihood. On the frequency and damping
channels it is a free-form pair of describing functions of the whole joint,

    k_eq(a) = ω(a)²,    c_eq(a) = 2 ζ(a) ω(a)        (mass-normalised, at phase resonance)

so the user sees the shape of the missing physics beside the base model's. Its
gain in ``χ²`` over the base model is what any smooth physics could gain; the
share of it a catalogue candidate captures (:func:`explained_share`) says whether
the catalogue explains the data.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from scipy.linalg import solve_triangular

from identification.criticism.calibration import Problem, Statistics
from identification.fitting.data import FitData

__all__ = ["FreeForm", "explained_share", "fit_reference"]


@dataclass(frozen=True)
class FreeForm:
    """The free-form reference's describing functions beside the base model's.

    Attributes
    ----------
    levels_m
        Amplitude levels (m).
    base_frequency_hz, base_damping_ratio
        The refitted base model's mean prediction at the levels.
    frequency_hz, damping_ratio
        The reference's (base + fitted smooth corrections).
    gain, degrees_of_freedom
        Its ``χ²`` gain over the base model and the number of independent columns.
    """

    levels_m: np.ndarray
    base_frequency_hz: np.ndarray
    base_damping_ratio: np.ndarray
    frequency_hz: np.ndarray
    damping_ratio: np.ndarray
    gain: float
    degrees_of_freedom: int

    @staticmethod
    def describing(frequency_hz: np.ndarray, damping_ratio: np.ndarray):
        """``(k_eq, c_eq)`` (1/s², 1/s) of a phase-resonant backbone."""
        omega = 2 * np.pi * np.asarray(frequency_hz)
        return omega**2, 2 * np.asarray(damping_ratio) * omega

    def to_dict(self) -> dict:
        k_base, c_base = self.describing(self.base_frequency_hz, self.base_damping_ratio)
        k_ref, c_ref = self.describing(self.frequency_hz, self.damping_ratio)
        return {
            "amplitude_mm": (1e3 * self.levels_m).tolist(),
            "k_eq_base": k_base.tolist(),
            "c_eq_base": c_base.tolist(),
            "k_eq_reference": k_ref.tolist(),
            "c_eq_reference": c_ref.tolist(),
            "frequency_hz_reference": self.frequency_hz.tolist(),
            "damping_ratio_reference": self.damping_ratio.tolist(),
            "gain": self.gain,
            "degrees_of_freedom": self.degrees_of_freedom,
        }


def fit_reference(
    problem: Problem, observed: Statistics, data: FitData, base_table: np.ndarray
) -> FreeForm:
    """The reference fitted to the observed campaign (generalised least squares on the
    base model's and the reference's directions). ``base_table`` is the base model's mean
    prediction at the levels, ``(n_levels, n_channels)``."""
    factor = observed.frame["factor"]
    columns = np.hstack([problem.base, problem.reference])
    white = solve_triangular(factor, columns, lower=True)
    target = solve_triangular(factor, problem.residual, lower=True)
    solution, *_ = np.linalg.lstsq(white, target, rcond=1e-10)
    correction = np.full(problem.metric.keep.size, np.nan)
    correction[problem.metric.keep] = (columns @ solution) / problem.metric.weights
    table = base_table + correction.reshape(base_table.shape)
    f, z = data.column("frequency_hz"), data.column("damping_ratio")
    return FreeForm(
        data.levels_m,
        base_table[:, f],
        base_table[:, z],
        table[:, f],
        table[:, z],
        float(observed.reference[0]),
        observed.reference_rank,
    )


def explained_share(
    candidate_gain: float, candidate_parameters: int, reference_gain: float, reference_dof: int
) -> float | None:
    """Share of the reference's gain a candidate captures, each less what noise alone
    would give it (its degrees of freedom), clipped to [0, 1]; None when the reference
    gains nothing beyond noise."""
    room = reference_gain - reference_dof
    if room <= 0:
        return None
    return float(np.clip((candidate_gain - candidate_parameters) / room, 0.0, 1.0))
