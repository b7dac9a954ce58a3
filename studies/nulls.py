"""The null study: the false-discovery rate and the p-values of the calibrated decision over
many null campaigns, each criticised with its truth's own structure (anything found is a
false discovery).

Two sources of campaigns: ``"balance"`` (fast harmonic-balance assemblies with lab
conditions, :func:`~studies.campaigns.draw_lab_campaign`: the same 5-harmonic balance the
criticism predicts with) and ``"rig"`` (:func:`rig_campaign`: the lab rig's time
integration under a phase-locked loop, records extracted as a user's are — the lab-like
nulls the p-values are calibrated on, ``bench/criticism_nulls.py``).
"""

from __future__ import annotations

import dataclasses
import pickle
import time
from collections.abc import Callable, Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np

from identification.criticism.criticism import criticize
from identification.effects.coulomb_friction import EFFECT as COULOMB_FRICTION
from identification.effects.quadratic_stiffness import EFFECT as QUADRATIC_STIFFNESS
from identification.measurements.backbone import BackboneSet
from identification.measurements.extraction import extract_backbones
from identification.rig import RIG_PRESETS, LabRig, rig_for_preset
from identification.rig.presets import lab_hidden_scenario
from studies.driver import Campaign, CampaignRow, is_discovery, run_campaigns

__all__ = [
    "LAB_DRIFT_TRUTHS",
    "LAB_NULL_TRUTHS",
    "NO_FLOOR",
    "NULL_TRUTHS",
    "NullRow",
    "null_study",
    "rig_campaign",
]

#: Truths of the null campaigns (the criticised model has each truth's structure): the
#: study's name → the rig preset.
NULL_TRUTHS: dict[str, str] = {
    "linear": "lab-pure",
    "hardening": "lab-all-hardening",
    "friction": lab_hidden_scenario(COULOMB_FRICTION.name),
    "arch": lab_hidden_scenario(QUADRATIC_STIFFNESS.name),
    "joint": "trc-like",
}
#: Lab-like null truths of the rig source: the lab presets with one artefact each on a
#: linear-viscous truth and no hidden effect, drift left out (drift has its own verdict).
LAB_NULL_TRUTHS: dict[str, str] = {
    "pure": "lab-pure",
    "distorted": "lab-distorted",
    "ripple": "lab-ripple",
    "lock": "lab-lock",
    "dropouts": "lab-dropouts",
}
#: The drift scenario of the rig source, studied apart.
LAB_DRIFT_TRUTHS: dict[str, str] = {"drift": "lab-drift"}
_SOURCES = ("balance", "rig")
#: Systematic floors all but off (``noise_floor`` of a criticism): the bootstrap's own
#: calibration, without the stated systematic errors the rig does not simulate.
NO_FLOOR = {"frequency_hz": 1e-6, "damping_ratio": 1e-9, "harmonics": 1e-7}


@dataclass(frozen=True, kw_only=True)
class NullRow(CampaignRow):
    """One null campaign criticised with its truth's structure.

    Attributes
    ----------
    verdict, p_value
        The criticism's verdict and p-value.
    catalogue_gain, catalogue_threshold
        The best catalogue candidate's gain and its calibrated threshold.
    reference_gain, reference_threshold, reference_dof
        The reference test's gain, calibrated threshold and degrees of freedom.
    false_discovery
        The verdict proposes something (:func:`~studies.driver.is_discovery`).
    proposed
        The effects proposed, ranked.
    """

    verdict: str
    p_value: float
    catalogue_gain: float
    catalogue_threshold: float
    reference_gain: float
    reference_threshold: float
    reference_dof: int
    false_discovery: bool
    proposed: tuple[str, ...]


def rig_campaign(
    preset: str,
    n_curves: int,
    seed: Sequence[int],
    *,
    levels: int = 8,
    cache: Path | None = None,
) -> BackboneSet:
    """The backbones of a lab-rig campaign of ``n_curves`` assemblies, as a user extracts them.

    Assembly ``a`` (1…n) is drawn with the seed ``[*seed, a]`` and measured with
    ``[*seed, a, 1]``; a lab rig places record ``a`` at ``(a − 1)/(n − 1)`` of the campaign
    for its drift. The preset's own hold time and schedule are kept.

    Parameters
    ----------
    preset
        A rig preset (:data:`~identification.rig.RIG_PRESETS`).
    n_curves
        Assemblies (records) of the campaign.
    seed
        The campaign's seed.
    levels
        Excitation levels per branch of a record.
    cache
        A folder: the backbones are kept there (a pickle named by preset, curves, levels
        and seed) and read back on a later call (the simulation dominates a study's time).
    """
    path = None
    if cache is not None:
        key = "_".join(str(s) for s in seed)
        path = Path(cache) / f"{preset}_{n_curves}x{levels}_{key}.pkl"
        if path.exists():
            with path.open("rb") as stream:
                return pickle.load(stream)
    rig = rig_for_preset(preset, levels=levels)
    records = []
    for a in range(1, n_curves + 1):
        name = f"Config{rig.config}_PRT_Assemb{a}"
        draw, measure = np.random.default_rng([*seed, a]), np.random.default_rng([*seed, a, 1])
        if isinstance(rig, LabRig):
            position = (a - 1) / max(n_curves - 1, 1)
            assembly = rig.draw_assembly(draw)
            records.append(rig.simulate_assembly(assembly, measure, name, position)[0])
        else:
            records.append(rig.simulate(*rig.draw(draw), measure, name))
    measured = extract_backbones(records)
    if path is not None:
        path.parent.mkdir(parents=True, exist_ok=True)
        with path.open("wb") as stream:
            pickle.dump(measured, stream)
    return measured


def null_study(
    campaigns: int,
    *,
    truths: Sequence[str] | None = None,
    curve_counts: Sequence[int] | None = None,
    seed: int = 0,
    progress: Callable[[NullRow], None] | None = None,
    source: str = "balance",
    levels: int = 8,
    cache: Path | None = None,
    **options: Any,
) -> list[NullRow]:
    """``campaigns`` null campaigns, each criticised with its truth's structure.

    Truths and curve counts are taken in turn. With ``source="balance"`` each campaign
    draws its lab conditions (:data:`~studies.campaigns.NULL_CONDITIONS`, each present with
    probability ½, and 5, 6 or 8 levels per branch) from its own seed
    (:func:`~studies.driver.run_campaigns`); with ``source="rig"`` it is a lab-rig campaign
    (:func:`rig_campaign`, seed ``[seed, k]`` for campaign ``k``) whose conditions are its
    preset's.

    Parameters
    ----------
    campaigns
        Number of campaigns.
    truths
        Keys of :data:`NULL_TRUTHS` (balance; default all) or of :data:`NULL_TRUTHS`,
        :data:`LAB_NULL_TRUTHS` and :data:`LAB_DRIFT_TRUTHS` (rig; default
        :data:`LAB_NULL_TRUTHS`).
    curve_counts
        Assemblies per campaign, in turn (default 1, 3, 5, 10 for the balance, 3 for the rig).
    seed
        Seed of the study.
    progress
        Called with each row as it is done.
    source
        ``"balance"`` or ``"rig"``.
    levels, cache
        Rig source: levels per branch, and a folder keeping the simulated campaigns
        (:func:`rig_campaign`).
    **options
        Passed to :func:`identification.criticism.criticism.criticize`.

    Returns
    -------
    list of NullRow
        A row per campaign with the verdict and whether it is a false discovery.
    """
    if source not in _SOURCES:
        raise ValueError(f"source must be one of {_SOURCES}, got {source!r}")

    def judge(campaign: Campaign) -> NullRow:
        crit = criticize(campaign.truth, campaign.measured, **options)
        return NullRow.of(
            campaign,
            verdict=crit.verdict,
            p_value=crit.p_value,
            catalogue_gain=float(crit.observed.catalogue[0]),
            catalogue_threshold=crit.calibration.catalogue_threshold,
            reference_gain=float(crit.observed.reference[0]),
            reference_threshold=crit.calibration.reference_threshold,
            reference_dof=crit.observed.reference_rank,
            false_discovery=is_discovery(crit.verdict),
            proposed=tuple(c.effect for c in crit.missing()),
        )

    if source == "balance":
        return run_campaigns(
            campaigns, tuple(NULL_TRUTHS) if truths is None else truths,
            (1, 3, 5, 10) if curve_counts is None else curve_counts, seed,
            NULL_TRUTHS.__getitem__, judge, progress,
        )  # fmt: skip
    presets = {**NULL_TRUTHS, **LAB_NULL_TRUTHS, **LAB_DRIFT_TRUTHS}
    truths = tuple(LAB_NULL_TRUTHS) if truths is None else truths
    counts = (3,) if curve_counts is None else curve_counts
    rows = []
    for k in range(campaigns):
        name = truths[k % len(truths)]
        n_curves = counts[(k // len(truths)) % len(counts)]
        began = time.perf_counter()
        measured = rig_campaign(presets[name], n_curves, (seed, k), levels=levels, cache=cache)
        # The criticised model is the preset's truth (its base model: nothing is hidden).
        campaign = Campaign(k, name, RIG_PRESETS[presets[name]].model, n_curves, levels,
                            (presets[name],), measured)  # fmt: skip
        row = dataclasses.replace(judge(campaign), seconds=time.perf_counter() - began)
        rows.append(row)
        if progress is not None:
            progress(row)
    return rows
