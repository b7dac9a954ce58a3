"""The criticism's settings (one frozen record) and the constants its rules use.

The rules' constants were measured by simulation; their studies are ``bench/criticism*.py``
and their figures ``bench/results/criticism*.json`` (summarised in ``BENCHMARKS.md``).
"""

from __future__ import annotations

from collections.abc import Mapping
from dataclasses import dataclass, field, replace
from enum import StrEnum
from typing import Any

from identification.criticism import calibration as cal
from identification.effects import LINEAR_STIFFNESS, VISCOUS_DAMPING

__all__ = [
    "ALPHA",
    "EXPLAINED",
    "LINEAR_PAIR",
    "MAX_REFITS",
    "MAX_TERM_REFITS",
    "N_BOOTSTRAP",
    "PARTLY",
    "SEPARATION",
    "TERM_OVERLAP",
    "VERDICTS",
    "WORSE",
    "CriticismConfig",
    "Verdict",
]

ALPHA = cal.ALPHA
N_BOOTSTRAP = cal.N_BOOTSTRAP
#: Share of the free-form reference's gain an adequate candidate must capture to explain the data.
EXPLAINED = 0.8
#: Share below which the catalogue does not explain the data ("partly explained" between).
PARTLY = 0.5
#: Separation statistic (χ²₁, 1 %) below which the data cannot tell two candidates apart;
#: the ``χ²`` a replacement must gain in the swap step (:class:`~.moves.Swap`), so the
#: loop does not swap inside what it reports as one group. Its false-swap rate and power
#: are measured by :func:`studies.swap_study` (``bench/criticism_swap.py``,
#: figures in ``bench/results/criticism_swap_calibration*.json``).
SEPARATION = 6.63
#: A channel is made worse beyond its noise when its χ² ends beyond its calibrated bound and
#: rises by more than this (χ²₁, 1 %) and by more than its value before (it doubles).
#: Its false vetoes are counted by the same study.
WORSE = 6.63
STOP_SHARE = 0.7  # the loop's parsimony rule (criticism/ending.py; docs/criticism.md)
#: Candidates refitted (nonlinear) at most, best linearised gains first.
MAX_REFITS = 8
#: The model's own terms that are never put in a model-term group: the linear pair every
#: model holds (what the catalogue's nonlinear effects are measured against).
LINEAR_PAIR = (LINEAR_STIFFNESS, VISCOUS_DAMPING)
#: Catalogue effects refitted in place of one model term at most (model-term groups),
#: best linearised match first.
MAX_TERM_REFITS = 3
#: Prescreen of a model-term group: a catalogue effect is refitted in place of a model term
#: only when its linearised signature, off the model's other parameters, shares at least this
#: much (squared cosine) with the term's; a rival that shares less cannot stand in for it
#: within :data:`SEPARATION` unless the term itself is barely needed.
TERM_OVERLAP = 0.5


class Verdict(StrEnum):
    """The verdicts of a criticism: one list, shared by the words, ``criticism.json`` (which
    writes the plain strings), the report and the studies (``docs/criticism.md``, "Verdicts").

    Attributes
    ----------
    NOTHING_MISSING
        The calibrated decision does not fire: nothing is missing beyond the scatter.
    DRIFT
        The decision does not fire, and the up- and down-stepped branches differ by time,
        not amplitude: drift, not missing physics.
    EXPLAINED
        The decision fires and an admissible, adequate catalogue effect captures at least
        :data:`EXPLAINED` of the free-form reference's gain.
    PARTLY_EXPLAINED
        The decision fires and the best proposed effect captures at least :data:`PARTLY` of
        it but is not explained: it captures less than :data:`EXPLAINED`, leaves the residual
        beyond the scatter in a channel group, or shows only a slip onset that a nearby mode
        fits as well (:func:`~identification.criticism.adequacy.onset_only`).
    NOT_EXPLAINED
        The decision fires and no catalogue effect is proposed: the free-form describing
        functions show the shape of what is missing.
    SECOND_MODE
        A second mode exchanging energy with the measured one (or seen beside it) locates
        a frequency and gains more than its own calibrated threshold and than the
        catalogue's best column by :data:`SEPARATION`; or, in multi-point records, its
        participation names it — its drive at ``2ω`` beyond a linear mode's, or its
        fundamental shaped by a resonance near the first
        (:mod:`identification.criticism.second_mode`).
    """

    NOTHING_MISSING = "nothing missing"
    DRIFT = "drift"
    EXPLAINED = "explained"
    PARTLY_EXPLAINED = "partly explained"
    NOT_EXPLAINED = "not explained by the catalogue"
    SECOND_MODE = "explained by a second mode"


#: The verdicts, in :class:`Verdict`'s order.
VERDICTS = tuple(Verdict)
#: Information criteria a candidate is reported by.
CRITERIA = ("aic", "bic")
POSTERIOR_KINDS = ("population", "mean")


@dataclass(frozen=True)
class CriticismConfig:
    """How a criticism judges (the same for every round of a loop).

    Attributes
    ----------
    method
        Harmonic balance: ``"auto"``, ``"single"`` or ``"multi"``.
    weights
        Channel weights of the likelihood (see
        :func:`identification.fitting.least_squares.fit_backbones`).
    criterion
        ``"bic"`` or ``"aic"``: the information criterion *reported* per candidate.
    alpha
        Probability that a campaign the model explains gets a finding.
    n_bootstrap, seed
        Bootstrap campaigns of the calibration and their seed.
    posterior_kind
        ``"population"`` or ``"mean"``: what a posterior's draws spread like
        (:func:`~identification.criticism.criticism.criticize`).
    """

    method: str = "auto"
    weights: Mapping[str, float] = field(default_factory=dict)
    criterion: str = "bic"
    alpha: float = ALPHA
    n_bootstrap: int = N_BOOTSTRAP
    seed: int = 0
    posterior_kind: str = "population"

    def __post_init__(self) -> None:
        if self.criterion not in CRITERIA:
            raise ValueError(f"criterion must be 'aic' or 'bic', got {self.criterion!r}")
        if self.posterior_kind not in POSTERIOR_KINDS:
            raise ValueError(
                f"posterior_kind must be 'population' or 'mean', got {self.posterior_kind!r}"
            )
        object.__setattr__(self, "weights", dict(self.weights or {}))
        object.__setattr__(self, "alpha", float(self.alpha))
        object.__setattr__(self, "n_bootstrap", int(self.n_bootstrap))
        object.__setattr__(self, "seed", int(self.seed))

    @classmethod
    def of(cls, config: CriticismConfig | None = None, **settings: Any) -> CriticismConfig:
        """``config`` with the given settings changed (None values left as they are), or a
        new one from the settings."""
        given = {k: v for k, v in settings.items() if v is not None}
        return cls(**given) if config is None else replace(config, **given)
