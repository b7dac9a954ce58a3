"""Sampler defaults per population and forward model: the one table the updating, the
``pm-joint update`` help and the reports read, so that none of them can drift.

Light on purpose (no PyMC import): ``pm-joint --help`` builds its text from it.
"""

from __future__ import annotations

from dataclasses import dataclass

__all__ = [
    "DEFAULT_FORWARD",
    "FORWARD_MODELS",
    "GRADIENT_SAMPLERS",
    "POPULATION_MODELS",
    "SAMPLERS",
    "SAMPLER_DEFAULTS",
    "SamplerDefault",
    "default_help",
    "forward_help",
    "sampler_defaults",
    "sampler_reason",
]

#: The samplers by name.
SAMPLERS = ("metropolis", "demetropolisz", "nuts", "nutpie")
#: The samplers that need the gradient (a forward model that is a native pytensor graph).
GRADIENT_SAMPLERS = ("nuts", "nutpie")
#: The population models of ``pm-joint update --population``.
POPULATION_MODELS = ("matching", "hierarchical")
#: The forward models of ``pm-joint update --forward``.
FORWARD_MODELS = ("surrogate", "harmonic", "pll")
#: The forward model a population model runs on unless told otherwise.
DEFAULT_FORWARD = {"matching": "surrogate", "hierarchical": "harmonic"}


@dataclass(frozen=True)
class SamplerDefault:
    """What one (population model, forward model) pair samples with unless told otherwise.

    ``draws`` and ``tune`` are per chain; ``reason`` says why that sampler, in the
    words every run prints (CLI, report).
    """

    sampler: str
    draws: int
    tune: int
    reason: str


#: Sampler, draws and tuning steps per chain, and why that sampler, by (population model,
#: forward model). The sampler comparison behind the harmonic row: bench/sampling.py,
#: bench/results/sampling.json.
SAMPLER_DEFAULTS = {
    ("matching", "surrogate"): SamplerDefault(
        "metropolis", draws=30_000, tune=3_000,
        reason="the paper's sampler, its proposal covariance learned while tuning, "
        "proposing in the prior box's coordinates",
    ),
    ("matching", "pll"): SamplerDefault(
        "metropolis", draws=30_000, tune=3_000,
        reason="the PLL simulator has no gradient: the paper's Metropolis, its proposal "
        "covariance learned while tuning, proposing in the prior box's coordinates",
    ),
    ("matching", "harmonic"): SamplerDefault(
        "demetropolisz", draws=30_000, tune=5_000,
        reason="the best min-ESS/s measured on this forward model among the four samplers "
        "(bench/results/sampling.json)",
    ),
    ("hierarchical", "harmonic"): SamplerDefault(
        "nutpie", draws=1_000, tune=1_000,
        reason="a parameter vector per curve (over a hundred dimensions): gradient "
        "samplers only, nutpie's NUTS the fastest",
    ),
    ("matching", "modal_harmonic"): SamplerDefault(
        "demetropolisz", draws=30_000, tune=5_000,
        reason="the sampler of population matching on the one-mode harmonic balance, "
        "whose N-mode twin this forward model is",
    ),
    ("hierarchical", "modal_harmonic"): SamplerDefault(
        "nutpie", draws=1_000, tune=1_000,
        reason="a parameter vector per assembly: gradient samplers only, nutpie's NUTS "
        "the fastest",
    ),
    ("matching", "modal_surrogate"): SamplerDefault(
        "metropolis", draws=30_000, tune=3_000,
        reason="the paper's sampler on its surrogate, as for one mode",
    ),
    ("hierarchical", "modal_surrogate"): SamplerDefault(
        "nutpie", draws=1_000, tune=1_000,
        reason="a parameter vector per assembly: gradient samplers only, nutpie's NUTS "
        "through each mode's network",
    ),
}  # fmt: skip


def sampler_defaults(population: str, forward: str) -> SamplerDefault:
    """The defaults of one pair; a ValueError names the pairs that exist."""
    if population not in POPULATION_MODELS:
        raise ValueError(f"population must be one of {POPULATION_MODELS}, got {population!r}")
    if (population, forward) not in SAMPLER_DEFAULTS:
        runs_on = ", ".join(f for p, f in SAMPLER_DEFAULTS if p == population)
        raise ValueError(f"population model {population!r} does not run on forward model "
                         f"{forward!r}; it runs on: {runs_on}")  # fmt: skip
    return SAMPLER_DEFAULTS[population, forward]


def run_settings(
    population: str, forward: str, sampler: str | None, draws: int | None, tune: int | None
) -> tuple[str, int, int]:
    """The sampler, draws and tuning steps of a run: those given, else the pair's defaults."""
    defaults = sampler_defaults(population, forward)
    return sampler or defaults.sampler, draws or defaults.draws, tune or defaults.tune


def sampler_reason(population: str, forward: str, sampler: str) -> str:
    """Why a run sampled with ``sampler``: the table's reason where it is the default."""
    default = sampler_defaults(population, forward)
    if sampler != default.sampler:
        return "chosen by the caller"
    return f"the default of {population} on {forward}: {default.reason}"


def default_help(field: str) -> str:
    """One field of the table in words, grouped by value in the table's order, e.g.
    ``"30000 (matching on surrogate, matching on pll); 1000 (hierarchical on harmonic)"``."""
    groups: dict[object, list[str]] = {}
    for (population, forward), default in SAMPLER_DEFAULTS.items():
        groups.setdefault(getattr(default, field), []).append(f"{population} on {forward}")
    return "; ".join(f"{value} ({', '.join(pairs)})" for value, pairs in groups.items())


def forward_help() -> str:
    """The default forward model per population model, in words."""
    return ", ".join(f"{forward} for {population}" for population, forward in
                     DEFAULT_FORWARD.items())  # fmt: skip
