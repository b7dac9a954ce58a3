"""Reproducibility: the same seed gives the same result at every stage.

Rig data (byte for byte), identified model, surrogate weights (CPU) and
posterior draws are each produced twice with one seed and compared exactly;
a different seed must change them (so the seed is really used). Tiny sizes.

Also: ``tests/test_surrogates.py::test_same_seed_gives_the_same_weights``
(weights, and a different seed gives different ones).
"""

import warnings

import numpy as np
import pymc as pm
import pytest
import torch
from oscillators import duffing

from identification.artifacts import sha256_file
from identification.rig import Rig
from identification.sindy import identify
from pm_joint.inference import build_model, sample
from surrogates.nets import NetConfig
from surrogates.runtime import SurrogateSpec
from surrogates.train import TrainingConfig, train_surrogate

LIBRARY = ["linear_stiffness", "viscous_damping", "cubic_stiffness"]


def _rig() -> Rig:
    return Rig.preset("trc-like", levels=3, hold_s=0.6, ramp_s=0.05)


@pytest.fixture(scope="module")
def campaigns(tmp_path_factory):
    """One assembly written twice with seed 5, and once with seed 6."""
    return {
        label: _rig().write_campaign(tmp_path_factory.mktemp(label), assemblies=1, seed=seed)
        for label, seed in (("first", 5), ("again", 5), ("other", 6))
    }


def _hashes(campaign) -> dict[str, str]:
    return {p.name: sha256_file(p) for p in sorted(campaign.folder.iterdir())}


def test_same_seed_gives_byte_identical_rig_files(campaigns):
    first, again, other = (_hashes(campaigns[k]) for k in ("first", "again", "other"))
    assert len(first) == 4  # data, steps and modes files, ground truth
    assert first == again
    assert first["Config1_PRT_Assemb1"] != other["Config1_PRT_Assemb1"]
    assert first["ground_truth.json"] != other["ground_truth.json"]


def _identified(campaign, seed):
    return identify(campaign[0], LIBRARY, ensemble=True, n_models=5, seed=seed)


def test_same_records_and_seed_give_the_same_identified_model(campaigns):
    first = _identified(campaigns["first"], seed=3)
    again = _identified(campaigns["again"], seed=3)
    assert first.model == again.model
    assert first.coefficients == again.coefficients
    np.testing.assert_array_equal(first.ensemble_coefficients, again.ensemble_coefficients)
    np.testing.assert_array_equal(first.inclusion_probability, again.inclusion_probability)
    reseeded = _identified(campaigns["first"], seed=4)
    assert reseeded.model == first.model  # the fit itself has no randomness
    assert not np.array_equal(reseeded.ensemble_coefficients, first.ensemble_coefficients)


def test_same_seed_gives_the_same_surrogate_weights_whatever_the_global_torch_state():
    rng = np.random.default_rng(0)
    levels = np.linspace(1.0, 5.0, 41)
    parameters = np.column_stack([rng.uniform(0.9, 1.1, 40), rng.uniform(1.0, 2.0, 40)])
    amplitude = parameters[:, 1:] * 1e-4 * levels  # a backbone the parameters set exactly
    frequency = parameters[:, :1] * (100.0 + levels)
    backbones = np.stack([amplitude, frequency], axis=-1)
    spec = SurrogateSpec(("k", "c"), [[0.9, 1.1], [1.0, 2.0]], levels)
    net = NetConfig(latent_dim=8, conv_filters=(8, 4), ffnn_width=16, ffnn_depth=2)
    config = TrainingConfig(net=net, max_epochs=3, finetune_epochs=2, progress=False, seed=7)
    threads = torch.get_num_threads()
    torch.set_num_threads(1)
    try:
        torch.manual_seed(1)
        first = train_surrogate(parameters, backbones, spec, config)
        torch.manual_seed(2)  # a different global state must not matter
        torch.rand(10)
        again = train_surrogate(parameters, backbones, spec, config)
    finally:
        torch.set_num_threads(threads)
    weights, weights_again = first.model.state_dict(), again.model.state_dict()
    assert weights.keys() == weights_again.keys()
    assert all(torch.equal(weights[name], weights_again[name]) for name in weights)
    np.testing.assert_array_equal(first.predict(parameters), again.predict(parameters))


def _posterior(pm_model, seed):
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")  # one short chain: PyMC warns about diagnostics
        idata = sample(
            pm_model,
            sampler="demetropolisz",  # joint proposals: the short chain moves from its start
            draws=20,
            tune=10,
            chains=1,
            cores=1,
            random_seed=seed,
            progressbar=False,
        )
    return {name: idata.posterior[name].values for name in ("linear_stiffness", "cubic_stiffness")}


def test_same_seed_gives_the_same_posterior_draws(duffing_triplet):
    pm_model = build_model(
        duffing(),
        duffing_triplet,
        forward="harmonic",
        names=["linear_stiffness", "cubic_stiffness"],
        family="mvn",  # the copula's graph takes far longer to compile
        n_grid=15,
    )
    assert isinstance(pm_model, pm.Model)
    first, again, other = (_posterior(pm_model, seed) for seed in (3, 3, 4))
    for name in first:
        assert np.unique(first[name]).size > 5  # the chain moved
        np.testing.assert_array_equal(first[name], again[name])
        assert not np.array_equal(first[name], other[name])
