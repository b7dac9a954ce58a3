"""ModalModel: N modal oscillators coupled through joint elements and polynomial couplings.

The equations of motion, in mass-normalised modal coordinates ``η_m`` with the
base acceleration ``a_base(t)`` as the excitation::

    η̈_m + 2 ζ_m ω_m η̇_m + ω_m² η_m
        + Σ_j φ_jm Σ_{e at joint j} c_e φ_e(q_j, q̇_j)       (joint elements)
        + Σ_{couplings on mode m} κ Π_k η_k^{p_k}            (modal couplings)
        = −Γ_m a_base(t),            q_j = Σ_m φ_jm η_m

with ``ω_m = 2π f_m`` the linear frequency, ``ζ_m`` the linear damping ratio,
``Γ_m`` the base participation factor of mode ``m``, ``φ_jm`` the shape of mode
``m`` at joint coordinate ``j`` and ``φ_e`` a catalogue effect
(:data:`identification.effects.CATALOGUE`). A joint element's force acts on the
modes through the same shapes that build its coordinate (virtual work), so a
conservative element keeps the modal equations conservative. Couplings are
monomials of degree 2 or 3 in the modal coordinates (geometric nonlinearity,
1:2 and 1:3 internal resonances); they are written per equation, so a coupling
derived from a potential ``V`` is entered as its ``∂V/∂η_m`` on every mode ``m``.

Modes, joints and couplings are numbered from 1, as in reports (``mode 1`` is the
first mode of :attr:`ModalModel.modes`). The JSON form is versioned
(``format: "pm-joint/ModalModel"``, version 1) and carries the SHA-256 of its
content. One-mode models keep :class:`~identification.model.JointModel` and its
format; :meth:`ModalModel.from_joint_model` gives the equivalent one-mode
``ModalModel`` (the linear pair becomes the mode, every other term a joint
element with unit shape).
"""

from __future__ import annotations

import dataclasses
import math
from collections.abc import Mapping, Sequence
from dataclasses import dataclass, field
from typing import Any

import numpy as np

from identification.artifacts import (
    JsonDocument,
    sha256_json,
)
from identification.effects import LINEAR_STIFFNESS, VISCOUS_DAMPING, get_effect
from identification.model import JointModel

__all__ = ["FORMAT", "FORMAT_VERSION", "Coupling", "JointElement", "ModalModel", "Mode"]

FORMAT = "pm-joint/ModalModel"
FORMAT_VERSION = 1


def _finite(value: Any, what: str) -> float:
    try:
        number = float(value)
    except (TypeError, ValueError):
        raise ValueError(f"{what} must be a number, got {value!r}") from None
    if not math.isfinite(number):
        raise ValueError(f"{what} must be finite, got {number}")
    return number


@dataclass(frozen=True)
class Mode:
    """A linear modal oscillator.

    Attributes
    ----------
    frequency_hz
        Linear (small-amplitude, joint elements aside) natural frequency (Hz), > 0.
    damping_ratio
        Linear viscous damping ratio ζ (≥ 0).
    participation
        Base participation factor Γ: the modal force is ``−Γ a_base``.
    """

    frequency_hz: float
    damping_ratio: float = 0.0
    participation: float = 1.0

    def __post_init__(self) -> None:
        f = _finite(self.frequency_hz, "mode frequency_hz")
        if f <= 0:
            raise ValueError(f"mode frequency_hz must be > 0, got {f}")
        zeta = _finite(self.damping_ratio, "mode damping_ratio")
        if zeta < 0:
            raise ValueError(f"mode damping_ratio must be ≥ 0, got {zeta}")
        object.__setattr__(self, "frequency_hz", f)
        object.__setattr__(self, "damping_ratio", zeta)
        object.__setattr__(self, "participation", _finite(self.participation, "participation"))


@dataclass(frozen=True)
class JointElement:
    """A catalogue effect acting on joint coordinate ``joint``: force ``c · φ(q, q̇)``.

    Attributes
    ----------
    effect
        Catalogue name (:data:`identification.effects.CATALOGUE`).
    coefficient
        Its coefficient ``c`` (units of the effect, mass-normalised).
    shape
        Shape parameters by name (defaults filled in).
    joint
        Joint coordinate the element acts on, numbered from 1.
    """

    effect: str
    coefficient: float
    shape: Mapping[str, float] = field(default_factory=dict)
    joint: int = 1

    def __post_init__(self) -> None:
        effect = get_effect(self.effect)
        what = f"element {self.effect!r}"
        object.__setattr__(self, "coefficient", _finite(self.coefficient, f"{what}: coefficient"))
        p0, p1 = effect.shape_values(**dict(self.shape))  # validates names and values
        object.__setattr__(self, "shape", dict(zip(effect.shape, (p0, p1), strict=False)))
        if isinstance(self.joint, bool) or not isinstance(self.joint, int | np.integer):
            raise ValueError(f"{what}: joint must be an integer ≥ 1, got {self.joint!r}")
        if self.joint < 1:
            raise ValueError(f"{what}: joint must be ≥ 1 (joints count from 1), got {self.joint}")
        object.__setattr__(self, "joint", int(self.joint))

    @property
    def label(self) -> str:
        """Its parameter name: ``joint{j}.{effect}``."""
        return f"joint{self.joint}.{self.effect}"


@dataclass(frozen=True)
class Coupling:
    """A polynomial modal coupling ``κ Π_k η_k^{p_k}`` in the equation of mode ``mode``.

    Attributes
    ----------
    mode
        Equation the term enters, numbered from 1.
    powers
        Exponent of every modal coordinate (one per mode); total degree 2 or 3.
    coefficient
        κ (1/(m·s²) for degree 2, 1/(m²·s²) for degree 3, per unit modal mass).
    """

    mode: int
    powers: tuple[int, ...]
    coefficient: float

    def __post_init__(self) -> None:
        if isinstance(self.mode, bool) or not isinstance(self.mode, int | np.integer):
            raise ValueError(f"coupling mode must be an integer ≥ 1, got {self.mode!r}")
        powers = tuple(self.powers)
        if not all(isinstance(p, int | np.integer) and not isinstance(p, bool) for p in powers):
            raise ValueError(f"coupling powers must be integers, got {powers!r}")
        if any(p < 0 for p in powers):
            raise ValueError(f"coupling powers must be ≥ 0, got {powers!r}")
        if sum(powers) not in (2, 3):
            raise ValueError(
                f"a coupling is quadratic or cubic in the modal coordinates: powers {powers!r} "
                f"have degree {sum(powers)}"
            )
        object.__setattr__(self, "mode", int(self.mode))
        object.__setattr__(self, "powers", tuple(int(p) for p in powers))
        object.__setattr__(self, "coefficient", _finite(self.coefficient, "coupling coefficient"))

    def text(self) -> str:
        """The monomial as it reads, e.g. ``η1²·η2``."""
        superscript = {1: "", 2: "²", 3: "³"}
        return "·".join(f"η{k + 1}{superscript[p]}" for k, p in enumerate(self.powers) if p)


@dataclass(frozen=True)
class ModalModel(JsonDocument):
    """N modal oscillators coupled through joint elements and polynomial couplings.

    Attributes
    ----------
    modes
        The modal oscillators, mode 1 first.
    joint_shapes
        ``φ_jm``: one row per joint coordinate, one entry per mode.
    elements
        Joint elements; at most one per (joint, effect).
    couplings
        Polynomial modal couplings.
    name
        Free-text label kept in JSON files.
    """

    modes: tuple[Mode, ...]
    joint_shapes: tuple[tuple[float, ...], ...]
    elements: tuple[JointElement, ...] = ()
    couplings: tuple[Coupling, ...] = ()
    name: str = ""

    def __post_init__(self) -> None:
        modes = tuple(self.modes)
        if not modes or not all(isinstance(m, Mode) for m in modes):
            raise ValueError("a ModalModel needs at least one Mode")
        n = len(modes)
        rows = tuple(tuple(_finite(v, "joint shape") for v in row) for row in self.joint_shapes)
        if any(len(row) != n for row in rows):
            raise ValueError(
                f"joint_shapes must have one entry per mode ({n}) in every row, got "
                f"{[len(row) for row in rows]}"
            )
        elements = tuple(self.elements)
        seen = set()
        for element in elements:
            if not isinstance(element, JointElement):
                raise ValueError(f"elements must be JointElement records, got {element!r}")
            if element.joint > len(rows):
                raise ValueError(
                    f"element {element.effect!r} acts on joint {element.joint}, but the model "
                    f"has {len(rows)} joint coordinate(s) (rows of joint_shapes)"
                )
            if element.label in seen:
                raise ValueError(f"element {element.label} appears twice; add the coefficients")
            seen.add(element.label)
        couplings = tuple(self.couplings)
        for coupling in couplings:
            if not isinstance(coupling, Coupling):
                raise ValueError(f"couplings must be Coupling records, got {coupling!r}")
            if len(coupling.powers) != n:
                raise ValueError(
                    f"coupling powers {coupling.powers} must have one entry per mode ({n})"
                )
            if not 1 <= coupling.mode <= n:
                raise ValueError(f"coupling acts on mode {coupling.mode}; modes are 1..{n}")
        object.__setattr__(self, "modes", modes)
        object.__setattr__(self, "joint_shapes", rows)
        object.__setattr__(self, "elements", elements)
        object.__setattr__(self, "couplings", couplings)
        object.__setattr__(self, "name", str(self.name))

    # ------------------------------------------------------------------ access
    @property
    def n_modes(self) -> int:
        return len(self.modes)

    @property
    def n_joints(self) -> int:
        return len(self.joint_shapes)

    @property
    def polynomial(self) -> bool:
        """Every force is a polynomial of degree ≤ 3 (the AFT is exact with few samples)."""
        return all(get_effect(e.effect).polynomial for e in self.elements)

    @property
    def parameter_names(self) -> list[str]:
        """Names of the scalar parameters a batch may override (see ``modal_arrays``).

        ``mode{m}.frequency_hz``, ``mode{m}.damping_ratio``, ``mode{m}.participation``,
        ``joint{j}.mode{m}`` (the shape entries), ``joint{j}.{effect}`` (element
        coefficients) and ``coupling{i}`` (coupling coefficients).
        """
        names = []
        for m in range(1, self.n_modes + 1):
            names += [f"mode{m}.frequency_hz", f"mode{m}.damping_ratio", f"mode{m}.participation"]
        for j in range(1, self.n_joints + 1):
            names += [f"joint{j}.mode{m}" for m in range(1, self.n_modes + 1)]
        names += [e.label for e in self.elements]
        names += [f"coupling{i}" for i in range(1, len(self.couplings) + 1)]
        return names

    def equation(self, mode: int) -> str:
        """The equation of motion of ``mode`` (numbered from 1), in words and symbols."""
        if not 1 <= mode <= self.n_modes:
            raise ValueError(f"mode must be 1..{self.n_modes}, got {mode}")
        m = mode - 1
        spec = self.modes[m]
        parts = [f"η{mode}'' + 2·{spec.damping_ratio:.4g}·ω{mode}·η{mode}' + ω{mode}²·η{mode}"]
        for element in self.elements:
            weight = self.joint_shapes[element.joint - 1][m]
            if weight != 0.0:
                # The catalogue's term in x, ẋ, read at the joint coordinate q_j.
                term = f"{get_effect(element.effect).term} at x = q{element.joint}"
                parts.append(f"{weight:.4g}·{element.coefficient:.4g}·[{term}]")
        for coupling in self.couplings:
            if coupling.mode == mode:
                parts.append(f"{coupling.coefficient:.4g}·{coupling.text()}")
        return (
            " + ".join(parts)
            + f" = −{spec.participation:.4g}·a_base,  ω{mode} = 2π·{spec.frequency_hz:.6g} Hz"
        )

    def with_parameters(self, values: Mapping[str, float]) -> ModalModel:
        """The model with the named parameters (:attr:`parameter_names`) set to ``values``.

        Raises
        ------
        ValueError
            A name is not one of :attr:`parameter_names`.
        """
        unknown = sorted(set(values) - set(self.parameter_names))
        if unknown:
            raise ValueError(f"unknown parameters {unknown}; the model has {self.parameter_names}")
        fields = ("frequency_hz", "damping_ratio", "participation")
        modes = [
            dataclasses.replace(
                mode,
                **{f: float(values[name]) for f in fields if (name := f"mode{m}.{f}") in values},
            )
            for m, mode in enumerate(self.modes, start=1)
        ]
        shapes = [
            tuple(float(values.get(f"joint{j}.mode{m}", v)) for m, v in enumerate(row, start=1))
            for j, row in enumerate(self.joint_shapes, start=1)
        ]
        elements = [
            dataclasses.replace(e, coefficient=float(values.get(e.label, e.coefficient)))
            for e in self.elements
        ]
        couplings = [
            dataclasses.replace(c, coefficient=float(values.get(f"coupling{i}", c.coefficient)))
            for i, c in enumerate(self.couplings, start=1)
        ]
        return dataclasses.replace(
            self, modes=tuple(modes), joint_shapes=tuple(shapes), elements=tuple(elements),
            couplings=tuple(couplings),
        )  # fmt: skip

    # ------------------------------------------------------- one-mode models
    @classmethod
    def from_joint_model(cls, model: JointModel) -> ModalModel:
        """The one-mode ModalModel of a :class:`JointModel` (same equation of motion).

        The linear stiffness ``k`` and viscous damping ``c`` become the mode
        (``f = √k / 2π``, ``ζ = c / (2√k)``, ``Γ = 1``), every other term a joint
        element on joint 1 with unit shape.
        """
        k = model.coefficient(LINEAR_STIFFNESS) if LINEAR_STIFFNESS in model else 0.0
        if not k > 0:
            raise ValueError("the JointModel needs a positive linear stiffness to be a mode")
        c = model.coefficient(VISCOUS_DAMPING) if VISCOUS_DAMPING in model else 0.0
        omega = math.sqrt(k)
        elements = tuple(
            JointElement(t.effect, t.coefficient, dict(t.shape), joint=1)
            for t in model.terms
            if t.effect not in (LINEAR_STIFFNESS, VISCOUS_DAMPING)
        )
        return cls(
            modes=(Mode(omega / (2.0 * math.pi), c / (2.0 * omega), 1.0),),
            joint_shapes=((1.0,),),
            elements=elements,
            name=model.name,
        )

    # -------------------------------------------------------------------- JSON
    def _content(self) -> dict[str, Any]:
        return {
            "modes": [
                {
                    "frequency_hz": m.frequency_hz,
                    "damping_ratio": m.damping_ratio,
                    "participation": m.participation,
                }
                for m in self.modes
            ],
            "joint_shapes": [list(row) for row in self.joint_shapes],
            "elements": [
                {
                    "effect": e.effect,
                    "joint": e.joint,
                    "coefficient": e.coefficient,
                    "shape": dict(e.shape),
                }
                for e in self.elements
            ],
            "couplings": [
                {"mode": c.mode, "powers": list(c.powers), "coefficient": c.coefficient}
                for c in self.couplings
            ],
        }

    @property
    def content_sha256(self) -> str:
        """SHA-256 of the canonical JSON of the content (modes, shapes, elements, couplings)."""
        return sha256_json(self._content())

    def to_dict(self) -> dict[str, Any]:
        """JSON-ready description (see :meth:`from_dict`), with :attr:`content_sha256`."""
        return {
            "format": FORMAT,
            "version": FORMAT_VERSION,
            "name": self.name,
            **self._content(),
            "content_sha256": self.content_sha256,
        }

    @classmethod
    def from_dict(cls, data: Mapping[str, Any], source: str = "modal model") -> ModalModel:
        """Build a model from :meth:`to_dict` output; ValueError naming what is wrong."""
        if not isinstance(data, Mapping):
            raise ValueError(f"{source}: expected a JSON object, got {type(data).__name__}")
        if data.get("format") != FORMAT:
            raise ValueError(f"{source}: not a {FORMAT} file (format {data.get('format')!r})")
        version = data.get("version")
        if not isinstance(version, int) or not 1 <= version <= FORMAT_VERSION:
            raise ValueError(
                f"{source}: format version {version!r} is not one this pm-joint reads "
                f"(1 to {FORMAT_VERSION})"
            )
        for key in ("modes", "joint_shapes"):
            if not isinstance(data.get(key), list):
                raise ValueError(f"{source}: field {key!r} must be a list")
        try:
            modes = tuple(
                Mode(
                    **_fields(
                        entry,
                        ("frequency_hz", "damping_ratio", "participation"),
                        f"{source}: modes[{i}]",
                    )
                )
                for i, entry in enumerate(data["modes"])
            )
            elements = tuple(
                JointElement(
                    **_fields(
                        entry,
                        ("effect", "coefficient", "shape", "joint"),
                        f"{source}: elements[{i}]",
                    )
                )
                for i, entry in enumerate(_list(data, "elements", source))
            )
            couplings = tuple(
                Coupling(
                    **_fields(entry, ("mode", "powers", "coefficient"), f"{source}: couplings[{i}]")
                )
                for i, entry in enumerate(_list(data, "couplings", source))
            )
            model = cls(
                modes,
                tuple(tuple(r) for r in data["joint_shapes"]),
                elements,
                couplings,
                name=str(data.get("name", "")),
            )
        except (TypeError, ValueError) as exc:
            if str(exc).startswith(source):
                raise
            raise ValueError(f"{source}: {exc}") from None
        cls.check_content(data, model, source, "the model")
        return model


def _list(data: Mapping[str, Any], key: str, source: str) -> list[Any]:
    value = data.get(key, [])
    if not isinstance(value, list):
        raise ValueError(f"{source}: field {key!r} must be a list")
    return value


def _fields(entry: Any, allowed: Sequence[str], where: str) -> dict[str, Any]:
    """The fields of one JSON object, refusing unknown ones (a typo would be lost)."""
    if not isinstance(entry, Mapping):
        raise ValueError(f"{where}: expected an object")
    unknown = set(entry) - set(allowed)
    if unknown:
        raise ValueError(f"{where}: unknown field(s) {sorted(unknown)}; allowed: {list(allowed)}")
    return dict(entry)
