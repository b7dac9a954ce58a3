"""Updating an N-mode ModalModel on per-mode backbones (#27 item 5).

* Reading a ``--modes N`` table mode by mode, the default parameters and prior box.
* ``pm-joint update --model MODAL.json`` on per-mode backbones of a known two-mode
  population: the measured curves are the multi-harmonic phase-resonance backbones of the
  library's Newton balance (7 harmonics, :func:`identification.multimode.phase_resonance`:
  other equations than the single-harmonic pytensor graph the likelihood runs on) of
  assemblies whose linear frequencies scatter lognormally by 0.3 % (damping ratios by 5 %);
  the template starts
  1 % off. The posterior's population range must cover the population's median
  frequencies (the truth) within its own 99 % interval widened by one assembly scatter.
* The rig (slow): free decays of the two-mode virtual TRC, ``identify --modes 2``, the
  two-mode updating; the truth's small-amplitude modal frequencies (the rig's ground
  truth per assembly, :func:`identification.rig.modal_rig.small_amplitude_frequencies_hz`)
  inside the posterior's 99 % interval widened by the rig's assembly scatter (the preset's
  lognormal 0.25 % on each mode's frequency, the physics' tolerance, not the code's).
"""

from __future__ import annotations

import dataclasses
import json
import math

import numpy as np
import pandas as pd
import pytest

from identification.multimode import ModalModel, phase_resonance
from identification.multimode.model import JointElement, Mode
from identification.multimode.solve import HarmonicSettings
from pm_joint.cli import EXIT_NOT_CONVERGED, main
from pm_joint.inference import load_posterior
from pm_joint.inference.modal import (
    assembly_labels,
    modal_bounds,
    modal_update_names,
    read_mode_backbones,
)

#: The synthetic population: linear frequencies of each assembly drawn lognormally (and the
#: damping ratios, by 5 %, as on the two-mode rig: a channel without scatter has no density).
SCATTER = 0.003
N_ASSEMBLIES = 5
TEMPLATE_OFFSET = 1.01


def _truth() -> ModalModel:
    """Two modes (100 Hz and 230 Hz, no internal resonance), a hardening joint moving with both."""
    return ModalModel(
        modes=(Mode(100.0, 0.004, 1.0), Mode(230.0, 0.003, 1.0)),
        joint_shapes=((1.0, 0.5),),
        elements=(JointElement("cubic_stiffness", 4e10),),
        name="test two modes",
    )


def _population_table(seed: int = 0) -> pd.DataFrame:
    """Per-mode backbones of drawn assemblies (the ``--modes N`` decay table's columns)."""
    rng = np.random.default_rng(seed)
    truth = _truth()
    rows = []
    for i in range(N_ASSEMBLIES):
        modes = tuple(
            dataclasses.replace(m, frequency_hz=m.frequency_hz * math.exp(SCATTER * rng.normal()),
                                damping_ratio=m.damping_ratio * math.exp(0.05 * rng.normal()))
            for m in truth.modes
        )  # fmt: skip
        drawn = dataclasses.replace(truth, modes=modes)
        for mode, top in ((1, 2e-3), (2, 1e-3)):
            amplitude = np.geomspace(2e-5, top, 25)
            solution = phase_resonance(drawn, amplitude, mode=mode,
                                       settings=HarmonicSettings(harmonics=7))  # fmt: skip
            assert solution.converged.all()
            for a, f, z in zip(amplitude, solution.frequency_hz, solution.damping_ratio,
                               strict=True):  # fmt: skip
                rows.append({"curve": f"A{i + 1} mode {mode}", "mode": mode,
                             "amplitude_mm": 1e3 * a, "frequency_hz": f,
                             "damping_ratio": z})  # fmt: skip
    return pd.DataFrame(rows)


def test_a_modes_table_is_read_mode_by_mode_and_a_one_mode_table_refused(tmp_path):
    table = _population_table()
    # A PLL modal table: a mode's rows where the record did not lock it carry no frequency.
    table.loc[len(table)] = {"curve": "A1 mode 2", "mode": 2, "amplitude_mm": 0.5,
                             "frequency_hz": np.nan, "damping_ratio": np.nan}  # fmt: skip
    measured = read_mode_backbones(table)
    assert sorted(measured) == [1, 2]
    assert [len(b) for b in measured[2]] == [25] * N_ASSEMBLIES
    assemblies, owner = assembly_labels(measured)
    assert assemblies == [f"A{i + 1}" for i in range(N_ASSEMBLIES)]
    assert owner[2].tolist() == list(range(N_ASSEMBLIES))
    with pytest.raises(ValueError, match="no 'mode' column"):
        read_mode_backbones(table.drop(columns="mode"))


def test_the_updated_parameters_and_their_box():
    model = _truth()
    names = modal_update_names(model)
    assert names == ["mode1.frequency_hz", "mode1.damping_ratio", "mode2.frequency_hz",
                     "mode2.damping_ratio", "joint1.cubic_stiffness"]  # fmt: skip
    bounds = modal_bounds(model, names)
    low, high = bounds["mode2.frequency_hz"]
    assert low < 230.0 < high and high / low < 1.05  # well inside the gap to any 1:2 resonance
    assert bounds["mode1.damping_ratio"][0] < 0.004 < bounds["mode1.damping_ratio"][1]
    # A damping ratio identified 5 times too high: the factor-3 box misses the truth, the box
    # that takes in the measured damping ratios holds it (and the other bounds are the same).
    off = dataclasses.replace(
        model, modes=(dataclasses.replace(model.modes[0], damping_ratio=0.02), model.modes[1])
    )
    measured = read_mode_backbones(_population_table())
    narrow, wide = modal_bounds(off, names), modal_bounds(off, names, measured)
    assert not narrow["mode1.damping_ratio"][0] < 0.004
    assert wide["mode1.damping_ratio"][0] < 0.004 < wide["mode1.damping_ratio"][1]
    lowest = min(b.damping_ratio.min() for b in measured[1])
    assert wide["mode1.damping_ratio"][0] == pytest.approx(lowest)
    assert {k: v for k, v in wide.items() if k != "mode1.damping_ratio"} == {
        k: v for k, v in narrow.items() if k != "mode1.damping_ratio"
    }


# Slow: the N-mode graph's scan compiles for minutes on a cold cache (CI's).
@pytest.mark.slow
def test_update_with_a_modal_model_covers_the_populations_frequencies(tmp_path):
    csv = tmp_path / "backbones.csv"
    _population_table().to_csv(csv, index=False)
    truth = _truth()
    offset = [dataclasses.replace(m, frequency_hz=TEMPLATE_OFFSET * m.frequency_hz)
              for m in truth.modes]  # fmt: skip
    template = dataclasses.replace(truth, modes=tuple(offset))
    model = template.to_json(tmp_path / "modal.json")
    out = tmp_path / "posterior.nc"
    code = main(["update", str(csv), "--model", str(model), "--out", str(out),
                 "--draws", "2000", "--tune", "1000", "--seed", "1"])  # fmt: skip
    assert code in (0, EXIT_NOT_CONVERGED)
    idata = load_posterior(out)
    assert json.loads(idata.attrs["modes"]) == [1, 2]
    assert json.loads(idata.attrs["pm_joint_metadata"])["forward"] == "modal_harmonic"
    assert "convergence" in idata.attrs
    assert_covers_population_frequencies(idata["posterior"], truth)


def assert_covers_population_frequencies(posterior, truth: ModalModel) -> None:
    """Each mode's frequency of the population inside the posterior's 99 % interval widened
    by one assembly scatter, and the median moved from the template towards it."""
    for m, spec in enumerate(truth.modes, start=1):
        draws = posterior[f"mode{m}.frequency_hz"].values.ravel()
        low, high = np.quantile(draws, [0.005, 0.995])
        pad = SCATTER * spec.frequency_hz
        assert low - pad <= spec.frequency_hz <= high + pad, (m, low, high)
        # The data moved it: the posterior's median is nearer the truth than the template.
        median = np.median(draws)
        assert abs(median - spec.frequency_hz) < abs(median - TEMPLATE_OFFSET * spec.frequency_hz)


@pytest.mark.slow
def test_two_mode_updating_on_rig_decays_recovers_the_modal_frequencies(tmp_path):
    from identification.rig.modal_rig import (
        ModalRig,
        read_modal_ground_truth,
        small_amplitude_frequencies_hz,
    )
    from identification.rig.presets import MODAL_RIG_PRESETS

    records = tmp_path / "records"
    ModalRig.preset("two-mode", test="free-decay").write_campaign(records, assemblies=3, seed=0)
    decay = ["--test", "free-decay"]
    assert main(["backbones", str(records), *decay, "--modes", "2"]) in (0, None)
    model = tmp_path / "two.json"
    identify = ["identify", str(records), *decay, "--modes", "2", "--out", str(model)]
    assert main(identify) in (0, None)
    out = tmp_path / "posterior.nc"
    code = main(["update", str(records), *decay, "--model", str(model), "--out", str(out),
                 "--draws", "10000", "--tune", "3000"])  # fmt: skip
    assert code in (0, EXIT_NOT_CONVERGED)
    posterior = load_posterior(out)["posterior"]
    truth = read_modal_ground_truth(records)
    frequencies = np.array([small_amplitude_frequencies_hz(t.model) for t in truth.values()])
    scatter = MODAL_RIG_PRESETS["two-mode"].variability
    for m in (1, 2):
        draws = posterior[f"mode{m}.frequency_hz"].values.ravel()
        low, high = np.quantile(draws, [0.005, 0.995])
        centre = frequencies[:, m - 1].mean()
        pad = scatter[f"mode{m}.frequency_hz"] * centre
        assert low - pad <= centre <= high + pad, (m, low, high, centre)


def test_the_hierarchical_model_shares_each_assemblys_parameters_across_its_modes():
    from pm_joint.inference.modal import modal_hierarchical_model

    measured = read_mode_backbones(_population_table())
    pm_model = modal_hierarchical_model(_truth(), measured, n_levels=6)
    assert pm_model.coords["curve"] == tuple(f"A{i + 1}" for i in range(N_ASSEMBLIES))
    assert pm_model.coords["group"] == ("mode 1", "mode 2")
    curve = pm_model["curve_index"].get_value()
    mode = pm_model["mode_index"].get_value()
    # Every assembly reaches the 6 levels of each mode (its curve spans the mode's range).
    assert np.bincount(curve).tolist() == [12] * N_ASSEMBLIES
    assert np.bincount(mode).tolist() == [6 * N_ASSEMBLIES] * 2
    assert [rv.name for rv in pm_model.observed_RVs] == ["frequency_hz", "damping_ratio"]
    # A noise and a slope per mode and channel: a frequency noise in Hz of one mode says
    # nothing of another's.
    assert pm_model.named_vars_to_dims["frequency_hz_noise"] == ("group",)
    assert pm_model.named_vars_to_dims["damping_ratio_noise_slope"] == ("group",)
