"""Prediction with identified N-mode models: the acceptance of issue 27 on held-out decays.

The two-mode model identified by ``identify --modes 2`` and the one-mode model of today's
identification, both from the same tuning-seed decays of the independent simulator's
two-mode truth (:mod:`studies.modal_identification`), predict decays on held-out seeds;
the two-mode model's NMTE must be at most half the one-mode model's. The rig's case
(``pm-joint rig --preset two-mode --test free-decay``) is the slow test and
``bench/identify_modes.py``.
"""

from __future__ import annotations

import json

import numpy as np
import pytest

from identification.effects import LINEAR_STIFFNESS, VISCOUS_DAMPING
from identification.sindy.identify import identify
from identification.sindy.modal_identify import identify_modes
from pm_joint.cli import main
from studies import modal_identification as case
from studies.seeds import HELD_OUT_SEED

TWO_MODE_EFFECTS = ["quadratic_damping", "cubic_damping"]
ONE_MODE_EFFECTS = [LINEAR_STIFFNESS, VISCOUS_DAMPING, "quadratic_damping", "cubic_stiffness",
                    "quadratic_stiffness"]  # fmt: skip


@pytest.fixture(scope="module")
def models(tmp_path_factory):
    records = case.decay_records(range(2), tmp_path_factory.mktemp("train"), duration_s=0.4)
    two = identify_modes(records, 2, TWO_MODE_EFFECTS, mode_shapes=case.MODE_SHAPES).model
    one = identify(records, ONE_MODE_EFFECTS, edge_periods=2.0).model
    return two, one


def test_two_modes_halve_the_one_mode_error_on_held_out_decays(models, tmp_path):
    held_out = case.decay_records([HELD_OUT_SEED, HELD_OUT_SEED + 1], tmp_path)
    result = case.compare(*models, held_out, mode_shapes=case.MODE_SHAPES)
    assert result.ratio <= case.RATIO_TARGET


def test_predict_command_on_an_identified_modal_model(models, tmp_path, capsys):
    two, _ = models
    (record,) = case.decay_records([HELD_OUT_SEED + 2], tmp_path)
    shapes = tmp_path / "shapes.txt"
    shapes.write_text(case.MODE_SHAPES.to_text())
    model = two.to_json(tmp_path / "two.json")
    out = tmp_path / "prediction.csv"
    code = main(["predict", "--model", str(model), str(record.path), "--test", "free-decay",
                 "--response", ",".join(case.SENSORS), "--quantity", "displacement",
                 "--mode-shapes", str(shapes), "--out", str(out)])  # fmt: skip
    (line,) = capsys.readouterr().out.strip().splitlines()
    assert code in (0, None) and line.startswith("NMTE ") and line.endswith(" %")
    assert out.read_text().splitlines()[0] == "time," + ",".join(case.SENSORS)
    summary = json.loads(out.with_name(out.name + ".json").read_text())
    assert set(summary["per_sensor_nmte"]) == set(case.SENSORS)
    assert float(line.split()[1]) == pytest.approx(100 * summary["nmte"], abs=0.006)
    np.testing.assert_allclose(summary["sensor_shapes"], case.MODE_SHAPES.shapes, atol=1e-9)


@pytest.mark.slow
@pytest.mark.xfail(
    reason="one held-out assembly decides it: each rig assembly draws its own frequencies "
    "(σ 0.25 %), and a model of other assemblies drifts in phase; the preset's nominal truth "
    "itself reaches ratios 0.32 and 0.53 on tuning campaigns 1 and 2; over 9 held-out "
    "assemblies the ratio is 0.488, the nominal truth's 0.436 (bench/results/identify_modes.json)",
    strict=False,
)
def test_two_modes_halve_the_one_mode_error_on_the_rigs_held_out_decays(tmp_path):
    """The two-mode rig (its own truth: microslip and hardening joint, quadratic coupling,
    lab artefacts), identified on one campaign and predicted on a held-out one."""
    train, held = tmp_path / "train", tmp_path / "held"
    rig = ["rig", "--preset", "two-mode", "--test", "free-decay", "--assemblies"]
    assert main([*rig, "2", "--seed", "0", "--out", str(train)]) in (0, None)
    assert main([*rig, "1", "--seed", str(HELD_OUT_SEED), "--out", str(held)]) in (0, None)
    two, one = tmp_path / "two.json", tmp_path / "one.json"
    options = ["--test", "free-decay"]
    assert main(["identify", str(train), "--modes", "2", *options, "--out", str(two)]) in (0, None)
    assert main(["identify", str(train), *options, "--out", str(one)]) in (0, None)
    (record,) = sorted(p for p in held.glob("*_Assemb*") if p.is_file())
    errors = {}
    for name, model in (("two", two), ("one", one)):
        out = tmp_path / f"{name}.csv"
        assert main(["predict", "--model", str(model), str(record), *options,
                     "--out", str(out)]) in (0, None)  # fmt: skip
        errors[name] = json.loads(out.with_name(out.name + ".json").read_text())["nmte"]
    assert errors["two"] <= case.RATIO_TARGET * errors["one"]
