"""The studies' own machinery: the campaign driver and its sources, typed rows as they are
written and read back (with the loop's end state), the outcome categories, the seed
convention, and the effect lists taken from the catalogue."""

import dataclasses
import json
import math

import numpy as np
import pytest

from identification.criticism.config import SEPARATION
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
    CampaignSource,
    EndState,
    SeedRange,
    SwapOutcome,
    SwapRow,
    SwapTrial,
    TermTrial,
    TermTrialOutcome,
    held_out_seeds,
    is_held_out,
    lab_conditions,
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
    assert all(r.seed == 5 and r.source == "harmonic balance" for r in rows)


def test_the_driver_draws_a_rig_campaign_from_the_presets_records():
    """The lab-rig source: the preset's records simulated and their backbones extracted (one
    point per hold, up and down), with the preset's own lab conditions; the row says so."""
    preset = NULL_TRUTHS["hardening"]

    def judge(campaign):
        (curve,) = campaign.measured
        # up-down schedule: every level held going up, all but the top going down
        assert curve.amplitude_m.size == 2 * campaign.n_levels - 1
        assert curve.time_s is not None and np.all(np.diff(curve.time_s) > 0)
        return CampaignRow.of(campaign)

    (row,) = run_campaigns(1, ("hardening",), (1,), HELD_OUT_SEED, NULL_TRUTHS.__getitem__,
                           judge, source=CampaignSource.LAB_RIG)  # fmt: skip
    assert row.source == "lab rig" and row.seed == HELD_OUT_SEED
    assert row.conditions == lab_conditions(preset) and "schedule" in row.conditions


def test_a_swap_row_is_written_with_its_keys_and_read_back():
    trials = (SwapTrial("stribeck_friction", 1.5, False, ""), SwapTrial(None, -9.0, True, ""))
    row = SwapRow(
        campaign=3, truth="coulomb_friction", n_curves=5, n_levels=6, conditions=("ripple",),
        seconds=1.25, wrong_first=False, proposed_first="coulomb_friction",
        groups=(("coulomb_friction", "stribeck_friction"),), add_worse=(), added="coulomb_friction",
        added_was_proposed=True, alternatives=("stribeck_friction",), trials=trials,
        best_replacement_gain=1.5, decision=trials[1].decision, false_swap=True, corrected=None,
        swap_veto=None, seed=HELD_OUT_SEED, source="lab rig",
        end_state=EndState("ẍ + 4e5·x = 0", "nothing missing", 0.5,
                           ("linear_stiffness", "viscous_damping")),
    )  # fmt: skip
    written = json.loads(json.dumps(row.to_dict()))
    assert written["levels"] == 6 and "n_levels" not in written
    assert written["trials"][0] == {"add": "stribeck_friction", "delta_chi2": 1.5, "kept": False,
                                    "why": ""}  # fmt: skip
    assert written["decision"] == "removed" and row.outcome is SwapOutcome.REMOVED
    assert written["end_state"]["verdict"] == "nothing missing"
    assert (written["seed"], written["source"]) == (HELD_OUT_SEED, "lab rig")
    assert SwapRow.from_dict(written) == row
    older = {
        k: v
        for k, v in written.items()
        if k not in ("groups", "added_was_proposed", "seed", "source", "end_state")
    }
    read = SwapRow.from_dict(older)
    assert read.groups is None and read.end_state is None
    assert (read.seed, read.source) == (None, "harmonic balance")  # the only source then
    assert "coulomb_friction" in rows_table([row], ("campaign", "truth", "levels")).splitlines()[1]


def test_a_term_trial_is_written_with_its_lambda_and_judged_by_it():
    trial = TermTrial("cubic_stiffness", "exponential", 40.0, -1.0, "", True, design_lambda=2.5)
    assert trial.to_dict()["lambda"] == 2.5 and "design_lambda" not in trial.to_dict()
    assert trial.outcome is TermTrialOutcome.RIGHT_GROUP
    far = dataclasses.replace(trial, design_lambda=SEPARATION)
    assert far.outcome is TermTrialOutcome.FALSE_FLAG
    assert dataclasses.replace(far, standing=False).outcome is TermTrialOutcome.SEPARATED
    assert dataclasses.replace(trial, standing=False).outcome is TermTrialOutcome.NOT_GROUPED_CLOSE
    assert dataclasses.replace(trial, effect=None, design_lambda=None).outcome is None


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
