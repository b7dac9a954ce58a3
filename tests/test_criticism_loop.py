"""The criticism loop that stops: admissibility over the measured range, the stop rules
and the loop's final answer (:mod:`identification.criticism.ending`)."""

import json

import numpy as np
import pytest
from oscillators import measured_curve

from identification.analytical.harmonic import backbone as harmonic_backbone
from identification.criticism.adequacy import admissibility
from identification.criticism.config import STOP_SHARE, Verdict
from identification.criticism.criticism import criticize, run_rounds
from identification.criticism.ending import Stop
from identification.measurements.backbone import BackboneSet
from identification.model import JointModel
from studies import criticism_study

W0 = 2 * np.pi * 101.0
K0 = W0**2
C0 = 2 * 0.003 * W0
AMPS = 1e-3 * np.geomspace(0.05, 2.0, 10)


def linear(**extra) -> JointModel:
    return JointModel({"linear_stiffness": K0, "viscous_damping": C0, **extra})


def test_a_negative_linear_stiffness_is_inadmissible():
    """A structure whose own spring pushes away at rest (made up for by a stiff hardening
    term) is no joint, whatever it predicts at the levels."""
    model = JointModel({"linear_stiffness": -0.1 * K0, "viscous_damping": C0,
                        "cubic_stiffness": 1e12})  # fmt: skip
    levels = AMPS[[3, -1]]
    problems = admissibility(model, levels, np.full(2, 101.0), np.full(2, 0.003))
    assert any("non-positive linear stiffness" in p for p in problems), problems
    assert not any("linear stiffness" in p for p in admissibility(
        linear(), levels, np.full(2, 101.0), np.full(2, 0.003)))  # fmt: skip


def test_a_damping_dip_between_two_levels_is_inadmissible():
    """Summed equivalent damping c(a) = c₀ + 4F/(π a ω) + ¾ c₃ a² ω² with c₀ < 0: positive at
    the two tested levels (dry friction dominates low, cubic damping high), negative in
    between, least at a* where dc/da = 0 (A/a* = 2 B a*² for A = 4F/(πω), B = ¾ c₃ ω², and
    c(a*) = c₀ + 1.5 A/a*). Checking at the levels alone passes it; over the measured range
    it feeds energy in around a*."""
    omega, a_star, c0 = W0, 5e-4, -C0
    friction_term = C0 * a_star / 3  # A: c(a*) = c₀ + C0/2 = −C0/2
    friction = friction_term * np.pi * omega / 4
    c3 = friction_term / (2 * a_star**3) / (0.75 * omega**2)

    def damping(a):
        return c0 + 4 * friction / (np.pi * a * omega) + 0.75 * c3 * a**2 * omega**2

    levels = np.array([a_star / 8, a_star * 6])
    assert (damping(levels) > 0).all() and damping(a_star) < 0  # the case is as described
    model = JointModel({"linear_stiffness": K0, "viscous_damping": c0,
                        "coulomb_friction": friction, "cubic_damping": c3})  # fmt: skip
    zeta = damping(levels) / (2 * omega)
    problems = admissibility(model, levels, np.full(2, 101.0), zeta)
    (dip,) = [p for p in problems if "between the levels" in p]
    low, high = (float(x) for x in dip.split(" at ")[1].split(" mm")[0].split("–"))
    assert low < 1e3 * a_star < high, dip
    # the reported range is where the closed form is negative, to the grid's spacing
    grid = np.geomspace(levels[0], levels[-1], 4000)
    negative = grid[damping(grid) < 0]
    assert low == pytest.approx(1e3 * negative.min(), rel=0.15)
    assert high == pytest.approx(1e3 * negative.max(), rel=0.15)


@pytest.fixture(scope="module")
def duffing_loop():
    """Three assemblies of a Duffing joint (one effect beyond the linear pair), closed-form
    single-harmonic backbones plus noise, through the loop from the linear start."""
    rng = np.random.default_rng(3)
    curves = []
    for i in range(3):
        truth = linear(cubic_stiffness=1.4e10).replace(
            linear_stiffness=K0 * np.exp(0.005 * rng.standard_normal())
        )
        curves.append(
            measured_curve(harmonic_backbone(truth, AMPS), rng, 0.003, 1e-6, f"assembly{i}")
        )
    start = criticize(linear(), BackboneSet(curves))
    return start, run_rounds(start, 3)


def test_one_hidden_effect_is_added_and_the_loop_stops(duffing_loop):
    """The truth holds one effect beyond the linear pair: the loop adds it, finds nothing
    missing after it and stops there — no second term — and says so: the added effect with
    the share of the gain left that it explained (nearly all of it), the stop, the final
    verdict and p-value, an admissible final model, the shape of the rest."""
    start, chain = duffing_loop
    end = chain[-1].loop_end
    assert [a.effect for a in end.added] == ["cubic_stiffness"], end.lines()
    assert end.stop == Stop.NOTHING_MISSING and end.verdict == Verdict.NOTHING_MISSING
    assert end.added[0].share > 0.9 and end.smallest_share >= STOP_SHARE
    assert end.admissible and not end.rest.fires
    assert end.p_value == chain[-1].p_value > chain[-1].alpha
    assert len(chain) == 2 and start.loop_end is None  # the start's criticism left as it was
    # one line per item in the summary, the same record in the JSON
    lines = [x for x in chain[-1].summary().splitlines() if x.startswith("loop end:")]
    assert lines == end.lines() and len(lines) == 6
    written = json.loads(chain[-1].to_json())["loop_end"]
    assert written["stop"] == "nothing missing" and written["admissible"]
    assert [a["effect"] for a in written["added"]] == ["cubic_stiffness"]
    assert len(written["rest"]["k_eq"]) == chain[-1].data.levels_m.size


def test_a_share_threshold_above_the_candidate_stops_before_it(duffing_loop):
    """The same campaign with a share threshold above any share (shares are at most 1): the
    loop adds nothing, stops on the share, and its final verdict is the start's own (the
    calibrated test fires: "explained", never "nothing missing")."""
    start, _ = duffing_loop
    (only,) = run_rounds(start, 3, min_share=1.01)
    end = only.loop_end
    assert end.stop == Stop.BELOW_SHARE and end.added == ()
    assert end.verdict == start.verdict == Verdict.EXPLAINED and start.significant


def _checked_end(result):
    """The loop's end of a lab-rig run, checked against the acceptance of the loop."""
    last = result.criticisms[-1]
    end = last.loop_end
    assert end.admissible, end.lines()
    assert all(a.share is None or a.share >= STOP_SHARE for a in end.added), end.lines()
    quiet = end.verdict in (Verdict.NOTHING_MISSING, Verdict.DRIFT)
    assert quiet == (not last.significant), end.lines()  # the final calibrated test decides
    return end


@pytest.mark.slow
def test_a_lab_rig_campaign_with_one_hidden_effect_gets_it_and_no_second_term():
    """Lab rig (PLL records, mild artefacts), cubic damping hidden from a linear start: the
    loop adds cubic damping and stops with nothing else added."""
    result = criticism_study("lab-hidden-cubic-damping", 0, start="linear", rounds=3)
    end = _checked_end(result)
    assert [a.effect for a in end.added] == ["cubic_damping"], end.lines()


@pytest.mark.slow
@pytest.mark.parametrize("scenario", ["lab-iwan", "lab-clearance"])
def test_an_out_of_catalogue_joint_ends_admissible_and_consistent(scenario):
    """Lab rig, physics no catalogue term is: run to its end, the loop's final model is
    admissible, every effect it holds beyond the start explained at least the stated share
    of the gain left when it came in, and where the final calibrated test fires the
    verdict says something is missing."""
    _checked_end(criticism_study(scenario, 0, start="linear", rounds=3))
