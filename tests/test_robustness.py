"""Numerical robustness at the integration level: failures are detected and reported.

Unit-level tests elsewhere:

* PLL: a diverging or unstable model gives unlocked (NaN) levels, never an
  exception: ``tests/test_pll.py::test_negative_stiffness_diverges_into_unlocked_levels``,
  ``::test_negative_damping_diverges_into_unlocked_levels``,
  ``::test_batch_marks_only_the_bad_set``, ``::test_unreachable_lock_gives_unlocked_levels``;
  the PLL Op's NaN rows and failure count:
  ``tests/test_forward.py::test_pll_op_gives_nan_for_sets_it_cannot_run``.
* Surrogate outside its box: ``tests/test_surrogates.py::test_parameters_outside_the_box``
  (``extrapolate="raise" | "flag" | "allow"``) and
  ``tests/test_forward.py::test_surrogate_op_gives_nan_outside_its_box``.
* Likelihood of a NaN prediction: ``tests/test_likelihood.py::
  test_nan_prediction_gives_minus_inf_and_is_counted``.

Here the same failures go through :func:`pm_joint.build_model`: the
model's log density at a parameter vector where the forward model fails is
-inf (a sampler rejects the proposal and goes on), the likelihood's
:class:`~pm_joint.distributions.NanCounter` and the forward Op count it, and the
log density at a good vector stays finite. The rig refuses to write a record
of a model that diverges. A long record is read block by block, with progress.
"""

import sys
import warnings
from pathlib import Path

import numpy as np
import pymc as pm
import pytensor.tensor as pt
import pytest

from identification.measurements import text_table
from identification.measurements.backbone import Backbone, BackboneSet
from identification.measurements.records import DATA_COLUMNS, StepSchedule, read_record
from identification.rig import Rig
from pm_joint.distributions import BackboneAmplitude, NanCounter
from pm_joint.forward import SurrogateOp
from pm_joint.inference import build_model
from surrogates.runtime import SurrogateRuntime, SurrogateSpec

sys.path.insert(0, str(Path(__file__).parent))
from oscillators import duffing
from toy_surrogate import amplitude_frequency_weights, write_surrogate

OMEGA = 2 * np.pi * 100.0


def log_density(pm_model, values: dict[str, float]) -> float:
    """The model's log density at physical parameter values (transformed for PyMC)."""
    point = {}
    for rv in pm_model.free_RVs:
        transform = pm_model.rvs_to_transforms[rv]
        value = pt.as_tensor(values[rv.name])
        if transform is not None:
            value = transform.forward(value, *rv.owner.inputs)
        point[pm_model.rvs_to_values[rv].name] = value.eval()
    logp = pm_model.compile_logp(mode="FAST_COMPILE")  # a quick compile: two calls
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", RuntimeWarning)  # NanCounter's report
        return float(logp(point))


def _failures() -> int:
    return NanCounter.counts.get("backbone", 0)


def test_pll_forward_model_that_diverges_gives_minus_inf_and_is_counted(duffing_triplet):
    names = ["linear_stiffness", "viscous_damping"]
    bounds = {"linear_stiffness": (0.5 * OMEGA**2, 1.5 * OMEGA**2), "viscous_damping": (-30, 40)}
    pm_model = build_model(
        duffing(),
        duffing_triplet,
        forward="pll",
        names=names,
        bounds=bounds,
        family="mvn",
        n_grid=5,
    )
    op = pm_model.forward_op
    before, failed = _failures(), op.n_failed
    good = log_density(pm_model, {"linear_stiffness": OMEGA**2, "viscous_damping": 5.0})
    assert np.isfinite(good) and (_failures(), op.n_failed) == (before, failed)
    unstable = {"linear_stiffness": OMEGA**2, "viscous_damping": -25.0}  # negative damping
    assert log_density(pm_model, unstable) == -np.inf
    assert (_failures(), op.n_failed) == (before + 1, failed + 1)


def test_harmonic_forward_model_without_a_backbone_gives_minus_inf_and_is_counted(duffing_triplet):
    names = ["linear_stiffness", "cubic_stiffness"]
    bounds = {"linear_stiffness": (-(OMEGA**2), 2 * OMEGA**2), "cubic_stiffness": (0.0, 2e10)}
    pm_model = build_model(
        duffing(), duffing_triplet, forward="harmonic", names=names, bounds=bounds, family="mvn"
    )
    before = _failures()
    assert np.isfinite(
        log_density(pm_model, {"linear_stiffness": OMEGA**2, "cubic_stiffness": 1e10})
    )
    no_stiffness = {"linear_stiffness": -0.5 * OMEGA**2, "cubic_stiffness": 1e9}
    assert log_density(pm_model, no_stiffness) == -np.inf
    assert _failures() == before + 1


@pytest.fixture(scope="module")
def surrogate(tmp_path_factory):
    """A linear toy surrogate: amplitude c·a_ℓ and frequency k·f_ℓ at nine levels."""
    levels = np.linspace(1.0, 5.0, 9)
    spec = SurrogateSpec(("k", "c"), [[0.9, 1.1], [1.0, 2.0]], levels)
    weights = amplitude_frequency_weights(1e-4 * levels, 100.0 + levels)
    return SurrogateRuntime.load(write_surrogate(tmp_path_factory.mktemp("toy"), spec, weights))


@pytest.fixture(scope="module")
def toy_measured(surrogate):
    """Four backbones the toy surrogate reproduces exactly, at (k, c) inside its box."""
    amplitude, frequency = 1e-4 * surrogate.levels, 100.0 + surrogate.levels
    return BackboneSet(
        Backbone(c * amplitude, k * frequency, np.full(amplitude.size, 0.01), label=f"c{i}")
        for i, (k, c) in enumerate([(0.97, 1.2), (1.0, 1.5), (1.02, 1.4), (0.99, 1.6)])
    )


INSIDE, OUTSIDE = {"k": 1.0, "c": 1.5}, {"k": 1.3, "c": 1.5}


def test_surrogate_priors_beyond_its_box_are_refused(surrogate, toy_measured):
    with pytest.raises(ValueError, match=r"prior bounds of 'k' .* leave the surrogate's training"):
        build_model(
            None, toy_measured, forward="surrogate", surrogate=surrogate,
            bounds={"k": (0.5, 1.5), "c": (1.0, 2.0)},
        )  # fmt: skip


def test_surrogate_outside_its_box_is_flagged_and_gives_minus_inf(surrogate, toy_measured):
    _, flagged = surrogate.predict([list(INSIDE.values()), list(OUTSIDE.values())],
                                   extrapolate="flag")  # fmt: skip
    assert flagged.tolist() == [False, True]
    op = SurrogateOp(surrogate)
    with pm.Model() as pm_model:  # unbounded priors, so a proposal can leave the box
        theta = pt.stack([pm.Normal("k", 1.0, 0.2), pm.Normal("c", 1.5, 0.2)])
        BackboneAmplitude("backbone", op(theta), observed=toy_measured, family="mvn")
    assert np.isfinite(log_density(pm_model, INSIDE)) and op.n_failed == 0
    assert log_density(pm_model, OUTSIDE) == -np.inf
    assert op.n_failed == 1


def test_a_surrogate_inside_its_box_is_not_counted_as_a_failure(surrogate, toy_measured):
    pm_model = build_model(
        None, toy_measured, forward="surrogate", surrogate=surrogate, family="mvn"
    )
    before = _failures()
    assert np.isfinite(log_density(pm_model, INSIDE))
    assert _failures() == before


def test_rig_refuses_a_model_that_diverges(tmp_path):
    rig = Rig(duffing(damping_ratio=-50.0 / (2 * OMEGA)), (0.05, 0.1), hold_s=0.3, ramp_s=0.05)
    with pytest.raises(RuntimeError, match=r"Config1_PRT_Assemb1: .*diverged"):
        rig.write_campaign(tmp_path, assemblies=1)
    assert not any(tmp_path.iterdir())  # nothing half-written


def test_a_long_record_is_read_block_by_block_with_progress(tmp_path, monkeypatch, capsys):
    """Many blocks (4 kB each here) give the numbers numpy's own text reader gives."""
    rng = np.random.default_rng(0)
    data = rng.standard_normal((3000, len(DATA_COLUMNS)))
    data[:, 0] = np.arange(3000) / 1e4
    path = tmp_path / "Config1_PRT_Assemb1"
    np.savetxt(path, data, fmt="%.9e")
    monkeypatch.setattr(text_table, "_BLOCK_BYTES", 4096)
    steps = StepSchedule([0.0, 1.0], [1.0, 1.0])
    record = read_record(path, steps=steps, progress=True)
    np.testing.assert_array_equal(record.data, np.loadtxt(path))
    assert path.stat().st_size > 100 * 4096
    bar = capsys.readouterr().err.replace("\r", "\n").splitlines()
    assert any("100%" in line and path.name in line for line in bar), bar[-3:]
