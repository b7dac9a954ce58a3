"""Figures of a criticism: measured against predicted, signatures, the free-form
describing functions, the loop's history.

Each function draws on matplotlib axes it is given (no pyplot, no global
backend state); :func:`write_figures` draws all four on
:class:`matplotlib.figure.Figure` objects and writes them as PNG atomically.
``crit`` is a :class:`identification.criticism.criticism.Criticism` (typed
``Any`` here: :meth:`~identification.criticism.criticism.Criticism.write` draws
with these functions, so this module must not import that one).
"""

from __future__ import annotations

import io
from collections.abc import Mapping, Sequence
from pathlib import Path
from typing import Any

import numpy as np

from identification.artifacts import atomic_write_bytes
from identification.criticism.readings import CHANNEL_LABELS
from identification.fitting.data import HARMONIC_ORDERS

__all__ = ["plot_comparison", "plot_freeform", "plot_history", "plot_signatures", "write_figures"]


def _panels(crit: Any, residual: np.ndarray, n_axes: int) -> list[tuple[str, str]]:
    """(label, channel) of the panels: frequency, damping, and with measured harmonics
    and a third axis the harmonic (cosine part) with the largest miss in ``residual``."""
    panels = [("frequency_hz", "frequency_hz"), ("damping_ratio", "damping_ratio")]
    if crit.data.has_harmonics and n_axes > 2:
        misses = {h: np.nanmax(np.abs(residual[:, crit.data.column(f"harmonic{h}_cos")]))
                  for h in HARMONIC_ORDERS}  # fmt: skip
        order = max(misses, key=misses.get)
        panels.append((f"harmonic{order}", f"harmonic{order}_cos"))
    return panels


def _title(label: str) -> str:
    name = CHANNEL_LABELS[label][0]
    return f"{name} (cos part)" if label.startswith("harmonic") else name


def plot_comparison(crit: Any, axes) -> Any:
    """Measured vs predicted backbones (top) and the mean residual with its bands (bottom).

    ``axes``: 2 rows × 2 columns (frequency, damping), or × 3 with measured harmonics
    (the harmonic the model misses most, cosine part). The model is the refitted
    one (the posterior median with a posterior). The grey band is ± the calibrated
    ``where`` bound in standard errors of the mean curve (between-curve scatter over
    the number of curves ⊕ floors, widened by a posterior's population-mean
    uncertainty); with a posterior the predictive 95 % band is drawn too; failure
    ranges are shaded.
    """
    axes = np.asarray(axes).reshape(2, -1)
    data = crit.data
    amplitudes_mm = 1e3 * data.levels_m
    grid = np.geomspace(data.amplitude_m.min(), data.amplitude_m.max(), 80)
    model = crit.base.model
    curve = crit.predict_at(model, grid)
    mean_residual = data.mean_residual(crit.base.predicted)
    bound = crit.calibration.where_bound
    failures = crit.where()
    for column, (label, channel) in enumerate(_panels(crit, mean_residual, axes.shape[1])):
        _, unit, factor = CHANNEL_LABELS[label]
        top, bottom = axes[0, column], axes[1, column]
        j = data.column(channel)
        for i, name in enumerate(data.labels):
            rows = data.curve == i
            top.plot(1e3 * data.amplitude_m[rows], factor * data.values[rows, j], ".", alpha=0.6,
                     label=name if len(data.labels) <= 8 else None)  # fmt: skip
        top.plot(1e3 * grid, factor * curve[:, j], "k-", lw=2, label="model")
        entry = crit.comparison[channel]
        if "band_low" in entry:
            top.fill_between(amplitudes_mm, factor * entry["band_low"], factor * entry["band_high"],
                             color="C0", alpha=0.2, label="posterior 95 %")  # fmt: skip
        top.set(xscale="log", ylabel=f"{_title(label)} ({'%' if factor == 100 else unit})")
        residual, se = crit.residual(channel)
        bottom.fill_between(amplitudes_mm, -bound * factor * se, bound * factor * se, color="0.85",
                            label=f"±{bound:.2g} SE (calibrated bound)")  # fmt: skip
        bottom.plot(amplitudes_mm, factor * residual, "o-", color="C3", label="mean residual")
        bottom.axhline(0.0, color="k", lw=0.8)
        for failure in failures:
            if failure.channel == label:
                bottom.axvspan(failure.from_mm, failure.to_mm, color="C3", alpha=0.1)
        bottom.set(xscale="log", xlabel="amplitude (mm)",
                   ylabel=f"measured − model ({unit})")  # fmt: skip
        bottom.legend(fontsize="small")
    axes[0, 0].legend(fontsize="small")
    axes[0, 0].set_title(model.equation(3), fontsize="small", loc="left")
    return axes


def plot_signatures(crit: Any, axes, top: int = 3) -> Any:
    """The refitted base model's residual beside the signatures of the top candidates.

    ``axes``: frequency and damping axes, and with measured harmonics a third for the
    harmonic the refitted model misses most (cosine part, in phase with the
    fundamental's displacement). A candidate's signature is the change of the
    prediction it brings; the right effect's follows the residual.
    """
    axes = np.atleast_1d(np.asarray(axes)).ravel()
    data = crit.data
    amplitudes_mm = 1e3 * data.levels_m
    shown = [c for c in crit.candidates if c.fit is not None][:top]
    base = shown[0].base if shown else crit.base
    residual = data.mean_residual(base.predicted)
    se = np.column_stack([crit.residual(c)[1] for c in data.channels])
    bound = crit.calibration.where_bound
    for ax, (label, channel) in zip(axes, _panels(crit, residual, len(axes)), strict=False):
        _, unit, factor = CHANNEL_LABELS[label]
        j = data.column(channel)
        ax.fill_between(amplitudes_mm, -bound * factor * se[:, j], bound * factor * se[:, j],
                        color="0.85")  # fmt: skip
        ax.plot(
            amplitudes_mm, factor * residual[:, j], "ko-", lw=2, label="residual (refitted model)"
        )
        for k, candidate in enumerate(shown):
            legend = f"{candidate.effect} (Δχ² {candidate.delta_chi2:.0f}, {candidate.status})"
            ax.plot(amplitudes_mm, factor * candidate.signature[channel], "--", color=f"C{k}",
                    label=legend)  # fmt: skip
        ax.axhline(0.0, color="k", lw=0.8)
        ax.set(xscale="log", xlabel="amplitude (mm)", ylabel=unit, title=_title(label))
    axes[0].legend(fontsize="small")
    return axes


def plot_freeform(crit: Any, axes) -> Any:
    """The free-form describing functions beside the model's: ``k_eq(a)`` and ``c_eq(a)``.

    ``axes``: two axes. The refitted model's equivalent stiffness ``ω(a)²`` and damping
    ``2ζ(a)ω(a)`` (mass-normalised, at phase resonance), the free-form reference's
    (what any smooth physics fitted to the same data gives: the shape of what is
    missing), and the best catalogue candidate's where one was refitted.
    """
    ref = crit.reference
    mm = 1e3 * ref.levels_m
    k_base, c_base = ref.describing(ref.base_frequency_hz, ref.base_damping_ratio)
    k_ref, c_ref = ref.describing(ref.frequency_hz, ref.damping_ratio)
    curves = [("model", k_base, c_base, "k-"), ("free-form reference", k_ref, c_ref, "C3o-")]
    best = crit.best
    if best is not None and best.fit is not None:
        table = best.signature
        f = ref.base_frequency_hz + table["frequency_hz"]
        z = ref.base_damping_ratio + table["damping_ratio"]
        k_best, c_best = ref.describing(f, z)
        curves.append((f"+ {best.effect} ({best.status})", k_best, c_best, "C0--"))
    ax_k, ax_c = np.asarray(axes).ravel()[:2]
    for label, k, c, style in curves:
        ax_k.plot(mm, k / k_base[0], style, label=label)
        ax_c.plot(mm, c, style, label=label)
    ax_k.set(xscale="log", xlabel="amplitude (mm)", ylabel="k_eq / k_eq(smallest level)",
             title="equivalent stiffness ω²")  # fmt: skip
    ax_c.set(xscale="log", xlabel="amplitude (mm)", ylabel="c_eq (1/s)",
             title="equivalent damping 2ζω")  # fmt: skip
    ax_k.legend(fontsize="small")
    return axes


def plot_history(history: Sequence[Any], ax) -> Any:
    """Frequency RMSE (Hz, left) and damping RMSE (%-points, right) along the loop.

    ``history``: :class:`~identification.criticism.criticism.Step` objects or their
    ``to_dict()`` (as in ``criticism.json``).
    """
    steps = [s if isinstance(s, Mapping) else s.to_dict() for s in history]
    x = np.arange(len(steps))
    ax.plot(x, [s["frequency_rmse_hz"] for s in steps], "o-", color="C0", label="frequency")
    ax.set(ylabel="frequency RMSE (Hz)", yscale="log", xticks=x)
    ax.set_xticklabels([s["action"] for s in steps], rotation=20, ha="right")
    twin = ax.twinx()
    twin.plot(x, [100 * s["damping_rmse"] for s in steps], "s--", color="C3", label="damping")
    twin.set(ylabel="damping RMSE (%-points)", yscale="log")
    ax.legend(handles=ax.lines + twin.lines, fontsize="small")
    return ax


def write_figures(crit: Any, folder: str | Path) -> dict[str, Path]:
    """Draw the four figures of a criticism and write them as PNG into ``folder``.

    ``comparison.png`` (:func:`plot_comparison`), ``signatures.png``
    (:func:`plot_signatures`), ``freeform.png`` (:func:`plot_freeform`) and
    ``history.png`` (:func:`plot_history`).
    """
    from matplotlib.figure import Figure  # no pyplot: no global backend state

    folder = Path(folder)
    columns = 3 if crit.data.has_harmonics else 2
    figures = {
        "comparison": (Figure(figsize=(5.5 * columns, 7), layout="constrained"), (2, columns),
                       plot_comparison),
        "signatures": (Figure(figsize=(5.5 * columns, 4), layout="constrained"), (1, columns),
                       plot_signatures),
        "freeform": (Figure(figsize=(11, 4), layout="constrained"), (1, 2), plot_freeform),
    }  # fmt: skip
    paths = {}
    for name, (figure, grid, plot) in figures.items():
        plot(crit, figure.subplots(*grid))
        paths[name] = _save(figure, folder / f"{name}.png")
    figure = Figure(figsize=(7, 4), layout="constrained")
    plot_history(crit.history, figure.subplots())
    paths["history"] = _save(figure, folder / "history.png")
    return paths


def _save(figure, path: Path) -> Path:
    buffer = io.BytesIO()
    figure.savefig(buffer, format="png", dpi=110)
    return atomic_write_bytes(path, buffer.getvalue())
