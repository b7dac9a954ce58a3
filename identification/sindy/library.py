"""The SINDy library: catalogue columns along a record, and how alike they are on the data.

A column is a catalogue effect with fixed shape parameters (:class:`LibraryTerm`);
a library is a list of them, and a shape grid gives one library per combination
of scanned shape values (:func:`library_grid`).

**One filter on both sides.** The target ``y = ẍ + a_base`` is band-limited
(first three harmonics), so every library column passes the same zero-phase
band-pass before the regression (:func:`design_matrix`). A column's harmonics
above the band would otherwise have nothing to match (Coulomb's square wave
keeps only 90 % of its energy in harmonics 1 and 3, which would bias its
coefficient by about 10 %), and its slow mean (x², ẋ²) nothing to balance.

**Mean offset.** An asymmetric stiffness shifts the mean of the relative
displacement with the amplitude; velocity data cannot show that offset, and
without it the cubic term leaks into the quadratic one (a relative bias of about
``−1.5 c₃ a² / k`` on the quadratic coefficient, with ``c₃`` the cubic one and
``k`` the linear stiffness: −11 % for a 3 % cubic frequency shift).
:func:`mean_offset` gives the offset a model implies, to be added back to the
displacement before the columns are built.

**Collinearity.** Terms that data of this kind cannot tell apart are reported,
not hidden: ``x²`` and ``ẋ²`` act only through the second harmonic, with a ratio
``−ω²`` that barely changes over a resonance test (|r| ≈ 0.99–0.9996 in the
tests); ``x·|x|``, ``x³`` and ``x`` (or ``ẋ·|ẋ|``, ``ẋ³``, ``ẋ``, Coulomb) are
separated only by their harmonics and by how they scale with amplitude
(|r| ≈ 0.96–0.97 between x·|x| and x³, and between ẋ·|ẋ| and ẋ³);
``tanh(x/x_s)`` and ``exp(x/x_s) − 1`` with ``x_s`` above the amplitudes are
nearly polynomials (|r| ≈ 0.98–0.99 with ``x``). :func:`column_correlation`
measures it, a :class:`CollinearityWarning` names pairs beyond
:data:`COLLINEARITY_WARNING`, and :func:`check_rank` refuses a library whose
columns are linearly dependent.
"""

from __future__ import annotations

import itertools
import math
from collections.abc import Mapping, Sequence
from dataclasses import dataclass, field
from typing import Any

import numpy as np

from identification.effects import CATALOGUE, Effect, get_effect
from identification.effects.base import NUMERICAL_SHAPES
from identification.effects.eq3 import EQ3
from identification.measurements.signals import Kinematics
from identification.model import JointModel, Term
from identification.sindy import padding

#: The paper's library: polynomials up to cubic in (x, ẋ) and its joint terms
#: (every catalogue effect but the hysteretic one).
PAPER_LIBRARY: tuple[str, ...] = tuple(
    name for name, effect in CATALOGUE.items() if not effect.hysteretic
)


def _monomial_order(effect: Effect) -> tuple[int, int, int]:
    """Where a polynomial effect's column goes: by degree, then the higher power of x first.

    The powers ``(i, j)`` of a monomial ``c xⁱ ẋʲ`` are read from how its force scales,
    ``φ(2, 1) = 2ⁱ φ(1, 1)`` and ``φ(1, 2) = 2ʲ φ(1, 1)`` (exact in floating point);
    a polynomial of several monomials goes after them. The catalogue index breaks ties.
    """
    force = getattr(effect.force, "py_func", effect.force)
    unit = force(1.0, 1.0, 0.0, 0.0)
    powers = []
    for x, v in ((2.0, 1.0), (1.0, 2.0)):
        ratio = abs(force(x, v, 0.0, 0.0) / unit) if unit else 0.0
        power = math.log2(ratio) if ratio > 0 else math.nan
        powers.append(round(power) if float(power).is_integer() else None)
    i, j = powers
    if i is None or j is None:
        return 4, 0, effect.index
    return i + j, -i, effect.index


#: Every monomial of degree 1 to 3 in (x, ẋ): the catalogue's polynomial effects
#: (:attr:`~identification.effects.Effect.polynomial`), by degree, x's power first.
POLYNOMIAL_LIBRARY: tuple[str, ...] = tuple(
    effect.name
    for effect in sorted((e for e in CATALOGUE.values() if e.polynomial), key=_monomial_order)
)

#: How each catalogue coefficient of the ``pandey2025`` preset reads in the paper's Eq. 3.
EQ3_SYMBOLS: dict[str, str] = {effect: coefficient.symbols for effect, coefficient in EQ3.items()}

#: The two groups of library columns, each thresholded against its own force.
GROUPS = ("conservative", "dissipative")
#: |r| between two library columns above which a :class:`CollinearityWarning` is given.
COLLINEARITY_WARNING = 0.99
#: Cutoff of the slow mean's low-pass, as a fraction of the band's lower edge. The band's
#: lower edge sits at about 0.72 of the lowest fundamental, so the order-8 low-pass
#: attenuates the fundamental by (1/0.36)^16 ≈ 1e7; a slow mean varies with the amplitude
#: (level ramps of 0.1 s, decay times of 0.1 s and more), far below the cutoff. A lower cutoff
#: only lengthens the low-pass's start transient, which the exact model's residual over the
#: start of a free decay shows.
SLOW_CUTOFF = 0.5
#: Condition number of the scaled library above which it counts as rank-deficient (the
#: Gram matrix resolves condition numbers up to about 1e8 in double precision).
RANK_DEFICIENT = 1e7


class CollinearityWarning(UserWarning):
    """Two library columns are so alike on the data that only their combination is identified."""


class RankDeficientLibraryError(ValueError):
    """Some library columns are linearly dependent on the data (the message names them)."""


@dataclass(frozen=True)
class LibraryTerm:
    """One library column: a catalogue effect with fixed shape parameters."""

    effect: str
    shape: dict[str, float] = field(default_factory=dict)

    def __post_init__(self) -> None:
        effect = get_effect(self.effect)
        values = effect.shape_values(**self.shape)  # validates names and values
        object.__setattr__(self, "shape", dict(zip(effect.shape, values, strict=False)))

    def feature(self, x: np.ndarray, v: np.ndarray) -> np.ndarray:
        """The column ``φ(x, v)`` along a path (the Jenkins force needs the whole path)."""
        return CATALOGUE[self.effect].feature(x, v, **self.shape)


def library_grid(
    effects: Sequence[str], shapes: Mapping[str, Mapping[str, Any]] | None
) -> list[tuple[LibraryTerm, ...]]:
    """Every library of the shape-parameter grid (a scalar shape value is fixed).

    Raises
    ------
    ValueError
        Unknown or repeated effects, shapes for effects outside the library,
        or shape values that are not a number or a 1-D list of numbers.
    """
    if isinstance(effects, str) or len(effects) == 0:
        raise ValueError(f"effects must be a non-empty list of catalogue names, got {effects!r}")
    for name in effects:
        get_effect(name)
    duplicates = sorted({n for n in effects if list(effects).count(n) > 1})
    if duplicates:
        raise ValueError(f"effect(s) {duplicates} appear more than once in the library")
    shapes = dict(shapes or {})
    stray = sorted(set(shapes) - set(effects))
    if stray:
        raise ValueError(f"shapes given for effect(s) {stray} that are not in the library")
    axes = []  # (effect, parameter, values)
    for name, params in shapes.items():
        for param, values in params.items():
            values = np.atleast_1d(np.asarray(values, dtype=float))
            if values.ndim != 1 or values.size == 0:
                raise ValueError(f"shape {name}.{param} must be a number or a 1-D list of numbers")
            axes.append((name, param, values))
    grid = []
    for combination in itertools.product(*(values for _, _, values in axes)):
        chosen: dict[str, dict[str, float]] = {}
        for (name, param, _), value in zip(axes, combination, strict=True):
            chosen.setdefault(name, {})[param] = float(value)
        grid.append(tuple(LibraryTerm(name, chosen.get(name, {})) for name in effects))
    return grid


def shape_text(terms: Sequence[LibraryTerm]) -> str:
    """The shape parameters of a library, as ``effect.param=value`` (for messages)."""
    return ", ".join(f"{t.effect}.{k}={v:g}" for t in terms for k, v in t.shape.items()
                     if k not in NUMERICAL_SHAPES) or "default shapes"  # fmt: skip


def library_model(terms: Sequence[LibraryTerm], coefficients: np.ndarray) -> JointModel:
    """The :class:`JointModel` of a library's SI coefficients (model convention; zeros left out)."""
    return JointModel(
        [Term(t.effect, float(c), t.shape) for t, c in zip(terms, coefficients, strict=True) if c],
        name="sindy",
    )


def is_dissipative(term: LibraryTerm) -> bool:
    """Whether a column is odd in the velocity, ``φ(x, −ẋ) = −φ(x, ẋ)`` (damping-like).

    Such terms reverse with the motion and take energy out; the others (even
    in ``ẋ``, and the Jenkins element: a stiffness with hysteresis, whose
    force follows the displacement path) store it. Checked numerically at
    points covering every sign combination of ``x`` and ``ẋ``.
    """
    x = np.linspace(-1e-3, 1e-3, 41)
    v = 0.2 * np.cos(np.linspace(0.0, 9.0, 41))
    return bool(np.allclose(term.feature(x, -v), -term.feature(x, v), rtol=1e-9, atol=0))


def design_matrix(
    kin: Kinematics, terms: Sequence[LibraryTerm], offset: np.ndarray | None = None
) -> tuple[np.ndarray, np.ndarray]:
    """Library columns and target of one record, band-passed like the data.

    Parameters
    ----------
    kin
        Band-limited kinematics of the record
        (:func:`~identification.measurements.signals.kinematics`).
    terms
        Library columns.
    offset
        Slow mean of the displacement to add back (:func:`mean_offset`), or None.

    Returns
    -------
    theta, y
        ``(n_valid, n_terms)`` columns and ``(n_valid,)`` absolute acceleration
        ``ẍ + a_base`` (m/s²) over the valid samples.
    """
    rows = design_rows(kin, terms, offset)
    return rows[:-1].T, rows[-1]


def design_rows(
    kin: Kinematics, terms: Sequence[LibraryTerm], offset: np.ndarray | None
) -> np.ndarray:
    """``(n_terms + 1, n_valid)``: the columns of :func:`design_matrix` as rows, then y."""
    rows = np.empty((len(terms) + 1, kin.valid.stop - kin.valid.start))
    rows[:-1] = feature_rows(kin, terms, offset)
    rows[-1] = regression_target(kin)
    return rows


def regression_target(kin: Kinematics) -> np.ndarray:
    """``y = ẍ + a_base`` over the valid samples.

    Not band-passed a second time: on the open-loop sweeps of ``tests/test_sindy.py``
    a second (padded) band-pass of ``y`` raised the residual of the exact model and
    made the selection keep a spurious ``x·ẋ²``.
    """
    return kin.absolute_acceleration[kin.valid]


def feature_rows(
    kin: Kinematics, terms: Sequence[LibraryTerm], offset: np.ndarray | None
) -> np.ndarray:
    """``(n_terms, n_valid)``: each column along the record, band-passed, over the valid samples."""
    x = kin.displacement if offset is None else kin.displacement + offset
    rows = np.empty((len(terms), x.size))
    for i, term in enumerate(terms):
        rows[i] = term.feature(x, kin.velocity)
    # Rows are contiguous in memory, so filtering along the last axis is the fast way.
    return padding.bandpass(rows, kin.sampling_rate_hz, kin.band_hz)[:, kin.valid]


def depends_on_displacement(term: LibraryTerm) -> bool:
    """Whether a column changes with the displacement (so with a mean offset added to it)."""
    x = np.linspace(-1e-3, 1e-3, 41)
    v = 0.2 * np.cos(np.linspace(0.0, 9.0, 41))
    return not np.array_equal(term.feature(x, v), term.feature(x + 1e-4, v))


class Columns:
    """Band-passed library columns of a set of records, each computed once.

    Building the library is most of an identification's time (a feature and a
    zero-phase band-pass per column and record); the reference fit, the shape
    scan, the shape grid and the mean-offset iterations ask for the same columns
    again. Columns that do not depend on the displacement are shared with the
    collections made for other offsets (:meth:`with_offsets`).
    """

    def __init__(
        self,
        kins: Sequence[Kinematics],
        offsets: Sequence[np.ndarray | None],
        shared: dict[tuple, list[np.ndarray]] | None = None,
    ) -> None:
        self.kins = list(kins)
        self.offsets = list(offsets)
        self._shared = {} if shared is None else shared  # displacement-independent columns
        self._own: dict[tuple, list[np.ndarray]] = {}
        self._targets: dict[int, np.ndarray] = {}

    def with_offsets(self, offsets: Sequence[np.ndarray | None]) -> Columns:
        """The columns of the same records with other displacement offsets."""
        return Columns(self.kins, offsets, self._shared)

    def rows(self, terms: Sequence[LibraryTerm]) -> list[np.ndarray]:
        """Per record, ``(n_terms + 1, n_valid)`` rows as :func:`design_rows` gives them."""
        missing = list({_key(t): t for t in terms if self._find(t) is None}.values())
        if missing:
            computed = [feature_rows(k, missing, o)
                        for k, o in zip(self.kins, self.offsets, strict=True)]  # fmt: skip
            for i, term in enumerate(missing):
                store = self._own if depends_on_displacement(term) else self._shared
                store[_key(term)] = [c[i] for c in computed]
        out = []
        for r, kin in enumerate(self.kins):
            rows = np.empty((len(terms) + 1, kin.valid.stop - kin.valid.start))
            for i, term in enumerate(terms):
                rows[i] = self._find(term)[r]
            rows[-1] = self._target(r)
            out.append(rows)
        return out

    def _target(self, record: int) -> np.ndarray:
        if record not in self._targets:
            self._targets[record] = regression_target(self.kins[record])
        return self._targets[record]

    def _find(self, term: LibraryTerm) -> list[np.ndarray] | None:
        key = _key(term)
        return self._own.get(key, self._shared.get(key))


def _key(term: LibraryTerm) -> tuple:
    return (term.effect, tuple(sorted(term.shape.items())))


def slow_cutoff_hz(band_hz: tuple[float, float]) -> float:
    """Cutoff (Hz) of the low-pass that takes the slow mean of a record: :data:`SLOW_CUTOFF`
    of the band's lower edge."""
    return SLOW_CUTOFF * band_hz[0]


def mean_offset(model: JointModel, kin: Kinematics, iterations: int = 3) -> np.ndarray:
    """Slow mean of the displacement implied by the model's quasi-static balance.

    The band-limited displacement ``x'`` has no slow part, but the true one is
    ``x' + m(t)`` with ``m`` such that the slow part of the restoring force
    vanishes: ``slow(f(x' + m, ẋ)) = 0``. Solved by the fixed point
    ``m ← m − slow(f(x' + m, ẋ)) / k_lin``, with "slow" a low-pass at
    :data:`SLOW_CUTOFF` of the band's lower edge (:func:`slow_cutoff_hz`).
    """
    k = model.linear_stiffness
    if k <= 0:
        raise ValueError(f"model has no positive linear stiffness (k = {k}); no offset defined")
    cutoff = slow_cutoff_hz(kin.band_hz)
    offset = np.zeros_like(kin.displacement)
    for _ in range(iterations):
        force = model.restoring_force(kin.displacement + offset, kin.velocity)
        offset = offset - padding.lowpass(force, kin.sampling_rate_hz, cutoff) / k
    return offset


def check_rank(gram: np.ndarray, names: Sequence[str]) -> None:
    """:class:`RankDeficientLibraryError` naming the columns when the library is rank-deficient.

    ``gram`` is the augmented Gram matrix of ``[Θ | y]``; its last row and column are ignored.
    """
    values, vectors = np.linalg.eigh(_unit_columns(gram))
    singular = np.sqrt(np.clip(values, 0.0, None))  # ascending
    if singular[0] > singular[-1] / RANK_DEFICIENT:
        return
    null = np.abs(vectors[:, 0])
    involved = [names[i] for i in np.flatnonzero(null > 0.1 * null.max())]
    condition = singular[-1] / singular[0] if singular[0] > 0 else math.inf
    raise RankDeficientLibraryError(
        f"the library is rank-deficient on these records: columns {involved} are linearly "
        f"dependent (condition number {condition:.3g}); drop all but one of them"
    )


def column_correlation(gram: np.ndarray) -> tuple[np.ndarray, float]:
    """Column correlations and condition number of the library (unit columns).

    ``gram`` is the augmented Gram matrix of ``[Θ | y]``; its last row and column are ignored.
    """
    correlation = _unit_columns(gram)
    values = np.clip(np.linalg.eigvalsh(correlation), 0.0, None)
    return correlation, float(np.sqrt(values[-1] / values[0])) if values[0] > 0 else math.inf


def _unit_columns(gram: np.ndarray) -> np.ndarray:
    """Gram of the library columns scaled to unit norm: their correlation matrix.

    The columns are band-passed, hence zero-mean, so the cosine of the angle
    between two columns is their Pearson correlation. Unit columns make the
    condition number independent of how the columns were scaled for the thresholds.
    """
    g = gram[:-1, :-1]
    norms = np.sqrt(np.diag(g))
    return g / np.outer(norms, norms)
