"""JointModel: a mass-normalised 1-DOF joint model made of catalogue effects.

The equation of motion, with x the displacement relative to the base::

    ẍ + Σ_i c_i φ_i(x, ẋ) = −a_base(t)     (base excitation)
    ẍ + Σ_i c_i φ_i(x, ẋ) = g·F(t)         (force excitation)

where each φ_i is a catalogue effect (:mod:`identification.effects`) and the
hysteretic ``microslip`` term, when present, is a Jenkins element whose force
is scaled by its coefficient. ``g`` is the **modal forcing gain** (1/kg: the
mode's participation at the driving point over its modal mass), the model's
parameter ``forcing_gain``: it links force-driven tests to base-driven ones
and free decays. Backbones (frequency and power-balance damping at each
amplitude) do not depend on it once a force-driven test's damping is in modal
units (:mod:`identification.measurements.forcing`), so it is not among the
:attr:`JointModel.parameter_names` that fits and updating move.
"""

from __future__ import annotations

import math
from collections.abc import Iterable, Mapping, Sequence
from dataclasses import dataclass, field
from typing import Any

import numpy as np

from identification.artifacts import (
    JsonDocument,
    sha256_json,
)
from identification.effects import (
    CATALOGUE,
    LINEAR_STIFFNESS,
    get_effect,
    restoring_force,
)
from identification.effects.base import NUMERICAL_SHAPES
from identification.effects.eq3 import eq3_coefficients

__all__ = ["PRESETS", "JointModel", "Term", "parameter_bounds"]

FORMAT = "pm-joint/JointModel"
FORMAT_VERSION = 1


@dataclass(frozen=True)
class Term:
    """One effect of a model with its coefficient and shape parameters."""

    effect: str
    coefficient: float
    shape: dict[str, float] = field(default_factory=dict)

    def __post_init__(self) -> None:
        effect = get_effect(self.effect)
        if not math.isfinite(self.coefficient):
            raise ValueError(f"coefficient of {self.effect!r} is not finite: {self.coefficient}")
        p0, p1 = effect.shape_values(**self.shape)  # validates names and values
        object.__setattr__(self, "coefficient", float(self.coefficient))
        object.__setattr__(self, "shape", dict(zip(effect.shape, (p0, p1), strict=False)))

    def text(self, precision: int = 4) -> str:
        """The term as it reads in an equation, coefficient included."""
        term = get_effect(self.effect).term_text(self.shape, precision)
        return f"{abs(self.coefficient):.{precision}g}·{term}"

    @property
    def hysteretic(self) -> bool:
        """Whether the term's force depends on the loading history (its state is carried)."""
        return CATALOGUE[self.effect].hysteretic


class JointModel(JsonDocument):
    """A 1-DOF joint model ``ẍ + Σ c_i φ_i(x, ẋ) = −a_base``.

    Parameters
    ----------
    terms
        Either a mapping ``{effect_name: coefficient}`` (with
        ``{effect_name: {"coefficient": c, **shape}}`` for shape parameters)
        or an iterable of :class:`Term`.
    name
        Free-text label kept in JSON files and reports.
    forcing_gain
        Modal forcing gain ``g`` (1/kg) of force excitation, when known.

    Examples
    --------
    >>> m = JointModel({"linear_stiffness": (2 * np.pi * 100) ** 2, "cubic_stiffness": 1e9})
    >>> round(m.linear_frequency_hz, 6)
    100.0
    """

    def __init__(
        self,
        terms: Mapping[str, Any] | Iterable[Term],
        name: str = "",
        forcing_gain: float | None = None,
    ) -> None:
        if isinstance(terms, Mapping):
            terms = [_term_from_entry(k, v) for k, v in terms.items()]
        terms = tuple(terms)
        seen = set()
        for t in terms:
            if t.effect in seen:
                raise ValueError(f"effect {t.effect!r} appears twice in the model")
            seen.add(t.effect)
        # Catalogue order keeps equations, parameter vectors and JSON stable.
        self.terms: tuple[Term, ...] = tuple(sorted(terms, key=lambda t: CATALOGUE[t.effect].index))
        self.name = name
        if forcing_gain is not None:
            forcing_gain = float(forcing_gain)
            if not (math.isfinite(forcing_gain) and forcing_gain > 0):
                raise ValueError(f"forcing_gain must be finite and > 0 (1/kg), got {forcing_gain}")
        self.forcing_gain = forcing_gain

    # ------------------------------------------------------------------ access
    @property
    def effects(self) -> list[str]:
        """Catalogue names of the model's effects, in catalogue order."""
        return [t.effect for t in self.terms]

    def __contains__(self, effect: str) -> bool:
        return effect in self.effects

    def __getitem__(self, effect: str) -> Term:
        for t in self.terms:
            if t.effect == effect:
                return t
        raise KeyError(f"effect {effect!r} is not in the model (it has {self.effects})")

    def coefficient(self, effect: str) -> float:
        """Coefficient of ``effect``, 0 when the model does not have it."""
        return self[effect].coefficient if effect in self else 0.0

    @property
    def stateful_terms(self) -> tuple[Term, ...]:
        """The hysteretic terms, whose state the integrators carry (catalogue order)."""
        return tuple(t for t in self.terms if t.hysteretic)

    @property
    def hysteretic_term(self) -> Term | None:
        """The model's hysteretic term (the Jenkins element the kernels carry), None if none.

        The catalogue holds one hysteretic effect
        (:data:`~identification.effects.HYSTERETIC`), so a model holds at most one.
        """
        stateful = self.stateful_terms
        return stateful[0] if stateful else None

    @property
    def has_microslip(self) -> bool:
        """Whether the model has the hysteretic Jenkins element (:attr:`hysteretic_term`)."""
        return self.hysteretic_term is not None

    @property
    def linear_stiffness(self) -> float:
        """Small-amplitude stiffness (1/s²): linear term plus the stuck hysteretic element."""
        k = self.coefficient(LINEAR_STIFFNESS)
        for term in self.stateful_terms:
            k += CATALOGUE[term.effect].stuck_stiffness(term.coefficient, term.shape)
        return k

    @property
    def linear_frequency_hz(self) -> float:
        """Natural frequency of the linearised model (Hz)."""
        k = self.linear_stiffness
        if k <= 0:
            raise ValueError(f"model has no positive linear stiffness (k = {k})")
        return math.sqrt(k) / (2 * math.pi)

    # --------------------------------------------------------------- building
    def with_effect(self, effect: str, coefficient: float, **shape: float) -> JointModel:
        """A copy with ``effect`` added; ValueError if it is already present."""
        if effect in self:
            raise ValueError(f"effect {effect!r} is already in the model")
        return self._like([*self.terms, Term(effect, coefficient, shape)])

    def without(self, effect: str) -> JointModel:
        """A copy with ``effect`` removed."""
        self[effect]
        return self._like([t for t in self.terms if t.effect != effect])

    def replace(self, **coefficients: float) -> JointModel:
        """A copy with new coefficients or shape values, by parameter name.

        Names are those of :attr:`parameter_names`, with ``.`` written ``__``
        when passed as keywords (``microslip__k_t=...``) or as a dict via
        :meth:`with_parameters`.
        """
        return self.with_parameters({k.replace("__", "."): v for k, v in coefficients.items()})

    def with_parameters(self, values: Mapping[str, float]) -> JointModel:
        """A copy with the named parameters (see :attr:`parameter_names`) set."""
        unknown = set(values) - set(self.parameter_names)
        if unknown:
            raise ValueError(
                f"unknown parameter(s) {sorted(unknown)}; the model has {self.parameter_names}"
            )
        terms = []
        for t in self.terms:
            shape = {n: values.get(f"{t.effect}.{n}", v) for n, v in t.shape.items()}
            terms.append(Term(t.effect, values.get(t.effect, t.coefficient), shape))
        return self._like(terms)

    def _like(self, terms: Iterable[Term]) -> JointModel:
        """A model of these terms with this one's name and forcing gain."""
        return JointModel(terms, name=self.name, forcing_gain=self.forcing_gain)

    def with_forcing_gain(self, forcing_gain: float | None) -> JointModel:
        """A copy with the modal forcing gain ``g`` (1/kg) of force excitation."""
        return JointModel(self.terms, name=self.name, forcing_gain=forcing_gain)

    # ------------------------------------------------------- parameter vector
    @property
    def parameter_names(self) -> list[str]:
        """Flat parameter names: each effect's coefficient, then ``effect.shape``.

        The regularising velocity ``v_reg`` of the friction terms is a numerical
        device, not a physical parameter, and is left out.
        """
        names = []
        for t in self.terms:
            names.append(t.effect)
            names += [f"{t.effect}.{n}" for n in t.shape if n not in NUMERICAL_SHAPES]
        return names

    @property
    def parameters(self) -> dict[str, float]:
        """Current value of every parameter in :attr:`parameter_names`."""
        out = {}
        for t in self.terms:
            out[t.effect] = t.coefficient
            out.update(
                {f"{t.effect}.{n}": v for n, v in t.shape.items() if n not in NUMERICAL_SHAPES}
            )
        return out

    # ---------------------------------------------------------------- physics
    def kernel_arrays(self) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """``(indices, coefficients, shapes)`` of the memoryless terms for numba kernels.

        ``shapes`` has two columns (``p0, p1`` of the force kernels). The
        hysteretic term is excluded; see :meth:`microslip_arrays`.
        """
        memoryless = [t for t in self.terms if not t.hysteretic]
        indices = np.array([CATALOGUE[t.effect].index for t in memoryless], dtype=np.int64)
        coefficients = np.array([t.coefficient for t in memoryless], dtype=np.float64)
        shapes = np.zeros((len(memoryless), 2))
        for i, t in enumerate(memoryless):
            shapes[i] = CATALOGUE[t.effect].shape_values(**t.shape)
        return indices, coefficients, shapes

    def microslip_arrays(self) -> tuple[float, float, float]:
        """``(coefficient, p0, p1)`` of the hysteretic term for the numba kernels; zeros
        when absent.

        For the Jenkins element that is ``(coefficient, k_t, F_s)``: its shape values in
        the order its force kernel takes them.
        """
        t = self.hysteretic_term
        if t is None:
            return 0.0, 0.0, 0.0
        return (t.coefficient, *CATALOGUE[t.effect].shape_values(**t.shape))

    def restoring_force(self, x: np.ndarray, v: np.ndarray) -> np.ndarray:
        """Σ c_i φ_i(x, v) along a trajectory (the microslip element starts unstressed)."""
        x = np.asarray(x, dtype=float)
        v = np.asarray(v, dtype=float)
        total = np.zeros(np.broadcast(x, v).shape)
        for t in self.terms:
            total = total + t.coefficient * CATALOGUE[t.effect].feature(x, v, **t.shape)
        return total

    def rhs(self, t: float, state: np.ndarray, base_acceleration: float) -> np.ndarray:
        """Right-hand side of the first-order system, for ODE solvers.

        ``state`` is ``[x, ẋ]``, or ``[x, ẋ, z]`` when the model has the hysteretic term,
        with ``z`` the Jenkins slider force (differential form: ż = k_t ẋ while
        sticking, 0 while slipping).
        """
        x, v = state[0], state[1]
        idx, coef, shapes = self.kernel_arrays()
        f = restoring_force(idx, coef, shapes, x, v)
        if not self.has_microslip:
            return np.array([v, -f - base_acceleration])
        c, k_t, f_s = self.microslip_arrays()
        z = state[2]
        sticking = abs(z) < f_s or z * v < 0
        return np.array([v, -f - c * z - base_acceleration, k_t * v if sticking else 0.0])

    @property
    def state_size(self) -> int:
        """Length of the state vector of :meth:`rhs`."""
        return 3 if self.has_microslip else 2

    # -------------------------------------------------------------------- text
    def equation(self, precision: int = 4) -> str:
        """The equation of motion as readable text."""
        text = "ẍ"
        for t in self.terms:
            sign = "−" if t.coefficient < 0 else "+"
            text += f" {sign} {t.text(precision)}"
        if self.forcing_gain is None:
            return text + " = −a_base(t)"
        return text + f" = −a_base(t) or g·F(t), g = {self.forcing_gain:.{precision}g} 1/kg"

    def __repr__(self) -> str:
        label = f" {self.name!r}" if self.name else ""
        return f"<JointModel{label}: {self.equation()}>"

    def __eq__(self, other: object) -> bool:
        return (
            isinstance(other, JointModel)
            and self.terms == other.terms
            and self.forcing_gain == other.forcing_gain
        )

    def __hash__(self) -> int:
        terms = tuple((t.effect, t.coefficient, tuple(t.shape.items())) for t in self.terms)
        return hash((terms, self.forcing_gain))

    # -------------------------------------------------------------------- JSON
    def _terms_json(self) -> list[dict[str, Any]]:
        return [
            {"effect": t.effect, "coefficient": t.coefficient, "shape": dict(t.shape)}
            for t in self.terms
        ]

    @property
    def content_sha256(self) -> str:
        """SHA-256 of the canonical JSON of the terms (effects, coefficients, shapes), and of
        the forcing gain where the model has one."""
        if self.forcing_gain is None:
            return sha256_json(self._terms_json())
        return sha256_json({"terms": self._terms_json(), "forcing_gain": self.forcing_gain})

    def to_dict(self) -> dict[str, Any]:
        """JSON-ready description (see :meth:`from_dict`), with :attr:`content_sha256`."""
        return {
            "format": FORMAT,
            "version": FORMAT_VERSION,
            "name": self.name,
            "equation": self.equation(),
            "terms": self._terms_json(),
            **({} if self.forcing_gain is None else {"forcing_gain": self.forcing_gain}),
            "content_sha256": self.content_sha256,
        }

    @classmethod
    def from_dict(cls, data: Mapping[str, Any], source: str = "model") -> JointModel:
        """Build a model from :meth:`to_dict` output; ValueError naming what is wrong.

        When ``data`` has a ``content_sha256`` it must match the terms read
        (:class:`~identification.artifacts.IntegrityError` otherwise); data
        without one (files written before it existed) are accepted.
        """
        if not isinstance(data, Mapping):
            raise ValueError(f"{source}: expected a JSON object, got {type(data).__name__}")
        if data.get("format", FORMAT) != FORMAT:
            raise ValueError(f"{source}: not a JointModel file (format {data.get('format')!r})")
        version = data.get("version", FORMAT_VERSION)
        if not isinstance(version, int) or version > FORMAT_VERSION:
            raise ValueError(
                f"{source}: format version {version!r} is not one this pm-joint reads "
                f"(up to {FORMAT_VERSION})"
            )
        if "terms" not in data:
            raise ValueError(f"{source}: missing field 'terms'")
        if not isinstance(data["terms"], list):
            raise ValueError(f"{source}: field 'terms' must be a list of objects")
        terms = []
        for i, entry in enumerate(data["terms"]):
            where = f"{source}: terms[{i}]"
            if not isinstance(entry, Mapping):
                raise ValueError(f"{where}: expected an object")
            for key in ("effect", "coefficient"):
                if key not in entry:
                    raise ValueError(f"{where}: missing field {key!r}")
            shape = entry.get("shape", {})
            if not isinstance(shape, Mapping):
                raise ValueError(f"{where}: field 'shape' must be an object of shape values")
            try:
                coefficient = float(entry["coefficient"])
                terms.append(Term(entry["effect"], coefficient, dict(shape)))
            except (TypeError, ValueError) as exc:
                raise ValueError(f"{where} ({entry.get('effect')!r}): {exc}") from None
        gain = data.get("forcing_gain")
        try:
            model = cls(terms, name=str(data.get("name", "")),
                        forcing_gain=None if gain is None else float(gain))  # fmt: skip
        except (TypeError, ValueError) as exc:
            raise ValueError(f"{source}: {exc}") from None
        cls.check_content(data, model, source, "the terms")
        return model

    # ----------------------------------------------------------------- presets
    @classmethod
    def preset(cls, name: str) -> JointModel:
        """A named model from :data:`PRESETS`."""
        try:
            return cls(PRESETS[name], name=name)
        except KeyError:
            raise ValueError(f"unknown preset {name!r}; available: {', '.join(PRESETS)}") from None


def _term_from_entry(effect: str, value: Any) -> Term:
    if isinstance(value, Mapping):
        value = dict(value)
        if "coefficient" not in value:
            raise ValueError(f"effect {effect!r}: missing 'coefficient'")
        coefficient = value.pop("coefficient")
        return Term(effect, coefficient, value)
    return Term(effect, value)


#: Named models. ``pandey2025`` is the paper's identified Eq. 3
#: (:mod:`identification.effects.eq3`).
PRESETS: dict[str, dict[str, Any]] = {"pandey2025": eq3_coefficients()}


def parameter_bounds(
    model: JointModel,
    names: Sequence[str],
    relative_spread: float | Mapping[str, float] = 0.2,
) -> np.ndarray:
    """``(n_params, 2)`` box ``value ± relative_spread·|value|`` around the model's parameters.

    The one box every stage draws around a model: the surrogate's training data
    and the updating's uniform priors. Rows are in the order of ``names``, each
    ``(low, high)`` whatever the sign of the value.

    Parameters
    ----------
    model
        The model whose parameter values are the centres.
    names
        Parameter names (:attr:`JointModel.parameter_names`).
    relative_spread
        One relative spread for every name, or one per name.

    Raises
    ------
    ValueError
        For an unknown name, a spread that is missing, not finite or not > 0,
        a parameter that is zero (a relative box around it is empty: give its
        bounds), and a shape parameter (a name with a dot, e.g.
        ``microslip.F_s``, which must stay positive) with a spread of 1 or more.
    """
    values = model.parameters
    rows = []
    for name in names:
        if name not in values:
            raise ValueError(f"unknown parameter {name!r}; the model has {model.parameter_names}")
        spread = (
            relative_spread.get(name) if isinstance(relative_spread, Mapping) else relative_spread
        )
        if spread is None:
            raise ValueError(f"spread: no relative spread given for parameter {name!r}")
        if not (math.isfinite(spread) and spread > 0):
            raise ValueError(f"spread of parameter {name!r} must be finite and > 0, got {spread}")
        value = values[name]
        if value == 0:
            raise ValueError(
                f"parameter {name!r} is 0 in the model: a relative spread gives an empty box; "
                "pass its bounds"
            )
        if "." in name and spread >= 1:
            raise ValueError(f"shape parameter {name!r} must stay > 0: spread {spread} must be < 1")
        rows.append(sorted((value - spread * abs(value), value + spread * abs(value))))
    return np.array(rows, dtype=float)
