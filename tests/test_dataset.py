"""Surrogate datasets: sampling, inversion onto excitation levels, files, measured curves.

Independent expectations: the closed-form single-harmonic Duffing backbone
(``ω² = k + ¾ k3 a²``, base excitation ``A = c ω a`` at phase resonance), the
harmonic-balance solver re-evaluated at the produced amplitudes, the Latin
hypercube's one-point-per-stratum property, and curves that are linear in the
level (which linear interpolation must reproduce exactly).
"""

from __future__ import annotations

import concurrent.futures
import dataclasses
import math

import numpy as np
import pytest
import torch

from identification.analytical.harmonic import backbone
from identification.measurements.backbone import Backbone, BackboneSet
from identification.model import JointModel, parameter_bounds
from identification.rig import RIG_PRESETS
from surrogates.dataset import (
    BackboneDataset,
    add_measured,
    generate_dataset,
    nominal_levels,
    sample_parameters,
)
from surrogates.evaluate import backbone_metrics
from surrogates.export import export_surrogate
from surrogates.nets import NetConfig
from surrogates.runtime import SurrogateRuntime
from surrogates.train import TrainingConfig, train_surrogate

torch.set_num_threads(1)

TRC = RIG_PRESETS["trc-like"].model
TRC_NAMES = ["linear_stiffness", "viscous_damping", "cubic_stiffness", "microslip.k_t",
             "microslip.F_s"]  # fmt: skip
K, C, K3 = (2 * np.pi * 100.0) ** 2, 2 * 0.003 * 2 * np.pi * 100.0, 3.2e10
DUFFING = JointModel({"linear_stiffness": K, "viscous_damping": C, "cubic_stiffness": K3})
DUFFING_NAMES = ["linear_stiffness", "viscous_damping", "cubic_stiffness"]
ALL_CHANNELS = ("amplitude_m", "frequency_hz", "damping_ratio")


def small(model=TRC, names=None, n=6, **options):
    options = {"spread": 0.1, "n_levels": 9, "progress": False, **options}
    return generate_dataset(model, names, n, **options)


# -- parameters and levels ----------------------------------------------------------


@pytest.mark.parametrize("sampler", ["lhs", "sobol"])
def test_qmc_samples_lie_within_bounds_and_are_seeded(sampler):
    box = parameter_bounds(JointModel.preset("pandey2025"), ["cubic_stiffness", "van_der_pol"], 0.3)
    x = sample_parameters(box, 64, sampler=sampler, seed=3)
    assert x.shape == (64, 2)
    assert np.all((x >= box[:, 0]) & (x <= box[:, 1]))
    np.testing.assert_array_equal(x, sample_parameters(box, 64, sampler=sampler, seed=3))
    assert not np.array_equal(x, sample_parameters(box, 64, sampler=sampler, seed=4))
    if sampler == "lhs":  # one point in each of the 64 strata of every axis
        strata = np.floor(64 * (x - box[:, 0]) / np.ptp(box, axis=1)).astype(int)
        assert all(sorted(column) == list(range(64)) for column in strata.T)


def test_nominal_levels_hold_the_nominal_model_at_the_requested_amplitudes():
    amplitudes = np.geomspace(5e-5, 2e-3, 9)
    levels = nominal_levels(DUFFING, (5e-5, 2e-3), 9)
    np.testing.assert_allclose(levels, C * amplitudes * np.sqrt(K + 0.75 * K3 * amplitudes**2))
    # A box of zero width around the nominal model gives back those amplitudes.
    data = small(DUFFING, DUFFING_NAMES, n=2, spread=1e-12, amplitude_range_m=(5e-5, 2e-3))
    np.testing.assert_allclose(data.Y[..., 0], np.broadcast_to(amplitudes, (2, 9)), rtol=1e-9)


# -- inversion onto the levels ---------------------------------------------------------


def test_duffing_backbones_on_levels_match_the_closed_form():
    data = small(DUFFING, DUFFING_NAMES, n=5, spread=0.2, channels=ALL_CHANNELS)
    k, c, k3 = data.X.T[:, :, None]
    a, f, zeta = np.moveaxis(data.Y, -1, 0)
    omega = np.sqrt(k + 0.75 * k3 * a**2)
    np.testing.assert_allclose(
        c * omega * a, np.broadcast_to(data.spec.levels, a.shape), rtol=1e-10
    )
    np.testing.assert_allclose(2 * np.pi * f, omega, rtol=1e-12)
    np.testing.assert_allclose(zeta, c / (2 * omega), rtol=1e-10)
    assert data.provenance["harmonic"] == {"method": "single", "harmonics": 1}


@pytest.mark.parametrize("harmonic", ["single", "multi"])
def test_trc_backbones_reproduce_the_harmonic_balance(harmonic):
    data = small(TRC, TRC_NAMES, n=4, harmonic=harmonic, harmonics=3, channels=ALL_CHANNELS)
    assert len(data) == 4 and data.provenance["counts"]["failed"] == 0
    for x, y in zip(data.X, data.Y, strict=True):
        again = backbone(TRC, y[:, 0], parameters=x[None], names=TRC_NAMES, method=harmonic,
                         harmonics=3)  # fmt: skip
        assert again.converged.all()
        np.testing.assert_allclose(again.base_acceleration[0], data.spec.levels, rtol=1e-8)
        np.testing.assert_allclose(again.frequency_hz[0], y[:, 1], rtol=1e-12)
        np.testing.assert_allclose(again.damping_ratio[0], y[:, 2], rtol=1e-10)
    assert np.all(np.diff(data.Y[..., 0], axis=1) > 0)


def _dipping_model() -> tuple[JointModel, np.ndarray]:
    """Damping that falls then rises with amplitude: A(a) rises, dips near 0.6 mm, rises."""
    a0, k3 = 1e-3, 0.1 * K / 1e-6
    c3 = 1.2 * C / (a0**4 * 9 / 16 * k3)
    vdp = 4 * (-2 * C / a0**2 - 0.75 * c3 * K)
    model = JointModel({"linear_stiffness": K, "viscous_damping": C, "cubic_stiffness": k3,
                        "van_der_pol": vdp, "cubic_damping": c3})  # fmt: skip
    return model, np.geomspace(0.2, 2.0, 7)


def test_non_monotone_excitation_takes_the_first_crossing_and_flags_it():
    model, levels = _dipping_model()
    dense = np.geomspace(1e-5, 3e-3, 4000)
    excitation = backbone(model, dense).base_acceleration
    assert np.any(np.diff(excitation) < 0)  # the case is really non-monotone
    with pytest.raises(ValueError, match="not positive and increasing"):
        nominal_levels(model, (1e-4, 2e-3))
    options = {"levels": levels, "amplitude_range_m": (1e-4, 2e-3), "progress": False}
    with pytest.warns(UserWarning, match="0 of 3 parameter sets failed .*; 3 kept with a non-mo"):
        data = generate_dataset(model, ["viscous_damping"], 3, spread=0.01, **options)
    assert data.non_monotone.all() and data.provenance["counts"]["non_monotone"] == 3
    for x, y in zip(data.X, data.Y, strict=True):
        dense_x = backbone(model, dense, parameters=x[None], names=["viscous_damping"])
        for level, a in zip(levels, y[:, 0], strict=True):
            below = dense < a * (1 - 1e-9)
            assert np.all(dense_x.base_acceleration[0][below] < level)  # no earlier root
    with pytest.warns(UserWarning, match="3 of 3 parameter sets failed"):
        dropped = generate_dataset(
            model, ["viscous_damping"], 3, spread=0.01, non_monotone="drop", **options
        )
    assert len(dropped) == 0 and dropped.provenance["counts"]["failed"] == 3
    assert all("not monotone" in reason for reason in dropped.failed_reasons)


def test_failed_sets_are_dropped_with_their_reason():
    # Levels far above what 0.6–6 mm needs: no set reaches the top one.
    with pytest.warns(UserWarning, match="3 of 3 parameter sets failed and were dropped"):
        data = small(DUFFING, DUFFING_NAMES, n=3, levels=[0.1, 1e4], amplitude_range_m=(2e-4, 2e-3))
    assert len(data) == 0 and data.failed_parameters.shape == (3, 3)
    assert data.provenance["counts"] == {"requested": 3, "kept": 0, "failed": 3,
                                         "non_monotone": 0, "measured": 0}  # fmt: skip
    assert "top level 1e+04 m/s² is not reached below 6 mm" in data.failed_reasons[0]


def test_executor_gives_identical_data():
    local = small(n=7, chunk_size=3)
    with concurrent.futures.ThreadPoolExecutor(2) as pool:
        remote = small(n=7, chunk_size=3, executor=pool)
    np.testing.assert_array_equal(local.X, remote.X)
    np.testing.assert_array_equal(local.Y, remote.Y)


def test_pll_method_agrees_with_the_closed_form():
    data = generate_dataset(
        DUFFING, DUFFING_NAMES, 2, spread=0.05, levels=np.geomspace(0.05, 3.0, 3),
        method="pll", progress=False,
    )  # fmt: skip
    assert len(data) == 2 and data.provenance["method"] == "pll"
    k, c, k3 = data.X.T[:, :, None]
    a, f = np.moveaxis(data.Y, -1, 0)
    omega = np.sqrt(k + 0.75 * k3 * a**2)
    np.testing.assert_allclose(2 * np.pi * f, omega, rtol=3e-3)
    np.testing.assert_allclose(c * omega * a, np.broadcast_to(data.spec.levels, a.shape), rtol=0.02)


# -- files ------------------------------------------------------------------------------


def test_save_load_round_trip_and_hash_check(tmp_path):
    data = small(n=5, channels=ALL_CHANNELS)
    path = data.save(tmp_path / "data.npz")
    loaded = BackboneDataset.load(path)
    for name in ("X", "Y", "origin", "non_monotone", "failed_parameters", "failed_reasons"):
        np.testing.assert_array_equal(getattr(loaded, name), getattr(data, name))
    assert loaded.spec.to_dict() == data.spec.to_dict()
    assert loaded.provenance == data.provenance and loaded.content_hash == data.content_hash
    assert JointModel.from_dict(loaded.provenance["model"]) == TRC
    assert loaded.provenance["sampler"] == "lhs" and loaded.provenance["seed"] == 0

    with np.load(path) as stored:
        arrays = {key: stored[key] for key in stored.files}
    arrays["Y"] = arrays["Y"].copy()
    arrays["Y"][2, 3, 1] *= 1 + 1e-12
    np.savez(tmp_path / "tampered.npz", **arrays)
    with pytest.raises(ValueError, match=r"tampered\.npz: hash mismatch"):
        BackboneDataset.load(tmp_path / "tampered.npz")
    (tmp_path / "broken.npz").write_bytes(path.read_bytes()[:100])
    with pytest.raises(ValueError, match=r"not a readable \.npz dataset"):
        BackboneDataset.load(tmp_path / "broken.npz")


def test_split_is_seeded_and_disjoint():
    data = small(n=10)
    train, test = data.split(3, seed=1)
    assert (len(train), len(test)) == (7, 3)
    rows = {tuple(x) for x in train.X} | {tuple(x) for x in test.X}
    assert len(rows) == 10
    np.testing.assert_array_equal(test.X, data.split(3, seed=1)[1].X)
    assert test.provenance["subset_of"] == data.content_hash


# -- measured curves ----------------------------------------------------------------


def _duffing_curve(x, levels, label, phase_deg=0.0):
    """Closed-form Duffing backbone on its own levels; damping as the extraction reports it."""
    k, c, k3 = x
    a = np.empty(levels.size)
    for i, level in enumerate(levels):  # c a ω(a) = level, increasing in a
        low, high = 0.0, level / (c * math.sqrt(k))
        for _ in range(200):
            mid = 0.5 * (low + high)
            low, high = (mid, high) if c * mid * math.sqrt(k + 0.75 * k3 * mid**2) < level else (
                low, mid)  # fmt: skip
        a[i] = 0.5 * (low + high)
    omega = np.sqrt(k + 0.75 * k3 * a**2)
    zeta = c / (2 * omega) * np.cos(np.radians(phase_deg))  # D = |Q_b| cos(phase error) / 2|Q|
    return Backbone(a, omega / (2 * np.pi), zeta, excitation_level=levels / 10.0,
                    phase_error_deg=np.full(levels.size, phase_deg), label=label)  # fmt: skip


def test_add_measured_interpolates_onto_the_dataset_levels():
    data = small(DUFFING, DUFFING_NAMES, n=4, spread=0.2, channels=ALL_CHANNELS)
    label = data.X[0]
    levels = data.spec.levels
    # Power balance: the curve on the dataset levels plus points outside, 3° off resonance.
    own = np.concatenate([[0.5 * levels[0]], levels, [2 * levels[-1]]])
    exact = _duffing_curve(label, own, "exact", phase_deg=3.0)
    # Level × gain: a curve linear in the level, which linear interpolation must reproduce.
    gain_levels = np.linspace(levels[0], levels[-1], 6)
    linear = Backbone(1e-4 * gain_levels, 100.0 + 0.5 * gain_levels, 0.004 + 1e-4 * gain_levels,
                      excitation_level=gain_levels / 10.0, label="linear")  # fmt: skip
    with_power = add_measured(data, BackboneSet([exact]), label[None])
    np.testing.assert_allclose(with_power.Y[-1, :, :2], data.Y[0, :, :2], rtol=1e-12)
    # The measured damping is the power balance's, cos(phase error) included.
    np.testing.assert_allclose(with_power.Y[-1, :, 2], data.Y[0, :, 2] * np.cos(np.radians(3.0)))
    assert list(with_power.origin[-1:]) == ["measured:exact"] and with_power.n_measured == 1
    assert with_power.provenance["measured"]["level_source"] == "power balance"
    with_gain = add_measured(data, BackboneSet([linear]), label[None], level_gain=10.0)
    expected = np.stack([1e-4 * levels, 100.0 + 0.5 * levels, 0.004 + 1e-4 * levels], axis=-1)
    np.testing.assert_allclose(with_gain.Y[-1], expected, rtol=1e-12)
    assert with_gain.provenance["counts"]["measured"] == 1 and len(with_gain) == 5


def test_add_measured_excludes_curves_with_their_reasons():
    data = small(DUFFING, DUFFING_NAMES, n=3, spread=0.2)
    levels = data.spec.levels
    short = _duffing_curve(data.X[0], np.geomspace(levels[0], 0.5 * levels[-1], 5), "short")
    good = _duffing_curve(data.X[1], np.geomspace(0.9 * levels[0], levels[-1], 5), "good")
    outside = _duffing_curve(data.X[2], np.geomspace(0.5 * levels[0], 2 * levels[-1], 5), "out")
    labels = np.vstack([data.X[0], data.X[1], data.X[2] * [1.0, 1.0, 10.0]])
    with pytest.warns(UserWarning) as caught:
        mixed = add_measured(data, BackboneSet([short, good, outside]), labels)
    assert sorted(str(w.message).split(":")[1] for w in caught) == [
        " curve 'out' left out",
        " curve 'short' left out",
    ]
    assert len(mixed) == 4 and mixed.origin[-1] == "measured:good"
    excluded = mixed.provenance["measured"]["excluded"]
    assert set(excluded) == {"short", "out"}
    assert f"the dataset needs {levels[0]:.4g}–{levels[-1]:.4g} m/s²" in excluded["short"]
    assert "'cubic_stiffness'" in excluded["out"] and "outside the training box" in excluded["out"]
    no_levels = dataclasses.replace(good, excitation_level=None, label="bare")
    with pytest.warns(UserWarning, match="'bare' left out: it has no excitation levels"):
        add_measured(data, BackboneSet([no_levels]), data.X[1:2], level_gain=10.0)
    with pytest.raises(ValueError, match=r"labels must have shape \(1, 3\)"):
        add_measured(data, BackboneSet([good]), data.X[:2])


# -- end to end ---------------------------------------------------------------------


def test_tiny_surrogate_trains_exports_and_runs_on_a_trc_dataset(tmp_path):
    data = BackboneDataset.load(small(n=48, n_levels=41).save(tmp_path / "trc.npz"))
    train, test = data.split(8, seed=0)
    net = NetConfig(latent_dim=8, conv_filters=(8, 4), ffnn_width=32, ffnn_depth=2)
    config = TrainingConfig(net=net, max_epochs=200, finetune_epochs=50, progress=False)
    surrogate = train_surrogate(train.X, train.Y, train.spec, config)
    runtime = SurrogateRuntime.load(export_surrogate(surrogate, tmp_path / "surrogate"))
    assert runtime.parameter_names == tuple(TRC_NAMES)
    np.testing.assert_array_equal(runtime.levels, data.spec.levels)
    predicted = runtime.predict(test.X)
    np.testing.assert_allclose(predicted, surrogate.predict(test.X), rtol=1e-5)
    metrics = backbone_metrics(predicted, test.Y, test.spec)
    # A tiny net on 40 curves already beats the mean training curve clearly.
    mean_curve = np.broadcast_to(train.Y.mean(axis=0), test.Y.shape)
    baseline = backbone_metrics(mean_curve, test.Y, test.spec)
    frequency_mae = metrics["channels"]["frequency_hz"]["mae"]
    assert frequency_mae < 0.5 * baseline["channels"]["frequency_hz"]["mae"]
    assert metrics["pearson_min_channel"] > 0.9
