"""A force-driven phase-resonance campaign through the command line.

``pm-joint rig --force-driven`` drives the rig's ground truth (the TRC-like panel: microslip,
cubic hardening) by a measured force through the PLL simulator, ends each record in a ring-down
and writes HDF5 files of the column layout. The records say nothing of the modal forcing gain
(10 1/kg, kept in the ground-truth sidecar only): the backbones read it from each record's own
decay, the identification keeps it as the model's ``forcing_gain``, and updating and criticism
run on those backbones as on base-driven ones.
"""

import json

import numpy as np
import pandas as pd
import pytest

from identification.analytical import harmonic
from identification.model import JointModel
from pm_joint.cli import main
from pm_joint.inference import load_posterior


@pytest.fixture(scope="module")
def campaign(tmp_path_factory):
    folder = tmp_path_factory.mktemp("force") / "campaign"
    argv = ["rig", "trc-like", "--out", str(folder), "--force-driven", "--assemblies", "3",
            "--levels", "6", "--workers", "1"]  # fmt: skip
    assert main(argv) == 0
    return folder


def test_force_driven_campaign_through_every_stage(campaign, tmp_path):
    truth = json.loads((campaign / "ground_truth.json").read_text())
    assert truth["rig"]["forcing_gain"] == 10.0
    assert main(["backbones", str(campaign)]) == 0
    table = pd.read_csv(campaign / "backbones.csv")
    assert len(table) == 18
    # the nominal truth's multi-harmonic backbone (the assemblies scatter about it by ~0.2 %)
    nominal = JointModel.from_dict(truth["rig"]["nominal_model"])
    small = table[table["amplitude_mm"] < 0.12]
    expected = harmonic.backbone(nominal, 1e-3 * small["amplitude_mm"].to_numpy())
    np.testing.assert_allclose(small["frequency_hz"], expected.frequency_hz, rtol=5e-3)
    # damping in modal units: the gain measured from the decays, 0.25 % where the joint sticks
    np.testing.assert_allclose(small["damping_ratio"], expected.damping_ratio, rtol=0.15)

    model = tmp_path / "model.json"
    effects = "linear_stiffness,viscous_damping,cubic_stiffness"
    assert main(["identify", str(campaign), "--effects", effects, "--out", str(model)]) == 0
    identified = JointModel.from_json(model)
    assert identified.forcing_gain == pytest.approx(10.0, rel=0.03)

    posterior = tmp_path / "posterior.nc"
    argv = ["update", str(campaign), "--forward", "harmonic", "--model", str(model)]
    argv += ["--out", str(posterior), "--sampler", "demetropolisz"]
    # 200 draws of one chain: the posterior is written and said not to have converged (exit 3).
    assert main([*argv, "--draws", "200", "--tune", "200", "--chains", "1"]) == 3
    assert load_posterior(posterior).posterior.sizes["draw"] == 200

    crit = tmp_path / "criticism"
    assert main(["criticize", str(campaign), "--model", str(model), "--out", str(crit)]) == 0
    ranking = json.loads((crit / "criticism.json").read_text())["ranking"]
    assert ranking and ranking[0]["effect"] == "microslip"  # the rig's hidden joint physics
