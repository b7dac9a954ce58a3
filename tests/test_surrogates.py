"""Backbone surrogate: networks, training, ONNX export, runtime, evaluation.

The data are closed-form single-harmonic backbones of a base-excited Duffing
oscillator with viscous and Coulomb damping (mass-normalised, x relative to the
base): at phase resonance the base-acceleration amplitude A balances the
dissipation, A = a·(c + 4F/(π a ω))·ω with ω² = k + ¾·k3·a², and the backbone
frequency is ω / 2π.
"""

from __future__ import annotations

import json
import pickle
import shutil
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest
import torch

from studies import table5_study
from surrogates.dataset import BackboneDataset
from surrogates.evaluate import PAPER_TABLE5, backbone_metrics
from surrogates.export import export_surrogate
from surrogates.nets import Autoencoder, KerasConv1d, LatentRegressor, NetConfig
from surrogates.runtime import SurrogateRuntime, SurrogateSpec
from surrogates.train import TrainingConfig, output_scaling, train_surrogate

torch.set_num_threads(1)

NAMES = ("k", "k3", "c", "F")
BOUNDS = np.array([[3.5e5, 4.5e5], [1e10, 4e10], [4.0, 10.0], [0.0, 0.1]])
LEVELS = np.linspace(0.2, 10.0, 41)  # base acceleration, m/s², all above 4F/π
TINY = NetConfig(latent_dim=8, conv_filters=(8, 4), ffnn_width=16, ffnn_depth=2)


def duffing_backbones(parameters: np.ndarray, damping_ratio: bool = False) -> np.ndarray:
    """Closed-form backbones ``(n, 41, 2 or 3)`` by bisection on the amplitude."""
    k, k3, c, friction = (parameters[:, i, None] for i in range(4))
    drive = LEVELS[None, :] - 4.0 * friction / np.pi
    low, high = np.zeros_like(drive), drive / (c * np.sqrt(k))  # k3 >= 0: a below linear one
    for _ in range(60):
        a = 0.5 * (low + high)
        above = a * c * np.sqrt(k + 0.75 * k3 * a**2) > drive
        high, low = np.where(above, a, high), np.where(above, low, a)
    a = 0.5 * (low + high)
    omega = np.sqrt(k + 0.75 * k3 * a**2)
    channels = [a, omega / (2 * np.pi)]
    if damping_ratio:
        channels.append((c + 4.0 * friction / (np.pi * a * omega)) / (2 * omega))
    return np.stack(channels, axis=-1)


def dataset(n: int, seed: int, damping_ratio: bool = False):
    rng = np.random.default_rng(seed)
    x = BOUNDS[:, 0] + rng.random((n, 4)) * np.ptp(BOUNDS, axis=1)
    channels = ("amplitude_m", "frequency_hz") + (("damping_ratio",) if damping_ratio else ())
    return x, duffing_backbones(x, damping_ratio), SurrogateSpec(NAMES, BOUNDS, LEVELS, channels)


def test_closed_form_backbones_solve_the_power_balance():
    x, y, _ = dataset(20, seed=3, damping_ratio=True)
    a, omega, zeta = y[..., 0], 2 * np.pi * y[..., 1], y[..., 2]
    k, k3, c, friction = (x[:, i, None] for i in range(4))
    np.testing.assert_allclose(
        a * (c + 4 * friction / (np.pi * a * omega)) * omega,
        np.broadcast_to(LEVELS, a.shape),
        rtol=1e-10,
    )
    np.testing.assert_allclose(omega**2, k + 0.75 * k3 * a**2, rtol=1e-12)
    np.testing.assert_allclose(
        2 * zeta * omega**2 * a, np.broadcast_to(LEVELS, a.shape), rtol=1e-10
    )  # A = 2ζω²a


# -- networks ---------------------------------------------------------------


def _keras_conv(kernel, c_in, c_out):
    return kernel * c_in * c_out + c_out


def _keras_dense(n_in, n_out):
    return n_in * n_out + n_out


def _counts(module):
    return [
        sum(p.numel() for p in child.parameters())
        for child in module.children()
        if any(True for _ in child.parameters())
    ]


def test_layer_parameter_counts_match_the_papers_keras_model():
    autoencoder, ffnn = Autoencoder(41, 2), LatentRegressor(12)
    # Keras counts of Tables 2–4, layer by layer.
    assert (
        _counts(autoencoder.encoder)
        == [_keras_conv(5, 2, 64), _keras_conv(5, 64, 32), _keras_dense(41 * 32, 64)]
        == [704, 10272, 84032]
    )
    assert (
        _counts(autoencoder.decoder)
        == [_keras_dense(64, 1312), _keras_conv(5, 32, 64), _keras_conv(5, 64, 2)]
        == [85280, 10304, 642]
    )
    assert _counts(ffnn.layers) == [6656, 262656, 262656, 262656, 32832]
    assert _counts(ffnn.layers)[0] == _keras_dense(12, 512)


def test_layer_output_shapes_follow_the_paper():
    autoencoder = Autoencoder(41, 3)
    shapes = {}
    for name, module in autoencoder.named_modules():
        if name.count(".") == 1:
            module.register_forward_hook(lambda m, i, o, name=name: shapes.update({name: o.shape}))
    backbone = torch.randn(5, 41, 3)
    assert autoencoder(backbone).shape == (5, 41, 3)
    assert shapes == {  # convolutions run channels-first inside
        "encoder.conv1": (5, 64, 41),
        "encoder.conv2": (5, 32, 41),
        "encoder.dense": (5, 64),
        "decoder.dense": (5, 1312),
        "decoder.conv1": (5, 64, 41),
        "decoder.conv2": (5, 3, 41),
    }
    assert LatentRegressor(7)(torch.rand(5, 7)).shape == (5, 64)


@pytest.mark.parametrize("padding", ["causal", "same"])
def test_keras_padding_against_a_direct_sum(padding):
    conv = KerasConv1d(
        2, 3, kernel_size=5, padding=padding, dilation=4 if padding == "causal" else 1
    )
    x = torch.randn(1, 2, 41)
    w, b = conv.conv.weight.detach().numpy(), conv.conv.bias.detach().numpy()
    d = conv.conv.dilation[0]
    # Keras: causal output j sees x[j - (4 - m)·d]; same sees x[j + (m - 2)·d]; zeros outside.
    shift = (lambda m: (m - 4) * d) if padding == "causal" else (lambda m: (m - 2) * d)
    xn = x[0].numpy()
    expected = np.tile(b[:, None], (1, 41))
    for j in range(41):
        for m in range(5):
            if 0 <= j + shift(m) < 41:
                expected[:, j] += w[:, :, m] @ xn[:, j + shift(m)]
    np.testing.assert_allclose(conv(x)[0].detach().numpy(), expected, rtol=1e-5, atol=1e-6)


# -- training -----------------------------------------------------------------


@pytest.fixture(scope="module")
def data():
    x, y, spec = dataset(400, seed=1)
    return (x[:300], y[:300]), (x[300:], y[300:]), spec


@pytest.fixture(scope="module")
def trained(data):
    (x, y), _, spec = data
    config = TrainingConfig(max_epochs=25, finetune_epochs=25, progress=False)
    return train_surrogate(x, y, spec, config)


def test_short_training_learns_the_backbones(trained, data):
    _, (x_test, y_test), spec = data
    first = trained.history["autoencoder"][0]["val_loss"]
    best = min(r["val_loss"] for r in trained.history["autoencoder"])
    assert best < 0.1 * first
    metrics = backbone_metrics(trained.predict(x_test), y_test, spec)
    assert metrics["pearson_min_channel"] >= 0.99
    assert metrics["channels"]["frequency_hz"]["mape_pct"] < 1.0
    # The (un-)scalings must be right: an untrained model predicts nothing this close.
    assert metrics["channels"]["amplitude_m"]["mae"] < 0.05 * y_test[..., 0].mean()
    assert trained.n_train + trained.n_validation == 300
    assert set(trained.history) == {"autoencoder", "ffnn", "finetune"}


def test_same_seed_gives_the_same_weights():
    x, y, spec = dataset(40, seed=2)
    config = TrainingConfig(net=TINY, max_epochs=3, finetune_epochs=2, progress=False, seed=7)
    first, second = (train_surrogate(x, y, spec, config).model.state_dict() for _ in range(2))
    assert all(torch.equal(first[name], second[name]) for name in first)
    other = train_surrogate(
        x,
        y,
        spec,
        TrainingConfig(net=TINY, max_epochs=3, finetune_epochs=2, progress=False, seed=8),
    )
    assert not torch.equal(
        first["regressor.layers.0.weight"], other.model.state_dict()["regressor.layers.0.weight"]
    )


def test_training_rejects_parameters_outside_its_box():
    x, y, spec = dataset(30, seed=2)
    x[4, 2] = 11.0
    with pytest.raises(ValueError, match=r"parameter 'c' = 11 in row 4 .*upper bound 10\)"):
        train_surrogate(x, y, spec, TrainingConfig(net=TINY, max_epochs=1, progress=False))


def test_output_scaling_standardises_and_survives_constant_entries():
    _, y, _ = dataset(50, seed=4)
    y[:, 0, 1] = 100.0  # a level where every curve has the same frequency
    offset, scale = output_scaling(y, "level")
    z = (y - offset) / scale
    np.testing.assert_allclose(z[:, 1:].mean(axis=0), 0, atol=1e-9)
    np.testing.assert_allclose(z[:, 1:].std(axis=0), 1, rtol=1e-9)
    np.testing.assert_allclose(scale[0, 1], y[..., 1].std())  # falls back to the channel spread
    offset, scale = output_scaling(y, "channel")
    np.testing.assert_allclose(scale[7], y.std(axis=(0, 1)))


# -- export and runtime --------------------------------------------------------


@pytest.fixture(scope="module")
def exported(trained, tmp_path_factory):
    return export_surrogate(trained, tmp_path_factory.mktemp("surrogate"))


def test_onnx_graph_reproduces_the_torch_model(trained, exported, data):
    _, (x_test, _), _ = data
    runtime = SurrogateRuntime.load(exported)
    expected = trained.predict(x_test)
    np.testing.assert_allclose(runtime.predict(x_test), expected, rtol=1e-5)
    np.testing.assert_allclose(runtime.frequency_hz(x_test[3]), expected[3, :, 1], rtol=1e-5)
    np.testing.assert_allclose(runtime.amplitude_m(x_test[:2]), expected[:2, :, 0], rtol=1e-5)


def test_sidecar_describes_the_graph(exported, trained):
    sidecar = json.loads((exported / "surrogate.json").read_text())
    assert sidecar["parameter_names"] == list(NAMES)
    np.testing.assert_array_equal(sidecar["levels"], LEVELS)
    assert sidecar["channel_units"] == {"amplitude_m": "m", "frequency_hz": "Hz"}
    assert sidecar["training"]["n_train"] == trained.n_train
    assert sidecar["versions"]["torch"] == torch.__version__
    np.testing.assert_allclose(sidecar["scalers"]["output"]["scale"], trained.output_scale)


def test_runtime_pickles_without_its_session(exported, data):
    _, (x_test, _), _ = data
    runtime = SurrogateRuntime.load(exported)
    expected = runtime.predict(x_test)
    clone = pickle.loads(pickle.dumps(runtime))
    assert clone._session is None
    np.testing.assert_array_equal(clone.predict(x_test), expected)


def test_tampered_graph_is_refused(exported, tmp_path):
    folder = Path(shutil.copytree(exported, tmp_path / "tampered"))
    graph = bytearray((folder / "surrogate.onnx").read_bytes())
    graph[len(graph) // 2] ^= 0x01
    (folder / "surrogate.onnx").write_bytes(bytes(graph))
    with pytest.raises(ValueError, match=r"surrogate\.onnx: hash mismatch"):
        SurrogateRuntime.load(folder)


@pytest.mark.parametrize("edit", ["parameters", "levels"])
def test_sidecar_that_does_not_match_the_graph_is_refused(exported, tmp_path, edit):
    folder = Path(shutil.copytree(exported, tmp_path / "edited"))
    sidecar = json.loads((folder / "surrogate.json").read_text())
    del sidecar["content_sha256"]  # as an older or hand-written sidecar: the graph check decides
    if edit == "parameters":
        sidecar["parameter_names"] = sidecar["parameter_names"][:3]
        sidecar["bounds"] = sidecar["bounds"][:3]
    else:
        sidecar["levels"] = sidecar["levels"][:40]
    (folder / "surrogate.json").write_text(json.dumps(sidecar))
    with pytest.raises(ValueError, match="sidecar does not match the graph"):
        SurrogateRuntime.load(folder)


def test_wrong_parameter_count_names_the_expected_parameters(exported):
    runtime = SurrogateRuntime.load(exported)
    with pytest.raises(ValueError, match=r"expected vectors of 4 parameters \(k, k3, c, F\)"):
        runtime.predict(np.ones((2, 3)))
    with pytest.raises(ValueError, match="parameter 'k3' is not finite"):
        runtime.predict(np.array([4e5, np.nan, 5.0, 0.05]))


def test_parameters_outside_the_box(exported):
    runtime = SurrogateRuntime.load(exported)
    inside = BOUNDS.mean(axis=1)
    outside = inside.copy()
    outside[3] = -0.01
    with pytest.raises(ValueError, match=r"parameter 'F' = -0.01 in row 1 .*lower bound 0\)"):
        runtime.predict(np.vstack([inside, outside]))
    backbones, flagged = runtime.predict(np.vstack([inside, outside, inside]), extrapolate="flag")
    assert backbones.shape == (3, 41, 2)
    np.testing.assert_array_equal(flagged, [False, True, False])
    single, flag = runtime.predict(inside, extrapolate="flag")
    assert single.shape == (41, 2) and not flag
    allowed = SurrogateRuntime.load(exported, extrapolate="allow").predict(outside)
    np.testing.assert_array_equal(allowed, backbones[1])


def test_runtime_loads_and_predicts_without_torch(exported):
    script = (
        "import sys; sys.modules['torch'] = None\n"
        "from surrogates import SurrogateRuntime\n"
        f"r = SurrogateRuntime.load({str(exported)!r})\n"
        f"print(r.predict({BOUNDS.mean(axis=1).tolist()!r}).shape)\n"
        "assert 'torch' not in [m for m, v in sys.modules.items() if v is not None]\n"
    )
    result = subprocess.run(
        [sys.executable, "-c", script],
        capture_output=True,
        text=True,
        cwd=Path(__file__).parents[1],
        check=False,
    )
    assert result.returncode == 0, result.stderr
    assert result.stdout.strip() == "(41, 2)"


def test_three_channel_surrogate_round_trips(tmp_path):
    x, y, spec = dataset(40, seed=5, damping_ratio=True)
    config = TrainingConfig(net=TINY, max_epochs=2, finetune_epochs=1, progress=False)
    surrogate = train_surrogate(x, y, spec, config)
    runtime = SurrogateRuntime.load(export_surrogate(surrogate, tmp_path))
    assert runtime.channels == ("amplitude_m", "frequency_hz", "damping_ratio")
    np.testing.assert_allclose(
        runtime.channel("damping_ratio", x[:5]), surrogate.predict(x[:5])[..., 2], rtol=1e-5
    )


# -- evaluation ----------------------------------------------------------------


def test_metrics_against_a_known_error():
    _, y, spec = dataset(30, seed=6)
    predicted = y * np.array([1.02, 0.999])  # +2 % amplitude, −0.1 % frequency
    metrics = backbone_metrics(predicted, y, spec)
    amplitude, frequency = metrics["channels"]["amplitude_m"], metrics["channels"]["frequency_hz"]
    assert amplitude["mape_pct"] == pytest.approx(2.0) and frequency["mape_pct"] == pytest.approx(
        0.1
    )
    assert metrics["mse_amplitude_mm2"] == pytest.approx(np.mean((0.02e3 * y[..., 0]) ** 2))
    assert frequency["mae"] == pytest.approx(np.mean(1e-3 * y[..., 1]))
    assert metrics["pearson_min_channel"] == pytest.approx(1.0)
    shuffled = backbone_metrics(y[::-1], y, spec)
    assert shuffled["channels"]["amplitude_m"]["pearson"] < 0.9


def test_table5_study_rows_carry_the_papers_figures():
    x, y, spec = dataset(260, seed=8)
    data = BackboneDataset(
        X=x, Y=y, spec=spec, origin=np.full(len(x), "analytical"),
        non_monotone=np.zeros(len(x), bool), failed_parameters=np.empty((0, 4)),
        failed_reasons=np.empty(0, str), provenance={},
    ).with_splits(0.1, 0.1)  # fmt: skip
    config = TrainingConfig(net=TINY, max_epochs=2, finetune_epochs=0, progress=False)
    rows = table5_study(data, sizes=(150, 200), config=config)
    assert [r.n_train for r in rows] == [150, 200]
    assert all(r.n_validation == 26 and r.n_test == 26 for r in rows)
    assert rows[0].paper_mse is None
    assert (rows[1].paper_mse, rows[1].paper_mae, rows[1].paper_mape) == PAPER_TABLE5[200]
    assert all(r.mse_amplitude_mm2 > 0 and r.rmse_frequency_hz > 0 for r in rows)
    assert all(r.table5_representation == "excitation_levels" for r in rows)
    with pytest.raises(ValueError, match="only 208 training curves"):
        table5_study(data, sizes=(209,), config=config)


def test_a_widened_box_in_the_sidecar_is_a_hash_mismatch(tmp_path, trained):
    folder = export_surrogate(trained, tmp_path / "surrogate")
    sidecar_path = folder / "surrogate.json"
    sidecar = json.loads(sidecar_path.read_text())
    sidecar["bounds"][0][1] *= 2.0  # a wider training box than the network knows
    sidecar_path.write_text(json.dumps(sidecar))
    with pytest.raises(ValueError, match="hash mismatch: the sidecar's content"):
        SurrogateRuntime.load(folder)


def test_a_quartic_head_carries_a_quartic_through_the_exported_graph(tmp_path):
    # Backbones that are a quartic in the box-scaled parameters u at every level: the degree-4
    # head fits them exactly (the networks' residual is nil), a cubic cannot.
    rng = np.random.default_rng(4)
    x = BOUNDS[:, 0] + rng.random((300, 4)) * np.ptp(BOUNDS, axis=1)
    u = (x - BOUNDS[:, 0]) / np.ptp(BOUNDS, axis=1)
    ramp = np.linspace(1.0, 2.0, LEVELS.size)
    quartic = u[:, :1] ** 4 + 0.5 * u[:, 1:2] ** 2 * u[:, 2:3] * u[:, 3:4]
    y = np.stack([1e-3 * (1 + ramp * quartic), 100 + ramp * quartic], axis=-1)
    spec = SurrogateSpec(NAMES, BOUNDS, LEVELS, ("amplitude_m", "frequency_hz"))
    fit, new = slice(0, 250), slice(250, 300)
    errors = {}
    for degree in (3, 4):
        config = TrainingConfig(net=TINY, max_epochs=1, finetune_epochs=0, progress=False,
                                head_degree=degree)  # fmt: skip
        trained = train_surrogate(x[fit], y[fit], spec, config)
        runtime = SurrogateRuntime.load(export_surrogate(trained, tmp_path / f"head{degree}"))
        assert runtime.metadata["scalers"]["head"]["degree"] == degree
        errors[degree] = np.max(np.abs(runtime.predict(x[new]) / y[new] - 1))
    assert errors[4] < 2e-6 and errors[3] > 1e-4
