"""Posterior draws in the criticism: from a DataTree to parameter names and draws.

The criticism engine (:mod:`identification.criticism.criticism`) takes a
:class:`~identification.model.JointModel` and, optionally, posterior draws as a
``(names, draws)`` pair; this module turns what ``pm.sample`` returns into that
pair (:func:`posterior_samples`) and criticises a posterior directly
(:func:`criticize`).
"""

from __future__ import annotations

from collections.abc import Mapping, Sequence
from typing import Any

import numpy as np

from identification.criticism.criticism import Criticism
from identification.criticism.criticism import criticize as criticize_model
from identification.effects import CATALOGUE, LINEAR_STIFFNESS
from identification.measurements.backbone import BackboneSet
from identification.model import JointModel
from pm_joint.inference.models import POPULATION_SUFFIX

__all__ = ["criticize", "posterior_samples"]


def posterior_samples(
    posterior: Any, names: Sequence[str] | None = None, max_draws: int = 200
) -> tuple[list[str], np.ndarray]:
    """Parameter names and ``(n_draws, n_names)`` draws from a posterior.

    ``posterior`` is an arviz/xarray ``DataTree`` from ``pm.sample`` (its
    ``posterior`` group), an ``xarray.Dataset``, a mapping ``{name: draws}`` or a
    ``(names, draws)`` pair. Variables are kept when their name is a model
    parameter name (``names``) or, without ``names``, a catalogue parameter
    (``cubic_stiffness``, ``microslip.k_t``, …). At most ``max_draws`` draws are
    kept (evenly spaced), enough for a 95 % band.

    A hierarchical posterior (:func:`~pm_joint.inference.hierarchical_model`)
    gives the draws of its population's median assembly (``{p}_population``,
    ``θ0·exp(μ)``), named ``p``: their spread is the uncertainty of the
    population-mean curve, not the scatter of the assemblies, which is what a
    criticism of the population's model widens its test by.
    """
    if isinstance(posterior, tuple) and len(posterior) == 2:
        keys, draws = list(posterior[0]), np.asarray(posterior[1], dtype=float)
        if draws.ndim != 2 or draws.shape[1] != len(keys):
            raise ValueError(f"posterior draws must be (n_draws, {len(keys)}), got {draws.shape}")
        table = dict(zip(keys, draws.T, strict=True))
    else:
        variables = _variables(posterior)
        if not isinstance(variables, Mapping):
            raise ValueError(
                f"posterior must be a DataTree, Dataset, mapping or (names, draws), "
                f"got {type(posterior).__name__}"
            )
        table = {str(k): np.asarray(variables[k], dtype=float).reshape(-1) for k in variables}
        population = {
            k.removesuffix(POPULATION_SUFFIX): v
            for k, v in table.items()
            if k.endswith(POPULATION_SUFFIX)
        }
        table = population or table
    wanted = [k for k in table if (k in names if names is not None else _is_catalogue_parameter(k))]
    if not wanted:
        raise ValueError(
            f"the posterior has no variable named like a model parameter "
            f"(it has {sorted(table)}; expected e.g. {list(names or [LINEAR_STIFFNESS])})"
        )
    draws = np.column_stack([table[k] for k in wanted])
    if not np.isfinite(draws).all():
        raise ValueError("posterior draws contain NaN or inf")
    keep = np.unique(np.linspace(0, draws.shape[0] - 1, min(max_draws, draws.shape[0])).astype(int))
    return wanted, draws[keep]


def _variables(posterior: Any) -> Any:
    """The variables of a posterior: a DataTree's ``posterior`` group, a Dataset's data
    variables, or the object itself (a mapping)."""
    if hasattr(posterior, "children") and "posterior" in posterior.children:
        posterior = posterior["posterior"].to_dataset()
    return getattr(posterior, "data_vars", posterior)


def _posterior_kind(posterior: Any) -> str:
    """``"mean"`` for a hierarchical posterior (its ``{p}_population`` draws are of the
    population's median assembly), else ``"population"`` (draws spread like the assemblies,
    as population matching gives): the criticism widens its test accordingly."""
    variables = _variables(posterior)
    if isinstance(variables, Mapping) and any(
        str(k).endswith(POPULATION_SUFFIX) for k in variables
    ):
        return "mean"
    return "population"


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


def criticize(
    model_or_posterior: JointModel | Any,
    measured: BackboneSet | None = None,
    *,
    posterior: Any = None,
    **options: Any,
) -> Criticism:
    """Criticise a model, or a posterior, against measured backbones.

    Parameters
    ----------
    model_or_posterior
        A :class:`~identification.model.JointModel`, or a posterior (``DataTree``
        from ``pm.sample``, Dataset, mapping or ``(names, draws)``) with variables
        named like catalogue parameters, whose medians make the model.
    measured
        Measured backbones (see :func:`identification.criticism.criticism.criticize`).
    posterior
        Posterior draws of the model's parameters (any form
        :func:`posterior_samples` reads); with a posterior as the first argument
        its own draws are used.
    **options
        Passed on to :func:`identification.criticism.criticism.criticize`
        (``records``, ``candidates``, ``history``, ``alpha``, …). ``posterior_kind``
        defaults to ``"mean"`` for a hierarchical posterior (the draws of its population's
        median assembly) and ``"population"`` otherwise.

    Returns
    -------
    The :class:`~identification.criticism.criticism.Criticism`: the model at the
    posterior medians, with the posterior-predictive band from the draws.
    """
    draws = None
    model = model_or_posterior
    if not isinstance(model, JointModel):
        names, values = posterior_samples(model)
        model, draws = _model_from_samples(names, values), (names, values)
        options.setdefault("posterior_kind", _posterior_kind(model_or_posterior))
    if posterior is not None:
        draws = posterior_samples(posterior, names=model.parameter_names)
        options.setdefault("posterior_kind", _posterior_kind(posterior))
    return criticize_model(model, measured, posterior=draws, **options)
