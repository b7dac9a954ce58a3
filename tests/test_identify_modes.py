"""``identify --modes N``: coupled modal equations from the independent simulator's decays.

The truth (:mod:`studies.modal_identification`): two modes at 100 and 201 Hz coupled by the
potential ``κ q₁² q₂`` (forces ``2κ q₁ q₂`` on mode 1, ``κ q₁²`` on mode 2) and through a
joint ``q = q₁ + 0.5 q₂`` with quadratic damping ``c q̇|q̇|``, integrated by DOP853 in
:mod:`independent.decays` (no code shared with the library).

Tolerances: the accelerations come from the displacement by two central differences with their
gain ``1 − (ωh)²/3`` divided out (:mod:`identification.sindy.modal_derivatives`; left in, it
would lower the frequencies by ``(ωh)²/6``: 0.07 % at 100 Hz, 0.27 % at 201 Hz for 10 kHz
sampling); frequencies are asked within 0.05 %, below that bias. The band-pass and the finite record
length leave coefficients within a few percent: 5 % is asked of the coupling, the joint
damping and the damping ratios.
"""

from __future__ import annotations

import json

import numpy as np
import pytest

from identification.effects import LINEAR_STIFFNESS, VISCOUS_DAMPING
from identification.measurements.columns import open_records
from identification.multimode.model import ModalModel
from identification.sindy.modal_identify import identify_modes, modal_library_effects
from independent.decays import ModalSystem, PotentialTerm, modal_free_decay
from pm_joint.cli import main
from studies import modal_identification as case

QUADRATIC_DAMPING, CUBIC_DAMPING, CUBIC_STIFFNESS = (
    "quadratic_damping",
    "cubic_damping",
    "cubic_stiffness",
)
COULOMB_FRICTION, ABS_STIFFNESS, VELOCITY_SQUARED = (
    "coulomb_friction",
    "abs_stiffness",
    "velocity_squared",
)
#: The joint effects offered: the true one among others that could imitate it.
EFFECTS = [QUADRATIC_DAMPING, CUBIC_DAMPING, COULOMB_FRICTION, ABS_STIFFNESS]


@pytest.fixture(scope="module")
def identified(tmp_path_factory):
    records = case.decay_records(range(2), tmp_path_factory.mktemp("decays"), duration_s=0.4)
    return identify_modes(records, 2, EFFECTS, mode_shapes=case.MODE_SHAPES)


def test_recovers_the_truths_frequencies_damping_coupling_and_joint(identified):
    model = identified.model
    frequencies = [m.frequency_hz for m in model.modes]
    np.testing.assert_allclose(frequencies, case.FREQUENCIES_HZ, rtol=5e-4)
    np.testing.assert_allclose([m.damping_ratio for m in model.modes], case.DAMPING_RATIOS,
                               rtol=0.05)  # fmt: skip
    assert set(identified.terms) == {f"joint.{QUADRATIC_DAMPING}", "V:x1²·x2"}
    couplings = {(c.mode, c.powers): c.coefficient for c in model.couplings}
    assert set(couplings) == {(1, (1, 1)), (2, (2, 0))}
    assert couplings[(1, (1, 1))] == pytest.approx(2 * case.COUPLING, rel=0.05)
    assert couplings[(2, (2, 0))] == pytest.approx(case.COUPLING, rel=0.05)
    (element,) = model.elements
    assert element.effect == QUADRATIC_DAMPING
    assert element.coefficient == pytest.approx(case.JOINT_DAMPING, rel=0.05)
    np.testing.assert_allclose(model.joint_shapes, [case.JOINT_SHAPE], atol=1e-9)


def test_couplings_derive_from_a_potential(identified):
    """Every coupling's force is ∂V/∂x_m of one potential: the mixed partials agree."""
    model = identified.model
    coefficient = {(c.mode, c.powers): c.coefficient for c in model.couplings}
    for (mode, powers), value in coefficient.items():
        for other in range(1, model.n_modes + 1):
            if other == mode:
                continue
            # V ∋ κ Π x^p: the mode-m force κ p_m x^(p−e_m) pairs with κ p_o x^(p−e_o).
            full = list(powers)
            full[mode - 1] += 1
            if full[other - 1] == 0:
                continue
            partner = tuple(p - (k == other - 1) for k, p in enumerate(full))
            assert coefficient[(other, partner)] / full[other - 1] == pytest.approx(
                value / full[mode - 1], rel=1e-12
            )


def test_the_library_keeps_what_acts_on_the_joint():
    kept, notes = modal_library_effects(
        [LINEAR_STIFFNESS, VISCOUS_DAMPING, CUBIC_STIFFNESS, VELOCITY_SQUARED, QUADRATIC_DAMPING]
    )
    assert kept == [QUADRATIC_DAMPING]
    assert any(CUBIC_STIFFNESS in n and "couplings" in n for n in notes)
    assert any(VELOCITY_SQUARED in n and "neither" in n for n in notes)


def test_one_mode_is_refused_here():
    with pytest.raises(ValueError, match="n_modes ≥ 2"):
        identify_modes([], 1, EFFECTS)


def test_the_command_writes_a_modal_model(tmp_path, capsys):
    case.decay_records([3], tmp_path)
    shapes = tmp_path / "shapes.txt"
    shapes.write_text(case.MODE_SHAPES.to_text())
    out = tmp_path / "two.json"
    code = main(["identify", str(tmp_path / "decay_3.csv"), "--modes", "2", "--test",
                 "free-decay", "--response", ",".join(case.SENSORS), "--quantity",
                 "displacement", "--mode-shapes", str(shapes), "--effects",
                 ",".join(EFFECTS), "--out", str(out)])  # fmt: skip
    printed = capsys.readouterr().out
    assert code in (0, None)
    model = ModalModel.from_json(out)
    assert model.n_modes == 2 and json.loads(out.read_text())["format"] == "pm-joint/ModalModel"
    assert "η1''" in printed and "η2''" in printed


def test_modes_1_is_todays_identification_byte_for_byte(tmp_path):
    case.decay_records([4], tmp_path)
    record = str(tmp_path / "decay_4.csv")
    common = ["identify", record, "--test", "free-decay", "--response", "s1", "--quantity",
              "displacement", "--effects", f"{LINEAR_STIFFNESS},{VISCOUS_DAMPING}"]  # fmt: skip
    assert main([*common, "--out", str(tmp_path / "a.json")]) in (0, None)
    assert main([*common, "--modes", "1", "--out", str(tmp_path / "b.json")]) in (0, None)
    assert (tmp_path / "a.json").read_bytes() == (tmp_path / "b.json").read_bytes()


def test_linear_damping_alone_keeps_no_joint_damping(tmp_path):
    """The power balance's selection does not invent a joint damping the truth lacks."""
    system = ModalSystem(case.FREQUENCIES_HZ, case.DAMPING_RATIOS, joint_shape=case.JOINT_SHAPE,
                         couplings=(PotentialTerm(case.COUPLING, (2, 1)),))  # fmt: skip
    records = []
    for seed in range(2):
        rng = np.random.default_rng(seed)
        q0 = 1e-3 * rng.uniform([0.6, 0.1], [1.0, 0.4])
        decay = modal_free_decay(system, q0, np.zeros(2), sensor_shapes=case.SHAPES,
                                 fs_hz=case.FS_HZ, duration_s=0.4, time_digits=7)  # fmt: skip
        path = decay.write_csv(tmp_path / f"linear_{seed}.csv", "displacement", case.SENSORS)
        records += open_records(path, case.LAYOUT)
    result = identify_modes(records, 2, EFFECTS, mode_shapes=case.MODE_SHAPES)
    assert not any(term.startswith("joint.") for term in result.terms)
    np.testing.assert_allclose([m.damping_ratio for m in result.model.modes],
                               case.DAMPING_RATIOS, rtol=0.05)  # fmt: skip
