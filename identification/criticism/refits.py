"""Candidate refits: the criticised model's structure and its extensions refitted.

:class:`Refits` is the one place a criticism refits a model (through
:class:`~identification.fitting.fitter.Fitter`): the base model (once per
harmonic-balance method), the base with a catalogue effect added, and any other
structure (a swap's or a model-term trial's); the ones it has done are kept, and
several refits run as tasks on an executor when one is given (each the same serial
fit, so a result does not depend on where it ran).
"""

from __future__ import annotations

from collections.abc import Iterable, Mapping, Sequence
from typing import Any

from identification.fitting.fitter import Fitter
from identification.fitting.least_squares import FitResult
from identification.model import JointModel

__all__ = ["Refits"]


class Refits:
    """The refits of one criticised model.

    Parameters
    ----------
    fitter
        The data and the fitting options.
    model
        The model criticised.
    posterior
        Whether the model is a posterior's median (judged as given, not refitted).
    executor
        Anything with ``submit(fn, *args, **kwargs)`` (a dask ``Client``, a
        ``concurrent.futures`` pool), or None: here.
    prefitted
        Refits already done, by key (``"base:<method>"``, ``"add:<effect>"``).
    """

    def __init__(
        self,
        fitter: Fitter,
        model: JointModel,
        *,
        posterior: bool = False,
        executor: Any = None,
        prefitted: Mapping[str, FitResult] | None = None,
    ) -> None:
        self.fitter = fitter
        self.model = model
        self.posterior = posterior
        self.executor = executor
        self.done: dict[str, FitResult] = dict(prefitted or {})

    def method_for(self, model: JointModel) -> str:
        """The harmonic balance ``model`` needs on these data."""
        return self.fitter.method_for(model)

    def base(self, method: str | None = None) -> FitResult:
        """The criticised model's structure refitted (once per harmonic-balance method;
        default the one it needs); with a posterior, the posterior median as given (the
        posterior is what is judged)."""
        method = method or self.method_for(self.model)
        key = f"base:{method}"
        if key not in self.done:
            if self.posterior:
                self.done[key] = self.fitter.evaluate(self.model, method=method)
            else:
                self.done[key] = self.fitter.fit(self.model, method=method)
        return self.done[key]

    def extension(self, effect: str, **shape: float) -> tuple[JointModel, str, dict]:
        """The refitted base model with ``effect`` added (coefficient 0 marks it as new: the
        fit scans its start), the method of its refit and the shape start values to scan."""
        if effect in self.model:
            raise ValueError(
                f"effect {effect!r} is already in the model ({', '.join(self.model.effects)})"
            )
        method = self.method_for(self.model.with_effect(effect, 0.0, **shape))
        extended = self.base(method).model.with_effect(effect, 0.0, **shape)
        scan = {f"{effect}.{k}": [v] for k, v in shape.items()}
        scan = {k: v for k, v in scan.items() if k in extended.parameter_names}
        return extended, method, scan

    def extended(self, effect: str, **shape: float) -> FitResult:
        """The base model with ``effect`` added, refitted (kept unless start values were
        given)."""
        key = f"add:{effect}"
        if shape or key not in self.done:
            model, method, scan = self.extension(effect, **shape)
            result = self.fitter.fit(model, method=method, shape_scan=scan or None)
            if shape:
                return result
            self.done[key] = result
        return self.done[key]

    def prefetch(self, effects: Iterable[str]) -> None:
        """The extensions by ``effects`` refitted as tasks on the executor (nothing
        without one or with fewer than two to do; :meth:`extended` does them here)."""
        todo = [e for e in effects if f"add:{e}" not in self.done]
        if self.executor is None or len(todo) < 2:
            return
        jobs = {e: self.extension(e) for e in todo}  # the base fits, here, once per method
        futures = {
            e: self.executor.submit(self.fitter.fit, model, method=method, shape_scan=scan or None)
            for e, (model, method, scan) in jobs.items()
        }
        for effect, future in futures.items():
            self.done[f"add:{effect}"] = future.result()

    def structure(self, model: JointModel) -> FitResult:
        """``model``'s structure refitted to the data (a new effect at coefficient 0 gets
        its start scanned, as :meth:`extended` does)."""
        return self.structures([model])[0]

    def structures(self, models: Sequence[JointModel]) -> list[FitResult]:
        """Each model's structure refitted; each a task on the executor when there is one
        and more than one model."""
        if self.executor is None or len(models) < 2:
            return [self.fitter.fit(m) for m in models]
        return [f.result() for f in [self.executor.submit(self.fitter.fit, m) for m in models]]
