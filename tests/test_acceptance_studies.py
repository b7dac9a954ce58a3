"""The acceptance studies at a small size, in every ``make test`` (issue #25, item 6).

Each test is one study of ``docs/studies.md`` on held-out seeds (``studies.seeds``: the
rules were fixed on tuning seeds, never on these), with its pass rule in its docstring, so
a regression of the criticism fails CI. The data come from the lab rig (records simulated
through the PLL simulator with lab artefacts, backbones extracted) or from the independent
simulator (``tests/independent_sim.py``: scipy's DOP853 on forces written here), never from
the harmonic balance the criticism predicts with. The full sizes are the slow tests of
``tests/test_criticism.py`` and ``python bench/criticism.py --study``.
"""

import math

import numpy as np
import pytest
from independent_sim import free_decay

from identification.criticism.config import STOP_SHARE, Verdict
from identification.criticism.criticism import criticize
from identification.criticism.moves import run_rounds
from identification.effects import LINEAR_STIFFNESS, VISCOUS_DAMPING
from identification.measurements.columns import ColumnRecord
from identification.measurements.extraction import extract_backbone
from identification.rig import (
    LAB_HIDDEN_SCENARIOS,
    LAB_NULL_SCENARIOS,
    LAB_OUT_OF_CATALOGUE_SCENARIOS,
    RIG_PRESETS,
)
from independent.campaigns import OUT_OF_CATALOGUE_JOINTS
from studies import (
    HELD_OUT_SEED,
    QUIET_VERDICTS,
    HiddenOutcome,
    NullOutcome,
    OutsideOutcome,
    criticism_study,
    held_out_block,
    held_out_seeds,
    independent_out_of_catalogue,
)

#: Among the longest files of ``make test``: handed out first (tests/conftest.py).
pytestmark = pytest.mark.heavy

#: The one held-out seed of the CI studies: the first of the first held-out block.
SEED = HELD_OUT_SEED
#: The full size's seeds (slow): five held-out seeds after the CI one.
FULL_SEEDS = held_out_seeds(5, offset=1)
#: The lab null scenarios run in CI: the clean lab, and every artefact at once on a linear
#: and on a hardening truth (the others are the slow study's).
CI_NULLS = ("lab-pure", "lab-all", "lab-all-hardening")


def _study(scenario: str, start: str, seed: int = SEED):
    """The scenario through the loop at the studies' standard size: 3 assemblies, 8 levels."""
    return criticism_study(scenario, seed, start=start, assemblies=3, levels=8)


def _only_the_effect_missing(scenario: str) -> str:
    """The start that lacks only the hidden effect: the bare linear-viscous model, or the
    preset's base model where the preset hides its effect on a cubic-hardening base (from
    the bare linear start two effects would be missing there)."""
    nonlinear = set(RIG_PRESETS[scenario].base_model.effects) - {LINEAR_STIFFNESS, VISCOUS_DAMPING}
    return "base" if nonlinear else "linear"


@pytest.mark.parametrize("scenario", LAB_HIDDEN_SCENARIOS)
def test_every_catalogue_effect_hidden_on_the_lab_rig_is_found(scenario):
    """Pass rule: from the start that lacks only the hidden effect (the bare linear-viscous
    model; the preset's cubic-hardening base for quadratic stiffness and microslip), the
    row is a ``hit`` (:class:`studies.HiddenOutcome`): the hidden effect is ranked first or
    in the first flagged group of a round with only the truth's effects added before, or
    the loop's final model holds it and nothing beyond the truth; and the key channel's
    error is down ≥ 80 % at the loop's end. Each lab preset hides its effect at a size that
    shows clearly over 0.05–2 mm (many times the systematic floors), so a miss here is a
    regression, not bad luck.

    Why not the bare linear start for the hardening-base presets: it lacks two effects
    there, and the loop stops when the first candidate captures less than ``STOP_SHARE``
    (70 %) of the gain left. On held-out seed 1 000 000 the quadratic-stiffness row's first
    candidate is ẋ², a stand-in for x³ and x² at once (64 %; x² 52 %, x³ 26 %): the loop
    stops "partly explained" (p = 0.0005) with nothing added — the same with the bootstrap
    before issue #25's recalibration, so not a regression of it, but the loop's stated
    parsimony. That row's claim is the slow test's end-state rule
    (:func:`test_hidden_effects_full_size`). (From the linear start neither "start
    adequate" nor a model-term group can arise: the start has no nonlinear term; from the
    base, its x³ is the truth's.)"""
    result = _study(scenario, _only_the_effect_missing(scenario))
    assert result.outcome is HiddenOutcome.HIT, result.row()
    assert result.passed, result.row()


@pytest.mark.parametrize("scenario", CI_NULLS)
def test_lab_null_scenarios_propose_nothing(scenario):
    """Pass rule: criticised from the truth's own structure (the preset's base model), the
    row is ``quiet`` (:class:`studies.NullOutcome`): round 1 proposes nothing ("nothing
    missing" or "drift") and the loop adds nothing. Each decision fires on a null campaign
    with probability at most its calibrated level α (1 %), so the chance that one of these
    three fails without a regression is at most 3 %."""
    assert scenario in LAB_NULL_SCENARIOS
    result = _study(scenario, "base")
    assert result.outcome is NullOutcome.QUIET, result.row()
    assert not result.added, result.row()


@pytest.mark.parametrize("scenario", LAB_OUT_OF_CATALOGUE_SCENARIOS)
def test_out_of_catalogue_joints_are_never_explained_by_the_catalogue(scenario):
    """Pass rule: from the truth's catalogue part, no round of the loop — the first or one
    after its additions — says the catalogue explains the joint (outcome not
    ``explained``, :class:`studies.OutsideOutcome`), and nothing proposed is inadmissible.
    The joints (Iwan, clearance, preloaded contact, power-law damping, a second mode) are
    physics no catalogue term is. The end-state rule of the slow study (the loop ends "not
    explained" or "partly explained") is stricter."""
    result = _study(scenario, "base")
    assert result.outcome is not OutsideOutcome.EXPLAINED, result.row()
    assert all(not c.problems for crit in result.criticisms for c in crit.missing())


@pytest.mark.parametrize("joint", sorted(OUT_OF_CATALOGUE_JOINTS))
def test_independent_out_of_catalogue_joints_end_the_loop_as_stated(joint):
    """Out of the catalogue, from the independent simulator (``independent``: its own
    phase-resonance balance and forces, no library kernel): each joint of
    ``OUT_OF_CATALOGUE_JOINTS`` (a 12-slider Iwan joint, a ±0.3 mm clearance, a preloaded
    contact, damping ∝ |v|^1.5), 3 assemblies at 10 levels over 0.05–2 mm, from the
    linear-viscous model fitted to them through the loop (3 rounds). Pass rule (the loop
    bench's, docs/criticism.md "On the independent simulator"): no round says
    "explained"; the final model is admissible; every final term explained at least
    ``STOP_SHARE`` of the gain left when it came in; where the final calibrated test fires,
    the final verdict is not one that proposes nothing; and no second mode is named for
    one-mode physics. Seed: the first of held-out block 5 (the bench's block after the
    second-mode rule's last change; on the CI studies' seed 1 000 000 this test found the
    refit placing a mode for the Iwan joint, which changed the rule, so that seed no longer
    holds this claim out)."""
    measured, start = independent_out_of_catalogue(joint, held_out_block(5))
    chain = run_rounds(criticize(start, measured), 3)
    verdicts = [c.verdict for c in chain]
    assert Verdict.EXPLAINED not in verdicts, [c.summary() for c in chain]
    end = chain[-1].loop_end
    assert end.admissible, end
    assert end.smallest_share is None or end.smallest_share >= STOP_SHARE, end
    final = chain[-1]
    if final.fires["catalogue"] or final.fires["reference"]:
        assert final.verdict not in QUIET_VERDICTS, final.summary()
    assert final.verdict != Verdict.SECOND_MODE, final.summary()


@pytest.mark.slow
@pytest.mark.parametrize("seed", list(FULL_SEEDS))
@pytest.mark.parametrize("start", ["linear", "sindy"])
@pytest.mark.parametrize("scenario", LAB_HIDDEN_SCENARIOS)
def test_hidden_effects_full_size(scenario, start, seed):
    """Full size of the hidden-effect study on held-out seeds: from the linear start the row
    is a ``hit`` where the preset's base is linear-viscous; on a cubic-hardening base two
    effects are missing from it and the loop may stop below its share (see
    :func:`test_every_catalogue_effect_hidden_on_the_lab_rig_is_found`), so there it keeps
    no effect outside the truth and, where its final test fires, does not end proposing
    nothing. From SINDy's polynomial model a hit (``start term swapped`` included), or not
    judged (``start adequate``, ``start term group``: the start's own terms reproduce the
    effect within the scatter, which the rig's truth confirms: the truth and the refitted
    start differ by less than the where-bound at every level). Never a ``miss``."""
    result = _study(scenario, start, seed)
    if start == "linear" and _only_the_effect_missing(scenario) == "linear":
        assert result.outcome is HiddenOutcome.HIT, result.row()
        return
    if start == "linear":
        final = result.criticisms[-1]
        assert all(e in result.truth for e in result.kept), result.row()
        if final.p_value <= final.alpha:
            assert final.verdict not in QUIET_VERDICTS, result.row()
        return
    assert result.outcome is not HiddenOutcome.MISS, result.row()
    if result.passed is None:
        assert result.truth_gap < result.criticisms[0].calibration.where_bound, result.row()


@pytest.mark.slow
@pytest.mark.parametrize("seed", list(FULL_SEEDS))
@pytest.mark.parametrize("scenario", LAB_NULL_SCENARIOS)
def test_lab_nulls_full_size(scenario, seed):
    """Full size of the lab nulls on held-out seeds: every row ``quiet`` from the truth's
    structure (each decision at α = 1 %: 40 rows, so one false alarm is within chance;
    the rate's interval is ``bench/criticism.py --study``'s)."""
    result = _study(scenario, "base", seed)
    assert result.outcome is NullOutcome.QUIET, result.row()


@pytest.mark.slow
@pytest.mark.parametrize("seed", list(FULL_SEEDS)[:2])
@pytest.mark.parametrize("start", ["base", "sindy"])
@pytest.mark.parametrize("scenario", LAB_OUT_OF_CATALOGUE_SCENARIOS)
def test_out_of_catalogue_full_size_ends_unexplained(scenario, start, seed):
    """The issue's end-state rule on held-out seeds: the loop ends "not explained by the
    catalogue" or "partly explained" (``OutsideOutcome.said_unexplained``), no round says
    "explained", and where the final calibrated test fires (p ≤ α) the final verdict is
    never one that proposes nothing."""
    result = _study(scenario, start, seed)
    final = result.criticisms[-1]
    assert result.outcome.said_unexplained, result.row()
    if final.p_value <= final.alpha:
        assert final.verdict not in ("nothing missing", "drift"), result.row()


# --------------------------------------------------------------------------
# Independent ring-downs through backbone extraction, against analytical backbones

FS_HZ = 10_000.0
OMEGA0 = 2 * np.pi * 101.0
ZETA0 = 0.002
C0 = 2 * ZETA0 * OMEGA0


def _analytical(kind: str, size: float, amplitude_m: np.ndarray, frequency_hz: np.ndarray):
    """The first-order (single-harmonic) backbone of ``ẍ + ω0²x + c0ẋ + f(x, ẋ) = 0``:
    frequency from the equivalent stiffness, damping ratio from the energy a cycle
    dissipates, ``ζ = ⟨f_d·ẋ⟩ / (ω³a²)`` (closed forms of the cycle averages; the
    amplitude-dependent frequency from the measured curve where the damping needs it)."""
    omega = 2 * np.pi * frequency_hz
    if kind == "cubic stiffness":  # Duffing: ω² = ω0² + ¾k₃a²
        return np.sqrt(OMEGA0**2 + 0.75 * size * amplitude_m**2) / (2 * np.pi), C0 / (2 * omega)
    if kind == "quadratic damping":  # c₂ẋ|ẋ|: ⟨|ẋ|³⟩ = 4(aω)³/(3π)
        return np.full_like(amplitude_m, OMEGA0 / (2 * np.pi)), C0 / (2 * omega) + (
            4 * size * amplitude_m / (3 * np.pi)
        )
    # cubic damping c₃ẋ³: ⟨ẋ⁴⟩ = 3(aω)⁴/8
    return np.full_like(amplitude_m, OMEGA0 / (2 * np.pi)), C0 / (2 * omega) + (
        3 * size * amplitude_m**2 * omega / 8
    )


#: Ring-downs of the independent simulator: the extra force, its size (about +5 % in
#: frequency, or the damping ratio doubled to tripled, at 1.5 mm) and the start amplitude.
RING_DOWNS = {
    "cubic stiffness": (lambda k3: lambda x, v: k3 * x**3, 1.85e10),
    "quadratic damping": (lambda c2: lambda x, v: c2 * v * abs(v), 6.0),
    "cubic damping": (lambda c3: lambda x, v: c3 * v**3, 12.0),
}


@pytest.mark.parametrize("kind", RING_DOWNS)
def test_independent_ring_downs_are_their_analytical_backbones(kind):
    """Pass rule: a free decay of the independent simulator (DOP853 on the force written
    here, from 1.5 mm, 0.1 µm of sensor noise, 10 kHz), taken through the library's decay
    extraction, gives a backbone that spans 0.3–1.2 mm and lies within 0.1 % in frequency
    and 5 % in damping ratio of the analytical single-harmonic backbone at every point
    inside it. The single-harmonic closed forms are off by the harmonics' share, below
    1e-4 in frequency and 1 % in damping at these sizes; the tolerances hold margin for the
    extraction's windows over a decaying amplitude."""
    make, size = RING_DOWNS[kind]
    extra = make(size)

    def force(x, v):
        return OMEGA0**2 * x + C0 * v + extra(x, v)

    decay = free_decay(force, 1.5e-3, 0.0, fs_hz=FS_HZ, duration_s=1.6, rtol=1e-9)
    rng = np.random.default_rng(SEED)
    noisy = decay["displacement_m"] + 1e-7 * rng.standard_normal(decay["time_s"].size)
    record = ColumnRecord(decay["time_s"], noisy, "displacement", f"ring-down {kind}",
                          test="free-decay")  # fmt: skip
    curve = extract_backbone(record)
    inside = (curve.amplitude_m > 0.3e-3) & (curve.amplitude_m < 1.2e-3)
    assert inside.sum() >= 5, curve.amplitude_m
    a, f, zeta = curve.amplitude_m[inside], curve.frequency_hz[inside], curve.damping_ratio[inside]
    f_ref, zeta_ref = _analytical(kind, size, a, f)
    np.testing.assert_allclose(f, f_ref, rtol=1e-3, err_msg=kind)
    np.testing.assert_allclose(zeta, zeta_ref, rtol=0.05, err_msg=kind)
    # the test can fail: the nonlinearity moves the backbone by far more than the tolerance
    linear_f, linear_zeta = OMEGA0 / (2 * np.pi), C0 / (2 * OMEGA0)
    moved = max(np.max(np.abs(f_ref / linear_f - 1)) / 1e-3,
                np.max(np.abs(zeta_ref / linear_zeta - 1)) / 0.05)  # fmt: skip
    assert moved > 5 and math.isfinite(moved)
