"""Model criticism: where a joint model fails, and which physical effect it lacks.

A misspecification check says *that* a model is wrong; this module says *which
physics* is missing. The loop a user runs::

    crit = criticize(model, measured)   # compare, locate, rank
    crit.where()            # amplitude ranges where the residual beats the scatter
    crit.missing()          # catalogue effects that pay for their complexity, best first
    crit2 = crit.add("microslip")                        # refit with it, look again
    plot_history(crit2.history, ax)                      # the error falling

* **Compare.** The model's harmonic-balance backbone against the measured curves
  at the measured amplitudes; the residual averaged over curves at amplitude
  levels with its standard error from the scatter across curves (and, given
  posterior draws, the posterior-predictive band and its coverage).
* **Where.** Runs of consecutive levels where the mean residual exceeds
  ``z`` standard errors, per channel, in words and as data.
* **Missing.** Every catalogue effect the model lacks is added and the extended
  model refitted (:func:`identification.fitting.least_squares.fit_backbones`); the error
  reduction and the change of an information criterion against the refitted model
  without it (BIC by default) rank them. Only effects with ``ΔIC`` below ``threshold``
  (default −10: "very strong" evidence) are proposed. Each gets the signature it
  leaves (the change of the predicted backbone it brings, beside the residual)
  and a reading made from that signature and the catalogue
  (:mod:`identification.criticism.readings`).
* **Harmonics.** Backbones cannot separate some effects (``x²`` and ``x³`` both
  soften or harden in ``a²``). Backbones extracted from test records keep the
  second and third harmonics of the response their hold fits measured; they
  enter the fit as a third channel: ``x²`` leaves a second harmonic phase-locked
  to the fundamental, ``x³`` a third. (The mean displacement an even term also
  leaves is invisible to velocity sensors.)

Figures are drawn by :mod:`identification.criticism.plots`; posterior draws from
PyMC come in through ``pm_joint``'s adapter (this engine imports no PyMC).
"""

from __future__ import annotations

import json
from collections.abc import Mapping, Sequence
from dataclasses import dataclass
from functools import cached_property
from pathlib import Path
from typing import Any

import numpy as np
from numpy.typing import ArrayLike

from identification.artifacts import atomic_write_text
from identification.criticism.plots import write_figures
from identification.criticism.readings import CHANNEL_LABELS, _reading
from identification.effects import CATALOGUE, get_effect
from identification.fitting.data import BACKBONE_CHANNELS, HARMONIC_ORDERS, FitData, fit_data
from identification.fitting.least_squares import FitResult, default_free, evaluate, fit_backbones
from identification.fitting.prediction import predict_channels, resolve_method
from identification.measurements.backbone import BackboneSet
from identification.measurements.extraction import extract_backbones
from identification.measurements.records import Record
from identification.model import JointModel

__all__ = [
    "AMBIGUITY",
    "DEFAULT_THRESHOLD",
    "Candidate",
    "Criticism",
    "FailureRange",
    "Step",
    "criticize",
]

FORMAT = "pm-joint/criticism"
#: ΔIC below which an effect is proposed (BIC: < −10 is "very strong" evidence).
DEFAULT_THRESHOLD = -10.0
#: Candidates within this ΔIC of the best are reported as not clearly separated.
AMBIGUITY = 6.0


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
        name, unit, factor = CHANNEL_LABELS[self.channel]
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
# The criticism


class Criticism:
    """A model criticised against measured backbones (build it with :func:`criticize`).

    Attributes
    ----------
    model
        The model criticised (the posterior median when a posterior was given).
    data
        The measured data (:class:`identification.fitting.data.FitData`).
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
                    "the measured harmonics were used"
                    if self.data.has_harmonics
                    else "give backbones extracted from the test records: their 2nd and 3rd "
                    "harmonics separate even from odd terms"
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
                f"{CHANNEL_LABELS[k][0] if k in CHANNEL_LABELS else k} RMSE "
                f"{CHANNEL_LABELS.get(k, ('', '', 100.0))[2] * before:.2g} → "
                f"{CHANNEL_LABELS.get(k, ('', '', 100.0))[2] * after:.2g}"
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

        Figures (:func:`identification.criticism.plots.write_figures`):
        ``comparison.png`` (measured vs predicted with residual bands),
        ``signatures.png`` (residual with the top candidates' signatures),
        ``history.png`` (the error along the loop).
        """
        paths = {"json": atomic_write_text(Path(folder) / "criticism.json", self.to_json())}
        return paths | write_figures(self, folder)


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
# Entry point


def criticize(
    model: JointModel,
    measured: BackboneSet | None = None,
    *,
    records: Sequence[Record] | None = None,
    posterior: tuple[Sequence[str], ArrayLike] | None = None,
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
        The model to criticise.
    measured
        Measured backbones. The harmonics they carry (backbones extracted from test
        records keep their 2nd and 3rd harmonics) become a fitted channel (see the
        module notes); backbones without them are compared in frequency and damping.
    records
        Test records to extract the backbones from when ``measured`` is None
        (:func:`identification.measurements.extraction.extract_backbones`).
    posterior
        Posterior draws of the model's parameters, ``(names, (n_draws, n_names))``,
        names among the model's parameter names (a few hundred draws suffice for a
        95 % band; ``pm_joint``'s ``criticize`` takes a DataTree from ``pm.sample``):
        the model is compared at their medians, and they give the
        posterior-predictive band, its coverage, and widen the significance test.
    candidates
        Effects to try; default every catalogue effect the model lacks.
    history
        Steps of an earlier criticism (``crit.history``) to continue.
    criterion, threshold
        ``"bic"`` or ``"aic"``, and the ΔIC below which an effect is proposed.
    method
        Harmonic balance: ``"auto"``, ``"single"`` or ``"multi"``.
    weights, noise_floor
        See :func:`identification.fitting.least_squares.fit_backbones`.
    n_periods
        Periods per hold used for the backbone points of ``records``.
    z
        Standard errors a mean residual must exceed to be significant.

    Raises
    ------
    ValueError
        Bad input (both or neither of ``measured`` and ``records``); data too sparse
        (fewer than 3 points per curve in the shared range).
    """
    if not isinstance(model, JointModel):
        raise ValueError(
            f"model must be a JointModel, got {type(model).__name__} (a posterior from "
            "pm.sample is criticised through pm_joint's criticize)"
        )
    draws = None
    if posterior is not None:
        draws = _checked_draws(model, posterior)
        model = model.with_parameters(dict(zip(draws[0], np.median(draws[1], axis=0), strict=True)))
    if measured is None:
        if not records:
            raise ValueError("give the measured backbones or the records to extract them from")
        measured = extract_backbones(records, n_periods=n_periods)
    elif records is not None:
        raise ValueError(
            "give the measured backbones or the records to extract them from, not both "
            "(the backbones carry the harmonics their hold fits measured)"
        )
    data = fit_data(measured, noise_floor)
    steps = [s if isinstance(s, Step) else Step.from_dict(s) for s in history]
    return Criticism(
        model, data, method=method, weights=weights, candidates=candidates, criterion=criterion,
        threshold=threshold, z=z, posterior=draws, history=steps,
    )  # fmt: skip


def _checked_draws(
    model: JointModel, posterior: tuple[Sequence[str], ArrayLike]
) -> tuple[list[str], np.ndarray]:
    """``(names, draws)`` checked against the model: known names, one column each, finite."""
    try:
        names, draws = list(posterior[0]), np.asarray(posterior[1], dtype=float)
    except (TypeError, ValueError, IndexError):
        raise ValueError("posterior must be a (names, draws) pair of parameter draws") from None
    if draws.ndim != 2 or draws.shape[1] != len(names) or draws.shape[0] == 0:
        raise ValueError(f"posterior draws must be (n_draws, {len(names)}), got {draws.shape}")
    unknown = [n for n in names if n not in model.parameter_names]
    if unknown:
        raise ValueError(
            f"posterior names {unknown} are not parameters of the model ({model.parameter_names})"
        )
    if not np.isfinite(draws).all():
        raise ValueError("posterior draws contain NaN or inf")
    return names, draws
