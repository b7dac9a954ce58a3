"""The criticism as JSON: one round's report and the whole ``criticism.json``."""

from __future__ import annotations

import json
from typing import TYPE_CHECKING, Any

import numpy as np

from identification.criticism.records import ranking_entry

if TYPE_CHECKING:
    from identification.criticism.criticism import Criticism

__all__ = ["FORMAT", "jsonable", "round_report", "to_dict", "to_json"]

FORMAT = "pm-joint/criticism"


def round_report(crit: Criticism) -> dict[str, Any]:
    """This round: the model, the decision, the ranking and the groups."""
    return {
        "action": crit.history[-1].action,
        "equation": crit.base.model.equation(),
        "verdict": str(crit.verdict),
        "verdict_text": crit.verdict_text,
        "significant": crit.significant,
        "small": crit.small,
        "threshold": crit.threshold,
        "p_value": crit.p_value,
        "explained_share": crit.explained_share,
        "second_mode": _second_mode(crit),
        "ranking": [ranking_entry(c) for c in crit.missing()],
        "groups": [g.to_dict() for g in crit.groups],
        "term_groups": [g.to_dict() for g in crit.term_groups],
        "swaps": [s.to_dict() for s in crit.swaps],
        "summary": crit.summary(),
    }


def to_dict(crit: Criticism) -> dict[str, Any]:
    """JSON-ready report (``criticism.json``)."""
    comparison = {
        channel: {k: v.tolist() for k, v in entry.items()}
        for channel, entry in crit.comparison.items()
    }
    covariance = crit.metric.covariance
    observed = crit.observed
    return {
        "format": FORMAT,
        "version": 2,
        "model": crit.base.model.to_dict(),
        "equation": crit.base.model.equation(),
        "method": crit.base.method,
        "criterion": crit.criterion,
        "verdict": str(crit.verdict),
        "verdict_text": crit.verdict_text,
        "significant": crit.significant,
        "small": crit.small,
        "unexplained": crit.unexplained,
        "explained_share": crit.explained_share,
        "second_mode": _second_mode(crit),
        "threshold": crit.threshold,
        "thresholds": crit.calibration.to_dict(),
        "alpha": crit.alpha,
        "n_bootstrap": crit.n_bootstrap,
        "p_value": crit.p_value,
        "statistics": {
            "catalogue_gain": float(observed.catalogue[0]),
            "reference_gain": float(observed.reference[0]),
            "reference_dof": observed.reference_rank,
            "chi2": float(observed.chi2[0]),
            "fires": crit.fires,
        },
        "adequate": crit.adequate,
        "beyond_scatter": list(crit.beyond_scatter),
        "covariance": {
            "kind": covariance.kind,
            "n_curves": covariance.n_curves,
            "correlation_shrinkage": covariance.correlation_shrinkage,
            "variance_shrinkage": covariance.variance_shrinkage,
            "noise_floor": dict(crit.data.noise_floor),
            "posterior_widened": crit.posterior is not None,
        },
        "caveats": crit.caveats,
        "frequency_rmse_hz": crit.base.frequency_rmse_hz,
        "damping_rmse": crit.base.damping_rmse,
        "harmonic_rmse": crit.base.harmonic_rmse,
        "fails_at": [f.to_dict() for f in crit.where()],
        "no_solution": crit.no_solution_texts(),
        "ranking": [ranking_entry(c) for c in crit.missing()],
        "groups": [g.to_dict() for g in crit.groups],
        "term_groups": [g.to_dict() for g in crit.term_groups],
        "ambiguous": crit.ambiguous,
        "candidates": [c.to_dict() for c in crit.candidates],
        "drift": [d.to_dict() for d in crit.drift],
        "reference": crit.reference.to_dict(),
        "rounds": crit.rounds,
        "loop_end": crit.loop_end.to_dict() if crit.loop_end else None,
        "history": [s.to_dict() for s in crit.history],
        "summary": crit.summary(),
        "n_curves": len(crit.data.labels),
        "n_points": crit.data.n_points,
        "channels": list(crit.data.channels),
        "amplitude_mm": (1e3 * crit.data.levels_m).tolist(),
        "comparison": comparison,
    }


def _second_mode(crit: Criticism) -> dict[str, Any] | None:
    """The second-mode finding (``frequency_hz``, ``ratio``, ``share``, ``where``, whether
    it was ``named`` and why not); None where the decision does not fire."""
    return crit.second_mode.to_dict() if crit.significant else None


def to_json(crit: Criticism) -> str:
    """:func:`to_dict` as JSON text (NaN and inf written as null)."""
    return json.dumps(jsonable(to_dict(crit)), indent=2, ensure_ascii=False)


def jsonable(value: Any) -> Any:
    """numpy scalars and non-finite floats made JSON-safe (NaN/inf as null)."""
    if isinstance(value, dict):
        return {k: jsonable(v) for k, v in value.items()}
    if isinstance(value, list | tuple):
        return [jsonable(v) for v in value]
    if isinstance(value, np.ndarray):
        return jsonable(value.tolist())
    if isinstance(value, np.generic):
        value = value.item()
    if isinstance(value, float) and not np.isfinite(value):
        return None
    return value
