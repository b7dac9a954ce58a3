"""Has the sampler converged? One verdict per run, from the draws alone.

:func:`convergence_verdict` applies the thresholds of Vehtari et al. (2021):
rank-normalised split r̂ ≤ 1.01 and bulk and tail ESS ≥ 400 for every
component of every free variable, no divergent transitions; it also counts the
proposals whose log density was −inf (a forward model that returned NaN).
Reports open the updating section with :meth:`ConvergenceVerdict.headline`.
"""

from __future__ import annotations

import json
from dataclasses import asdict, dataclass, field
from typing import Any

import arviz as az
import numpy as np
import xarray as xr

from pm_joint.analysis.summaries import default_var_names, group_dataset

__all__ = ["ESS_MIN", "RHAT_MAX", "ConvergenceVerdict", "convergence_verdict"]

#: Largest r̂ accepted (rank-normalised split r̂).
RHAT_MAX = 1.01
#: Smallest bulk and tail effective sample size accepted, per component.
ESS_MIN = 400


@dataclass(frozen=True)
class ConvergenceVerdict:
    """The verdict and the figures behind it.

    ``parameters`` has one row per variable: the worst r̂ and the smallest bulk
    and tail ESS over its components. ``nan_proposals`` (of ``proposals``)
    counts the proposals with log density −inf where the sampler records it
    (pm-joint's Metropolis), None elsewhere; NUTS counts such points as
    divergences.
    """

    converged: bool
    parameters: list[dict[str, Any]]
    chains: int
    draws: int
    divergences: int | None
    nan_proposals: int | None
    proposals: int | None
    reasons: list[str] = field(default_factory=list)

    @property
    def nan_rate(self) -> float | None:
        """Share of proposals whose forward model returned NaN (None: not recorded)."""
        if self.nan_proposals is None or not self.proposals:
            return None
        return self.nan_proposals / self.proposals

    @property
    def label(self) -> str:
        return "converged" if self.converged else "NOT CONVERGED"

    def headline(self) -> str:
        """One line: the verdict, the worst figures and, when not converged, why."""
        rhat = max((p["r_hat"] for p in self.parameters), default=float("nan"))
        bulk = min((p["ess_bulk"] for p in self.parameters), default=float("nan"))
        tail = min((p["ess_tail"] for p in self.parameters), default=float("nan"))
        text = (
            f"{self.label}: {self.chains} chains × {self.draws} draws; max r̂ {rhat:.4f} "
            f"(≤ {RHAT_MAX}), min bulk ESS {bulk:.0f}, min tail ESS {tail:.0f} (≥ {ESS_MIN})"
        )
        if self.divergences is not None:
            text += f", {self.divergences} divergences"
        if self.nan_rate is not None:
            text += (
                f", {self.nan_proposals} of {self.proposals} proposals "
                f"({100 * self.nan_rate:.2f} %) with a NaN forward output"
            )
        if self.reasons:
            text += ". Not converged because: " + "; ".join(self.reasons)
        return text + "."

    def to_dict(self) -> dict[str, Any]:
        return {**asdict(self), "label": self.label, "nan_rate": self.nan_rate,
                "headline": self.headline(), "rhat_max": RHAT_MAX, "ess_min": ESS_MIN}  # fmt: skip


def _free_variables(idata: xr.DataTree) -> list[str]:
    """The free variables ``sample`` stored with the draws, else the scalar ones."""
    posterior = group_dataset(idata, "posterior")
    stored = idata.attrs.get("free_variables")
    if stored:
        names = [n for n in json.loads(stored) if n in posterior.data_vars]
        if names:
            return names
    return default_var_names(idata)


def convergence_verdict(
    idata: xr.DataTree,
    var_names: list[str] | None = None,
    *,
    rhat_max: float = RHAT_MAX,
    ess_min: float = ESS_MIN,
) -> ConvergenceVerdict:
    """Judge the draws: r̂, bulk and tail ESS per variable, divergences, NaN proposals.

    Parameters
    ----------
    idata
        A DataTree with ``posterior`` and (optionally) ``sample_stats``.
    var_names
        Variables to judge; default: the model's free variables as
        :func:`~pm_joint.inference.sampling.sample` stored them, else the
        scalar posterior variables.
    rhat_max, ess_min
        Thresholds (defaults :data:`RHAT_MAX`, :data:`ESS_MIN`).

    Notes
    -----
    One chain has no between-chain r̂: a single chain is never called converged.
    """
    names = list(var_names) if var_names is not None else _free_variables(idata)
    posterior = group_dataset(idata, "posterior")
    chains, draws = int(posterior.sizes["chain"]), int(posterior.sizes["draw"])
    rhat = az.rhat(idata, var_names=names)
    bulk = az.ess(idata, var_names=names, method="bulk")
    tail = az.ess(idata, var_names=names, method="tail")
    rows, reasons = [], []
    for name in names:
        row = {
            "variable": name,
            "size": int(
                np.prod(
                    [
                        posterior[name].sizes[d]
                        for d in posterior[name].dims
                        if d not in ("chain", "draw")
                    ]
                )
            ),
            # NaN (one chain, a constant component) propagates and fails the test below.
            "r_hat": float(np.max(np.asarray(rhat[name]))),
            "ess_bulk": float(np.min(np.asarray(bulk[name]))),
            "ess_tail": float(np.min(np.asarray(tail[name]))),
        }
        row["ok"] = bool(
            row["r_hat"] <= rhat_max and row["ess_bulk"] >= ess_min and row["ess_tail"] >= ess_min
        )
        rows.append(row)
    bad_rhat = [r["variable"] for r in rows if not r["r_hat"] <= rhat_max]
    low_ess = [r["variable"] for r in rows if not min(r["ess_bulk"], r["ess_tail"]) >= ess_min]
    if chains < 2:
        reasons.append("one chain: r̂ needs at least two")
    if bad_rhat:
        reasons.append(f"r̂ > {rhat_max} for {', '.join(bad_rhat)}")
    if low_ess:
        reasons.append(f"bulk or tail ESS < {ess_min:g} for {', '.join(low_ess)}")
    stats = idata["sample_stats"].to_dataset() if "sample_stats" in idata.children else None
    divergences = nan_proposals = proposals = None
    if stats is not None and "diverging" in stats:
        divergences = int(stats["diverging"].values.sum())
        if divergences:
            reasons.append(f"{divergences} divergent transitions")
    if stats is not None and "logp_inf" in stats:
        nan_proposals = int(stats["logp_inf"].values.sum())
        proposals = int(stats["logp_inf"].size)
    return ConvergenceVerdict(
        converged=not reasons, parameters=rows, chains=chains, draws=draws,
        divergences=divergences, nan_proposals=nan_proposals, proposals=proposals,
        reasons=reasons,
    )  # fmt: skip
