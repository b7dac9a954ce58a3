"""The words of the criticism: physical readings of fitted candidates.

A reading says what the fitted effect itself does in this test (its own change
of frequency, damping and harmonics, when above the scatter), the fitted term
with its sign and size, and then — only for an admissible fit — that this is
*consistent with* the catalogue's physical reading
(:attr:`identification.effects.Effect.reading`) and what the fitted numbers say.
An inadmissible fit (negative friction, cancelling terms) gets no physical story,
only what makes it inadmissible.
"""

from __future__ import annotations

from collections.abc import Mapping, Sequence

import numpy as np

from identification.effects import CATALOGUE
from identification.fitting.data import HARMONIC_ORDERS, FitData
from identification.fitting.least_squares import fit_scale
from identification.model import JointModel

#: Channel (or harmonic order) → (name in words, unit in words, factor from SI to that unit).
CHANNEL_LABELS = {
    "frequency_hz": ("frequency", "Hz", 1.0),
    "damping_ratio": ("damping", "%-points", 100.0),
    "harmonic2": ("2nd harmonic", "% of the fundamental", 100.0),
    "harmonic3": ("3rd harmonic", "% of the fundamental", 100.0),
}


def _reading(
    effect: str,
    model: JointModel,
    own: Mapping[str, np.ndarray],
    data: FitData,
    problems: Sequence[str] = (),
) -> str:
    """What the fitted effect does in this test, its fitted term, and the catalogue reading
    it is consistent with (none when ``problems`` make the fit inadmissible).

    ``own`` is the effect's contribution per channel at the levels (the refitted
    model with and without it); changes below twice the standard error of the
    measured mean are not mentioned.
    """
    amplitudes_mm = 1e3 * data.levels_m
    _, se = data.level_mean(data.values)
    phrases = []
    f = own["frequency_hz"] - own["frequency_hz"][0]
    i = int(np.argmax(np.abs(f)))
    if abs(f[i]) > 2 * np.median(se[:, 0]):
        verb = "softening" if f[i] < 0 else "hardening"
        phrases.append(f"frequency {verb} by {abs(f[i]):.2g} Hz up to {amplitudes_mm[i]:.2g} mm")
    d = own["damping_ratio"]
    i = int(np.argmax(np.abs(d)))
    if abs(d[i]) > 2 * np.median(se[:, 1]):
        what = "adding" if d[i] > 0 else "removing"
        phrases.append(
            f"damping {_trend(d)}, {what} up to {100 * abs(d[i]):.2g} %-points at "
            f"{amplitudes_mm[i]:.2g} mm"
        )
    if data.has_harmonics and all(f"harmonic{o}_cos" in own for o in HARMONIC_ORDERS):
        for order in HARMONIC_ORDERS:
            q = np.hypot(own[f"harmonic{order}_cos"], own[f"harmonic{order}_sin"])
            i = int(np.argmax(q))
            if q[i] > 2 * data.noise_floor["harmonics"]:
                ordinal = {2: "2nd", 3: "3rd"}[order]
                phrases.append(
                    f"a {ordinal} harmonic of {100 * q[i]:.2g} % of the fundamental at "
                    f"{amplitudes_mm[i]:.2g} mm"
                )
    evidence = (" while ".join(phrases[:2]) + "".join(f", {p}" for p in phrases[2:])) or (
        "a change below the scatter"
    )
    term = next(t for t in model.terms if t.effect == effect)
    fitted = f"fitted {'−' if term.coefficient < 0 else '+'}{term.text(3)}"
    if problems:
        return f"{evidence} ({fitted}); not admissible as physics: {'; '.join(problems)}"
    return (
        f"{evidence} ({fitted}); consistent with {CATALOGUE[effect].reading}"
        f"{_specifics(effect, model, data)}"
    )


def _trend(values: np.ndarray) -> str:
    """How a signed contribution moves with amplitude, in words."""
    peak = int(np.argmax(np.abs(values)))
    interior = 0 < peak < values.size - 1
    if interior and abs(values[-1]) < 0.7 * abs(values[peak]):
        shape = "rising then falling" if values[peak] > 0 else "falling then rising"
        return f"{shape} with amplitude"
    return "rising with amplitude" if values[-1] >= values[0] else "falling with amplitude"


def _specifics(effect: str, model: JointModel, data: FitData) -> str:
    """Fitted numbers a structural dynamicist reads directly (the effect's own words)."""
    term = next(t for t in model.terms if t.effect == effect)
    return CATALOGUE[effect].fitted_reading(term.coefficient, term.shape, fit_scale(model, data))
