"""One way into the fitting: a model against one data set under one set of options.

:class:`Fitter` holds the measured data (:class:`~identification.fitting.data.FitData`)
and the options every refit of a study shares (harmonic-balance method, channel
weights); its four methods are the whole interface the criticism, the studies and the
CLI need:

- :meth:`Fitter.method_for`: the harmonic balance a model needs on these data;
- :meth:`Fitter.evaluate`: the model as given (no fit);
- :meth:`Fitter.fit`: the model's parameters fitted (least squares);
- :meth:`Fitter.predict`: the model's channels at the data's points or at other
  amplitudes, driven by the excitation the holds measured there.

They are the single implementations of :mod:`identification.fitting.least_squares`
and :mod:`identification.fitting.prediction` with the data and options bound, so a
result does not depend on which door it came through.
"""

from __future__ import annotations

from collections.abc import Mapping, Sequence
from dataclasses import dataclass, field

import numpy as np
from numpy.typing import ArrayLike

from identification.fitting.data import FitData
from identification.fitting.least_squares import (
    FitResult,
    default_free,
    evaluate,
    fit_backbones,
)
from identification.fitting.prediction import predict_channels, resolve_method
from identification.measurements.backbone import BackboneSet
from identification.model import JointModel

__all__ = ["Fitter"]


@dataclass(frozen=True)
class Fitter:
    """A model against measured data, under fixed options.

    Parameters
    ----------
    data
        The measured data (build it from backbones with :meth:`from_backbones`).
    method
        Harmonic balance: ``"auto"`` (per model, :func:`resolve_method`), ``"single"``
        or ``"multi"``.
    weights
        Channel weights ``{"frequency_hz", "damping_ratio", "harmonics"}`` (default 1).
    """

    data: FitData
    method: str = "auto"
    weights: Mapping[str, float] = field(default_factory=dict)

    def __post_init__(self) -> None:
        # a plain copy (picklable: the refits may run as tasks on a dask cluster)
        object.__setattr__(self, "weights", dict(self.weights or {}))

    @classmethod
    def from_backbones(
        cls,
        measured: BackboneSet | FitData,
        *,
        method: str = "auto",
        weights: Mapping[str, float] | None = None,
        noise_floor: Mapping[str, float] | None = None,
    ) -> Fitter:
        """The fitter of measured backbones (``noise_floor``: overrides of the floors)."""
        from identification.fitting.data import fit_data

        data = measured if isinstance(measured, FitData) else fit_data(measured, noise_floor)
        return cls(data, method, weights or {})

    @property
    def _weights(self) -> dict[str, float] | None:
        return dict(self.weights) or None

    def method_for(self, model: JointModel) -> str:
        """The harmonic balance ``model`` needs on these data (``"single"`` or ``"multi"``)."""
        return resolve_method(self.method, model, self.data)

    def evaluate(
        self, model: JointModel, *, method: str | None = None, n_parameters: int | None = None
    ) -> FitResult:
        """The model as given against the data; the information criteria count
        ``n_parameters`` (default: the model's adjustable parameters,
        :func:`default_free`), so it compares with refitted models."""
        count = len(default_free(model)) if n_parameters is None else n_parameters
        return evaluate(
            model, self.data, method=method or self.method_for(model), weights=self._weights,
            n_parameters=count,
        )  # fmt: skip

    def fit(
        self,
        model: JointModel,
        *,
        method: str | None = None,
        free: Sequence[str] | None = None,
        shape_scan: Mapping[str, ArrayLike] | None = None,
    ) -> FitResult:
        """The model's parameters fitted to the data (:func:`fit_backbones`: an effect at
        coefficient 0 counts as new and gets its start scanned). A fit that meets a
        region without a periodic solution comes back with
        :attr:`FitResult.outcome` saying so, not as an error."""
        return fit_backbones(
            model, self.data, free, method=method or self.method_for(model),
            weights=self._weights, shape_scan=shape_scan,
        )  # fmt: skip

    def predict(
        self,
        model: JointModel,
        amplitude_m: ArrayLike | None = None,
        channels: Sequence[str] | None = None,
        *,
        method: str | None = None,
        parameters: ArrayLike | None = None,
        names: Sequence[str] | None = None,
    ) -> np.ndarray:
        """The model's channels at the data's points (``amplitude_m`` None, each driven by
        the excitation its hold measured) or at other amplitudes (driven by the
        excitation the holds measured there, :meth:`FitData.excitation_at`).

        ``channels`` default to the data's; ``parameters``/``names`` as
        :func:`predict_channels`. NaN where the harmonic balance has no solution.
        """
        data = self.data
        if amplitude_m is None:
            amplitude_m, forcing = data.amplitude_m, data.excitation_harmonics
        else:
            forcing = data.excitation_at(amplitude_m)
        return predict_channels(
            model, amplitude_m, data.channels if channels is None else channels,
            method=method or self.method_for(model), parameters=parameters, names=names,
            excitation_harmonics=forcing,
        )  # fmt: skip
