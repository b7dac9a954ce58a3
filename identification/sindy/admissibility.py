"""Which models the records admit: a backbone with positive damping, and no escape from the record.

Two checks, both physical, neither about the regression error:

* **Backbone** (:func:`admissible`): a resonance test measures positive damping
  at every level (the shaker feeds power in), at levels that rise with the
  amplitude, and a free decay decays; a model
  without damping, or whose damping turns negative inside the tested range,
  contradicts the records however small its regression error, and a
  phase-locked loop cannot run it there. A model with even terms (``x²``,
  ``ẋ²``, ``exp``: the terms that explain a 2nd harmonic or a mean offset in
  the data) is judged by multi-harmonic balance, the mean included; the
  single-harmonic describing functions ignore even terms altogether (on an
  asymmetric panel they predicted hardening to 118 Hz where the data softened to
  103 Hz). A model of odd terms alone has no 2nd harmonic and no mean, so
  single-harmonic balance judges it.
* **Simulation** (:func:`diverges`): started from a record's own state, at its
  first valid sample and at its largest amplitude, under its own excitation
  (none for a free decay), the model must stay within
  :data:`DIVERGENCE_FACTOR` times the record's largest displacement for
  :data:`SIMULATION_PERIODS` periods. A model fitted to samples near a saddle
  it cannot see (``exp(x/x_s)`` with a negative ``x³``) escapes from there.

:class:`Admissibility` holds both checks for one set of records and caches its
verdicts, so that the model selection (:mod:`.selection`) asks only about the
candidates it needs.
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass, field

import numpy as np
from numpy.typing import ArrayLike

from identification.analytical import harmonic, pll
from identification.effects import CATALOGUE
from identification.measurements.signals import Kinematics, amplitude_envelope
from identification.model import JointModel

#: A simulation leaving this many times the record's largest displacement has diverged.
DIVERGENCE_FACTOR = 10.0
#: Length of each simulation, in periods of the record's band's lower edge.
SIMULATION_PERIODS = 100.0


def backbone_method(model: JointModel) -> str:
    """``"multi"`` for a model with an even or mixed term, else ``"single"`` (see module notes)."""
    return "single" if all(CATALOGUE[e].parity == "odd" for e in model.effects) else "multi"


def admissible(
    model: JointModel,
    amplitudes_m: ArrayLike,
    method: str | None = None,
    increasing_excitation: bool = False,
) -> bool:
    """Whether ``model`` has a phase-resonant backbone with positive damping at every amplitude.

    ``method`` is that of :func:`identification.analytical.harmonic.backbone`;
    by default :func:`backbone_method`. A balance that does not converge at an
    amplitude counts as no backbone there. With ``increasing_excitation`` the
    base acceleration the backbone needs must also increase with the amplitude
    (see :class:`Admissibility`).
    """
    if not model.terms:
        return False
    result = harmonic.backbone(model, amplitudes_m, method=method or backbone_method(model))
    ok = np.all(result.converged) and np.all(result.damping_ratio > 0)
    if increasing_excitation:
        ok = ok and np.all(np.diff(result.base_acceleration) > 0)
    return bool(ok)


@dataclass(frozen=True, eq=False)
class Segment:
    """A stretch of a record to simulate: its times, excitation, initial state and bound."""

    t: np.ndarray
    base_acceleration: np.ndarray
    x0_m: float
    v0_m_s: float
    limit_m: float


def record_segments(kin: Kinematics, offset: np.ndarray | None) -> list[Segment]:
    """The stretches of a record :func:`diverges` simulates: from its first valid sample and
    from its largest amplitude (when that is not inside the first; earlier where the record
    ends within a length of it), :data:`SIMULATION_PERIODS` periods each (fewer where the
    record is shorter); the displacement includes ``offset`` (the slow mean) where given."""
    x = kin.displacement if offset is None else kin.displacement + offset
    valid = np.arange(kin.valid.start, kin.valid.stop)
    length = int(np.ceil(SIMULATION_PERIODS * kin.sampling_rate_hz / kin.band_hz[0]))
    envelope = amplitude_envelope(kin.displacement, kin.sampling_rate_hz, kin.band_hz[0] / 4)
    peak = int(valid[np.argmax(envelope[valid])])
    # The peak's segment starts early enough to hold a full length where the record allows.
    late = max(int(valid[0]), min(peak, int(valid[-1]) + 1 - length))
    starts = [valid[0]] + ([late] if peak >= valid[0] + length and late > valid[0] else [])
    limit = DIVERGENCE_FACTOR * float(np.max(np.abs(x[valid])))
    segments = []
    for start in starts:
        stop = min(start + length, valid[-1] + 1)
        segments.append(Segment(kin.t[start:stop], kin.base_acceleration[start:stop],
                                float(x[start]), float(kin.velocity[start]), limit))  # fmt: skip
    return segments


def diverges(model: JointModel, segment: Segment) -> bool:
    """Whether ``model``, started in the segment's state under its excitation, leaves its bound.

    A model too stiff to integrate at the record's sampling rate
    (:func:`identification.analytical.pll.simulate_base_excitation` refuses it)
    counts as diverging: it has a frequency far above the band.
    """
    try:
        x, _, _ = pll.simulate_base_excitation(
            model, segment.t, segment.base_acceleration, x0=segment.x0_m, v0=segment.v0_m_s
        )
    except ValueError:
        return True
    return not (np.all(np.isfinite(x)) and np.max(np.abs(x)) <= segment.limit_m)


def tested_amplitudes(kins: Sequence[Kinematics], n: int = 16) -> np.ndarray:
    """Amplitudes (m) spanning the records: 2nd percentile to largest of the envelope.

    The low percentile leaves out the start-up from rest, where no level is held.
    """
    envelope = np.concatenate(
        [amplitude_envelope(k.displacement, k.sampling_rate_hz, k.band_hz[0] / 4)[k.valid]
         for k in kins]
    )  # fmt: skip
    return np.geomspace(np.percentile(envelope, 2), envelope.max(), n)


@dataclass(eq=False)
class Admissibility:
    """Both checks for one set of records, with their verdicts cached per model.

    Attributes
    ----------
    amplitudes_m
        Amplitudes over which the backbone must exist with positive damping.
    segments
        Stretches of the records to simulate (:func:`record_segments`).
    driven
        Whether the records are driven (a base acceleration or force): then the
        excitation the backbone needs must increase with the amplitude over
        ``amplitudes_m``. A driven test held its amplitudes at rising levels; a model
        whose phase-resonant excitation falls with the amplitude would have jumped
        there (a PLL cannot hold it), and no level maps onto its amplitudes for the
        surrogate's labels and the updating. On the ``trc-like`` rig the
        amplitude-weighted selection otherwise kept a friction mix (Coulomb against
        Stribeck) whose damping ratio halved between 0.05 and 0.1 mm, where the
        records measured it constant. A free decay needs no excitation: not checked.
    """

    amplitudes_m: np.ndarray
    segments: list[Segment]
    driven: bool = False
    _verdicts: dict[tuple, str] = field(default_factory=dict, repr=False)

    @classmethod
    def of(
        cls,
        kins: Sequence[Kinematics],
        offsets: Sequence[np.ndarray | None],
        amplitudes_m: np.ndarray,
    ) -> Admissibility:
        """The checks of records ``kins`` with displacement offsets ``offsets``."""
        segments = [s for k, o in zip(kins, offsets, strict=True) for s in record_segments(k, o)]
        driven = any(np.any(k.base_acceleration[k.valid] != 0) for k in kins)
        return cls(np.asarray(amplitudes_m, dtype=float), segments, driven)

    def reason(self, model: JointModel) -> str:
        """Why ``model`` is not admissible ("" if it is)."""
        key = tuple((t.effect, t.coefficient, tuple(t.shape.values())) for t in model.terms)
        if key not in self._verdicts:
            self._verdicts[key] = self._judge(model)
        return self._verdicts[key]

    def __call__(self, model: JointModel) -> bool:
        """Whether ``model`` is admissible."""
        return not self.reason(model)

    def _judge(self, model: JointModel) -> str:
        if not admissible(model, self.amplitudes_m, increasing_excitation=self.driven):
            need = ", needing an excitation rising with the amplitude," if self.driven else ""
            return (f"no backbone with positive damping{need} over "
                    f"{1e3 * self.amplitudes_m[0]:.3g}–{1e3 * self.amplitudes_m[-1]:.3g} mm "
                    f"({backbone_method(model)}-harmonic balance)")  # fmt: skip
        for segment in self.segments:
            if diverges(model, segment):
                return (f"diverges when started from the record's state at "
                        f"t = {segment.t[0]:.4g} s")  # fmt: skip
        return ""
