"""Identification of coupled modal equations: SINDy per modal equation, energy-consistent.

``pm-joint identify --modes N`` (N ≥ 2). Each record gives ``N`` modal coordinates
``x_m`` (:mod:`.modal_coordinates`: the modal filter of its sensors, or the modes'
bands of one sensor) and the joint coordinate ``q = Σ_m φ_m x_m``. The equations of
the :class:`~identification.multimode.model.ModalModel` are regressed all at once:

    −(ẍ_m + Γ_m a_base) = ω_m² x_m + 2ζ_m ω_m ẋ_m + Σ_e c_e φ_m f_e(q, q̇) + Σ_p κ_p ∂V_p/∂x_m

**Library per modal equation.**

* The mode's own linear pair (always kept). The participation ``Γ_m`` of a base-driven
  record is fixed to :data:`PARTICIPATION`, as the one-mode model's: at phase resonance the
  base acceleration is in phase with the velocity, so only damping over participation is
  measured; 1 is the coordinate's own convention (the mode's displacement at its reference
  sensor relative to the base, as the two-mode rig defines it).
* Catalogue effects on the joint coordinate, each with **one** coefficient ``c_e`` shared by
  every equation through the weights ``φ_m`` (virtual work): a conservative element keeps
  the equations conservative, a dissipative one dissipates.
* Polynomial modal couplings from a potential: every monomial ``V_p = Π_k x_k^{p_k}`` of
  degree 3 and 4 (forces quadratic and cubic in the coordinates), each with **one**
  coefficient ``κ_p`` entering equation ``m`` as ``κ_p ∂V_p/∂x_m``. Couplings therefore
  exchange energy between the modes and never create it.

**Modal masses.** The coordinates are each mode's contribution at its reference sensor,
and every equation has unit mass in them, as the ModalModel's equations and the two-mode
rig's truth do. A potential in these coordinates is the physical one when the shapes are
mass-normalised and 1 at their reference sensors; otherwise the couplings still fit, but the
mode-to-mode ratios of a monomial's forces carry the modal masses' ratio and the potential
form constrains them wrongly (one sensor whose shapes differ per mode is the common case).

**Admissibility.** Consistent energy exchange holds by construction (above). A catalogue
effect that is a polynomial of the displacement alone (linear, quadratic and cubic
stiffness) *is* a combination of couplings on ``q``; it is read as those couplings (a
separate column would make the library rank-deficient). Effects that depend on the
velocity but are even in it (``ẋ²``, ``x·ẋ²``) neither derive from a potential nor
dissipate, and are left out. Damping must dissipate: a mode's linear damping must be
≥ 0 (else the identification fails, naming the mode), and a joint effect odd in the
velocity whose power ``c_e f_e q̇`` on the records is negative on average is dropped
from the support and the rest refitted.

Effects with a physical shape parameter (``tanh_saturation``, ``exponential``,
``stribeck_friction``, ``microslip``) need the one-mode identification's shape scan and
are left out here, with a note.

**Selection and cross-validation.** The stacked rows are weighted so that each equation
counts alike (its target's RMS) and the columns scaled to unit norm. The candidate
supports are those of sequential thresholding (pysindy's STLSQ,
:func:`.regression.stlsq`) and of backward elimination by held-out error, the linear
terms never dropped. Each is cross-validated across records (leave one record out; a
single record is cut into :data:`SINGLE_RECORD_FOLDS` blocks,
:func:`.selection.cross_validation`), and the one-standard-error rule keeps the support
with the fewest terms within one standard error of the best.
"""

from __future__ import annotations

import itertools
import math
from collections.abc import Sequence
from dataclasses import dataclass
from typing import Any

import numpy as np

from identification.effects import CATALOGUE, LINEAR_STIFFNESS, VISCOUS_DAMPING
from identification.effects.base import NUMERICAL_SHAPES
from identification.measurements.modes import Modes
from identification.multimode.model import Coupling, JointElement, ModalModel, Mode
from identification.sindy import padding
from identification.sindy.library import LibraryTerm, check_rank, is_dissipative
from identification.sindy.modal_coordinates import ModalKinematics, ModalSettings, modal_kinematics
from identification.sindy.regression import gram_factor, least_squares, stlsq
from identification.sindy.selection import cross_validation

__all__ = [
    "ModalIdentification",
    "identify_modal_kinematics",
    "identify_modes",
    "modal_library_effects",
]

#: Participation ``Γ`` of every mode (module notes).
PARTICIPATION = 1.0
#: Blocks a single record is cut into for cross-validation.
SINGLE_RECORD_FOLDS = 4
#: Lowest threshold of the path (normalised coefficient).
MIN_THRESHOLD = 1e-4


@dataclass(frozen=True)
class _Column:
    """One library column: what it is, and the coefficient it feeds."""

    name: str
    kind: str  # "stiffness", "damping", "joint", "coupling"
    mode: int = 0  # the equation, for a mode's own terms (from 0)
    term: LibraryTerm | None = None  # a joint effect
    powers: tuple[int, ...] = ()  # a potential monomial

    @property
    def always(self) -> bool:
        return self.kind in ("stiffness", "damping")


@dataclass(frozen=True, eq=False)
class ModalIdentification:
    """An N-mode identification.

    Attributes
    ----------
    model
        The identified :class:`ModalModel`.
    terms
        Names of the nonlinear columns kept (joint effects, potential monomials).
    library
        Names of every nonlinear column of the library.
    cv_error
        Cross-validated error of the kept support (normalised RMS of the weighted rows).
    left_out
        Catalogue effects of the request not in the modal library, with why.
    dropped
        Dissipative joint effects dropped for putting energy in.
    labels
        The records identified from.
    """

    model: ModalModel
    terms: tuple[str, ...]
    library: tuple[str, ...]
    cv_error: float
    left_out: tuple[str, ...]
    dropped: tuple[str, ...]
    labels: tuple[str, ...]

    def summary(self) -> str:
        """What was identified, in a few lines."""
        lines = [f"identified {self.model.n_modes} coupled modes from {len(self.labels)} "
                 f"record(s); cross-validated error {self.cv_error:.3g}"]  # fmt: skip
        for m, mode in enumerate(self.model.modes, start=1):
            lines.append(
                f"  mode {m}: {mode.frequency_hz:.5g} Hz, damping ratio "
                f"{mode.damping_ratio:.3g}, participation {mode.participation:.3g}"
            )
        kept = ", ".join(self.terms) or "none"
        lines.append(f"  nonlinear terms kept: {kept} (of {len(self.library)})")
        lines += [f"  left out: {note}" for note in self.left_out]
        lines += [f"  dropped (puts energy in): {name}" for name in self.dropped]
        return "\n".join(lines)


def modal_library_effects(effects: Sequence[str]) -> tuple[list[str], list[str]]:
    """The catalogue effects that act on the joint coordinate, and notes on the others.

    Polynomial stiffnesses are couplings; effects even in the velocity that depend on it
    are neither conservative nor dissipative (module notes).
    """
    kept, notes = [], []
    for name in effects:
        effect = CATALOGUE[name]
        term = LibraryTerm(name)
        x = np.linspace(-1e-3, 1e-3, 7)
        velocity_free = np.array_equal(term.feature(x, np.zeros(7)), term.feature(x, np.ones(7)))
        if name in (LINEAR_STIFFNESS, VISCOUS_DAMPING):
            continue  # the modes' own linear terms
        if set(effect.shape) - set(NUMERICAL_SHAPES):
            notes.append(f"{name} (a shape parameter to scan: identify it with one mode)")
            continue
        if effect.polynomial and velocity_free:
            notes.append(f"{name} (a polynomial of the displacement: read as modal couplings)")
        elif not effect.hysteretic and not velocity_free and not is_dissipative(term):
            notes.append(f"{name} (even in the velocity: neither conservative nor dissipative)")
        else:
            kept.append(name)
    return kept, notes


def _monomials(n_modes: int) -> list[tuple[int, ...]]:
    """Potential monomials of degree 3 and 4 (quadratic and cubic forces), by degree."""
    out = []
    for degree in (3, 4):
        for combo in itertools.combinations_with_replacement(range(n_modes), degree):
            out.append(tuple(combo.count(k) for k in range(n_modes)))
    return out


def _monomial_text(powers: Sequence[int]) -> str:
    superscript = {1: "", 2: "²", 3: "³", 4: "⁴"}
    return "V:" + "·".join(f"x{k + 1}{superscript[p]}" for k, p in enumerate(powers) if p)


def _columns(n_modes: int, effects: Sequence[str]) -> list[_Column]:
    columns = []
    for m in range(n_modes):
        columns += [_Column(f"mode{m + 1}.stiffness", "stiffness", m),
                    _Column(f"mode{m + 1}.damping", "damping", m)]  # fmt: skip
    columns += [_Column(f"joint.{e}", "joint", term=LibraryTerm(e)) for e in effects]
    columns += [_Column(_monomial_text(p), "coupling", powers=p) for p in _monomials(n_modes)]
    return columns


def _record_rows(kin: ModalKinematics, columns: Sequence[_Column]) -> list[np.ndarray]:
    """Per equation, ``(n_columns + 1, n_valid)`` column rows and the target ``−ẍ_m``."""
    n = len(kin.modes)
    valid, rate, band = kin.valid, kin.sampling_rate_hz, kin.band_hz
    x = np.array([k.displacement for k in kin.modes])
    # A coordinate's slow mean (a coupling's quasi-static push, x2 ~ −κx1²/2ω2²) is out of
    # the band but inside the nonlinear columns (x1·x2): a measured one is added back.
    full = np.array([k.displacement if k.mean_offset is None else k.displacement + k.mean_offset
                     for k in kin.modes])  # fmt: skip
    v = np.array([k.velocity for k in kin.modes])
    q, qdot = kin.joint_shape @ full, kin.joint_shape @ v
    raw_joint = {c.name: c.term.feature(q, qdot) for c in columns if c.kind == "joint"}
    filtered: dict[tuple, np.ndarray] = {}
    pending = []
    for c in columns:
        if c.kind == "joint":
            pending.append((c.name, raw_joint[c.name]))
        elif c.kind == "coupling":
            for m in range(n):
                if c.powers[m]:
                    gradient = c.powers[m] * np.prod(
                        [full[k] ** (p - (k == m)) for k, p in enumerate(c.powers)], axis=0
                    )
                    pending.append(((c.name, m), gradient))
    if pending:
        # One band-pass for the library as for the data (one filter on both sides).
        stacked = padding.bandpass(np.array([values for _, values in pending]), rate, band)
        filtered = {key: row[valid] for (key, _), row in zip(pending, stacked, strict=True)}
    out = []
    for m in range(n):
        rows = np.zeros((len(columns) + 1, valid.stop - valid.start))
        for i, c in enumerate(columns):
            if c.kind == "stiffness" and c.mode == m:
                rows[i] = x[m][valid]
            elif c.kind == "damping" and c.mode == m:
                rows[i] = v[m][valid]
            elif c.kind == "joint":
                rows[i] = kin.joint_shape[m] * filtered[c.name]
            elif c.kind == "coupling" and c.powers[m]:
                rows[i] = filtered[(c.name, m)]
        rows[-1] = -kin.modes[m].absolute_acceleration[valid]
        out.append(rows)
    return out


class _Problem:
    """The weighted, scaled Gram matrices of every cross-validation block."""

    def __init__(self, kins: Sequence[ModalKinematics], columns: Sequence[_Column]) -> None:
        per_record = [_record_rows(k, columns) for k in kins]
        n_modes = len(kins[0].modes)
        # Each equation counts alike: its rows over its target's RMS over all records.
        weights = [1.0 / math.sqrt(np.mean(np.concatenate([r[m][-1] for r in per_record]) ** 2))
                   for m in range(n_modes)]  # fmt: skip
        blocks = []
        for rows in per_record:
            weighted = np.hstack([w * r for w, r in zip(weights, rows, strict=True)])
            if len(per_record) > 1:
                blocks.append(weighted)
            else:
                # One record: cut each equation's rows into time blocks, alike for every mode.
                pieces = [np.array_split(w * r, SINGLE_RECORD_FOLDS, axis=1)
                          for w, r in zip(weights, rows, strict=True)]  # fmt: skip
                blocks += [np.hstack(parts) for parts in zip(*pieces, strict=True)]
        grams = [b @ b.T for b in blocks]
        self.sizes = np.array([b.shape[1] for b in blocks])
        total = sum(grams)
        norms = np.sqrt(np.diag(total))
        if not np.all(norms[:-1] > 0):
            empty = [c.name for c, s in zip(columns, norms, strict=False) if not s > 0]
            raise ValueError(f"library column(s) {empty} are zero on these records")
        self.scale = np.append(1.0 / norms[:-1], 1.0)
        self.grams = [g * np.outer(self.scale, self.scale) for g in grams]
        self.total = sum(self.grams)
        self.target = float(self.total[-1, -1])
        self.columns = list(columns)

    def cv_error(self, support: np.ndarray) -> float:
        """RMS of the held-out residual, every block left out once, over the target's RMS."""
        score = cross_validation(self.grams, self.sizes, [support])[0][0]
        return math.sqrt(score * self.sizes.sum() / self.target)

    def fit(self, support: np.ndarray) -> np.ndarray:
        """SI coefficients of the least-squares fit on ``support``."""
        return least_squares(gram_factor(self.total), support) * self.scale[:-1]


def _threshold_path(problem: _Problem) -> list[np.ndarray]:
    """Nested supports of sequential thresholding, from the full library down to the linear."""
    always = np.array([c.always for c in problem.columns])
    factor = gram_factor(problem.total)
    lam, active = MIN_THRESHOLD, np.ones_like(always)
    supports: list[np.ndarray] = []
    while True:
        xi = stlsq(factor, np.where(always, 0.0, lam), active)
        support = (xi != 0) | always
        if supports and np.array_equal(support, supports[-1]):
            lam *= 1.05
            continue
        supports.append(support)
        optional = support & ~always
        if not optional.any():
            return supports
        active = support
        lam = max(lam, float(np.abs(xi[optional]).min())) * (1 + 1e-6)


def _backward_path(problem: _Problem) -> list[np.ndarray]:
    """Backward elimination by held-out error from the full library, the linear terms kept.

    Thresholds order terms by their normalised size, which nearly collinear columns
    misorder (a coupling and a joint effect acting through the same harmonic); the
    elimination reaches the true support from the data's side
    (as :func:`.selection.backward_path` does for one mode).
    """
    always = np.array([c.always for c in problem.columns])
    support = np.ones_like(always)
    path = [support]
    while (support & ~always).any():
        trials = [support & (np.arange(support.size) != i)
                  for i in np.flatnonzero(support & ~always)]  # fmt: skip
        errors = cross_validation(problem.grams, problem.sizes, trials)[0]
        support = trials[int(np.argmin(errors))]
        path.append(support)
    return path


def _select(problem: _Problem) -> np.ndarray:
    """The fewest terms within one standard error of the best cross-validated support."""
    candidates = {s.tobytes(): s for s in [*_threshold_path(problem), *_backward_path(problem)]}
    supports = list(candidates.values())
    score, se = cross_validation(problem.grams, problem.sizes, supports)
    best = int(np.argmin(score))
    limit = score[best] + se[best] + 1e-12 * abs(score[best])
    qualified = [i for i in range(len(supports)) if score[i] <= limit]
    return supports[min(qualified, key=lambda i: (int(supports[i].sum()), score[i]))]


def _energy_input(problem: _Problem, coefficients: np.ndarray, kins) -> list[int]:
    """Indices of dissipative joint columns whose mean power on the records is negative."""
    bad = []
    for i, c in enumerate(problem.columns):
        if c.kind != "joint" or coefficients[i] == 0 or not is_dissipative(c.term):
            continue
        power = 0.0
        for kin in kins:
            x = np.array([k.displacement for k in kin.modes])[:, kin.valid]
            v = np.array([k.velocity for k in kin.modes])[:, kin.valid]
            q, qdot = kin.joint_shape @ x, kin.joint_shape @ v
            power += float(np.mean(coefficients[i] * c.term.feature(q, qdot) * qdot))
        if power < 0:
            bad.append(i)
    return bad


def identify_modal_kinematics(
    kins: Sequence[ModalKinematics], effects: Sequence[str]
) -> ModalIdentification:
    """Identify coupled modal equations from modal kinematics (module notes).

    Raises
    ------
    ValueError
        No records, a rank-deficient library (naming the columns), or a mode whose
        stiffness or damping comes out negative.
    """
    kins = list(kins)
    if not kins:
        raise ValueError("no records given")
    n_modes = len(kins[0].modes)
    joint_effects, notes = modal_library_effects(effects)
    columns = _columns(n_modes, joint_effects)
    problem = _Problem(kins, columns)
    check_rank(problem.total, [c.name for c in columns])
    support = _select(problem).copy()
    dropped = []
    while True:
        coefficients = problem.fit(support)
        bad = _energy_input(problem, coefficients, kins)
        if not bad:
            break
        support[bad] = False
        dropped += [columns[i].name for i in bad]
    model = _model(columns, coefficients, kins, n_modes)
    return ModalIdentification(
        model=model,
        terms=tuple(c.name for c, s in zip(columns, support, strict=True) if s and not c.always),
        library=tuple(c.name for c in columns if not c.always),
        cv_error=problem.cv_error(support),
        left_out=tuple(notes),
        dropped=tuple(dropped),
        labels=tuple(k.label for k in kins),
    )


def _model(columns, coefficients, kins, n_modes: int) -> ModalModel:
    """The ModalModel of the fitted coefficients."""
    stiffness, damping = np.zeros(n_modes), np.zeros(n_modes)
    elements, couplings = [], []
    for c, value in zip(columns, coefficients, strict=True):
        if c.kind == "stiffness":
            stiffness[c.mode] = value
        elif c.kind == "damping":
            damping[c.mode] = value
        elif value and c.kind == "joint":
            elements.append(JointElement(c.term.effect, float(value), dict(c.term.shape), 1))
        elif value:
            for m, p in enumerate(c.powers):
                if p:
                    powers = tuple(e - (k == m) for k, e in enumerate(c.powers))
                    couplings.append(Coupling(m + 1, powers, float(value) * p))
    modes = []
    for m in range(n_modes):
        if not stiffness[m] > 0:
            raise ValueError(f"mode {m + 1}: the identified stiffness ω² is {stiffness[m]:.4g} "
                             "≤ 0; the modal coordinates do not hold this mode")  # fmt: skip
        if damping[m] < 0:
            raise ValueError(f"mode {m + 1}: the identified linear damping is negative "
                             f"({damping[m]:.4g} 1/s): it would put energy in")  # fmt: skip
        omega = math.sqrt(stiffness[m])
        modes.append(Mode(omega / (2 * math.pi), damping[m] / (2 * omega), PARTICIPATION))
    joint_shape = tuple(float(v) for v in np.mean([k.joint_shape for k in kins], axis=0))
    couplings.sort(key=lambda c: (c.mode, -sum(c.powers), tuple(-p for p in c.powers)))
    return ModalModel(tuple(modes), (joint_shape,), tuple(elements), tuple(couplings),
                      name=f"sindy-{n_modes}-modes")  # fmt: skip


def identify_modes(
    records: Any,
    n_modes: int,
    effects: Sequence[str],
    *,
    mode_shapes: Modes | None = None,
    settings: ModalSettings | None = None,
) -> ModalIdentification:
    """Identify ``n_modes`` coupled modal equations from records (module notes).

    Parameters
    ----------
    records
        One record or a sequence (free decays, base-driven or PLL records; one or several
        sensors), fitted jointly and cross-validated across.
    n_modes
        Modes ``N`` ≥ 2 (one mode is :func:`.identify.identify`).
    effects
        Catalogue names asked for (:func:`modal_library_effects` keeps those that act on the
        joint coordinate).
    mode_shapes
        Mode shapes at the sensors (default: the records', else estimated).
    settings
        Band, edges and joint sensor of the modal coordinates.
    """
    records = [records] if hasattr(records, "time_s") else list(records)
    if n_modes < 2:
        raise ValueError(f"identify_modes needs n_modes ≥ 2, got {n_modes}")
    kins = modal_kinematics(records, n_modes, mode_shapes=mode_shapes, settings=settings)
    return identify_modal_kinematics(kins, effects)
