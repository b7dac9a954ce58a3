"""The N-mode backbone as a Python Op that compiles in seconds: a recorded program run by numba.

:func:`~pm_joint.forward.modal_harmonic.modal_backbone_graph` is a pytensor ``scan``
whose numba compile takes minutes for every new model (the template's values are
constants of the graph, so each model is a new function), and pytensor's numpy
evaluation of it runs operation by operation (tens of milliseconds per call).
A Metropolis-type sampler needs values only. :class:`ModalHarmonicOp` gives them
without compiling anything per model:

* **Recorded once.** The backbone's equations (the source of the graph,
  :mod:`pm_joint.forward.modal_harmonic`) are run once on recording values
  (:class:`_Value`): every operation on a per-point vector is appended to a program
  (opcode, output slot, input slots); operations on the template's constants are
  done there and then by numpy. The fixed-point loop is recorded once, as its own
  section, and run ``iterations`` times; what the backbone does not need (the
  harmonics' phases, the energies) is dropped.
* **Run by one numba function** (:func:`_run`), the same for every model and cached
  on disk (``cache=True``): a loop over the program's instructions, each a loop over
  the points. Its compile is paid once per machine, not per model.

The program performs the graph's operations in the graph's order on float64, so its
values are the graph's to rounding (tests/test_modal_op.py checks both). The
instruction set covers the arithmetic and the describing functions of the catalogue
but its special functions (``i1``, Dawson's integral, the tanh gain): a model with
such an element raises :class:`Unrecordable` at construction, and its caller keeps the
graph (:func:`pm_joint.inference.modal.build_modal_model` does).
"""

from __future__ import annotations

from collections.abc import Callable, Sequence
from typing import Any

import numba
import numpy as np
from numpy.typing import ArrayLike

from identification.checks import positive_vector
from identification.effects.base import NUMPY, ArrayNamespace
from identification.multimode.model import ModalModel
from pm_joint.forward.base import BackboneOp, checked_names
from pm_joint.forward.modal_harmonic import (
    ITERATIONS,
    Backend,
    backbone_equations,
)

__all__ = ["ModalHarmonicOp", "Unrecordable"]


class Unrecordable(NotImplementedError):
    """The model calls a function the recorded program has no instruction for."""


# Opcodes of the program; booleans are 1.0 / 0.0.
(COPY, ADD, SUB, MUL, DIV, POW, NEG, GT, GE, LT, LE, NE, AND, OR, WHERE, SQRT, ABS,
 ISFINITE, ARCTAN2, MINIMUM, EXP, SIN, COS, ARCCOS, TANH) = range(25)  # fmt: skip


class _Program:
    """Instructions ``(opcode, out, a, b, c)`` on slots, and the slots' constant values."""

    def __init__(self) -> None:
        self.code: list[tuple[int, int, int, int, int]] = []
        self.constants: dict[int, float] = {}
        self._by_value: dict[bytes, int] = {}
        self.n_slots = 0
        #: Where the fixed-point loop's instructions start and end in ``code``.
        self.loop_start = self.loop_end = 0
        #: The loop's states: (slot, its value one step before).
        self.state: list[tuple[int, int]] = []

    def slot(self) -> int:
        self.n_slots += 1
        return self.n_slots - 1

    def constant(self, value: float) -> int:
        key = np.float64(value).tobytes()  # by bits: 0.0 and −0.0, NaNs kept apart
        if key not in self._by_value:
            self._by_value[key] = self.slot()
            self.constants[self._by_value[key]] = float(value)
        return self._by_value[key]

    def emit(self, opcode: int, *inputs: Any) -> _Value:
        slots = [self.operand(x) for x in inputs]
        out = self.slot()
        self.code.append((opcode, out, *slots, *[0] * (3 - len(slots))))
        return _Value(self, out)

    def operand(self, x: Any) -> int:
        if isinstance(x, _Value):
            if x.program is not self:
                raise ValueError("a value of another program")
            return x.slot
        value = np.asarray(x)
        if value.ndim != 0:
            raise Unrecordable(f"an array constant of shape {value.shape}")
        return self.constant(float(value))


def _binary(opcode: int, reflected: bool = False) -> Callable:
    def method(self: _Value, other: Any) -> Any:
        if not isinstance(other, _Value | float | int | np.ndarray | np.generic):
            return NotImplemented  # a complex pair's own operators take it
        return self.program.emit(opcode, *((other, self) if reflected else (self, other)))

    return method


class _Value:
    """A per-point vector being recorded: operations on it append instructions."""

    # numpy arrays defer to the reflected operators here instead of making object arrays.
    __array_ufunc__ = None

    def __init__(self, program: _Program, slot: int) -> None:
        self.program, self.slot = program, slot

    __add__, __radd__ = _binary(ADD), _binary(ADD, True)
    __sub__, __rsub__ = _binary(SUB), _binary(SUB, True)
    __mul__, __rmul__ = _binary(MUL), _binary(MUL, True)
    __truediv__, __rtruediv__ = _binary(DIV), _binary(DIV, True)
    __pow__, __rpow__ = _binary(POW), _binary(POW, True)
    __gt__, __ge__, __lt__, __le__ = _binary(GT), _binary(GE), _binary(LT), _binary(LE)
    __and__, __rand__ = _binary(AND), _binary(AND, True)
    __or__, __ror__ = _binary(OR), _binary(OR, True)

    def __neg__(self) -> _Value:
        return self.program.emit(NEG, self)

    def __bool__(self) -> bool:
        raise Unrecordable("a branch on a recorded value")


def _recording(program: _Program) -> Backend:
    """The backend whose operations record instructions (numpy for constants alone)."""

    def elementwise(opcode: int, numpy_function: Callable) -> Callable:
        def function(*args: Any) -> Any:
            if any(isinstance(x, _Value) for x in args):
                return program.emit(opcode, *args)
            return numpy_function(*args)

        return function

    def unrecordable(name: str) -> Callable:
        def function(*_: Any) -> Any:
            raise Unrecordable(f"no instruction for {name}")

        return function

    def iterate(step: Callable, start: list, theta: Any, n: int) -> tuple[list, list]:
        state = [program.emit(COPY, x) for x in start]  # slots the loop writes back to
        program.loop_start = len(program.code)
        before = [program.emit(COPY, x) for x in state]
        out = step(*state)
        for x, target in zip(out, state, strict=True):
            program.code.append((COPY, target.slot, program.operand(x), 0, 0))
        program.loop_end = len(program.code)
        program.state = [(x.slot, b.slot) for x, b in zip(state, before, strict=True)]
        return state, before

    effects = ArrayNamespace(
        name="recorded",
        where=elementwise(WHERE, np.where),
        sqrt=elementwise(SQRT, np.sqrt),
        exp=elementwise(EXP, np.exp),
        sin=elementwise(SIN, np.sin),
        cos=elementwise(COS, np.cos),
        arccos=elementwise(ARCCOS, np.arccos),
        tanh=elementwise(TANH, np.tanh),
        abs=elementwise(ABS, np.abs),
        i1=unrecordable("i1"),
        ones_like=lambda x: 1.0 if isinstance(x, _Value) else NUMPY.ones_like(x),
        zeros_like=lambda x: 0.0 if isinstance(x, _Value) else NUMPY.zeros_like(x),
        dawsn=unrecordable("dawsn"),
        tanh_gain=unrecordable("tanh_gain"),
    )
    return Backend(
        effects=lambda: effects,
        constant=np.asarray,
        switch=effects.where,
        sqrt=effects.sqrt,
        abs=effects.abs,
        isfinite=elementwise(ISFINITE, np.isfinite),
        arctan2=elementwise(ARCTAN2, np.arctan2),
        minimum=elementwise(MINIMUM, np.minimum),
        neq=elementwise(NE, np.not_equal),
        zeros_like=lambda x: 0.0 if isinstance(x, _Value) else np.zeros_like(x),
        stack=lambda values, axis: list(values),
        broadcast_arrays=lambda *values: list(values),
        iterate=iterate,
    )


class _Theta:
    """θ while recording: ``theta[..., i, None]`` is parameter i's slot."""

    def __init__(self, program: _Program, n: int) -> None:
        self.slots = [program.slot() for _ in range(n)]
        self.program = program

    def __getitem__(self, key: Any) -> Any:
        if key == (Ellipsis, slice(None, 1)):
            return 0.0  # only its zeros are asked for (the states' shape)
        _, index, _ = key
        return _Value(self.program, self.slots[index])


#: Operations whose operands commute exactly (IEEE): one instruction for either order.
_COMMUTING = (ADD, MUL)


def _sections(program: _Program, outputs: Sequence[int]) -> tuple[list, list, list, dict]:
    """The program as (before the loop, the loop's body, after it), each instruction kept once.

    Semantics-preserving rewrites only, so the values stay those of the recorded
    operations: instructions of the body that do not depend on the loop's states move
    before it; an instruction that repeats an earlier one of its section (same opcode and
    operands) is dropped for the earlier one's slot; what neither the outputs nor the
    loop's states need is dropped. Also returns the slots renamed (dropped → kept).
    """
    code = program.code
    first = code[: program.loop_start]
    body = code[program.loop_start : program.loop_end]
    last = code[program.loop_end :]
    moving = {slot for pair in program.state for slot in pair}
    kept = []
    for instruction in body:
        if instruction[1] in moving or moving.intersection(instruction[2:]):
            moving.add(instruction[1])
            kept.append(instruction)
        else:
            first.append(instruction)  # the same value every step: computed once
    body = kept
    renamed: dict[int, int] = {}
    sections = []
    for section in (first, body, last):
        seen: dict[tuple, int] = {}
        out = []
        for op, slot, *operands in section:
            operands = [renamed.get(x, x) for x in operands]
            if op in _COMMUTING:
                operands[:2] = sorted(operands[:2])
            key = (op, *operands)
            if op != COPY and key in seen:
                renamed[slot] = seen[key]
                continue
            if op != COPY:
                seen[key] = slot
            out.append((op, slot, *operands))
        sections.append(out)
    needed = {renamed.get(x, x) for x in outputs}
    needed.update(slot for pair in program.state for slot in pair)
    for index in (2, 1, 0):
        kept = []
        for instruction in reversed(sections[index]):
            if instruction[1] in needed:
                kept.append(instruction)
                needed.update(instruction[2:])
        sections[index] = kept[::-1]
    return sections[0], sections[1], sections[2], renamed


# error_model "numpy": IEEE answers (inf, NaN) to a division by zero, as numpy and the graph give.
@numba.njit(cache=True, error_model="numpy")
def _run(
    code: np.ndarray, slots: np.ndarray, repeat: int, state: np.ndarray
) -> None:  # pragma: no cover - numba
    """Run the instructions ``repeat`` times on ``slots`` (one row a slot, one column a point).

    The branch on the opcode is taken once per instruction, the loop over the points inside.
    ``state`` pairs the loop's state slots with their values one step before: where a step
    changed no bit of any (NaN as NaN), every further step would repeat it, and the run stops
    there with the values ``repeat`` steps give.
    """
    n = slots.shape[1]
    for _ in range(repeat):
        if _ > 0 and _settled(slots, state):
            return
        for k in range(code.shape[0]):
            op = code[k, 0]
            out, x = slots[code[k, 1]], slots[code[k, 2]]
            y, z = slots[code[k, 3]], slots[code[k, 4]]
            if op == COPY:
                for i in range(n):
                    out[i] = x[i]
            elif op == ADD:
                for i in range(n):
                    out[i] = x[i] + y[i]
            elif op == SUB:
                for i in range(n):
                    out[i] = x[i] - y[i]
            elif op == MUL:
                for i in range(n):
                    out[i] = x[i] * y[i]
            elif op == DIV:
                for i in range(n):
                    out[i] = x[i] / y[i]
            elif op == POW:
                for i in range(n):
                    out[i] = x[i] ** y[i]
            elif op == NEG:
                for i in range(n):
                    out[i] = -x[i]
            elif op == GT:
                for i in range(n):
                    out[i] = 1.0 if x[i] > y[i] else 0.0
            elif op == GE:
                for i in range(n):
                    out[i] = 1.0 if x[i] >= y[i] else 0.0
            elif op == LT:
                for i in range(n):
                    out[i] = 1.0 if x[i] < y[i] else 0.0
            elif op == LE:
                for i in range(n):
                    out[i] = 1.0 if x[i] <= y[i] else 0.0
            elif op == NE:
                for i in range(n):
                    out[i] = 1.0 if x[i] != y[i] else 0.0
            elif op == AND:
                for i in range(n):
                    out[i] = 1.0 if (x[i] != 0.0 and y[i] != 0.0) else 0.0
            elif op == OR:
                for i in range(n):
                    out[i] = 1.0 if (x[i] != 0.0 or y[i] != 0.0) else 0.0
            elif op == WHERE:
                for i in range(n):
                    out[i] = y[i] if x[i] != 0.0 else z[i]
            elif op == SQRT:
                for i in range(n):
                    out[i] = np.sqrt(x[i])
            elif op == ABS:
                for i in range(n):
                    out[i] = abs(x[i])
            elif op == ISFINITE:
                for i in range(n):
                    out[i] = 1.0 if np.isfinite(x[i]) else 0.0
            elif op == ARCTAN2:
                for i in range(n):
                    out[i] = np.arctan2(x[i], y[i])
            elif op == MINIMUM:
                for i in range(n):
                    out[i] = x[i] if (x[i] <= y[i] or x[i] != x[i]) else y[i]
            elif op == EXP:
                for i in range(n):
                    out[i] = np.exp(x[i])
            elif op == SIN:
                for i in range(n):
                    out[i] = np.sin(x[i])
            elif op == COS:
                for i in range(n):
                    out[i] = np.cos(x[i])
            elif op == ARCCOS:
                for i in range(n):
                    out[i] = np.arccos(x[i])
            elif op == TANH:
                for i in range(n):
                    out[i] = np.tanh(x[i])


@numba.njit(cache=True)
def _settled(slots: np.ndarray, state: np.ndarray) -> bool:  # pragma: no cover - numba
    for k in range(state.shape[0]):
        now, before = slots[state[k, 0]], slots[state[k, 1]]
        for i in range(now.shape[0]):
            if now[i] != before[i] and not (now[i] != now[i] and before[i] != before[i]):
                return False
    return True


class ModalHarmonicOp(BackboneOp):
    """The phase-resonant backbone of one mode of an N-mode model, a Python Op (no gradient).

    The forward-model interface of :class:`~pm_joint.forward.modal_harmonic.
    ModalHarmonicGraph` and the same values (to rounding), from a program recorded at
    construction and run by one cached numba function (see the module notes): for a
    sampler that needs no gradient. ``(..., n_params)`` θ gives ``(..., n_points, 3)``,
    NaN where the fixed point does not settle.

    Raises
    ------
    Unrecordable
        The model has an element whose describing function calls a special function.
    """

    def __init__(
        self,
        model: ModalModel,
        names: Sequence[str] | None,
        amplitudes_m: ArrayLike,
        mode: int = 1,
        iterations: int = ITERATIONS,
    ) -> None:
        super().__init__()
        self.model = model
        self.parameter_names = checked_names(model, names)
        self.amplitudes_m = positive_vector(amplitudes_m, "amplitudes_m")
        self.n_points = self.amplitudes_m.size
        self.mode = mode
        program = _Program()
        theta = _Theta(program, self.n_params)
        amplitude = _Value(program, program.slot())
        tensors = backbone_equations(
            _recording(program), model, theta, self.parameter_names, self.amplitudes_m, mode,
            iterations, amplitude=amplitude,
        )  # fmt: skip
        columns = tensors.backbone[1:]  # frequency and damping ratio (the amplitude is the grid)
        outputs = [program.operand(c) for c in columns]
        *sections, renamed = _sections(program, outputs)
        outputs = [renamed.get(x, x) for x in outputs]
        # The slots still used, numbered afresh (most of the recorded ones were dropped).
        used = {x for section in sections for instruction in section for x in instruction[1:]}
        used.update(outputs, theta.slots, [amplitude.slot], *program.state)
        number = {slot: k for k, slot in enumerate(sorted(used))}
        self._sections = [
            np.array([(i[0], *(number[x] for x in i[1:])) for i in section], dtype=np.int64)
            .reshape(-1, 5)
            for section in sections
        ]  # fmt: skip
        self._repeats = (1, iterations, 1)
        self._state = np.array([[number[x] for x in p] for p in program.state], dtype=np.int64)
        self._outputs = [number[x] for x in outputs]
        self._theta_slots = np.array([number[x] for x in theta.slots], dtype=np.int64)
        self._amplitude_slot = number[amplitude.slot]
        kept = [(number[x], v) for x, v in program.constants.items() if x in number]
        self._constant_slots = np.array([k for k, _ in kept], dtype=np.int64)
        self._constant_values = np.array([v for _, v in kept], dtype=np.float64)[:, None]
        self.n_slots = len(number)

    def _backbones(self, flat: np.ndarray) -> np.ndarray:
        n_sets = flat.shape[0]
        slots = np.zeros((self.n_slots, n_sets * self.n_points))
        slots[self._constant_slots] = self._constant_values
        slots[self._amplitude_slot] = np.tile(self.amplitudes_m, n_sets)
        slots[self._theta_slots] = np.repeat(flat.T, self.n_points, axis=1)
        for section, repeat in zip(self._sections, self._repeats, strict=True):
            _run(section, slots, repeat, self._state)
        out = np.empty((n_sets, self.n_points, 3))
        out[..., 0] = self.amplitudes_m
        for column, slot in enumerate(self._outputs, start=1):
            out[..., column] = slots[slot].reshape(n_sets, self.n_points)
        return out

    def __repr__(self) -> str:
        return (
            f"ModalHarmonicOp({self.model.name or 'ModalModel'!r}, "
            f"names={list(self.parameter_names)}, n_points={self.n_points}, mode={self.mode})"
        )
