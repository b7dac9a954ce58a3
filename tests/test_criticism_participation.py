"""A second mode placed by its participation at the sensors (multi-point records).

The independent simulator's two-mode system (``independent.modal_resonance``: its own
harmonic balance, no library code) gives the second mode's coordinate at every hold of the
first's phase resonance, with hold-fit noise; its frequency is the simulator's own
parameter. Tuning seed 1 (``studies.seeds``).
"""

from __future__ import annotations

import json

import numpy as np
import pandas as pd
import pytest
from scipy.stats import chi2

from identification.criticism.config import Verdict
from identification.criticism.criticism import criticize
from identification.criticism.mode_refit import COUPLING_ROUTE, JOINT_ROUTE
from identification.criticism.participation import (
    ModeParticipation,
    locate_by_participation,
    locked_mode,
)
from identification.criticism.words import second_mode_words
from identification.measurements.backbone import BackboneSet
from identification.multimode.model import ModalModel
from identification.rig.presets import RIG_PRESETS, lab_hidden_scenario
from pm_joint.cli import main
from studies.campaigns import first_fit
from studies.second_mode import campaign, independent_campaign, second_mode_campaign

SEED = 1


@pytest.mark.parametrize(("ratio", "route"), [(1.92, COUPLING_ROUTE), (1.07, JOINT_ROUTE)])
def test_the_participation_places_the_independent_simulators_second_mode(ratio, route):
    """Near 1:2 the second harmonic's resonance, near 1:1 the fundamental's, places the mode
    within 5 % of the simulator's frequency, and the interval holds the stated frequency."""
    _, truth, participation = independent_campaign(ratio, SEED)
    answer = locate_by_participation(participation)
    assert answer.located, answer.why_not_located
    profile = answer.profile
    assert profile.route == route and profile.method == "participation"
    assert abs(profile.frequency_hz - truth) <= 0.05 * truth, (profile.frequency_hz, truth)
    low, high = profile.interval_hz
    assert low <= profile.frequency_hz <= high


def test_the_coupling_names_the_independent_simulators_mode_at_1_2():
    """At 1:2 the second harmonic of the simulator's second coordinate grows ∝ a² through
    its detuning: the coupling's drive takes far more than its threshold off, and the
    one-mode model's criticism names the mode from it — placed within 5 % — where the
    one-point screen names none (block 8 000 000: 0 of 16). Its ratio is to the first
    mode as the holds measure it (the simulator's 1.92), and its words say what named it:
    the exchange's χ² beyond the 99 % quantile of χ² with two degrees per curve, and the
    measured coordinate first in "where it shows"."""
    measured, model, truth, participation = campaign("independent 1:2", SEED)
    answer = locate_by_participation(participation)
    assert answer.exchanges, (answer.exchange, answer.exchange_threshold)
    crit = criticize(model, measured, participation=participation)
    mode = crit.second_mode
    assert mode.named and mode.named_by == "participation", mode.why
    assert abs(mode.frequency_hz - truth) <= 0.05 * truth
    assert abs(mode.ratio / 1.92 - 1) <= 0.05, mode.ratio
    assert mode.where[0].startswith("measured at the sensors: the second mode's harmonic 2")
    quantile = chi2.ppf(0.99, 2 * len(measured))
    assert f"beyond χ² {quantile:.3g} at 1 %" in second_mode_words(crit)


def test_a_mode_near_1_1_is_named_as_seen_beside_the_first():
    """Near 1:1 the independent simulator's one-point backbone shows the second mode too
    little for the screen (block 13 000 000: the catalogue explains it or nothing is
    missing), but its coordinate's fundamental is shaped by its resonance: the criticism
    names it as seen beside the first (mechanism "sensor", no exchange claimed), placed
    within 5 % of the simulator's frequency, and its words say the fundamental does not
    tell an exchange."""
    measured, model, truth, participation = campaign("independent near 1:1", SEED)
    answer = locate_by_participation(participation)
    assert answer.shows and not answer.exchanges
    crit = criticize(model, measured, participation=participation)
    mode = crit.second_mode
    assert crit.verdict == Verdict.SECOND_MODE, crit.summary()
    assert mode.named_by == "participation" and mode.mechanism == "sensor"
    assert abs(mode.frequency_hz - truth) <= 0.05 * truth, (mode.frequency_hz, truth)
    assert mode.resonance_gain == pytest.approx(answer.profile.gain)
    words = second_mode_words(crit)
    assert "shows in the response beside it" in words
    assert "not told at the fundamental" in words


def test_a_mode_near_neither_route_is_not_named():
    """A second mode at 1.5 × the first (the independent simulator, its second coordinate
    measured) is placed by neither route: the one-mode model's criticism names no mode, and
    ``add_mode`` refuses with the finding's reason."""
    measured, _, participation = independent_campaign(1.5, SEED)
    start = first_fit(RIG_PRESETS[lab_hidden_scenario("microslip")].base_model, measured)
    crit = criticize(start, measured, participation=participation)
    assert not crit.second_mode.named, crit.second_mode.text
    with pytest.raises(ValueError, match="no second mode to add"):
        crit.add_mode()


def test_a_mode_the_shaker_drives_at_2w_is_placed_but_not_named():
    """The two-mode rig with its second mode off the joint and uncoupled (15 points; the
    modal filter of the records' modes file): the shaker's distortion drives that mode at
    2ω, so its second harmonic places it within 5 % of the rig's mode at rest, but the
    measured excitation's harmonic explains it — the coupling's drive takes less than its
    threshold off — and the one-mode model's criticism names no second mode."""
    measured, start, truth, participation = campaign("uncoupled 1:2", SEED)
    read = participation()
    answer = locate_by_participation(read)
    assert answer.located and answer.profile.route == COUPLING_ROUTE, answer.why_not_located
    assert abs(answer.profile.frequency_hz - truth) <= 0.05 * truth
    assert answer.exchange < answer.exchange_threshold == pytest.approx(chi2.ppf(0.99, 6))
    crit = criticize(start, measured, participation=read)
    assert crit.verdict != Verdict.SECOND_MODE and not crit.second_mode.named, crit.summary()


def test_a_mode_between_the_routes_is_not_located():
    """A second mode at 1.5 × the first is near neither ω nor 2ω: no resonance of either
    route shapes its participation, and the answer says why instead of a frequency."""
    _, _, participation = independent_campaign(1.5, SEED)
    answer = locate_by_participation(participation)
    assert not answer.located
    assert "participation" in answer.why_not_located


def _modal_table(measured, participation) -> pd.DataFrame:
    """The table ``pm-joint backbones --modes 2`` writes, from the simulator's holds: the
    locked mode's rows and mode 2's rows (its participation only), mode 2's harmonics on
    both."""
    frames = []
    for curve, part in zip(measured, participation.curves, strict=True):
        rows = BackboneSet([curve]).to_table()
        rows.insert(1, "mode", 1)
        rows.insert(2, "hold", np.arange(1, len(rows) + 1))
        for k in range(part.harmonics_m.shape[1]):
            rows[f"mode2_h{k + 1}_amplitude_mm"] = 1e3 * np.abs(part.harmonics_m[:, k])
            rows[f"mode2_h{k + 1}_phase_deg"] = np.degrees(np.angle(part.harmonics_m[:, k]))
        other = rows.copy()
        other["mode"] = 2
        other[["frequency_hz", "damping_ratio"]] = np.nan
        frames += [rows, other]
    return pd.concat(frames, ignore_index=True)


def test_a_modal_table_gives_the_locked_backbones_and_the_next_modes_participation(tmp_path):
    """Read back from the table, the participation is the simulator's (mm → m, phases) and
    places the same frequency; ``pm-joint criticize`` takes the table, criticises the
    locked mode's backbones and, with ``--add-mode``, writes the two-mode model whose
    second mode is the simulator's within 5 %."""
    measured, start, truth, participation = campaign("independent near 1:1", SEED)
    table = _modal_table(measured, participation)
    assert locked_mode(table) == 1
    read = ModeParticipation.from_table(table)
    assert read.mode == 2 and len(read.curves) == len(participation.curves)
    for got, put in zip(read.curves, participation.curves, strict=True):
        np.testing.assert_allclose(got.harmonics_m, put.harmonics_m, rtol=1e-9, atol=1e-15)
        np.testing.assert_allclose(got.amplitude_m, put.amplitude_m, rtol=1e-9)
    placed = locate_by_participation(read).profile.frequency_hz
    assert placed == pytest.approx(locate_by_participation(participation).profile.frequency_hz)

    csv = tmp_path / "backbones.csv"
    table.to_csv(csv, index=False)
    model = tmp_path / "model.json"
    start.to_json(model)
    out = tmp_path / "criticism"
    argv = ["criticize", str(csv), "--model", str(model), "--out", str(out), "--add-mode"]
    assert main(argv) == 0
    report = json.loads((out / "criticism.json").read_text())
    assert report["n_curves"] == len(measured)
    two = ModalModel.from_json(out / "two_mode_model.json")
    assert two.n_modes == 2
    assert abs(two.modes[1].frequency_hz - truth) <= 0.05 * truth


@pytest.mark.parametrize("case", ["independent near 1:1", "independent 1:2"])
def test_adding_the_named_mode_recovers_the_simulators_mode_and_the_error_falls(case):
    """``crit.add_mode()`` on the independent simulator (tuning seed 1): the two-mode model's
    second mode lies within 5 % of the simulator's frequency, its joint shape entry within a
    factor 2 of the simulator's 0.3, mode 1 is the refitted base, and the χ² falls by at
    least 80 % of what a free-form stiffness and damping at every level take off (the share
    that makes a catalogue effect "explained")."""
    measured, start, truth, participation = campaign(case, SEED)
    crit = criticize(start, measured, participation=participation)
    added = crit.add_mode()
    two = added.model
    assert abs(two.modes[1].frequency_hz - truth) <= 0.05 * truth, (two.modes[1], truth)
    assert 0.15 <= abs(two.joint_shapes[0][1]) <= 0.6, two.joint_shapes
    base = ModalModel.from_joint_model(crit.decision.base.model)
    assert two.modes[0] == base.modes[0] and two.elements == base.elements
    assert added.chi2_after < added.chi2_before
    assert added.gain >= 0.8 * added.reference_gain, added.text


@pytest.mark.slow
def test_a_named_mode_is_placed_by_its_participation_on_the_two_mode_rig():
    """The two-mode rig near 1:1 (15 points; the modal filter of the records' modes file):
    the one-mode model's criticism names the second mode and its participation places it
    within 5 % of the rig's second mode at rest."""
    row = second_mode_campaign("two-mode near 1:1", SEED)
    assert row.named and row.multi_point, row.why
    assert row.located and row.located_by == "participation", row.location
    assert abs(row.named_hz - row.truth_hz) <= 0.05 * row.truth_hz, (row.named_hz, row.truth_hz)
