"""A model's predictions in the channel layout of measured backbones.

:func:`predict_channels` evaluates the harmonic-balance backbone
(:func:`identification.analytical.harmonic.backbone`) at measured amplitudes in
the channels of :mod:`identification.fitting.data`; :func:`resolve_method`
chooses the single- or multi-harmonic balance a model and its data need.
"""

from __future__ import annotations

from collections.abc import Sequence

import numpy as np
from numpy.typing import ArrayLike

from identification.analytical.harmonic import EXCITATION_KINDS, backbone
from identification.effects import CATALOGUE
from identification.fitting.data import BACKBONE_CHANNELS, HARMONIC_CHANNELS, FitData
from identification.measurements.quantities import check_choice
from identification.model import JointModel

__all__ = ["N_HARMONICS", "predict_channels", "resolve_method"]

#: Harmonics balanced by ``method="multi"``.
N_HARMONICS = 5


# --------------------------------------------------------------------------
# Model predictions in the channel layout


def resolve_method(method: str, model: JointModel, data: FitData | None = None) -> str:
    """``"auto"``: multi-harmonic balance when the model has even terms or the data
    harmonics (of the response, or of the excitation that drives it), else the (much
    faster) single-harmonic balance."""
    harmonics = data is not None and (
        data.has_harmonics
        or (data.excitation_harmonics is not None and bool(data.excitation_harmonics.any()))
    )
    if method == "auto":
        even = any(CATALOGUE[e].parity != "odd" for e in model.effects)
        return "multi" if even or harmonics else "single"
    if method not in ("single", "multi"):
        raise ValueError(f"method must be 'auto', 'single' or 'multi', got {method!r}")
    if method == "single" and harmonics:
        raise ValueError("the measured harmonics need method='multi' (or 'auto')")
    return method


def predict_channels(
    model: JointModel,
    amplitude_m: ArrayLike,
    channels: Sequence[str] = BACKBONE_CHANNELS,
    *,
    method: str = "single",
    parameters: ArrayLike | None = None,
    names: Sequence[str] | None = None,
    excitation_harmonics: ArrayLike | None = None,
    excitation_kind: str = "base_acceleration",
) -> np.ndarray:
    """Model prediction of each channel at the given amplitudes.

    ``excitation_harmonics`` (``(n_points, n_orders)``, e.g.
    :attr:`FitData.excitation_harmonics` or :meth:`FitData.excitation_at`) drives each
    point by the excitation its hold measured (``method="multi"``; see
    :func:`identification.analytical.harmonic.forcing_rows`); None, or all zero, is
    the pure sine. ``excitation_kind`` says what those ratios are of: the
    (equivalent) base acceleration, as extracted backbones carry them for base- and
    force-driven records alike, or ``"force"`` for the ratios of a force's own signal.

    Returns ``(n_points, n_channels)``, or ``(n_sets, n_points, n_channels)`` with
    ``parameters`` (see :func:`identification.analytical.harmonic.backbone`); NaN where the
    harmonic balance has no solution.
    """
    a = np.asarray(amplitude_m, dtype=float)
    harmonic_channels = [c for c in channels if c in HARMONIC_CHANNELS]
    if harmonic_channels and method != "multi":
        raise ValueError(f"channels {harmonic_channels} need method='multi'")
    forcing = None
    check_choice("excitation kind", excitation_kind, EXCITATION_KINDS)
    if excitation_harmonics is not None:
        forcing = np.asarray(excitation_harmonics, dtype=complex).reshape(a.size, -1)
        if not forcing.any():
            forcing = None
    if forcing is None:
        unique, inverse = np.unique(a, return_inverse=True)
        shared = {}
    else:  # one balance per distinct (amplitude, excitation)
        keys = np.column_stack([a, forcing.real, forcing.imag])
        rows, inverse = np.unique(keys, axis=0, return_inverse=True)
        unique = rows[:, 0]
        n_orders = forcing.shape[1]
        shared = {
            "excitation_harmonics": rows[:, 1 : 1 + n_orders] + 1j * rows[:, 1 + n_orders :],
            "excitation_kind": excitation_kind,
        }
    result = backbone(
        model, unique, parameters=parameters, names=names, method=method, harmonics=N_HARMONICS,
        **shared,
    )  # fmt: skip
    columns = []
    for channel in channels:
        if channel == "frequency_hz":
            columns.append(result.frequency_hz)
        elif channel == "damping_ratio":
            columns.append(result.damping_ratio)
        elif channel in HARMONIC_CHANNELS:
            order, part = int(channel[len("harmonic")]), channel.rsplit("_", 1)[1]
            table = result.harmonics_cos_m if part == "cos" else result.harmonics_sin_m
            columns.append(table[..., order] / unique)
        else:
            raise ValueError(f"unknown channel {channel!r}")
    return np.stack(columns, axis=-1)[..., inverse.reshape(-1), :]
