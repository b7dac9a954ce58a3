"""Studies that run the library end to end, for bench/, case_studies/ and the slow tests.

Outside the library: this package may import ``identification``, ``surrogates`` and
``pm_joint``; none of them imports it. One module per study family:

* :mod:`studies.hidden_effects` — :func:`criticism_study`: a rig scenario through the
  criticism loop from the start a user has, and whether it finds what the rig hid.
* :mod:`studies.nulls` — :func:`null_study`: the false-discovery rate of the calibrated
  decision over fast null campaigns.
* :mod:`studies.swaps` — :func:`swap_study`: how often the swap step undoes a right
  addition, how often it corrects a wrong one, on lab-rig campaigns.
* :mod:`studies.term_groups` — :func:`term_group_study`: how often a term of the truth's
  structure is grouped with a stand-in the data can tell it from, on lab-rig campaigns.
* :mod:`studies.table5` — :func:`table5_study`: the paper's Table 5, surrogate accuracy
  against training size.
* :mod:`studies.coverage` — :func:`population_coverage`: the calibration of the
  hierarchical model's intervals.

Beside them: :mod:`studies.outcomes` (every study's outcome categories and their rules,
fixed before it runs; ``docs/studies.md``), :mod:`studies.campaigns` (the campaign
simulators: the lab rig for validation, the harmonic balance for unit-level checks),
:mod:`studies.driver` (the one campaign driver of the null, swap and term-group studies),
:mod:`studies.rows` (typed rows written as dicts and tables, and the loop's end state
each records), :mod:`studies.binomial` (intervals of rates) and :mod:`studies.seeds` (the
seed convention: tuning seeds below :data:`HELD_OUT_SEED`, held-out seeds from it up).
"""

from studies.binomial import binomial_bounds, clopper_pearson
from studies.campaigns import (
    NULL_CONDITIONS,
    draw_lab_campaign,
    draw_rig_campaign,
    first_fit,
    independent_out_of_catalogue,
    lab_conditions,
    pll_campaign,
    rig_campaign,
    simulated_campaign,
    synthetic_campaign,
)
from studies.coverage import Coverage, population_coverage
from studies.driver import (
    QUIET_VERDICTS,
    Campaign,
    CampaignRow,
    CampaignSource,
    is_discovery,
    run_campaigns,
)
from studies.hidden_effects import (
    KEY_CHANNEL,
    START_LIBRARY,
    StudyResult,
    criticism_study,
    scenario_kind,
)
from studies.nulls import NULL_TRUTHS, NullRow, null_study
from studies.outcomes import (
    HiddenOutcome,
    NullOutcome,
    OutsideOutcome,
    SwapOutcome,
    TermTrialOutcome,
)
from studies.rows import EndState, Row, rows_table
from studies.seeds import HELD_OUT_SEED, SeedRange, held_out_block, held_out_seeds, is_held_out
from studies.swaps import SWAP_TRUTHS, SwapRow, SwapTrial, swap_study
from studies.table5 import Table5Row, table5_study
from studies.term_groups import TERM_TRUTHS, TermGroupRow, TermTrial, term_group_study

__all__ = [
    "HELD_OUT_SEED",
    "KEY_CHANNEL",
    "NULL_CONDITIONS",
    "NULL_TRUTHS",
    "QUIET_VERDICTS",
    "START_LIBRARY",
    "SWAP_TRUTHS",
    "TERM_TRUTHS",
    "Campaign",
    "CampaignRow",
    "CampaignSource",
    "Coverage",
    "EndState",
    "HiddenOutcome",
    "NullOutcome",
    "NullRow",
    "OutsideOutcome",
    "Row",
    "SeedRange",
    "StudyResult",
    "SwapOutcome",
    "SwapRow",
    "SwapTrial",
    "Table5Row",
    "TermGroupRow",
    "TermTrial",
    "TermTrialOutcome",
    "binomial_bounds",
    "clopper_pearson",
    "criticism_study",
    "draw_lab_campaign",
    "draw_rig_campaign",
    "first_fit",
    "held_out_block",
    "held_out_seeds",
    "independent_out_of_catalogue",
    "is_discovery",
    "is_held_out",
    "lab_conditions",
    "null_study",
    "pll_campaign",
    "population_coverage",
    "rig_campaign",
    "rows_table",
    "run_campaigns",
    "scenario_kind",
    "simulated_campaign",
    "swap_study",
    "synthetic_campaign",
    "table5_study",
    "term_group_study",
]
