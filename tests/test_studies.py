"""The studies' own machinery: the campaign driver, typed rows as they are written and read
back, and the effect lists taken from the catalogue."""

import json
import math

import pytest

from identification.effects import CATALOGUE
from identification.rig import RIG_PRESETS
from identification.rig.presets import lab_hidden_scenario
from studies import (
    HELD_OUT_SEED,
    KEY_CHANNEL,
    NULL_TRUTHS,
    SWAP_TRUTHS,
    TERM_TRUTHS,
    CampaignRow,
    SeedRange,
    SwapRow,
    SwapTrial,
    TermTrial,
    held_out_seeds,
    is_held_out,
    rows_table,
    run_campaigns,
)


def test_the_driver_takes_truths_and_curve_counts_in_turn_and_times_each_row():
    seen = []

    def judge(campaign):
        assert campaign.truth is RIG_PRESETS[NULL_TRUTHS[campaign.truth_name]].model
        assert len(campaign.measured) == campaign.n_curves
        assert campaign.n_levels in (5, 6, 8)
        return CampaignRow.of(campaign)

    rows = run_campaigns(
        3, ("linear", "hardening"), (1, 2), 5, NULL_TRUTHS.__getitem__, judge, seen.append
    )
    assert seen == rows
    assert [r.campaign for r in rows] == [0, 1, 2]
    assert [(r.truth, r.n_curves) for r in rows] == [
        ("linear", 1), ("hardening", 1), ("linear", 2),
    ]  # fmt: skip
    assert all(r.seconds > 0 and not math.isnan(r.seconds) for r in rows)
    again = run_campaigns(3, ("linear", "hardening"), (1, 2), 5, NULL_TRUTHS.__getitem__, judge)
    assert [(r.n_levels, r.conditions) for r in again] == [(r.n_levels, r.conditions) for r in rows]


def test_a_swap_row_is_written_with_its_keys_and_read_back():
    trials = (SwapTrial("stribeck_friction", 1.5, False, ""), SwapTrial(None, -9.0, True, ""))
    row = SwapRow(
        campaign=3, truth="coulomb_friction", n_curves=5, n_levels=6, conditions=("ripple",),
        seconds=1.25, wrong_first=False, proposed_first="coulomb_friction",
        groups=(("coulomb_friction", "stribeck_friction"),), add_worse=(), added="coulomb_friction",
        added_was_proposed=True, alternatives=("stribeck_friction",), trials=trials,
        best_replacement_gain=1.5, decision=trials[1].decision, false_swap=True, corrected=None,
        swap_veto=None,
    )  # fmt: skip
    written = json.loads(json.dumps(row.to_dict()))
    assert written["levels"] == 6 and "n_levels" not in written
    assert written["trials"][0] == {"add": "stribeck_friction", "delta_chi2": 1.5, "kept": False,
                                    "why": ""}  # fmt: skip
    assert written["decision"] == "removed"
    assert SwapRow.from_dict(written) == row
    older = {k: v for k, v in written.items() if k not in ("groups", "added_was_proposed")}
    assert SwapRow.from_dict(older).groups is None
    assert "coulomb_friction" in rows_table([row], ("campaign", "truth", "levels")).splitlines()[1]


def test_a_term_trial_is_written_with_its_lambda():
    trial = TermTrial("cubic_stiffness", "exponential", 40.0, -1.0, "", True, design_lambda=2.5)
    assert trial.to_dict()["lambda"] == 2.5 and "design_lambda" not in trial.to_dict()


def test_the_effect_lists_come_from_the_catalogue():
    hidden = [n for n, e in CATALOGUE.items() if e.hidden_scenario is not None]
    assert {lab_hidden_scenario(n) for n in hidden} <= set(KEY_CHANNEL)
    assert all(KEY_CHANNEL[lab_hidden_scenario(n)] == CATALOGUE[n].hidden_scenario.key_channel
               for n in hidden)  # fmt: skip
    assert set(SWAP_TRUTHS) < set(TERM_TRUTHS) <= set(hidden)
    assert all(preset in RIG_PRESETS for preset in NULL_TRUTHS.values())


def test_held_out_seeds_start_at_the_convention_and_never_straddle_it():
    """COMMON.md's convention: tuning seeds below 1 000 000, held-out ones from it up."""
    assert HELD_OUT_SEED == 1_000_000
    first = held_out_seeds(3)
    assert list(first) == [1_000_000, 1_000_001, 1_000_002] and first.held_out
    assert first.to_dict() == {"first": 1_000_000, "last": 1_000_002, "count": 3,
                               "kind": "held-out"}  # fmt: skip
    assert held_out_seeds(2, block=2, offset=5).first == 2_000_005
    assert SeedRange(0, 5).kind == "tuning" and not is_held_out(999_999)
    with pytest.raises(ValueError, match="straddle"):
        SeedRange(999_999, 2)
