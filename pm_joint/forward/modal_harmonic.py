"""The phase-resonant backbone of an N-mode model as a native, differentiable pytensor graph.

The N-mode twin of :mod:`pm_joint.forward.harmonic`: a :class:`~identification.
multimode.ModalModel`'s structure (modes, catalogue joint elements on joint
coordinates, polynomial modal couplings) and a tensor θ of its parameters
(leading axes: parameter sets) give, on an amplitude grid, the backbone that a
phase-locked test holding mode ``t`` measures (the problem of
:func:`identification.multimode.phase_resonance`): the locked mode's fundamental
is ``a cos θ``, the base acceleration ``A sin θ`` is 90° ahead of it, and ω and
A are unknown; the damping ratio is the power balance ``Γ_t A / (2 ω² a)``.

The approximation (first order in the coupling, single harmonic per force)
--------------------------------------------------------------------------
With complex amplitudes, ``η_m = Y_m0 + Σ_h Re(Y_mh e^{ihθ})``, ``Y_t1 = a``:

* **Fundamentals of every mode, by describing functions.** A joint element's
  force is its catalogue describing function at the joint coordinate's
  fundamental amplitude, ``c (k_eq + iω c_eq)(|Q_j|, ω) · Q_j`` with
  ``Q_j = Σ_m φ_jm Y_m1`` (the same parts as the one-mode graph, so an element
  acts through its fundamental only, as there). The fundamental rows of the
  modal equations::

      (ω_m² − ω² + 2iζ_m ω_m ω) Y_m1 + Σ_n S_mn Y_n1 + g_m = iΓ_m A,
      S_mn = Σ_j φ_jm φ_jn Σ_{e at j} c_e (k_eq,e + iω c_eq,e)(|Q_j|, ω)

  are, with S and the coupling force g frozen, linear in the other modes'
  ``Y_o1`` and in A: a complex ``(N−1)×(N−1)`` solve (Gaussian elimination
  unrolled in the graph, per point), then the locked row's imaginary part gives
  A and its real part ω² (with the ω²-proportional part of ``k_eq``, from
  ``x·ẋ²``, moved to the left as in the one-mode closed form).
* **Harmonics 0, 2, 3 driven by the couplings.** A polynomial coupling on the
  fundamentals has exact harmonics (quadratic: 0 and 2ω, the 1:2 mechanism;
  cubic: ω and 3ω, the 1:3 one). Every mode's response at harmonic ``h ≠ 1`` is
  that forcing over its own linear operator, ``Z_mh = −F_mh / D_m(hω)`` with
  ``D_m(Ω) = ω_m² − Ω² + 2iζ_m ω_m Ω``, and feeds back on the fundamentals to
  first order: ``M(y + z) ≈ M(y) + Σ_n ∂M/∂η_n(y) z_n`` for each monomial M.
  This is the leading effect of a quadratic coupling (it has no fundamental of
  its own) and gives, for the potential ``κ η1² η2``, the truncated balance
  {mode 1: ω; mode 2: 0, 2ω} exactly.
* **Solved to a fixed point.** S, g and the operators are re-evaluated at the
  last iterate ``ITERATIONS`` times (a fixed number of steps of a pytensor
  ``scan``, so the gradient is that of the iteration; it equals the implicit one
  where the iteration has settled). With one mode and no couplings nothing
  depends on the iterate but ω in ``c_eq``, and the graph is :func:`~pm_joint.forward.harmonic.
  harmonic_backbone_graph` (ω² from the first iteration, A from the second).

What it leaves out, hence its error: the higher harmonics of the joint
elements (the catalogue gives their fundamental only; for a Duffing element
this is the single-harmonic balance's ``(3/256)(k₃a²/ω²)²`` relative frequency
error), the elements' action on the harmonics ``h ≠ 1`` and of those harmonics
on the elements, and products of two driven harmonics (fourth order in the
coupling).

Where it fails: internal resonances
-----------------------------------
Near ``ω_m ≈ hω`` (1:1 with a mode on the joint, 1:2 through a quadratic, 1:3
through a cubic coupling) the driven response of mode m grows like
``1/D_m(hω)`` and depends on ω as strongly as the locked mode itself: the
backbone folds (the branch of the multi-harmonic continuation turns, the energy
goes to the other mode) and one response per mode and harmonic cannot follow
it. The fixed-point map of ω² then contracts slowly or not at all: where its
last step moves ω² by more than ``SETTLED`` (relative) or by more than the
other modes' fundamentals by more than ``SETTLED · a``, the point is reported
as not converged (``converged`` False) and its frequency and damping are NaN in
the forward-model output, as every forward model marks a point it cannot
evaluate. A resonance the damping holds down need not fold: there the
iteration settles and the point is returned, with an error above the truncation's
that grows as the resonance nears. ``detuning`` (the relative distance
``|D_m(hω)| / (hω)²`` of the nearest driven resonance) and the participation
(``energy_share`` of the other modes, their ``harmonic_amplitude_m``) say how
near it is, for a caller that wants to cut there.
"""

from __future__ import annotations

from collections.abc import Callable, Sequence
from dataclasses import dataclass
from typing import Any, NamedTuple

import numpy as np
import pytensor
import pytensor.tensor as pt
from numpy.typing import ArrayLike

from identification.checks import positive_vector
from identification.effects import get_effect
from identification.effects.base import NUMPY, ArrayNamespace, pytensor_namespace
from identification.multimode.model import ModalModel
from pm_joint.forward.base import checked_names

__all__ = [
    "ITERATIONS",
    "SETTLED",
    "Backend",
    "ModalBackboneTensors",
    "ModalHarmonicGraph",
    "backbone_equations",
    "modal_backbone_graph",
    "modal_backbone_numpy",
    "template_values",
]

#: Fixed-point iterations (steps of the graph's scan).
ITERATIONS = 16
#: Relative step of the last iteration below which a point counts as converged.
SETTLED = 1e-9
#: Harmonics every mode carries: 0 and 2 from quadratic, 1 and 3 from cubic terms.
HARMONICS = (0, 1, 2, 3)


class ModalBackboneTensors(NamedTuple):
    """The graph's outputs; ``P`` is θ's leading shape, ``A`` the amplitude grid's size.

    Attributes
    ----------
    backbone
        ``(*P, A, 3)``: amplitude (m), frequency (Hz), damping ratio of the locked
        mode, the forward-model layout; NaN where ``converged`` is False.
    frequency_hz, damping_ratio
        ``(*P, A)``, not masked.
    harmonic_amplitude_m, harmonic_phase_rad
        ``(*P, A, N, 4)``: every mode's modal amplitude ``|Y_mh|`` and phase ``φ_mh``
        at harmonics 0–3, ``η_m = Σ_h |Y_mh| cos(hθ + φ_mh)`` with the locked mode's
        fundamental ``a cos θ`` (the mean, harmonic 0, as a signed amplitude with
        phase 0).
    energy_share
        ``(*P, A, N)``: each mode's share of the period-averaged linear modal energy,
        as :func:`identification.multimode.energy_shares`.
    converged
        ``(*P, A)``: the fixed point settled and ω² > 0 (see the module notes).
    detuning
        ``(*P, A)``: distance to the nearest internal resonance, the smallest
        ``|D_m(hω)| / (hω)²`` over the other modes m and the harmonics h ≥ 1 they
        respond at (1, and those their couplings drive); +inf with one mode. The
        first-order answer degrades as it falls (see the module notes).
    """

    backbone: pt.TensorVariable
    frequency_hz: pt.TensorVariable
    damping_ratio: pt.TensorVariable
    harmonic_amplitude_m: pt.TensorVariable
    harmonic_phase_rad: pt.TensorVariable
    energy_share: pt.TensorVariable
    converged: pt.TensorVariable
    detuning: pt.TensorVariable


# --------------------------------------------------------------------------
# Complex arithmetic on pairs of real tensors (pytensor differentiates real graphs
# throughout; its complex gradients are partial).


@dataclass(frozen=True)
class _Complex:
    re: Any
    im: Any

    # numpy arrays defer to the reflected operators here (as pytensor tensors do), instead
    # of making an object array of this pair.
    __array_ufunc__ = None

    def __add__(self, other: Any) -> _Complex:
        other = _complex(other)
        return _Complex(self.re + other.re, self.im + other.im)

    __radd__ = __add__

    def __sub__(self, other: Any) -> _Complex:
        other = _complex(other)
        return _Complex(self.re - other.re, self.im - other.im)

    def __neg__(self) -> _Complex:
        return _Complex(-self.re, -self.im)

    def __mul__(self, other: Any) -> _Complex:
        other = _complex(other)
        return _Complex(
            self.re * other.re - self.im * other.im, self.re * other.im + self.im * other.re
        )

    __rmul__ = __mul__

    def __truediv__(self, other: Any) -> _Complex:
        other = _complex(other)
        norm = other.re**2 + other.im**2
        return _Complex(
            (self.re * other.re + self.im * other.im) / norm,
            (self.im * other.re - self.re * other.im) / norm,
        )

    def conj(self) -> _Complex:
        return _Complex(self.re, -self.im)

    def abs2(self) -> Any:
        return self.re**2 + self.im**2


def _complex(value: Any) -> _Complex:
    return value if isinstance(value, _Complex) else _Complex(value, 0.0)


_ZERO = _Complex(0.0, 0.0)

#: A signal as two-sided Fourier coefficients ``{h: c_h}``, ``η = Σ_h c_h e^{ihθ}``.
Signal = dict[int, _Complex]


def _two_sided(one_sided: dict[int, _Complex]) -> Signal:
    """``η = Y_0 + Σ_h Re(Y_h e^{ihθ})`` as two-sided coefficients."""
    signal: Signal = {}
    for h, y in one_sided.items():
        if h == 0:
            signal[0] = y
        else:
            signal[h], signal[-h] = 0.5 * y, 0.5 * y.conj()
    return signal


def _product(signals: Sequence[Signal]) -> Signal:
    """The product of the signals (convolution of their coefficients, untruncated)."""
    out: Signal = {0: _Complex(1.0, 0.0)}
    for signal in signals:
        terms: Signal = {}
        for h1, c1 in out.items():
            for h2, c2 in signal.items():
                terms[h1 + h2] = terms.get(h1 + h2, _ZERO) + c1 * c2
        out = terms
    return out


def _one_sided(signal: Signal, h: int) -> _Complex:
    """The one-sided coefficient ``Y_h`` of a real signal."""
    c = signal.get(h, _ZERO)
    return c if h == 0 else 2.0 * c


def _solve(matrix: list[list[_Complex]], rhs: list[list[_Complex]]) -> list[list[_Complex]]:
    """``matrix · x = rhs`` (columns of ``rhs``) by Gaussian elimination, unrolled.

    No pivoting: the matrix is the other modes' dynamic stiffness at ω, led by its
    diagonal ``ω_m² − ω²`` away from a 1:1 resonance (where the graph reports the
    point as not converged anyway).
    """
    n = len(matrix)
    a = [row[:] for row in matrix]
    b = [row[:] for row in rhs]
    for k in range(n):
        for i in range(k + 1, n):
            factor = a[i][k] / a[k][k]
            a[i] = [a[i][j] - factor * a[k][j] if j > k else _ZERO for j in range(n)]
            b[i] = [b[i][c] - factor * b[k][c] for c in range(len(b[i]))]
    x: list[list[_Complex]] = [[] for _ in range(n)]
    for i in reversed(range(n)):
        x[i] = [
            (b[i][c] - sum((a[i][j] * x[j][c] for j in range(i + 1, n)), _ZERO)) / a[i][i]
            for c in range(len(b[i]))
        ]
    return x


# --------------------------------------------------------------------------
# The array libraries the equations are written for: pytensor (the differentiable graph, its
# loop a scan) and numpy (values only, its loop a Python one). One source, so the two agree.


@dataclass(frozen=True)
class Backend:
    """The array functions the backbone's equations (:func:`backbone_equations`) call, for one
    library: pytensor's, numpy's, or :mod:`pm_joint.forward.modal_op`'s recording one."""

    effects: Callable[[], ArrayNamespace]
    constant: Callable
    switch: Callable
    sqrt: Callable
    abs: Callable
    isfinite: Callable
    arctan2: Callable
    minimum: Callable
    neq: Callable
    zeros_like: Callable
    stack: Callable
    broadcast_arrays: Callable
    #: ``(step, start, θ, n) -> (last, before)``: the states after ``n`` steps and ``n − 1``.
    iterate: Callable


def _scan(step: Callable, start: list, theta: Any, n: int) -> tuple[list, list]:
    # A scan, not an unrolled loop: the graph (and its compile time) stays one step long.
    # θ named as a non-sequence: traced implicitly, a PyMC prior's random draw would be copied
    # into the loop (its RNG with it) instead of its value entering it.
    steps = pytensor.scan(step, outputs_info=start, non_sequences=[theta], n_steps=n,
                          return_updates=False)  # fmt: skip
    return [s[-1] for s in steps], [s[-2] for s in steps]


def _loop(step: Callable, start: list, theta: Any, n: int) -> tuple[list, list]:
    before, last = start, start
    for _ in range(n):
        before, last = last, step(*last)
    return last, before


_PYTENSOR = Backend(
    effects=pytensor_namespace, constant=pt.constant, switch=pt.switch, sqrt=pt.sqrt,
    abs=pt.abs, isfinite=pt.isfinite, arctan2=pt.arctan2, minimum=pt.minimum, neq=pt.neq,
    zeros_like=pt.zeros_like, stack=pt.stack, broadcast_arrays=pt.broadcast_arrays,
    iterate=_scan,
)  # fmt: skip
_NUMPY = Backend(
    effects=lambda: NUMPY, constant=np.asarray, switch=np.where, sqrt=np.sqrt, abs=np.abs,
    isfinite=np.isfinite, arctan2=np.arctan2, minimum=np.minimum, neq=np.not_equal,
    zeros_like=np.zeros_like, stack=np.stack, broadcast_arrays=np.broadcast_arrays,
    iterate=_loop,
)  # fmt: skip


# --------------------------------------------------------------------------
# The graph.


def modal_backbone_graph(
    model: ModalModel,
    theta: Any,
    names: Sequence[str] | None,
    amplitudes_m: ArrayLike,
    *,
    mode: int = 1,
    iterations: int = ITERATIONS,
) -> ModalBackboneTensors:
    """Phase-resonant backbone of ``mode`` as a native, differentiable pytensor graph.

    Parameters
    ----------
    model
        Template model: its structure, and the values of parameters not in ``names``
        (shape parameters of the elements are the template's).
    theta
        ``(..., len(names))`` parameter values (a pytensor variable or array).
    names
        Order of θ, names of :attr:`ModalModel.parameter_names` (None: all).
    amplitudes_m
        Fundamental amplitudes of the locked mode's coordinate (m), 1-D, > 0.
    mode
        The locked mode, numbered from 1.
    iterations
        Fixed-point iterations (≥ 2: the damping uses the previous step's ω).

    Returns
    -------
    ModalBackboneTensors
        The backbone in the forward-model layout and every mode's participation.
    """
    names, amplitudes = _checked(model, names, amplitudes_m, mode, iterations)
    theta = pt.as_tensor_variable(theta).astype("float64")
    _check_width(theta.ndim, theta.type.shape[-1] if theta.ndim else None, names)
    return backbone_equations(_PYTENSOR, model, theta, names, amplitudes, mode, iterations)


def modal_backbone_numpy(
    model: ModalModel,
    theta: ArrayLike,
    names: Sequence[str] | None,
    amplitudes_m: ArrayLike,
    *,
    mode: int = 1,
    iterations: int = ITERATIONS,
) -> ModalBackboneTensors:
    """:func:`modal_backbone_graph`'s equations evaluated by numpy: no compile, no gradient.

    The same source as the graph (every operation in the same order, the loop a Python
    one), for a caller that needs values only and a few evaluations (the graph's scan
    compiles for minutes; a sampler's many calls go to
    :class:`~pm_joint.forward.modal_op.ModalHarmonicOp`, which records the same source
    once). Arguments and outputs as :func:`modal_backbone_graph`'s, as numpy arrays.
    """
    names, amplitudes = _checked(model, names, amplitudes_m, mode, iterations)
    theta = np.asarray(theta, dtype=np.float64)
    _check_width(theta.ndim, theta.shape[-1] if theta.ndim else None, names)
    with np.errstate(all="ignore"):  # invalid rows come out NaN, as in the graph
        return backbone_equations(_NUMPY, model, theta, names, amplitudes, mode, iterations)


def _checked(
    model: ModalModel, names: Sequence[str] | None, amplitudes_m: ArrayLike, mode: int,
    iterations: int,
) -> tuple[tuple[str, ...], np.ndarray]:  # fmt: skip
    """The parameter names and the amplitude grid, checked with the mode and iterations."""
    names = checked_names(model, names)
    amplitudes = positive_vector(amplitudes_m, "amplitudes_m")
    if isinstance(mode, bool) or not isinstance(mode, int | np.integer):
        raise ValueError(f"mode must be an integer, got {mode!r}")
    if not 1 <= mode <= model.n_modes:
        raise ValueError(f"mode must be 1..{model.n_modes} (modes count from 1), got {mode}")
    if not isinstance(iterations, int) or iterations < 2:
        raise ValueError(f"iterations must be an integer ≥ 2, got {iterations!r}")
    return names, amplitudes


def _check_width(ndim: int, width: int | None, names: Sequence[str]) -> None:
    if ndim == 0 or width not in (None, len(names)):
        raise ValueError(
            f"θ must have a last axis of {len(names)} parameters ({', '.join(names)}), "
            f"got {ndim} axes, the last of {width}"
        )


def backbone_equations(
    xp: Backend, model: ModalModel, theta: Any, names: Sequence[str], amplitudes: np.ndarray,
    mode: int, iterations: int, *, amplitude: Any = None,
) -> ModalBackboneTensors:  # fmt: skip
    """The backbone's equations in the array library ``xp`` (see the module notes), on checked
    arguments; ``amplitude`` stands for the grid where given (else its constant)."""
    values = _parameter_tensors(xp, model, theta, names)
    a = xp.constant(amplitudes) if amplitude is None else amplitude
    n, t = model.n_modes, mode - 1
    others = [m for m in range(n) if m != t]
    # Invalid rows (frequency ≤ 0, damping ratio < 0) compute on the template's
    # values and come out NaN, keeping every intermediate and gradient finite.
    # Every state of the iteration has the full shape (θ's leading axes, the grid).
    zero = xp.zeros_like(theta[..., :1]) + xp.zeros_like(a)
    valid = xp.constant(np.array(True))
    w, zeta = [], []
    for m, spec in enumerate(model.modes):
        f, z = values[f"mode{m + 1}.frequency_hz"], values[f"mode{m + 1}.damping_ratio"]
        valid = valid & (f > 0) & (z >= 0)
        w.append(2.0 * np.pi * xp.switch(f > 0, f, spec.frequency_hz))
        zeta.append(xp.switch(z >= 0, z, spec.damping_ratio))
    gamma = [values[f"mode{m + 1}.participation"] for m in range(n)]
    phi = [[values[f"joint{j + 1}.mode{m + 1}"] for m in range(n)] for j in range(model.n_joints)]
    coupling = [values[f"coupling{i + 1}"] for i in range(len(model.couplings))]
    elements = [
        (values[e.label], get_effect(e.effect), e.joint - 1,
         {k: xp.constant(v) for k, v in e.shape.items()})
        for e in model.elements
    ]  # fmt: skip

    def dynamic(m: int, frequency: Any) -> _Complex:
        """``D_m(Ω) = ω_m² − Ω² + 2iζ_m ω_m Ω``."""
        return _Complex(w[m] ** 2 - frequency**2, 2.0 * zeta[m] * w[m] * frequency)

    def joint_gains(y: list[_Complex], omega: Any) -> list[tuple[_Complex, Any]]:
        """Per joint: ``Σ c (k_eq + iω c_eq)`` without its ω²-part, and that part per ω²."""
        effects = xp.effects()
        gains = []
        for j in range(model.n_joints):
            q = sum((phi[j][m] * y[m] for m in range(n)), _ZERO)
            moving = q.abs2() > 0
            # A joint the motion does not reach is read at a millionth of the locked
            # amplitude: its small-amplitude limit (stuck, for friction, whose gains
            # diverge at 0), keeping the gradient finite.
            q_abs = xp.sqrt(xp.switch(moving, q.abs2(), (1e-6 * a) ** 2))
            gain, per_omega_squared = _ZERO, 0.0
            for c, effect, joint, shape in elements:
                if joint != j:
                    continue
                if effect.stiffness is not None:
                    gain = gain + c * effect.stiffness(effects, q_abs, **shape)
                if effect.stiffness_per_omega_squared is not None:
                    k2 = effect.stiffness_per_omega_squared(effects, q_abs, **shape)
                    per_omega_squared = per_omega_squared + c * k2
                if effect.damping is not None:
                    c_eq = effect.damping(effects, q_abs, omega, **shape)
                    gain = gain + _Complex(0.0, omega * c * c_eq)
            gains.append((gain, per_omega_squared))
        return gains

    def driven(y: list[_Complex], omega: Any) -> tuple[list[_Complex], list[dict[int, _Complex]]]:
        """Fundamental coupling force per mode, and every mode's driven harmonics 0, 2, 3."""
        fundamentals = [_two_sided({1: y[m]}) for m in range(n)]
        forcing: list[dict[int, _Complex]] = [{} for _ in range(n)]
        for kappa, term in zip(coupling, model.couplings, strict=True):
            on = forcing[term.mode - 1]
            product = _product([fundamentals[k] for k in _factors(term.powers)])
            for h in (0, 2, 3):
                if h in product:
                    on[h] = on.get(h, _ZERO) + _one_sided(product, h) * kappa
        harmonics = [
            {h: -f / dynamic(m, h * omega) for h, f in forcing[m].items()} for m in range(n)
        ]  # fmt: skip
        force = [_ZERO] * n
        for kappa, term in zip(coupling, model.couplings, strict=True):
            m = term.mode - 1
            factors = _factors(term.powers)
            own = _product([fundamentals[k] for k in factors])
            force[m] = force[m] + kappa * _one_sided(own, 1)
            # ∂M/∂η_k · z_k, once per factor of η_k in the monomial (p_k ∂/∂η_k).
            for i, k in enumerate(factors):
                if not harmonics[k]:
                    continue
                rest = [fundamentals[f] for f in factors[:i] + factors[i + 1 :]]
                signal = _product([*rest, _two_sided(harmonics[k])])
                force[m] = force[m] + kappa * _one_sided(signal, 1)
        return force, harmonics

    def iteration(omega_squared: Any, base: Any, *parts: Any) -> list[Any]:
        """One fixed-point step: ω², A and the other modes' fundamentals (re, im pairs)."""
        y = [_Complex(a, 0.0)] * n
        for i, m in enumerate(others):
            y[m] = _Complex(parts[2 * i], parts[2 * i + 1])
        omega = xp.sqrt(xp.switch(omega_squared > 0, omega_squared, w[t] ** 2))
        gains = joint_gains(y, omega)
        force, _ = driven(y, omega)

        def stiffness(m: int, k: int) -> _Complex:
            return sum(
                ((gains[j][0] + gains[j][1] * omega**2) * (phi[j][m] * phi[j][k])
                 for j in range(model.n_joints)),
                _ZERO,
            )  # fmt: skip

        matrix = [
            [stiffness(m, k) + (dynamic(m, omega) if m == k else _ZERO) for k in others]
            for m in others
        ]
        rhs = [[-(force[m] + stiffness(m, t) * a), _Complex(0.0, gamma[m])] for m in others]
        solution = _solve(matrix, rhs) if others else []
        # Locked row: R + β A − ω² (1 − K₂) a = 0, K₂ the ω²-part of its own joint stiffness.
        own = sum((gains[j][0] * phi[j][t] ** 2 for j in range(model.n_joints)), _ZERO)
        per_omega_squared = sum(phi[j][t] ** 2 * gains[j][1] for j in range(model.n_joints))
        r = (_Complex(w[t] ** 2, 2.0 * zeta[t] * w[t] * omega) + own) * a + force[t]
        beta = _Complex(0.0, -gamma[t])
        for m, (u, v) in zip(others, solution, strict=True):
            r = r + stiffness(t, m) * u
            beta = beta + stiffness(t, m) * v
        # No A holds the phase (β real) or the ω²-part of the stiffness outweighs the
        # inertia (1 − K₂ ≤ 0, where the one-mode graph has no backbone either): NaN.
        denominator = 1.0 - per_omega_squared
        solvable = xp.neq(beta.im, 0.0) & (denominator > 0)
        base = -r.im / xp.switch(solvable, beta.im, 1.0)
        omega_squared = (r.re + beta.re * base) / (a * xp.switch(solvable, denominator, 1.0))
        out = [xp.switch(solvable, omega_squared, np.nan), base]
        for u, v in solution:
            y_o = u + v * base
            out += [y_o.re, y_o.im]
        return [zero + x for x in out]

    start = [w[t] ** 2 + zero, zero] + [zero] * (2 * len(others))
    last, before = xp.iterate(iteration, start, theta, iterations)
    omega_squared, base = last[0], last[1]
    y = [_Complex(a, 0.0)] * n
    for i, m in enumerate(others):
        y[m] = _Complex(last[2 + 2 * i], last[3 + 2 * i])
    positive = omega_squared > 0
    omega = xp.sqrt(xp.switch(positive, omega_squared, w[t] ** 2))
    step = xp.abs(omega_squared - before[0]) / xp.switch(positive, omega_squared, 1.0)
    settled = step <= SETTLED
    for i in range(len(others)):
        re, im = (last[k] - before[k] for k in (2 + 2 * i, 3 + 2 * i))
        settled = settled & (re**2 + im**2 <= (SETTLED * a) ** 2)
    converged = valid & positive & settled & xp.isfinite(omega_squared)

    _, harmonics = driven(y, omega)
    frequency_hz = omega / (2.0 * np.pi)
    damping_ratio = gamma[t] * base / (2.0 * omega_squared * a)
    motion = [{**harmonics[m], 1: y[m]} for m in range(n)]
    amplitude, phase, energy = [], [], []
    for m in range(n):
        coefficients = [motion[m].get(h, _ZERO) + xp.zeros_like(a) for h in HARMONICS]
        mean = coefficients[0].re
        amplitude.append([mean] + [xp.sqrt(c.abs2()) for c in coefficients[1:]])
        phase.append([xp.zeros_like(mean)] + [xp.arctan2(c.im, c.re) for c in coefficients[1:]])
        e = 0.5 * w[m] ** 2 * mean**2
        for h, c in zip(HARMONICS[1:], coefficients[1:], strict=True):
            e = e + 0.25 * ((h * omega) ** 2 + w[m] ** 2) * c.abs2()
        energy.append(e)
    total = sum(energy)
    detuning = xp.constant(np.inf) + zero
    for m in others:
        for h in sorted({1, *harmonics[m]} - {0}):
            d = dynamic(m, h * omega)
            detuning = xp.minimum(detuning, xp.sqrt(d.abs2()) / (h * omega) ** 2)
    nan_where_not = lambda x: xp.switch(converged, x, np.nan)  # noqa: E731
    frequency_out, damping_out = nan_where_not(frequency_hz), nan_where_not(damping_ratio)
    return ModalBackboneTensors(
        backbone=xp.stack(xp.broadcast_arrays(a, frequency_out, damping_out), axis=-1),
        frequency_hz=frequency_hz,
        damping_ratio=damping_ratio,
        harmonic_amplitude_m=_stack_modes(xp, amplitude),
        harmonic_phase_rad=_stack_modes(xp, phase),
        energy_share=xp.stack(xp.broadcast_arrays(*(e / total for e in energy)), axis=-1),
        converged=converged,
        detuning=detuning,
    )


def _factors(powers: Sequence[int]) -> list[int]:
    """A monomial's modes, each as often as its power: ``(2, 1)`` gives ``[0, 0, 1]``."""
    return [k for k, p in enumerate(powers) for _ in range(p)]


def _stack_modes(xp: Backend, per_mode: list[list[Any]]) -> Any:
    """``(..., A, N, len(HARMONICS))`` from one list of per-harmonic tensors per mode."""
    rows = [xp.stack(xp.broadcast_arrays(*row), axis=-1) for row in per_mode]
    return xp.stack(xp.broadcast_arrays(*rows), axis=-2)


def template_values(model: ModalModel) -> dict[str, float]:
    """Every parameter's value in ``model``, by the names of :attr:`ModalModel.parameter_names`."""
    template = {}
    for m, spec in enumerate(model.modes, start=1):
        template[f"mode{m}.frequency_hz"] = spec.frequency_hz
        template[f"mode{m}.damping_ratio"] = spec.damping_ratio
        template[f"mode{m}.participation"] = spec.participation
    for j, row in enumerate(model.joint_shapes, start=1):
        for m, value in enumerate(row, start=1):
            template[f"joint{j}.mode{m}"] = value
    for element in model.elements:
        template[element.label] = element.coefficient
    for i, coupling in enumerate(model.couplings, start=1):
        template[f"coupling{i}"] = coupling.coefficient
    return template


def _parameter_tensors(
    xp: Backend, model: ModalModel, theta: Any, names: Sequence[str]
) -> dict[str, Any]:
    """Every parameter of ``model``: θ's column (with a trailing grid axis) or the template's."""
    template = template_values(model)
    return {
        name: theta[..., list(names).index(name), None] if name in names else xp.constant(value)
        for name, value in template.items()
    }


class ModalHarmonicGraph:
    """The N-mode phase-resonant backbone as a callable with the forward-model interface.

    Calling it on θ ``(..., n_params)`` builds :func:`modal_backbone_graph` and gives
    its ``(..., n_points, 3)`` backbone (NaN where the approximation does not
    settle, near an internal resonance); points are the locked mode's amplitude grid.

    Parameters
    ----------
    model
        Template model; parameters not in ``names`` keep its values.
    names
        Order of θ (None: all of :attr:`ModalModel.parameter_names`).
    amplitudes_m
        Amplitude grid (m), 1-D, > 0.
    mode
        The locked mode, numbered from 1.
    """

    def __init__(
        self,
        model: ModalModel,
        names: Sequence[str] | None,
        amplitudes_m: ArrayLike,
        mode: int = 1,
    ) -> None:
        self.model = model
        self.parameter_names = checked_names(model, names)
        self.amplitudes_m = positive_vector(amplitudes_m, "amplitudes_m")
        self.n_points = self.amplitudes_m.size
        self.mode = mode

    def __call__(self, theta: Any) -> pt.TensorVariable:
        return modal_backbone_graph(
            self.model, theta, self.parameter_names, self.amplitudes_m, mode=self.mode
        ).backbone

    def __repr__(self) -> str:
        return (
            f"ModalHarmonicGraph({self.model.name or 'ModalModel'!r}, "
            f"names={list(self.parameter_names)}, n_points={self.n_points}, mode={self.mode})"
        )
