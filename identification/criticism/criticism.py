"""Model criticism: where a joint model fails, and which physical effect it lacks.

A misspecification check says *that* a model is wrong; this module says *which
physics* is missing. The loop a user runs::

    crit = criticize(model, measured, records=campaign)   # compare, locate, rank
    crit.where()            # amplitude ranges where the residual beats the scatter
    crit.missing()          # catalogue effects that pay for their complexity, best first
    crit2 = crit.add("microslip")                        # refit with it, look again
    plot_history(crit2.history, ax)                      # the error falling

* **Compare.** The model's harmonic-balance backbone against the measured curves
  at the measured amplitudes; the residual averaged over curves at amplitude
  levels with its standard error from the scatter across curves (and, given a
  posterior, the posterior-predictive band and its coverage).
* **Where.** Runs of consecutive levels where the mean residual exceeds
  ``z`` standard errors, per channel, in words and as data.
* **Missing.** Every catalogue effect the model lacks is added and the extended
  model refitted (:func:`identification.fitting.fit.fit_backbones`); the error reduction
  and the change of an information criterion against the refitted model without
  it (BIC by default) rank them. Only effects with ``ΔIC`` below ``threshold``
  (default −10: "very strong" evidence) are proposed. Each gets the signature it
  leaves (the change of the predicted backbone it brings, beside the residual)
  and a reading made from that signature and the catalogue.
* **Records.** Backbones cannot separate some effects (``x²`` and ``x³`` both
  soften or harden in ``a²``). With test records the second and third harmonics
  of the response enter the fit as a third channel: ``x²`` leaves a second
  harmonic phase-locked to the fundamental, ``x³`` a third. (The mean
  displacement an even term also leaves is invisible to velocity sensors.)
"""

from __future__ import annotations

import io
import json
from collections.abc import Mapping, Sequence
from dataclasses import dataclass, field
from functools import cached_property
from pathlib import Path
from typing import Any

import numpy as np

from identification.artifacts import atomic_write_bytes, atomic_write_text
from identification.effects import CATALOGUE, get_effect
from identification.fitting.fit import (
    BACKBONE_CHANNELS,
    HARMONIC_ORDERS,
    FitData,
    FitResult,
    default_free,
    evaluate,
    extract_harmonics,
    fit_backbones,
    fit_data,
    predict_channels,
    resolve_method,
)
from identification.measurements.backbone import BackboneSet, extract_backbone
from identification.measurements.records import Record
from identification.model import JointModel

__all__ = [
    "AMBIGUITY",
    "DEFAULT_THRESHOLD",
    "KEY_CHANNEL",
    "Candidate",
    "Criticism",
    "FailureRange",
    "Step",
    "StudyResult",
    "criticize",
    "hidden_effect_study",
    "plot_comparison",
    "plot_history",
    "plot_signatures",
    "posterior_samples",
]

FORMAT = "pm-joint/criticism"
#: ΔIC below which an effect is proposed (BIC: < −10 is "very strong" evidence).
DEFAULT_THRESHOLD = -10.0
#: Candidates within this ΔIC of the best are reported as not clearly separated.
AMBIGUITY = 6.0
_LABELS = {
    "frequency_hz": ("frequency", "Hz", 1.0),
    "damping_ratio": ("damping", "%-points", 100.0),
    "harmonic2": ("2nd harmonic", "% of the fundamental", 100.0),
    "harmonic3": ("3rd harmonic", "% of the fundamental", 100.0),
}


# --------------------------------------------------------------------------
# Results


@dataclass(frozen=True)
class FailureRange:
    """An amplitude range where the model misses the measurement beyond the scatter.

    ``max_residual`` is measured minus predicted at the worst level, in the
    channel's SI unit (Hz, damping ratio, fraction of the fundamental for the
    harmonics, where it is the magnitude of the complex miss).
    """

    channel: str
    from_mm: float
    to_mm: float
    max_residual: float
    direction: str

    @property
    def text(self) -> str:
        name, unit, factor = _LABELS[self.channel]
        size = f"{abs(self.max_residual) * factor:.2g} {unit}"
        span = (
            f"at {self.from_mm:.2g} mm"
            if self.from_mm == self.to_mm
            else f"between {self.from_mm:.2g} and {self.to_mm:.2g} mm"
        )
        if self.channel.startswith("harmonic"):
            return f"the {name} of the response is {self.direction} by up to {size} {span}"
        return f"{name} is {self.direction} by up to {size} {span}"

    def __str__(self) -> str:
        return self.text

    def to_dict(self) -> dict[str, Any]:
        return {
            "channel": self.channel,
            "from_mm": self.from_mm,
            "to_mm": self.to_mm,
            "max_residual": self.max_residual,
            "direction": self.direction,
            "text": self.text,
        }


@dataclass(frozen=True)
class Candidate:
    """A catalogue effect added to the model and refitted.

    Attributes
    ----------
    effect
        Catalogue name.
    fit
        The refitted extended model.
    base
        The refitted model without it (same harmonic-balance method).
    criterion, delta_ic
        Information criterion and its change ``IC(fit) − IC(base)`` (negative: better).
    proposed
        Whether ``delta_ic`` is below the threshold.
    signature
        Per channel, at the levels: ``prediction(fit) − prediction(base)``, the
        change the effect brings; it should look like the base model's residual.
    reading
        Physical reading made specific to the evidence.
    """

    effect: str
    fit: FitResult
    base: FitResult
    criterion: str
    delta_ic: float
    proposed: bool
    signature: dict[str, np.ndarray]
    reading: str

    @property
    def n_new_parameters(self) -> int:
        return self.fit.n_parameters - self.base.n_parameters

    @property
    def error_reduction(self) -> dict[str, float]:
        """Fractional RMSE reduction per channel against the refitted base model."""
        out = {}
        for key, before, after in _rmse_pairs(self.base, self.fit):
            out[key] = float(1.0 - after / before) if before > 0 else 0.0
        return out

    def to_dict(self) -> dict[str, Any]:
        return {
            "effect": self.effect,
            "error_reduction": self.error_reduction,
            "delta_information_criterion": self.delta_ic,
            "criterion": self.criterion,
            "proposed": self.proposed,
            "reading": self.reading,
            "rmse_before": {k: b for k, b, _ in _rmse_pairs(self.base, self.fit)},
            "rmse_after": {k: a for k, _, a in _rmse_pairs(self.base, self.fit)},
            "parameters": self.fit.model.parameters,
            "equation": self.fit.model.equation(),
            "signature": {k: v.tolist() for k, v in self.signature.items()},
        }


def _rmse_pairs(before: FitResult, after: FitResult):
    for key in ("frequency_hz", "damping_ratio", "harmonics"):
        attribute = {"frequency_hz": "frequency_rmse_hz", "damping_ratio": "damping_rmse",
                     "harmonics": "harmonic_rmse"}[key]  # fmt: skip
        b, a = getattr(before, attribute), getattr(after, attribute)
        if b is not None and a is not None:
            yield key, float(b), float(a)


@dataclass(frozen=True)
class Step:
    """One step of the criticism loop: the model and how well it fits."""

    action: str
    equation: str
    effects: tuple[str, ...]
    frequency_rmse_hz: float
    damping_rmse: float
    harmonic_rmse: float | None
    information_criterion: float
    criterion: str

    def to_dict(self) -> dict[str, Any]:
        return {
            "action": self.action,
            "equation": self.equation,
            "effects": list(self.effects),
            "frequency_rmse_hz": self.frequency_rmse_hz,
            "damping_rmse": self.damping_rmse,
            "harmonic_rmse": self.harmonic_rmse,
            "information_criterion": self.information_criterion,
            "criterion": self.criterion,
        }

    @classmethod
    def from_dict(cls, data: Mapping[str, Any]) -> Step:
        return cls(**{**data, "effects": tuple(data["effects"])})


# --------------------------------------------------------------------------
# Posterior samples


def posterior_samples(
    posterior: Any, names: Sequence[str] | None = None, max_draws: int = 200, seed: int = 0
) -> tuple[list[str], np.ndarray]:
    """Parameter names and ``(n_draws, n_names)`` draws from a posterior.

    ``posterior`` is an arviz/xarray ``DataTree`` from ``pm.sample`` (its
    ``posterior`` group), an ``xarray.Dataset``, a mapping ``{name: draws}`` or a
    ``(names, draws)`` pair. Variables are kept when their name is a model
    parameter name (``names``) or, without ``names``, a catalogue parameter
    (``cubic_stiffness``, ``microslip.k_t``, …). At most ``max_draws`` draws are
    kept (evenly spaced), enough for a 95 % band.
    """
    if isinstance(posterior, tuple) and len(posterior) == 2:
        keys, draws = list(posterior[0]), np.asarray(posterior[1], dtype=float)
        if draws.ndim != 2 or draws.shape[1] != len(keys):
            raise ValueError(f"posterior draws must be (n_draws, {len(keys)}), got {draws.shape}")
        table = dict(zip(keys, draws.T, strict=True))
    else:
        if hasattr(posterior, "children") and "posterior" in posterior.children:
            posterior = posterior["posterior"].to_dataset()
        variables = getattr(posterior, "data_vars", posterior)
        if not isinstance(variables, Mapping):
            raise ValueError(
                f"posterior must be a DataTree, Dataset, mapping or (names, draws), "
                f"got {type(posterior).__name__}"
            )
        table = {str(k): np.asarray(variables[k], dtype=float).reshape(-1) for k in variables}
    wanted = [k for k in table if (k in names if names is not None else _is_catalogue_parameter(k))]
    if not wanted:
        raise ValueError(
            f"the posterior has no variable named like a model parameter "
            f"(it has {sorted(table)}; expected e.g. {list(names or ['cubic_stiffness'])})"
        )
    draws = np.column_stack([table[k] for k in wanted])
    if not np.isfinite(draws).all():
        raise ValueError("posterior draws contain NaN or inf")
    keep = np.unique(np.linspace(0, draws.shape[0] - 1, min(max_draws, draws.shape[0])).astype(int))
    return wanted, draws[keep]


def _is_catalogue_parameter(name: str) -> bool:
    effect, _, shape = name.partition(".")
    return effect in CATALOGUE and (not shape or shape in CATALOGUE[effect].shape)


def _model_from_samples(names: Sequence[str], draws: np.ndarray) -> JointModel:
    """Point model (posterior medians) built from catalogue-named draws."""
    median = dict(zip(names, np.median(draws, axis=0), strict=True))
    terms: dict[str, dict[str, float]] = {}
    for name, value in median.items():
        effect, _, shape = name.partition(".")
        entry = terms.setdefault(effect, {"coefficient": 1.0})
        entry[shape or "coefficient"] = float(value)
    return JointModel(terms, name="posterior median")


# --------------------------------------------------------------------------
# The criticism


class Criticism:
    """A model criticised against measured backbones (build it with :func:`criticize`).

    Attributes
    ----------
    model
        The model criticised (the posterior median when a posterior was given).
    data
        The measured data (:class:`identification.fitting.fit.FitData`).
    fit
        The model as given against the data (no refit).
    history
        Steps of the loop so far, this model last.
    """

    def __init__(
        self,
        model: JointModel,
        data: FitData,
        *,
        method: str = "auto",
        weights: Mapping[str, float] | None = None,
        candidates: Sequence[str] | None = None,
        criterion: str = "bic",
        threshold: float = DEFAULT_THRESHOLD,
        z: float = 2.0,
        posterior: tuple[list[str], np.ndarray] | None = None,
        history: Sequence[Step] = (),
        action: str | None = None,
        prefitted: Mapping[str, FitResult] | None = None,
    ) -> None:
        if criterion not in ("aic", "bic"):
            raise ValueError(f"criterion must be 'aic' or 'bic', got {criterion!r}")
        if not np.isfinite(threshold):
            raise ValueError(f"threshold must be finite, got {threshold}")
        self.model = model
        self.data = data
        self.method = method
        self.weights = dict(weights or {})
        self.criterion = criterion
        self.threshold = float(threshold)
        self.z = float(z)
        self.posterior = posterior
        self.candidate_effects = _candidate_list(model, candidates)
        self._prefitted = dict(prefitted or {})
        self.fit = evaluate(
            model, data, method=method, weights=weights, n_parameters=len(default_free(model))
        )
        step = Step(
            action=action or ("start" if not history else "criticize"),
            equation=model.equation(),
            effects=tuple(model.effects),
            frequency_rmse_hz=self.fit.frequency_rmse_hz,
            damping_rmse=self.fit.damping_rmse,
            harmonic_rmse=self.fit.harmonic_rmse,
            information_criterion=float(self.fit.information_criterion(criterion)),
            criterion=criterion,
        )
        previous = list(history)
        if previous and previous[-1].equation == step.equation:
            previous.pop()  # the same model criticised again: one step
        self.history: list[Step] = [*previous, step]

    # ---------------------------------------------------------------- compare
    @cached_property
    def comparison(self) -> dict[str, dict[str, np.ndarray]]:
        """Per channel at the levels: measured mean, prediction, residual, standard error
        (and ``band_low``/``band_high``/``coverage`` with a posterior)."""
        data = self.data
        mean_residual, standard_error = self.fit.level_residual()
        measured_mean, _ = data.level_mean(data.values)
        method = self.fit.method
        predicted = predict_channels(self.model, data.levels_m, data.channels, method=method)
        out = {}
        band = None
        if self.posterior is not None:
            names, draws = self.posterior
            samples = predict_channels(
                self.model, data.levels_m, data.channels, method=method, parameters=draws,
                names=names,
            )  # fmt: skip
            band = np.nanquantile(samples, [0.025, 0.975], axis=0)
            spread = np.nanstd(samples, axis=0)
            curves = data.at_levels(data.values)
        for j, channel in enumerate(data.channels):
            entry = {
                "measured_mean": measured_mean[:, j],
                "predicted": predicted[:, j],
                "residual": mean_residual[:, j],
                "standard_error": standard_error[:, j],
            }
            if band is not None:
                inside = (curves[:, :, j] >= band[0][:, j]) & (curves[:, :, j] <= band[1][:, j])
                entry |= {
                    "band_low": band[0][:, j],
                    "band_high": band[1][:, j],
                    "predictive_std": spread[:, j],
                    "coverage": np.mean(inside, axis=0),
                }
            out[channel] = entry
        return out

    def residual(self, channel: str) -> tuple[np.ndarray, np.ndarray]:
        """Mean residual (measured − model) of a channel at the levels and its standard
        error (scatter across curves, combined with the posterior spread if given)."""
        entry = self.comparison[channel]
        se = entry["standard_error"]
        if "predictive_std" in entry:
            se = np.hypot(se, entry["predictive_std"])
        return entry["residual"], se

    def where(self) -> list[FailureRange]:
        """Amplitude ranges where the mean residual exceeds ``z`` standard errors.

        A range is a run of at least two consecutive levels (one when there are
        only three levels) with a significant residual of one sign; the
        harmonics count per order, their cosine and sine parts together.
        """
        levels_mm = 1e3 * self.data.levels_m
        min_run = 1 if levels_mm.size <= 3 else 2
        ranges = []
        for channel in BACKBONE_CHANNELS:
            residual, se = self.residual(channel)
            significant = np.abs(residual) > self.z * se
            sign = np.sign(residual) * significant
            for start, stop in _runs(sign, min_run):
                worst = start + int(np.argmax(np.abs(residual[start:stop])))
                ranges.append(
                    FailureRange(
                        channel, float(levels_mm[start]), float(levels_mm[stop - 1]),
                        float(residual[worst]),
                        "under-predicted" if residual[worst] > 0 else "over-predicted",
                    )
                )  # fmt: skip
        if self.data.has_harmonics:
            for order in HARMONIC_ORDERS:
                parts = [self.residual(f"harmonic{order}_{p}") for p in ("cos", "sin")]
                miss = np.hypot(parts[0][0], parts[1][0])
                significant = np.any([np.abs(r) > self.z * s for r, s in parts], axis=0)
                measured = np.hypot(*(self.comparison[f"harmonic{order}_{p}"]["measured_mean"]
                                      for p in ("cos", "sin")))  # fmt: skip
                predicted = np.hypot(*(self.comparison[f"harmonic{order}_{p}"]["predicted"]
                                       for p in ("cos", "sin")))  # fmt: skip
                for start, stop in _runs(significant.astype(float), min_run):
                    worst = start + int(np.argmax(miss[start:stop]))
                    ranges.append(
                        FailureRange(
                            f"harmonic{order}", float(levels_mm[start]),
                            float(levels_mm[stop - 1]), float(miss[worst]),
                            "under-predicted" if measured[worst] > predicted[worst]
                            else "over-predicted",
                        )
                    )  # fmt: skip
        return ranges

    # ---------------------------------------------------------------- missing
    def _method_for(self, model: JointModel) -> str:
        return resolve_method(self.method, model, self.data)

    def _base_fit(self, method: str) -> FitResult:
        """The criticised model's structure refitted (once per harmonic-balance method)."""
        key = f"base:{method}"
        if key not in self._prefitted:
            self._prefitted[key] = fit_backbones(
                self.model, self.data, method=method, weights=self.weights or None
            )
        return self._prefitted[key]

    def _extended_fit(self, effect: str, **shape: float) -> FitResult:
        key = f"add:{effect}"
        if shape or key not in self._prefitted:
            if effect in self.model:
                raise ValueError(
                    f"effect {effect!r} is already in the model ({', '.join(self.model.effects)})"
                )
            # Coefficient 0 marks the effect as new: fit_backbones scans its start.
            method = self._method_for(self.model.with_effect(effect, 0.0, **shape))
            extended = self._base_fit(method).model.with_effect(effect, 0.0, **shape)
            scan = {f"{effect}.{k}": [v] for k, v in shape.items()}
            scan = {k: v for k, v in scan.items() if k in extended.parameter_names}
            result = fit_backbones(
                extended, self.data, method=method, weights=self.weights or None,
                shape_scan=scan or None,
            )  # fmt: skip
            if shape:
                return result
            self._prefitted[key] = result
        return self._prefitted[key]

    def _candidate(self, effect: str) -> Candidate:
        fit = self._extended_fit(effect)
        base = self._base_fit(fit.method)
        delta = float(fit.information_criterion(self.criterion) - base.information_criterion(
            self.criterion))  # fmt: skip
        levels = self.data.levels_m
        channels = self.data.channels
        ext = predict_channels(fit.model, levels, channels, method=fit.method)
        without = predict_channels(base.model, levels, channels, method=fit.method)
        signature = {c: ext[:, j] - without[:, j] for j, c in enumerate(channels)}
        # The effect's own contribution (the rest of the refitted model kept) for the words.
        alone = predict_channels(fit.model.without(effect), levels, channels, method=fit.method)
        own = ext - alone if np.isfinite(alone).all() else ext - without
        return Candidate(
            effect=effect,
            fit=fit,
            base=base,
            criterion=self.criterion,
            delta_ic=delta,
            proposed=bool(delta < self.threshold),
            signature=signature,
            reading=_reading(effect, fit.model, dict(zip(channels, own.T, strict=True)), self.data),
        )

    @cached_property
    def candidates(self) -> list[Candidate]:
        """Every candidate effect refitted, best first.

        Best is the lowest ΔIC, except that among proposed effects the data do not
        clearly separate from the best (ΔIC within :data:`AMBIGUITY`), the one with
        fewer new parameters comes first: a Stribeck law with a huge ``v_s`` *is*
        Coulomb friction, and noise alone must not make the richer law win.
        """
        ranked = sorted((self._candidate(e) for e in self.candidate_effects),
                        key=lambda c: c.delta_ic)  # fmt: skip
        if not ranked or not ranked[0].proposed:
            return ranked
        close = [c for c in ranked if c.proposed and c.delta_ic < ranked[0].delta_ic + AMBIGUITY]
        close.sort(key=lambda c: (c.n_new_parameters, c.delta_ic))
        return close + ranked[len(close) :]

    def missing(self) -> list[Candidate]:
        """The effects worth adding (ΔIC below the threshold), best first."""
        return [c for c in self.candidates if c.proposed]

    @property
    def significant(self) -> bool:
        """Whether some effect is missing (False: nothing significant missing)."""
        return bool(self.missing())

    @property
    def ambiguous(self) -> list[dict[str, Any]]:
        """Proposed effects the data do not clearly separate from the best one."""
        proposed = self.missing()
        if len(proposed) < 2:
            return []
        best = proposed[0]
        out = []
        for other in proposed[1:]:
            gap = other.delta_ic - best.delta_ic
            if gap < AMBIGUITY:
                hint = (
                    "the record harmonics were used"
                    if self.data.has_harmonics
                    else "give the test records: their 2nd and 3rd harmonics separate "
                    "even from odd terms"
                )
                out.append(
                    {
                        "effects": [best.effect, other.effect],
                        "gap": gap,
                        "text": f"the data cannot clearly separate {best.effect} from "
                        f"{other.effect} (Δ{self.criterion.upper()} {gap:.1f}); {hint}",
                    }
                )
        return out

    # -------------------------------------------------------------------- add
    def add(self, effect: str, **shape: float) -> Criticism:
        """Criticism of the model with ``effect`` added and everything refitted.

        Shape values (``k_t=…``, ``F_s=…``, ``v_s=…``) are start values of the fit.
        The returned criticism's :attr:`history` continues this one's.

        Raises
        ------
        ValueError
            If ``effect`` is not in the catalogue or already in the model.
        """
        get_effect(effect)
        if effect in self.model:
            raise ValueError(
                f"effect {effect!r} is already in the model ({', '.join(self.model.effects)})"
            )
        fit = self._extended_fit(effect, **shape)
        return Criticism(
            fit.model,
            self.data,
            method=self.method,
            weights=self.weights or None,
            candidates=[c for c in self.candidate_effects if c != effect],
            criterion=self.criterion,
            threshold=self.threshold,
            z=self.z,
            history=self.history,
            action=f"+ {effect}",
            prefitted={f"base:{fit.method}": fit},
        )

    # ------------------------------------------------------------------- text
    def summary(self) -> str:
        """A few lines in words: where the model fails and what it lacks."""
        lines = [f"model: {self.model.equation()}"]
        lines.append(
            f"frequency RMSE {self.fit.frequency_rmse_hz:.3g} Hz, damping RMSE "
            f"{100 * self.fit.damping_rmse:.3g} %-points"
            + (
                f", harmonics RMSE {100 * self.fit.harmonic_rmse:.3g} % of the fundamental"
                if self.fit.harmonic_rmse is not None
                else ""
            )
        )
        failures = self.where()
        lines += [f"fails: {f.text}" for f in failures] or ["fails: nowhere beyond the scatter"]
        proposed = self.missing()
        if not proposed:
            lines.append("missing: nothing significant")
        for c in proposed[:3]:
            reduction = ", ".join(
                f"{_LABELS[k][0] if k in _LABELS else k} RMSE "
                f"{_LABELS.get(k, ('', '', 100.0))[2] * before:.2g} → "
                f"{_LABELS.get(k, ('', '', 100.0))[2] * after:.2g}"
                for k, before, after in _rmse_pairs(c.base, c.fit)
            )
            lines.append(
                f"missing: {c.effect} (Δ{self.criterion.upper()} {c.delta_ic:.1f}; "
                f"{reduction}): {c.reading}"
            )
        lines += [a["text"] for a in self.ambiguous]
        return "\n".join(lines)

    def __repr__(self) -> str:
        return f"<Criticism of {self.model.equation()}>"

    # ------------------------------------------------------------------- JSON
    def to_dict(self) -> dict[str, Any]:
        """JSON-ready report (see :meth:`write`)."""
        comparison = {
            channel: {k: v.tolist() for k, v in entry.items()}
            for channel, entry in self.comparison.items()
        }
        return {
            "format": FORMAT,
            "version": 1,
            "model": self.model.to_dict(),
            "equation": self.model.equation(),
            "method": self.fit.method,
            "criterion": self.criterion,
            "threshold": self.threshold,
            "significant": self.significant,
            "frequency_rmse_hz": self.fit.frequency_rmse_hz,
            "damping_rmse": self.fit.damping_rmse,
            "harmonic_rmse": self.fit.harmonic_rmse,
            "fails_at": [f.to_dict() for f in self.where()],
            "ranking": [_ranking_entry(c) for c in self.missing()],
            "candidates": [c.to_dict() for c in self.candidates],
            "ambiguous": self.ambiguous,
            "history": [s.to_dict() for s in self.history],
            "summary": self.summary(),
            "n_curves": len(self.data.labels),
            "n_points": self.data.n_points,
            "channels": list(self.data.channels),
            "amplitude_mm": (1e3 * self.data.levels_m).tolist(),
            "comparison": comparison,
        }

    def to_json(self) -> str:
        """:meth:`to_dict` as JSON text (NaN and inf written as null)."""
        return json.dumps(_jsonable(self.to_dict()), indent=2, ensure_ascii=False)

    def write(self, folder: str | Path) -> dict[str, Path]:
        """Write ``criticism.json`` and the figures (PNG) into ``folder``.

        Figures: ``comparison.png`` (measured vs predicted with residual bands),
        ``signatures.png`` (residual with the top candidates' signatures),
        ``history.png`` (the error along the loop).
        """
        from matplotlib.figure import Figure  # no pyplot: no global backend state

        folder = Path(folder)
        paths = {"json": atomic_write_text(folder / "criticism.json", self.to_json())}
        columns = 3 if self.data.has_harmonics else 2
        figures = {
            "comparison": (Figure(figsize=(5.5 * columns, 7), layout="constrained"), (2, columns),
                           plot_comparison),
            "signatures": (Figure(figsize=(5.5 * columns, 4), layout="constrained"), (1, columns),
                           plot_signatures),
        }  # fmt: skip
        for name, (figure, grid, plot) in figures.items():
            plot(self, figure.subplots(*grid))
            paths[name] = _save(figure, folder / f"{name}.png")
        figure = Figure(figsize=(7, 4), layout="constrained")
        plot_history(self.history, figure.subplots())
        paths["history"] = _save(figure, folder / "history.png")
        return paths


def _save(figure, path: Path) -> Path:
    buffer = io.BytesIO()
    figure.savefig(buffer, format="png", dpi=110)
    return atomic_write_bytes(path, buffer.getvalue())


def _ranking_entry(c: Candidate) -> dict[str, Any]:
    return {
        "effect": c.effect,
        "error_reduction": c.error_reduction,
        "delta_information_criterion": c.delta_ic,
        "reading": c.reading,
        "equation": c.fit.model.equation(),
    }


def _jsonable(value: Any) -> Any:
    """numpy scalars and non-finite floats made JSON-safe (NaN/inf as null)."""
    if isinstance(value, dict):
        return {k: _jsonable(v) for k, v in value.items()}
    if isinstance(value, list | tuple):
        return [_jsonable(v) for v in value]
    if isinstance(value, np.generic):
        value = value.item()
    if isinstance(value, float) and not np.isfinite(value):
        return None
    return value


def _runs(sign: np.ndarray, min_run: int) -> list[tuple[int, int]]:
    """``[start, stop)`` of runs of equal non-zero values at least ``min_run`` long."""
    runs, start = [], None
    for i in range(sign.size + 1):
        value = sign[i] if i < sign.size else 0.0
        if start is not None and value != sign[start]:
            if i - start >= min_run:
                runs.append((start, i))
            start = None
        if start is None and value != 0:
            start = i
    return runs


def _candidate_list(model: JointModel, candidates: Sequence[str] | None) -> list[str]:
    if candidates is None:
        return [e for e in CATALOGUE if e not in model]
    out = []
    for effect in candidates:
        get_effect(effect)
        if effect in model:
            raise ValueError(f"candidate {effect!r} is already in the model")
        out.append(effect)
    return out


# --------------------------------------------------------------------------
# Readings


def _reading(effect: str, model: JointModel, own: Mapping[str, np.ndarray], data: FitData) -> str:
    """The catalogue reading, prefixed by what the fitted effect itself does in this test.

    ``own`` is the effect's contribution per channel at the levels (the refitted
    model with and without it); changes below twice the standard error of the
    measured mean are not mentioned.
    """
    levels_mm = 1e3 * data.levels_m
    _, se = data.level_mean(data.values)
    phrases = []
    f = own["frequency_hz"] - own["frequency_hz"][0]
    i = int(np.argmax(np.abs(f)))
    if abs(f[i]) > 2 * np.median(se[:, 0]):
        verb = "softening" if f[i] < 0 else "hardening"
        phrases.append(f"frequency {verb} by {abs(f[i]):.2g} Hz up to {levels_mm[i]:.2g} mm")
    d = own["damping_ratio"]
    i = int(np.argmax(np.abs(d)))
    if abs(d[i]) > 2 * np.median(se[:, 1]):
        what = "adding" if d[i] > 0 else "removing"
        phrases.append(
            f"damping {_trend(d)}, {what} up to {100 * abs(d[i]):.2g} %-points at "
            f"{levels_mm[i]:.2g} mm"
        )
    if data.has_harmonics:
        for order in HARMONIC_ORDERS:
            q = np.hypot(own[f"harmonic{order}_cos"], own[f"harmonic{order}_sin"])
            i = int(np.argmax(q))
            if q[i] > 2 * data.noise_floor["harmonics"]:
                ordinal = {2: "2nd", 3: "3rd"}[order]
                phrases.append(
                    f"a {ordinal} harmonic of {100 * q[i]:.2g} % of the fundamental at "
                    f"{levels_mm[i]:.2g} mm"
                )
    evidence = (" while ".join(phrases[:2]) + "".join(f", {p}" for p in phrases[2:])) or (
        "a change below the scatter"
    )
    return f"{evidence}: {CATALOGUE[effect].reading}{_specifics(effect, model, data)}"


def _trend(values: np.ndarray) -> str:
    """How a signed contribution moves with amplitude, in words."""
    peak = int(np.argmax(np.abs(values)))
    interior = 0 < peak < values.size - 1
    if interior and abs(values[-1]) < 0.7 * abs(values[peak]):
        shape = "rising then falling" if values[peak] > 0 else "falling then rising"
        return f"{shape} with amplitude"
    return "rising with amplitude" if values[-1] >= values[0] else "falling with amplitude"


def _specifics(effect: str, model: JointModel, data: FitData) -> str:
    """Fitted numbers a structural dynamicist reads directly."""
    c = model.coefficient(effect)
    if effect == "microslip":
        _, k_t, f_s = model.microslip_arrays()
        share = c * k_t / model.linear_stiffness
        share = f"the stuck joint carries {100 * share:.2g} % of the stiffness"
        onset = f_s / k_t
        if onset < data.amplitude_m.min():
            return (
                f" (slipping over the whole test, from {1e3 * onset:.2g} mm: it acts as "
                f"macroslip friction here; {share})"
            )
        return f" (slip from about {1e3 * onset:.2g} mm; {share})"
    if effect in ("coulomb_friction", "stribeck_friction"):
        return f" (slip force {abs(c):.3g} m/s² per unit modal mass)"
    if effect == "cubic_stiffness":
        return " (hardening)" if c > 0 else " (softening)"
    if effect == "quadratic_stiffness":
        return f" (x² coefficient {c:.3g} 1/(m·s²))"
    return ""


# --------------------------------------------------------------------------
# Entry point


def criticize(
    model: JointModel | Any,
    measured: BackboneSet | None = None,
    *,
    records: Sequence[Record] | None = None,
    posterior: Any = None,
    candidates: Sequence[str] | None = None,
    history: Sequence[Step | Mapping[str, Any]] = (),
    criterion: str = "bic",
    threshold: float = DEFAULT_THRESHOLD,
    method: str = "auto",
    weights: Mapping[str, float] | None = None,
    noise_floor: Mapping[str, float] | None = None,
    n_periods: int = 70,
    z: float = 2.0,
) -> Criticism:
    """Compare a model with measured backbones, locate its failures, rank what it lacks.

    Parameters
    ----------
    model
        A :class:`JointModel`, or a posterior (``DataTree`` from ``pm.sample`` with
        variables named like model parameters), whose medians make the model.
    measured
        Measured backbones; extracted from ``records`` when None.
    records
        The test records of the measured curves (names = curve labels): their
        2nd and 3rd harmonics become a fitted channel (see the module notes).
    posterior
        Posterior draws of the model's parameters (:func:`posterior_samples`
        accepts a DataTree, Dataset, mapping or ``(names, draws)``): gives the
        posterior-predictive band, its coverage, and widens the significance test.
    candidates
        Effects to try; default every catalogue effect the model lacks.
    history
        Steps of an earlier criticism (``crit.history``) to continue.
    criterion, threshold
        ``"bic"`` or ``"aic"``, and the ΔIC below which an effect is proposed.
    method
        Harmonic balance: ``"auto"``, ``"single"`` or ``"multi"``.
    weights, noise_floor
        See :func:`identification.fitting.fit.fit_backbones`.
    n_periods
        Periods per hold used for the backbone points and harmonics of ``records``.
    z
        Standard errors a mean residual must exceed to be significant.

    Raises
    ------
    ValueError
        Bad input; data too sparse (fewer than 3 points per curve in the shared range).
    """
    draws = None
    if not isinstance(model, JointModel):
        names, values = posterior_samples(model)
        model, draws = _model_from_samples(names, values), (names, values)
    if posterior is not None:
        names, values = posterior_samples(posterior, names=model.parameter_names)
        model = model.with_parameters(dict(zip(names, np.median(values, axis=0), strict=True)))
        draws = (names, values)
    records = list(records) if records is not None else None
    if measured is None:
        if not records:
            raise ValueError("give the measured backbones or the records to extract them from")
        measured = BackboneSet(extract_backbone(r, n_periods=n_periods) for r in records)
    harmonics = extract_harmonics(records, n_periods=n_periods) if records else None
    data = fit_data(measured, harmonics, noise_floor)
    steps = [s if isinstance(s, Step) else Step.from_dict(s) for s in history]
    return Criticism(
        model, data, method=method, weights=weights, candidates=candidates, criterion=criterion,
        threshold=threshold, z=z, posterior=draws, history=steps,
    )  # fmt: skip


# --------------------------------------------------------------------------
# Figures (each takes matplotlib axes)


def _panels(crit: Criticism, residual: np.ndarray, n_axes: int) -> list[tuple[str, str]]:
    """(label, channel) of the panels: frequency, damping, and with record harmonics
    and a third axis the harmonic (cosine part) with the largest miss in ``residual``."""
    panels = [("frequency_hz", "frequency_hz"), ("damping_ratio", "damping_ratio")]
    if crit.data.has_harmonics and n_axes > 2:
        misses = {h: np.nanmax(np.abs(residual[:, crit.data.column(f"harmonic{h}_cos")]))
                  for h in HARMONIC_ORDERS}  # fmt: skip
        order = max(misses, key=misses.get)
        panels.append((f"harmonic{order}", f"harmonic{order}_cos"))
    return panels


def _title(label: str) -> str:
    name = _LABELS[label][0]
    return f"{name} (cos part)" if label.startswith("harmonic") else name


def plot_comparison(crit: Criticism, axes) -> Any:
    """Measured vs predicted backbones (top) and the mean residual with its bands (bottom).

    ``axes``: 2 rows × 2 columns (frequency, damping), or × 3 with record harmonics
    (the harmonic the model misses most, cosine part). The grey band is ±z
    standard errors of the mean from the scatter across curves (widened by the
    posterior spread); with a posterior the predictive 95 % band is drawn too;
    failure ranges are shaded.
    """
    axes = np.asarray(axes).reshape(2, -1)
    data = crit.data
    levels_mm = 1e3 * data.levels_m
    grid = np.geomspace(data.amplitude_m.min(), data.amplitude_m.max(), 80)
    curve = predict_channels(crit.model, grid, data.channels, method=crit.fit.method)
    mean_residual, _ = crit.fit.level_residual()
    failures = crit.where()
    for column, (label, channel) in enumerate(_panels(crit, mean_residual, axes.shape[1])):
        _, unit, factor = _LABELS[label]
        top, bottom = axes[0, column], axes[1, column]
        j = data.column(channel)
        for i, name in enumerate(data.labels):
            rows = data.curve == i
            top.plot(1e3 * data.amplitude_m[rows], factor * data.values[rows, j], ".", alpha=0.6,
                     label=name if len(data.labels) <= 8 else None)  # fmt: skip
        top.plot(1e3 * grid, factor * curve[:, j], "k-", lw=2, label="model")
        entry = crit.comparison[channel]
        if "band_low" in entry:
            top.fill_between(levels_mm, factor * entry["band_low"], factor * entry["band_high"],
                             color="C0", alpha=0.2, label="posterior 95 %")  # fmt: skip
        top.set(xscale="log", ylabel=f"{_title(label)} ({'%' if factor == 100 else unit})")
        residual, se = crit.residual(channel)
        bottom.fill_between(levels_mm, -crit.z * factor * se, crit.z * factor * se, color="0.85",
                            label=f"±{crit.z:g} SE (scatter)")  # fmt: skip
        bottom.plot(levels_mm, factor * residual, "o-", color="C3", label="mean residual")
        bottom.axhline(0.0, color="k", lw=0.8)
        for failure in failures:
            if failure.channel == label:
                bottom.axvspan(failure.from_mm, failure.to_mm, color="C3", alpha=0.1)
        bottom.set(xscale="log", xlabel="amplitude (mm)",
                   ylabel=f"measured − model ({unit})")  # fmt: skip
        bottom.legend(fontsize="small")
    axes[0, 0].legend(fontsize="small")
    axes[0, 0].set_title(crit.model.equation(3), fontsize="small", loc="left")
    return axes


def plot_signatures(crit: Criticism, axes, top: int = 3) -> Any:
    """The refitted base model's residual beside the signatures of the top candidates.

    ``axes``: frequency and damping axes, and with record harmonics a third for the
    harmonic the refitted model misses most (cosine part, in phase with the
    fundamental's displacement). A candidate's signature is the change of the
    prediction it brings; the right effect's follows the residual.
    """
    axes = np.atleast_1d(np.asarray(axes)).ravel()
    data = crit.data
    levels_mm = 1e3 * data.levels_m
    shown = crit.missing()[:top] or crit.candidates[:top]
    base = shown[0].base if shown else crit.fit
    residual, se = base.level_residual()
    for ax, (label, channel) in zip(axes, _panels(crit, residual, len(axes)), strict=False):
        _, unit, factor = _LABELS[label]
        j = data.column(channel)
        ax.fill_between(levels_mm, -crit.z * factor * se[:, j], crit.z * factor * se[:, j],
                        color="0.85")  # fmt: skip
        ax.plot(levels_mm, factor * residual[:, j], "ko-", lw=2, label="residual (refitted model)")
        for k, candidate in enumerate(shown):
            legend = f"{candidate.effect} (Δ{crit.criterion.upper()} {candidate.delta_ic:.0f})"
            ax.plot(levels_mm, factor * candidate.signature[channel], "--", color=f"C{k}",
                    label=legend)  # fmt: skip
        ax.axhline(0.0, color="k", lw=0.8)
        ax.set(xscale="log", xlabel="amplitude (mm)", ylabel=unit, title=_title(label))
    axes[0].legend(fontsize="small")
    return axes


def plot_history(history: Sequence[Step | Mapping[str, Any]], ax) -> Any:
    """Frequency RMSE (Hz, left) and damping RMSE (%-points, right) along the loop."""
    steps = [s if isinstance(s, Step) else Step.from_dict(s) for s in history]
    x = np.arange(len(steps))
    ax.plot(x, [s.frequency_rmse_hz for s in steps], "o-", color="C0", label="frequency")
    ax.set(ylabel="frequency RMSE (Hz)", yscale="log", xticks=x)
    ax.set_xticklabels([s.action for s in steps], rotation=20, ha="right")
    twin = ax.twinx()
    twin.plot(x, [100 * s.damping_rmse for s in steps], "s--", color="C3", label="damping")
    twin.set(ylabel="damping RMSE (%-points)", yscale="log")
    ax.legend(handles=ax.lines + twin.lines, fontsize="small")
    return ax


# --------------------------------------------------------------------------
# Hidden-effect studies on the virtual rig


#: The channel whose error a hidden effect must take down (by ≥ 80 %) in the studies.
#: Damping effects leave the frequency at the noise level already; quadratic
#: stiffness is absorbed by the refitted cubic term in the backbone and shows
#: in the second harmonic of the records.
KEY_CHANNEL = {
    "hidden-cubic": "frequency_hz",
    "hidden-microslip": "frequency_hz",
    "hidden-two": "frequency_hz",
    "hidden-quadratic": "harmonics",
    "hidden-quadratic-damping": "damping_ratio",
    "hidden-coulomb": "damping_ratio",
}
_STEP_RMSE = {
    "frequency_hz": "frequency_rmse_hz",
    "damping_ratio": "damping_rmse",
    "harmonics": "harmonic_rmse",
}


@dataclass
class StudyResult:
    """One hidden-effect scenario run through the criticism loop.

    Keeps the measured backbones, the records and the fitted start model, so the
    same data can be criticised again another way.
    """

    scenario: str
    seed: int
    hidden: tuple[str, ...]
    measured: BackboneSet
    records: list[Record]
    start: JointModel
    criticisms: list[Criticism] = field(default_factory=list)

    @property
    def history(self) -> list[Step]:
        return self.criticisms[-1].history

    @property
    def added(self) -> list[str]:
        return [s.action[2:] for s in self.history if s.action.startswith("+ ")]

    @property
    def first(self) -> str | None:
        """The effect ranked first by the first criticism (None: nothing proposed)."""
        proposed = self.criticisms[0].missing()
        return proposed[0].effect if proposed else None

    def reduction(self, channel: str) -> float | None:
        """Fractional RMSE reduction of a channel from the start to the last step."""
        before, after = (getattr(s, _STEP_RMSE[channel]) for s in (self.history[0],
                                                                   self.history[-1]))  # fmt: skip
        return None if before is None or after is None else float(1 - after / before)

    @property
    def passed(self) -> bool:
        """Control: nothing proposed. Else: the hidden effect(s) found in as many
        rounds, the first of them ranked first, the key channel's error down ≥ 80 %."""
        if not self.hidden:
            return self.first is None
        key = self.reduction(KEY_CHANNEL[self.scenario])
        return (
            self.first in self.hidden
            and sorted(self.added) == sorted(self.hidden)
            and key is not None
            and key >= 0.8
        )

    def row(self) -> dict[str, Any]:
        """Table row: ranked first, what was added, RMSE per step, ΔIC per round."""
        return {
            "scenario": self.scenario,
            "seed": self.seed,
            "hidden": list(self.hidden),
            "ranked_first": self.first,
            "added": self.added,
            "delta_ic": [c.missing()[0].delta_ic for c in self.criticisms if c.missing()],
            "frequency_rmse_hz": [s.frequency_rmse_hz for s in self.history],
            "damping_rmse": [s.damping_rmse for s in self.history],
            "harmonic_rmse": [s.harmonic_rmse for s in self.history],
            "reduction": {c: self.reduction(c) for c in _STEP_RMSE},
            "key_channel": KEY_CHANNEL.get(self.scenario),
            "proposed_at_start": [c.effect for c in self.criticisms[0].missing()],
            "passed": self.passed,
        }


def hidden_effect_study(
    scenario: str,
    seed: int = 0,
    *,
    assemblies: int = 3,
    levels: int = 8,
    hold_s: float = 2.5,
    rounds: int = 3,
    use_records: bool = True,
) -> StudyResult:
    """Run a rig scenario through the loop: fit the base model, criticise, add, repeat.

    The rig (:meth:`identification.rig.Rig.preset`) draws ``assemblies`` assemblies
    and their noise as :meth:`~identification.rig.Rig.write_campaign` does (seeds
    ``[seed, a]`` and ``[seed, a, 1]``) but keeps the records in memory. The
    user's starting model is the preset's base model with its coefficients
    fitted to the backbones; each round adds the effect ranked first, until
    nothing significant is missing or ``rounds`` effects were added.
    """
    from identification.rig import RIG_PRESETS, Rig

    rig = Rig.preset(scenario, levels=levels, hold_s=hold_s)
    records = []
    for a in range(1, assemblies + 1):
        model, gain = rig.draw(np.random.default_rng([seed, a]))
        name = f"Config{rig.config}_PRT_Assemb{a}"
        records.append(rig.simulate(model, gain, np.random.default_rng([seed, a, 1]), name))
    measured = BackboneSet(extract_backbone(r) for r in records)
    start = fit_backbones(RIG_PRESETS[scenario].base_model, measured).model
    result = StudyResult(
        scenario, seed, RIG_PRESETS[scenario].hidden_effects, measured, records, start
    )
    crit = criticize(start, measured, records=records if use_records else None)
    result.criticisms.append(crit)
    for _ in range(rounds):
        proposed = crit.missing()
        if not proposed:
            break
        crit = crit.add(proposed[0].effect)
        result.criticisms.append(crit)
    return result
