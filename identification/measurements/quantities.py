"""What a test record measured: its test type, the response's quantity, the excitation's kind.

The vocabulary every reader and extractor shares, and the conversions between
the quantities of a harmonic signal.

* **Test types** (:data:`TEST_TYPES`): ``phase-resonance`` (PLL holds at the
  resonant phase, the TRC tests), ``stepped-sine`` (holds at set frequencies,
  not necessarily at resonance) and ``free-decay`` (ring-down after a release
  or after the excitation stops).
* **Sensor quantities** (:data:`QUANTITIES`): a response is a displacement (m),
  a velocity (m/s) or an acceleration (m/s²).
* **Excitation kinds** (:data:`EXCITATION_KINDS`): a base acceleration (m/s²) or
  base velocity (m/s) of a base-driven test, or a force (N) of a force-driven
  one (a voltage is read with its stated gain, N/V).

The model is ``ẍ + f(x, ẋ) = −a_base`` for base excitation and ``ẍ + f(x, ẋ) =
g·F`` for force excitation, with ``g`` the **modal forcing gain** (1/kg: the
participation of the driving point over the modal mass). Both are the same
equation with the *equivalent base acceleration* ``a_base = −g·F``; the hold
fits therefore turn every excitation into the fundamental and harmonics of an
equivalent base velocity (:func:`equivalent_base_velocity`), and the power
balance, the phase error and the backbone follow as for the TRC records.
"""

from __future__ import annotations

import numpy as np
from numpy.typing import ArrayLike

__all__ = [
    "BASE_KINDS",
    "EXCITATION_KINDS",
    "QUANTITIES",
    "TEST_TYPES",
    "UNITS",
    "check_choice",
    "derivative_order",
    "equivalent_base_velocity",
    "from_displacement",
    "mean_offsets",
    "to_velocity",
]

TEST_TYPES = ("phase-resonance", "stepped-sine", "free-decay")
QUANTITIES = ("displacement", "velocity", "acceleration")
EXCITATION_KINDS = ("base-acceleration", "base-velocity", "force")
#: Excitation kinds of a base-driven test.
BASE_KINDS = ("base-acceleration", "base-velocity")
#: SI unit of each quantity and excitation kind.
UNITS = {
    "displacement": "m",
    "velocity": "m/s",
    "acceleration": "m/s²",
    "base-acceleration": "m/s²",
    "base-velocity": "m/s",
    "force": "N",
}


def check_choice(what: str, value: str, choices: tuple[str, ...]) -> str:
    """``value`` if it is one of ``choices``, else a ValueError naming ``what`` and the choices."""
    if value not in choices:
        raise ValueError(f"{what} must be one of {', '.join(choices)}; got {value!r}")
    return value


def derivative_order(quantity: str) -> int:
    """Time derivatives of the displacement a quantity is: 0, 1 or 2."""
    return QUANTITIES.index(check_choice("quantity", quantity, QUANTITIES))


def from_displacement(phasors: ArrayLike, rate: ArrayLike, quantity: str) -> np.ndarray:
    """Phasors of ``quantity`` from displacement phasors: times ``rate ** order``.

    ``rate`` is the complex rate ``λ`` of each phasor's time dependence ``e^{λt}``
    (``ikω`` for harmonic ``k`` of a steady signal, ``k(−σ + iω)`` for a decaying
    one), so that ``d/dt`` is multiplication by ``λ``.
    """
    return np.asarray(phasors) * np.asarray(rate) ** derivative_order(quantity)


def to_velocity(phasors: ArrayLike, rate: ArrayLike, quantity: str) -> np.ndarray:
    """Velocity phasors of phasors of ``quantity`` (see :func:`from_displacement` for ``rate``)."""
    return np.asarray(phasors) * np.asarray(rate) ** (1 - derivative_order(quantity))


def equivalent_base_velocity(
    phasors: ArrayLike, rate: ArrayLike, kind: str, forcing_gain: float = 1.0
) -> np.ndarray:
    """Phasors of the base velocity that drives the model as the excitation ``phasors`` do.

    A base velocity is itself, a base acceleration ``A`` gives ``A / λ``, and a
    force ``F`` gives ``−g F / λ`` (the equivalent base acceleration is ``−g F``,
    ``g = forcing_gain`` in 1/kg); ``rate`` as in :func:`from_displacement`.
    """
    kind = check_choice("excitation kind", kind, EXCITATION_KINDS)
    phasors, rate = np.asarray(phasors), np.asarray(rate)
    if kind == "base-velocity":
        return phasors
    if kind == "base-acceleration":
        return phasors / rate
    return -forcing_gain * phasors / rate


def mean_offsets(amplitude_m: ArrayLike, mean_m: ArrayLike) -> np.ndarray:
    """Means of a displacement about its equilibrium, from the means measured at amplitudes.

    A displacement sensor's zero is not the structure's equilibrium (mounting,
    gravity, the static deflection before a release), so the equilibrium is the
    mean the record tends to at zero amplitude: a least-squares fit of the means
    by ``e + b a² (+ c a⁴ with six points or more)`` (the mean offset of a smooth
    restoring force is even in the amplitude, ``−k₂a²/(2k₁)`` to leading order),
    whose constant ``e`` is taken off. NaN means (points that did not observe
    it) stay NaN and do not enter the fit.
    """
    a = np.asarray(amplitude_m, dtype=float)
    mean = np.asarray(mean_m, dtype=float)
    seen = np.isfinite(mean)
    if seen.sum() < 2:
        return np.full_like(mean, np.nan)
    powers = [0, 2, 4] if seen.sum() >= 6 else [0, 2]
    scale = np.max(a[seen])
    basis = np.column_stack([(a[seen] / scale) ** n for n in powers])
    equilibrium = np.linalg.lstsq(basis, mean[seen], rcond=None)[0][0]
    return mean - equilibrium
