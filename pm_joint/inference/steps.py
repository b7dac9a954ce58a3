"""PyMC's Metropolis with its proposal covariance learned while tuning.

The paper samples with PyMC's Metropolis, one scalar coordinate at a time with
a scale tuned per coordinate. On a posterior whose parameters are correlated
(as the population-matching posterior is: several parameters move the
backbone alike) such chains crawl (bench/results/sampling.json compares the
samplers). :class:`CovarianceMetropolis` keeps PyMC's
Metropolis (its proposal, acceptance and scale tuning) and adds what PyMC's
Metropolis takes but does not learn, a proposal covariance: the first part of
tuning is the paper's coordinate-wise Metropolis (a pilot run), then the
chain proposes jointly from a normal with the covariance of its own pilot
draws (Haario et al.'s adaptive Metropolis, re-estimated over doubling
windows as Stan does for its mass matrix), scaled by 2.38/√d and tuned to
PyMC's acceptance band. After tuning, the proposal is fixed, so the draws are
those of a plain Metropolis–Hastings chain.

The chain walks in the prior box's own linear coordinates (``coordinates=
"box"``, the default): a uniform prior's value variable in PyMC is the logit
of the box fraction, and a ridge that is straight in the parameters (several
parameters moving the prediction alike, cut off by the box) is curved there,
where no single proposal covariance follows it (a known-answer test in
tests/test_convergence.py compares the two coordinates on the same draws). The
step maps each bounded coordinate to its box fraction ``u = sigmoid(z)``,
proposes there, rejects a proposal outside the box without evaluating the
model, and scores the rest by the log density in ``u`` (the model's, plus the
log Jacobian ``−Σ log u(1 − u)``): a Metropolis chain on the same posterior.

PyMC's Metropolis scores a proposal by ``logp(q) − logp(q0)``, evaluating the
model at both points every step, though the current point ``q0`` was scored
when it was proposed. Where the step moves every variable (nothing else
changes the model between steps), :class:`CovarianceMetropolis` keeps the
log density of the current point instead (:class:`KeptLogp`): one model
evaluation per proposal, the same chain.
"""

from __future__ import annotations

from collections.abc import Iterator
from contextlib import contextmanager
from dataclasses import field
from typing import Any, ClassVar

import numpy as np
import pymc as pm
import scipy.special
from pymc.blocking import RaveledVars
from pymc.logprob.transforms import IntervalTransform
from pymc.pytensorf import compile as compile_pytensor
from pymc.pytensorf import join_nonshared_inputs, make_shared_replacements
from pymc.step_methods import metropolis as pymc_metropolis
from pymc.step_methods.metropolis import (
    MetropolisState,
    MultivariateNormalProposal,
    NormalProposal,
)
from pymc.step_methods.state import dataclass_state

__all__ = ["CovarianceMetropolis", "KeptLogp"]


@dataclass_state
class CovarianceMetropolisState(MetropolisState):
    """PyMC's Metropolis state plus the proposal and where the adaptation stands.

    ``elemwise_update`` is not frozen here: the proposal turns joint while tuning.
    """

    elemwise_update: bool
    proposal_dist: Any
    tune_steps: int | None = field(metadata={"frozen": True})
    _step_count: int
    _window_ends: list
    _window_start: int
    _pilot: list
    _last: tuple | None


@contextmanager
def _deferred_delta_logp() -> Iterator[list]:
    """PyMC's Metropolis without its ``delta_logp`` compiled: the arguments are kept instead.

    ``pm.Metropolis.__init__`` compiles ``logp(q) − logp(q0)`` (its graph rewrites are about half
    of a step's set-up on the updating models), which :class:`KeptLogp` replaces wherever
    the step moves every variable; the kept arguments compile it where it does not.
    """
    kept: list = []
    compile_now = pymc_metropolis.delta_logp
    pymc_metropolis.delta_logp = lambda *args: kept.extend(args)
    try:
        yield kept
    finally:
        pymc_metropolis.delta_logp = compile_now


class CovarianceMetropolis(pm.Metropolis):
    """Metropolis whose tuning learns a joint proposal covariance from pilot draws.

    Parameters
    ----------
    vars
        Value variables (default: every free variable of the model), all in one step.
    adapt_covariance
        False: the paper's Metropolis throughout (coordinate-wise proposals,
        each coordinate's scale tuned), for comparison.
    pilot_fraction
        Share of the tuning steps run coordinate-wise (the paper's Metropolis)
        before the first covariance is estimated.
    final_fraction
        Share of the tuning steps at the end in which only the scale is tuned
        (the last covariance stays).
    coordinates
        ``"box"``: the chain proposes in the box fractions of the variables with
        both bounds (interval transform), see the module notes; ``"value"``:
        in PyMC's value variables (the logit of the box fraction).
    **kwargs
        PyMC's Metropolis options (``tune_interval``, ``scaling``, ...).

    Notes
    -----
    The sampler statistic ``logp_inf`` is True where a proposal inside the
    box had log density −inf: in the updating models that is a forward model
    that returned NaN (the likelihood's only −inf), so it counts the NaN rate.
    ``outside_box`` is True where a proposal left the prior box (rejected, the
    model not evaluated).
    """

    name = "metropolis"
    default_blocked = True  # one step over every variable: one compiled logp
    stats_dtypes_shapes: ClassVar = {
        **pm.Metropolis.stats_dtypes_shapes,
        "logp_inf": (bool, []),
        "outside_box": (bool, []),
    }
    _state_class = CovarianceMetropolisState

    def __init__(
        self,
        vars=None,
        *,
        adapt_covariance: bool = True,
        pilot_fraction: float = 0.2,
        final_fraction: float = 0.15,
        coordinates: str = "box",
        **kwargs,
    ) -> None:
        if not (pilot_fraction > 0 and final_fraction >= 0 and pilot_fraction + final_fraction < 1):
            raise ValueError("pilot_fraction and final_fraction must leave room for adaptation")
        if coordinates not in ("box", "value"):
            raise ValueError(f"coordinates must be 'box' or 'value', got {coordinates!r}")
        with _deferred_delta_logp() as deferred:
            super().__init__(vars, **kwargs)
        self.coordinates = coordinates
        self._box = np.zeros(0, dtype=int)  # raveled indices walked as box fractions
        self._last = None  # (value-space point, working point) of the last step
        if not self._keep_current_logp(kwargs):
            self.delta_logp = pymc_metropolis.delta_logp(*deferred)
        self.adapt_covariance = adapt_covariance
        self.pilot_fraction = pilot_fraction
        self.final_fraction = final_fraction
        self.n_dims = int(self.proposal_dist.s.size)
        self.tune_steps = None  # told by the sampler (set_tune_steps); else no covariance
        self._reset_adaptation()

    def _keep_current_logp(self, kwargs) -> bool:
        """Score proposals with :class:`KeptLogp` where the step moves every variable;
        False where it does not (PyMC's ``logp(q) − logp(q0)`` is needed then)."""
        model = pm.modelcontext(kwargs.get("model"))
        point = kwargs.get("initial_point") or model.initial_point()
        if make_shared_replacements(point, self.vars, model):
            return False  # another step moves the rest: the current point's logp can change
        [logp], joined = join_nonshared_inputs(point, [model.logp()], self.vars, {})
        function = compile_pytensor([joined], logp, **(kwargs.get("compile_kwargs") or {}))
        function.trust_input = True
        if self.coordinates == "box":
            self._box = _bounded_indices(model, self.vars, point)
        self.delta_logp = KeptLogp(function, self._box)
        return True

    # -- tuning schedule --------------------------------------------------------

    def set_tune_steps(self, tune: int) -> None:
        """How many tuning steps the chain will take (the windows depend on it)."""
        self.tune_steps = int(tune)
        self._reset_adaptation()

    def _windows(self) -> list[int]:
        """Step counts at which the covariance is re-estimated."""
        if not (self.adapt_covariance and self.tune_steps):
            return []
        start = int(self.pilot_fraction * self.tune_steps)
        stop = int((1 - self.final_fraction) * self.tune_steps)
        if start < max(10 * self.n_dims, 20) or stop <= start:
            return []  # too few steps for a covariance: stay coordinate-wise
        ends, width = [start], start
        while ends[-1] + 2 * width <= stop:
            width *= 2
            ends.append(ends[-1] + width)
        if ends[-1] < stop:
            ends[-1] = stop  # the last window takes the rest, as Stan's does
        return ends

    def _reset_adaptation(self) -> None:
        self._step_count = 0
        self._window_ends = self._windows()
        self._window_start = 0
        self._pilot: list[np.ndarray] = []
        self._set_coordinatewise()

    def _set_coordinatewise(self) -> None:
        self.proposal_dist = NormalProposal(np.ones(self.n_dims))
        self._set_elementwise(True)
        self.scaling = np.ones(self.n_dims)

    def _set_joint(self, covariance: np.ndarray) -> None:
        self.proposal_dist = MultivariateNormalProposal(covariance)
        self._set_elementwise(False)
        self.scaling = np.atleast_1d(2.38 / np.sqrt(self.n_dims))

    def _set_elementwise(self, elementwise: bool) -> None:
        n = self.n_dims if elementwise else 1
        self.elemwise_update = elementwise
        self.enum_dims = np.arange(n, dtype=int)
        self.accept_rate_iter = np.zeros(n, dtype=float)
        self.accepted_iter = np.zeros(n, dtype=bool)
        self.accepted_sum = np.zeros(n, dtype=int)
        self.steps_until_tune = self.tune_interval

    def reset_tuning(self) -> None:
        super().reset_tuning()
        self._reset_adaptation()

    # -- one step ---------------------------------------------------------------

    def astep(self, q0):
        info = q0.point_map_info
        if self._last is not None and np.array_equal(self._last[0], q0.data):
            w0 = self._last[1]  # the exact working point: no round-trip rounding
        else:
            w0 = _to_box(q0.data, self._box)
        kept = isinstance(self.delta_logp, KeptLogp)
        if kept:
            self.delta_logp.outside = self.delta_logp.infinite = False
        w, stats = super().astep(RaveledVars(w0, info))
        stats[0]["outside_box"] = kept and self.delta_logp.outside
        # −inf inside the box: the model itself (in the updating models a NaN forward output)
        stats[0]["logp_inf"] = bool(
            self.delta_logp.infinite if kept else np.any(np.isneginf(self.accept_rate_iter))
        )
        q = RaveledVars(_from_box(w.data, self._box), info)
        self._last = (q.data, w.data)
        if self.tune and self._window_ends:
            self._pilot.append(np.array(w.data, dtype=float))
            self._step_count += 1
            if self._window_ends and self._step_count == self._window_ends[0]:
                self._window_ends.pop(0)
                draws = np.array(self._pilot[self._window_start :])
                self._window_start = len(self._pilot)
                covariance = _regularised_covariance(draws)
                if covariance is not None:
                    self._set_joint(covariance)
        return q, stats


class KeptLogp:
    """``logp(q) − logp(q0)`` as PyMC's Metropolis asks for it, each point scored once.

    The log densities of the last two points scored are kept: a Metropolis
    step's current point is either the last proposal (accepted) or the point
    before it (rejected), so only the new proposal is evaluated. Exact: the
    model's log density is a deterministic function of the point.

    ``box`` lists the raveled indices given as box fractions ``u`` (the model
    takes ``logit(u)``): a point outside the box scores −inf unevaluated (and
    sets :attr:`outside`), one inside the model's log density plus the log
    Jacobian ``−Σ log u(1 − u)``; :attr:`infinite` is set where a point inside
    had log density −inf.
    """

    def __init__(self, logp, box: np.ndarray | None = None) -> None:
        self.logp = logp
        self.box = np.zeros(0, dtype=int) if box is None else np.asarray(box, dtype=int)
        self.outside = self.infinite = False
        self._kept: dict[bytes, float] = {}

    def __call__(self, q: np.ndarray, q0: np.ndarray) -> float:
        current = self._score(q0)  # first, so the proposal's entry evicts the other one
        return self._score(q) - current

    def _score(self, q: np.ndarray) -> float:
        key = q.tobytes()
        value = self._kept.pop(key, None)
        if value is None:
            value = self._evaluate(q)
        self._kept[key] = value  # most recent last
        if len(self._kept) > 2:
            del self._kept[next(iter(self._kept))]
        return value

    def _evaluate(self, w: np.ndarray) -> float:
        u = w[self.box]
        if not np.all((u > 0) & (u < 1)):
            self.outside = True
            return -np.inf
        value = float(self.logp(_from_box(w, self.box)))
        self.infinite |= np.isneginf(value)
        return value - float(np.sum(np.log(u) + np.log1p(-u)))


def _bounded_indices(model: pm.Model, value_vars, point) -> np.ndarray:
    """Raveled indices of the value variables that are logits of a bounded box."""
    indices, start = [], 0
    for var in value_vars:
        size = int(np.size(point[var.name]))
        transform = model.rvs_to_transforms.get(model.values_to_rvs[var])
        if isinstance(transform, IntervalTransform):
            rv = model.values_to_rvs[var]
            _, _, has_lower, has_upper = transform.get_a_and_b(rv.owner.inputs)
            if has_lower and has_upper:
                indices.extend(range(start, start + size))
        start += size
    return np.array(indices, dtype=int)


def _to_box(z: np.ndarray, box: np.ndarray) -> np.ndarray:
    """Value-space point → working point: the box indices as fractions sigmoid(z)."""
    w = np.array(z, dtype=float)
    w[box] = scipy.special.expit(w[box])
    return w


def _from_box(w: np.ndarray, box: np.ndarray) -> np.ndarray:
    """Working point → value-space point: logit of the box fractions."""
    z = np.array(w, dtype=float)
    z[box] = scipy.special.logit(z[box])
    return z


def _regularised_covariance(draws: np.ndarray) -> np.ndarray | None:
    """Sample covariance shrunk towards a small diagonal (Stan's regularisation).

    None where the window never moved (a stuck chain gives no direction to learn).
    """
    n = draws.shape[0]
    covariance = np.atleast_2d(np.cov(draws, rowvar=False))
    scale = np.diag(covariance)
    if not np.all(np.isfinite(covariance)) or np.any(scale <= 0):
        return None
    shrunk = (n / (n + 5.0)) * covariance + 1e-3 * (5.0 / (n + 5.0)) * np.diag(scale)
    try:
        np.linalg.cholesky(shrunk)
    except np.linalg.LinAlgError:
        return None
    return shrunk
