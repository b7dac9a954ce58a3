"""Virtual test rig: channels, noise, schedule, ground truth, presets, round trip."""

import ast
import json
from concurrent.futures import ThreadPoolExecutor
from pathlib import Path

import numpy as np
import pytest

import identification.analytical.pll  # noqa: F401  (the rig's simulator: missing, the suite fails)
from identification.analytical.harmonic import backbone as harmonic_backbone
from identification.measurements.extraction import extract_backbones
from identification.measurements.records import Campaign, Record, read_steps
from identification.model import JointModel
from identification.rig import (
    GROUND_TRUTH_FILE,
    RIG_PRESETS,
    Rig,
    first_bending_shape,
    read_ground_truth,
    trc_channels,
)

FS = 10_000.0


def test_first_bending_shape():
    shape = first_bending_shape().reshape(5, 3)  # along the length × across the width
    assert shape[2, 1] == 1.0 == shape.max()  # point 8, the centre
    np.testing.assert_allclose(shape, shape[::-1, :])  # symmetric about mid-length
    np.testing.assert_allclose(shape, shape[:, ::-1])  # and about the centre line
    # sin(πξ) at ξ = 1/6, 1/3: half and √3/2 of the centre along the centre line
    np.testing.assert_allclose(shape[:2, 1], [0.5, np.sqrt(3) / 2])
    assert np.all(shape[:, 0] < shape[:, 1])


def _harmonic_series(n=20_000, f=101.0, a=1e-3, base=2e-4):
    t = np.arange(n) / FS
    theta = 2 * np.pi * f * t + 0.3
    return t, -a * 2 * np.pi * f * np.sin(theta), -base * np.cos(theta), np.full(n, f), theta


def test_channels_map_to_the_record_views():
    t, v_rel, v_base, f, theta = _harmonic_series()
    data = trc_channels(t, v_rel, v_base, f, theta)
    record = Record(data, _steps_over(t), "Config1_PRT_Assemb1")
    np.testing.assert_allclose(record.excitation_velocity, v_base, atol=1e-15)
    np.testing.assert_allclose(record.response_velocity, v_rel, atol=1e-15)
    np.testing.assert_allclose(
        record.panel_velocity[:, 0], first_bending_shape()[0] * v_rel + v_base
    )
    np.testing.assert_array_equal(record.frequency_hz, f)
    phase = record.phase_deg
    assert phase.min() > -180 and phase.max() <= 180
    np.testing.assert_allclose(np.exp(1j * np.radians(phase)), np.exp(1j * theta), atol=1e-12)


def test_sensor_noise_is_white_independent_and_of_the_stated_level():
    t, v_rel, v_base, f, theta = _harmonic_series(n=50_000)
    clean = trc_channels(t, v_rel, v_base, f, theta)
    noisy = trc_channels(t, v_rel, v_base, f, theta, noise_m_s=1e-4, rng=np.random.default_rng(1))
    noise = (noisy - clean)[:, 1:18]
    np.testing.assert_allclose(noise.std(axis=0), 1e-4, rtol=0.03)
    correlation = np.corrcoef(noise.T) - np.eye(17)
    assert np.abs(correlation).max() < 0.03
    lag_one = np.mean(noise[1:] * noise[:-1]) / noise.var()
    assert abs(lag_one) < 0.02  # white: no correlation from sample to sample
    np.testing.assert_array_equal(noisy[:, [0, 18, 19]], clean[:, [0, 18, 19]])


def _steps_over(t):
    from identification.measurements.records import StepSchedule

    return StepSchedule([t[0], t[-1]], [1.0, 1.0])


def _small_rig(**options) -> Rig:
    model = JointModel({"linear_stiffness": (2 * np.pi * 100) ** 2, "viscous_damping": 6.0})
    settings = dict(levels_v=(0.05, 0.1), hold_s=0.3, ramp_s=0.05, noise_m_s=0.0)
    return Rig(model, **(settings | options))


def test_schedule_and_files(tmp_path):
    rig = _small_rig(config="4", variability={"linear_stiffness": 0.02, "shaker_gain": 0.05})
    campaign = rig.write_campaign(tmp_path, assemblies=2, runs=2, seed=3, comma=True,
                                  extension=".csv")  # fmt: skip
    assert campaign.names == ["Config4_PRT_Assemb1_1", "Config4_PRT_Assemb1_2",
                              "Config4_PRT_Assemb2_1", "Config4_PRT_Assemb2_2"]  # fmt: skip
    steps = read_steps(tmp_path / "Config4_PRT_amplitude_steps.csv")
    holds = steps.holds()
    assert [h.level for h in holds] == [0.05, 0.1]
    # a hold of 0.3 s is 3000 samples: first and last at 2999 samples apart
    np.testing.assert_allclose([h.duration_s for h in holds], 0.2999, rtol=1e-9)
    np.testing.assert_allclose([h.start_s for h in holds], [0.05, 0.4], rtol=1e-9)
    record = campaign[0]
    assert record.time_s.size == 2 * 3500 and record.sampling_rate_hz == pytest.approx(FS)
    assert record.modes.frequencies_hz[0] == pytest.approx(100.0)
    np.testing.assert_allclose(record.modes.first_bending.real, first_bending_shape(), rtol=1e-6)


def test_ground_truth_sidecar(tmp_path):
    rig = _small_rig(variability={"linear_stiffness": 0.02, "shaker_gain": 0.05}, noise_m_s=1e-4)
    rig.write_campaign(tmp_path, assemblies=2, runs=2, seed=3)
    truth = read_ground_truth(tmp_path)
    assert sorted(truth) == Campaign(tmp_path).names
    one, two = truth["Config1_PRT_Assemb1_1"], truth["Config1_PRT_Assemb1_2"]
    other = truth["Config1_PRT_Assemb2_1"]
    assert one.model == two.model and one.shaker_gain == two.shaker_gain  # same assembly
    assert one.model != other.model and one.shaker_gain != other.shaker_gain
    assert one.noise_m_s == 1e-4 and one.seed == (3, 1, 1) and two.seed == (3, 1, 2)
    sidecar = json.loads((tmp_path / GROUND_TRUTH_FILE).read_text())
    assert sidecar["rig"]["levels_v"] == [0.05, 0.1]
    # the same seed draws the same campaign, wherever it runs
    again = _small_rig(variability={"linear_stiffness": 0.02, "shaker_gain": 0.05}, noise_m_s=1e-4)
    with ThreadPoolExecutor(2) as executor:  # any concurrent.futures-style executor
        again.write_campaign(tmp_path / "again", assemblies=2, runs=2, seed=3, executor=executor)
    assert read_ground_truth(tmp_path / "again") == truth
    np.testing.assert_array_equal(Campaign(tmp_path / "again")[3].data, Campaign(tmp_path)[3].data)


def test_assembly_draws_are_lognormal_with_the_given_spread():
    rig = _small_rig(variability={"linear_stiffness": 0.05, "viscous_damping": 0.2})
    rng = np.random.default_rng(0)
    draws = [rig.draw(rng)[0] for _ in range(2000)]
    log_k = np.log([m.coefficient("linear_stiffness") / rig.model.coefficient("linear_stiffness")
                    for m in draws])  # fmt: skip
    log_c = np.log([m.coefficient("viscous_damping") / 6.0 for m in draws])
    assert log_k.std() == pytest.approx(0.05, rel=0.05) and abs(log_k.mean()) < 0.005
    assert log_c.std() == pytest.approx(0.2, rel=0.05)


def test_bad_rig_settings():
    with pytest.raises(ValueError, match="unknown parameter 'cubic_stiffness'"):
        _small_rig(variability={"cubic_stiffness": 0.1})
    with pytest.raises(ValueError, match="levels_v must be finite voltages > 0"):
        _small_rig(levels_v=(0.1, -1.0))
    with pytest.raises(ValueError, match="unknown rig preset 'nope'"):
        Rig.preset("nope")
    with pytest.raises(ValueError, match=r"pll_options cannot set \['max_hold_s'\]"):
        _small_rig(pll_options={"max_hold_s": 3.0})


@pytest.mark.heavy
@pytest.mark.parametrize("name", sorted(RIG_PRESETS))
def test_presets_show_their_hidden_effects(name):
    preset = RIG_PRESETS[name]
    assert set(preset.model.effects) - set(preset.base_model.effects) == set(preset.hidden_effects)
    amplitudes = np.geomspace(5e-5, 2e-3, 12)
    truth = harmonic_backbone(preset.model, amplitudes, method="multi", harmonics=5)
    base = harmonic_backbone(preset.base_model, amplitudes, method="multi", harmonics=5)
    assert truth.converged.all() and base.converged.all()
    frequency_change = np.abs(truth.frequency_hz / base.frequency_hz - 1).max()
    damping_ratio = (truth.damping_ratio / base.damping_ratio).max()
    shows = frequency_change >= 0.01 or damping_ratio >= 2
    assert shows == bool(preset.hidden_effects), (frequency_change, damping_ratio)
    if name == "trc-like":  # softening, then hardening to about 110 Hz at 2 mm
        f = truth.frequency_hz
        assert f.min() < f[0] - 0.5 and 108 < f[-1] < 112
        assert truth.damping_ratio.min() > 0.001 and truth.damping_ratio.max() < 0.015


@pytest.mark.heavy
def test_rig_round_trip_recovers_the_ground_truth(tmp_path):
    """Disk round trip of a trc-like campaign at 1e-4 m/s RMS vibrometer noise.

    The extracted backbone of every record matches the harmonic-balance backbone
    of that record's drawn ground truth at the extracted amplitudes. The rig
    simulates through the PLL simulator (:mod:`identification.analytical.pll`),
    imported plainly above: a missing core module fails, it does not skip.
    """
    rig = Rig.preset("trc-like", levels=6, hold_s=2.5, noise_m_s=1e-4)
    campaign = rig.write_campaign(tmp_path, assemblies=2, seed=11)
    curves = extract_backbones(campaign)
    truth = read_ground_truth(tmp_path)
    for curve in curves:
        model = truth[curve.label].model
        expected = harmonic_backbone(model, curve.amplitude_m, method="multi", harmonics=5)
        assert curve.amplitude_mm.min() > 0.04 and curve.amplitude_mm.max() > 1.5
        np.testing.assert_allclose(curve.frequency_hz, expected.frequency_hz, rtol=5e-3)
        np.testing.assert_allclose(curve.damping_ratio, expected.damping_ratio, rtol=0.10)
        assert np.abs(curve.phase_error_deg).max() < 5
    assert truth["Config1_PRT_Assemb1"].model != truth["Config1_PRT_Assemb2"].model


@pytest.mark.parametrize("pool", [False, True], ids=["in process", "executor"])
def test_a_failing_record_leaves_the_finished_ones_with_their_truth(tmp_path, monkeypatch, pool):
    rig = _small_rig(variability={"linear_stiffness": 0.02})
    simulate = Rig.simulate

    def fail_on_the_second(self, model, gain, rng, name):
        if name.endswith("Assemb2"):
            raise RuntimeError(f"{name}: diverged")
        return simulate(self, model, gain, rng, name)

    monkeypatch.setattr(Rig, "simulate", fail_on_the_second)
    executor = ThreadPoolExecutor(2) if pool else None
    with pytest.raises(RuntimeError, match="Assemb2: diverged"):
        rig.write_campaign(tmp_path, assemblies=3, seed=1, executor=executor)
    # in process the run stops at the failure; an executor finishes the others
    written = ["Config1_PRT_Assemb1"] + (["Config1_PRT_Assemb3"] if pool else [])
    assert Campaign(tmp_path).names == written
    assert sorted(read_ground_truth(tmp_path)) == written
    sidecar = json.loads((tmp_path / GROUND_TRUTH_FILE).read_text())
    assert sidecar["versions"]["numpy"] == np.__version__


def test_no_test_skips_over_a_missing_module_of_the_project():
    # A core module that cannot be imported must fail the suite, not skip a test.
    own = ("identification", "surrogates", "pm_joint")
    skipped = []
    for path in sorted(Path(__file__).parent.glob("*.py")):
        for node in ast.walk(ast.parse(path.read_text(encoding="utf-8"))):
            if (
                isinstance(node, ast.Call)
                and isinstance(node.func, ast.Attribute)
                and node.func.attr == "importorskip"
                and node.args
                and isinstance(node.args[0], ast.Constant)
                and str(node.args[0].value).split(".")[0] in own
            ):
                skipped.append(f"{path.name}:{node.lineno} {node.args[0].value}")
    assert not skipped, f"importorskip of the project's own modules: {skipped}"
