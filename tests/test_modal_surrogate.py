"""The surrogate of an N-mode model (#27 item 4): its data, its networks, the updating on it.

* **The data.** One mode's dataset on a two-mode model whose second mode neither moves the
  joint nor feels the base: mode 1 is a Duffing oscillator, whose single-harmonic backbone
  is closed form (``ω² = ω₁² + ¾ k₃ a²``, the viscous ratio ``ζ₁ω₁/ω``, the hold's drive
  ``2ζ₁ω₁ω a/Γ``), with no energy in the other mode. Softening, the drive ``∝ aω(a)`` peaks
  at ``a² = 2ω₁²/(3|k₃|)`` (a test stepping up has passed what lies beyond) and the
  backbone ends where ``ω²`` reaches 0: the mask's reasons there.
* **The surrogates and the updating.** ``pm-joint train-surrogate`` with a ModalModel on
  per-mode backbones of a known population (the multi-harmonic Newton balance of
  :func:`identification.multimode.phase_resonance`, 7 harmonics: other equations than the
  single-harmonic balance the surrogates learn), then ``pm-joint update --surrogate``: the
  networks beat the mean curve, the index refuses another model, and the population
  range covers the population's median frequencies as the harmonic-balance updating's
  test asks of it.
* **The hierarchical graph** reads each mode's network linearly between its grid points.
"""

from __future__ import annotations

import json
import math

import numpy as np
import pytensor.tensor as pt
import pytest
from test_modal_update import (
    N_ASSEMBLIES,
    TEMPLATE_OFFSET,
    _population_table,
    _truth,
    assert_covers_population_frequencies,
)

from identification.multimode.model import JointElement, ModalModel, Mode
from pm_joint.cli import EXIT_NOT_CONVERGED, main
from pm_joint.inference import load_posterior
from pm_joint.modal_surrogate import mode_evaluation
from surrogates.dataset.modal import MODAL_CHANNELS, generate_modal_dataset
from surrogates.grid import MASK_REASONS
from surrogates.modal import ModalSurrogate

OMEGA1 = 2 * np.pi * 100.0
ZETA1 = 0.004


def _duffing(k3: float) -> ModalModel:
    """Mode 1 a Duffing oscillator; mode 2 off the joint and not driven by the base."""
    return ModalModel(
        modes=(Mode(100.0, ZETA1, 1.0), Mode(230.0, 0.003, 0.0)),
        joint_shapes=((1.0, 0.0),),
        elements=(JointElement("cubic_stiffness", k3),),
    )


@pytest.mark.parametrize("k3", [4e10, -4e10])
def test_a_modes_dataset_is_the_closed_form_duffing_backbone(k3):
    model = _duffing(k3)
    names = ["mode1.frequency_hz", "joint1.cubic_stiffness"]
    box = np.array([[99.0, 101.0], sorted([0.9 * k3, 1.1 * k3])])
    grid = np.geomspace(1e-5, 5e-3, 30)
    data = generate_modal_dataset(
        mode_evaluation(model, names, grid, 1), names, box, grid, n=20, seed=3
    )
    assert data.spec.channels == MODAL_CHANNELS
    f1, k = data.X[:, :1], data.X[:, 1:]
    omega_squared = (2 * np.pi * f1) ** 2 + 0.75 * k * grid**2
    exists = omega_squared > 0
    omega = np.sqrt(np.where(exists, omega_squared, np.nan))
    drive = 2 * ZETA1 * (2 * np.pi * f1) * omega * grid
    # A test stepping up holds a point only while the drive still rises.
    rising = np.concatenate([np.ones((20, 1), bool), np.diff(np.nan_to_num(drive), axis=1) > 0], 1)
    held = exists & np.logical_and.accumulate(rising, axis=1)
    values = data.Y
    mask = values[..., MODAL_CHANNELS.index("has_backbone")] == 1
    np.testing.assert_array_equal(mask, held)
    expected = {
        "frequency_hz": omega / (2 * np.pi),
        "damping_ratio": ZETA1 * 2 * np.pi * f1 / omega,
        "base_acceleration_m_s2": drive,
        "other_modes_energy_share": np.zeros_like(drive),
    }
    for channel, value in expected.items():
        got = values[..., MODAL_CHANNELS.index(channel)]
        np.testing.assert_allclose(got[held], value[held], rtol=1e-9, atol=1e-12)
        assert np.all(got[~held] == 0)
    counts = data.provenance["counts"]["masked_entries"]
    assert set(counts) == set(MASK_REASONS)
    if k3 > 0:
        assert held.all()
    else:
        # Softening: the drive peaks, then the backbone ends (ω² ≤ 0) within the grid.
        assert counts["passed"] > 0 and counts["no_solution"] > 0
        assert counts["no_solution"] == int((~exists).sum())


@pytest.fixture(scope="module")
def small_surrogate(tmp_path_factory):
    """A quickly trained N-mode surrogate of the test population's model (its values are
    not what these tests check) and the population's per-mode backbones."""
    from pm_joint.inference.modal import read_mode_backbones
    from pm_joint.modal_surrogate import train_modal_surrogate

    measured = read_mode_backbones(_population_table())
    folder = tmp_path_factory.mktemp("modal_surrogate")
    surrogate = train_modal_surrogate(
        _truth(), measured, folder, n_curves=60, max_epochs=3, progress=False
    )
    return surrogate, measured


def test_the_hierarchical_graph_reads_a_modes_network_between_its_grid_points(small_surrogate):
    from pm_joint.forward import SurrogateOp
    from pm_joint.inference.modal import _mode_graph, _ModePoints

    surrogate, measured = small_surrogate
    runtime = surrogate.runtimes[2]
    grid = runtime.amplitudes_m
    owner = np.zeros(len(measured[2]), dtype=int)
    part = _ModePoints.read(measured[2], 2, owner, 7, (grid[0], grid[-1]))
    names = list(surrogate.parameter_names)
    theta = np.array([[np.mean(surrogate.bounds[n]) for n in names]] * 2)
    theta[1] *= 1.001
    graph = _mode_graph(_truth(), pt.as_tensor(theta), names, part, runtime).eval()
    on_grid = SurrogateOp(runtime, names)(pt.as_tensor(theta)).eval()
    for row in range(2):
        for column in (1, 2):
            expected = np.interp(part.grid, grid, on_grid[row, :, column])
            np.testing.assert_allclose(graph[row, :, column], expected, rtol=1e-5)


def test_the_hierarchical_model_on_a_surrogate_walls_in_its_training_box(small_surrogate):
    from pm_joint.inference.modal import WALL_WIDTH, modal_hierarchical_model

    surrogate, measured = small_surrogate
    pm_model = modal_hierarchical_model(_truth(), measured, n_levels=4, surrogate=surrogate)
    names = list(pm_model.coords["parameter"])
    wall = pm_model.compile_fn(pm_model["training_box_wall"], inputs=[pm_model["theta"]])
    box = np.array([surrogate.bounds[n] for n in names])
    inside = np.tile(box.mean(axis=1), (N_ASSEMBLIES, 1))
    assert wall({"theta": inside}) == 0
    # One assembly's first parameter 3 wall widths above the box: -(3²)/2.
    beyond = inside.copy()
    beyond[1, 0] = box[0, 1] + 3 * WALL_WIDTH * (box[0, 1] - box[0, 0])
    np.testing.assert_allclose(wall({"theta": beyond}), -4.5)


@pytest.mark.heavy
def test_an_n_mode_surrogate_updates_on_the_independent_balances_backbones(tmp_path):
    csv = tmp_path / "backbones.csv"
    _population_table().to_csv(csv, index=False)
    truth = _truth()
    offset = [
        Mode(TEMPLATE_OFFSET * m.frequency_hz, m.damping_ratio, m.participation)
        for m in truth.modes
    ]
    template = ModalModel(tuple(offset), truth.joint_shapes, truth.elements, name=truth.name)
    model = template.to_json(tmp_path / "modal.json")
    folder = tmp_path / "surrogate"
    assert main(["train-surrogate", str(csv), "--model", str(model), "--out", str(folder),
                 "--curves", "300", "--epochs", "150"]) in (0, None)  # fmt: skip
    surrogate = ModalSurrogate.load(folder)
    assert surrogate.modes == [1, 2]
    for mode, runtime in surrogate.runtimes.items():
        ratios = runtime.metadata["test"]["analytical"]["ratios"]
        # The networks learnt the parameters' effect: a fifth of the mean curve's error.
        assert ratios["frequency_hz"]["to_mean_curve"] < 0.2, (mode, ratios["frequency_hz"])
    with pytest.raises(ValueError, match="content hash"):
        surrogate.check_model(truth.content_sha256)
    out = tmp_path / "posterior.nc"
    update = ["update", str(csv), "--model", str(model), "--surrogate", str(folder)]
    code = main([*update, "--out", str(out), "--draws", "6000", "--tune", "2000", "--seed", "1"])
    assert code in (0, EXIT_NOT_CONVERGED)
    idata = load_posterior(out)
    assert json.loads(idata.attrs["pm_joint_metadata"])["forward"] == "modal_surrogate"
    posterior = idata["posterior"]
    assert_covers_population_frequencies(posterior, truth)
    assert math.isfinite(float(np.median(posterior["joint1.cubic_stiffness"].values)))
