"""Adding an effect is adding one module: the documented example, followed everywhere.

The new module (``quintic_stiffness``, φ = x⁵) is read from
``docs/adding-an-effect.md`` and dropped into the effects package's path at test
time, in a fresh process with its own numba cache; no other file is touched.
The process reports what the numba kernels, the single- and multi-harmonic
balance, the pytensor backbone graph, the SINDy library and the rig's lab-hidden
presets make of it, and this test checks that against independent expectations:
the rig's preset that hides it, and the closed-form
single-harmonic backbone ω² = k + ⅝q a⁴, and the exact period and fundamental
amplitude of the free oscillation ẍ + kx + qx⁵ = 0 (energy quadrature and an
ODE solve with the force written here, not taken from the module).
"""

from __future__ import annotations

import json
import os
import re
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest
from scipy import integrate

ROOT = Path(__file__).parents[1]
GUIDE = ROOT / "docs" / "adding-an-effect.md"
K = (2 * np.pi * 100.0) ** 2  # 1/s²
Q = 0.3 * K / 1e-3**4  # x⁵ coefficient: 30 % of the linear force at 1 mm
PEAKS_M = np.array([2e-4, 6e-4, 1e-3, 1.3e-3])  # displacement extremes of the free orbits

CHILD = r"""
import importlib.util, json, sys
import numpy as np

given = json.loads(sys.argv[1])
K, Q, amplitudes = given["K"], given["Q"], np.array(given["amplitudes_m"])
spec = importlib.util.find_spec("identification.effects")
spec.submodule_search_locations.append(given["folder"])  # as if the file were in the package
effects = importlib.util.module_from_spec(spec)
sys.modules[spec.name] = effects
spec.loader.exec_module(effects)

import pytensor.tensor as pt
import pytest
from identification.analytical.harmonic import backbone, default_time_samples
from identification.model import JointModel
from identification.sindy import PAPER_LIBRARY, LibraryTerm
from pm_joint.forward import describing_graph, harmonic_backbone_graph
from identification.rig import presets

effect = effects.CATALOGUE["quintic_stiffness"]
# The guide's test of the new effect, run as the test file would.
guide_test = {"CATALOGUE": effects.CATALOGUE, "pytest": pytest}
exec(open(given["guide_test"], encoding="utf-8").read(), guide_test)
for name in [n for n in guide_test if n.startswith("test_")]:
    guide_test[name]()
model = JointModel({"linear_stiffness": K, "quintic_stiffness": Q})
x = np.array([-1.3e-3, 2e-4, 9e-4])
indices, coefficients, shapes = model.kernel_arrays()
single = backbone(model, amplitudes, method="single")
multi = backbone(model, amplitudes, method="multi", harmonics=9)
theta = pt.vector("theta")
graph = harmonic_backbone_graph(model, theta, ["quintic_stiffness"], amplitudes)
k_graph, _ = describing_graph("quintic_stiffness", amplitudes, 600.0)
preset = presets.RIG_PRESETS[presets.lab_hidden_scenario("quintic_stiffness")]
print(json.dumps({
    "names": list(effects.CATALOGUE),
    "index": effect.index,
    "dispatched": [effects.memoryless_force(effect.index, xi, 0.3, 0.0, 0.0) for xi in x],
    "restoring": [effects.restoring_force(indices, coefficients, shapes, xi, 0.3) for xi in x],
    "feature": effect.feature(x, np.zeros(3)).tolist(),
    "n_time": default_time_samples(model, 9),
    "single_hz": single.frequency_hz.tolist(),
    "multi_hz": multi.frequency_hz.tolist(),
    "multi_converged": multi.converged.tolist(),
    "graph_hz": graph.eval({theta: [Q]}, mode="FAST_COMPILE")[:, 1].tolist(),
    "describing_graph": k_graph.eval(mode="FAST_COMPILE").tolist(),
    "in_paper_library": "quintic_stiffness" in PAPER_LIBRARY,
    "sindy_column": LibraryTerm("quintic_stiffness").feature(x, np.zeros(3)).tolist(),
    "guide_tests": [n for n in guide_test if n.startswith("test_")],
    "lab_hidden": list(presets.LAB_HIDDEN_SCENARIOS),
    "preset": {
        "hidden_effects": list(preset.hidden_effects),
        "truth": preset.model.parameters,
        "base": preset.base_model.parameters,
        "description": preset.description,
        "lab": sorted(preset.lab),
    },
    "k0": preset.base_model.linear_stiffness,
    "key_channel": effect.hidden_scenario.key_channel,
}))
"""


def guide_addition(path: str) -> str:
    """What the diff of ``docs/adding-an-effect.md`` adds to ``path``."""
    guide = GUIDE.read_text(encoding="utf-8")
    block = re.search(
        rf"```diff\n--- [^\n]*\n\+\+\+ b/{re.escape(path)}\n@@ -\d+,0 \+\d+,(\d+) @@\n(.*?)```",
        guide,
        re.DOTALL,
    )
    assert block, f"{GUIDE.name} lost the part of its example that adds to {path}"
    lines = block.group(2).splitlines()
    assert all(line.startswith("+") for line in lines)
    assert int(block.group(1)) == len(lines), f"the hunk header of {path} miscounts its lines"
    return "\n".join(line[1:] for line in lines) + "\n"


def free_orbit(peak_m: float) -> tuple[float, float]:
    """Period (s) and fundamental cosine amplitude (m) of ẍ + Kx + Qx⁵ = 0 from x = peak."""

    def energy_gap(x):
        return 0.5 * K * (peak_m**2 - x**2) + Q * (peak_m**6 - x**6) / 6.0

    # x = peak·sin φ removes the turning-point singularity of ∫dx/√(2(V(peak) − V(x))).
    period = (
        4
        * integrate.quad(
            lambda phi: peak_m * np.cos(phi) / np.sqrt(2 * energy_gap(peak_m * np.sin(phi))),
            0,
            np.pi / 2,
            epsabs=0,
            epsrel=1e-13,
        )[0]
    )
    orbit = integrate.solve_ivp(
        lambda t, y: [y[1], -K * y[0] - Q * y[0] ** 5],
        (0, period),
        [peak_m, 0.0],
        method="DOP853",
        rtol=1e-13,
        atol=1e-20,
        dense_output=True,
    )
    t = np.linspace(0, period, 4096, endpoint=False)  # periodic: the plain mean is spectral
    fundamental = 2 * np.mean(orbit.sol(t)[0] * np.cos(2 * np.pi * t / period))
    return period, fundamental


@pytest.fixture(scope="module")
def followed(tmp_path_factory):
    folder = tmp_path_factory.mktemp("effects")
    module = guide_addition("identification/effects/quintic_stiffness.py")
    (folder / "quintic_stiffness.py").write_text(module, encoding="utf-8")
    guide_test = tmp_path_factory.mktemp("tests") / "guide_test.py"
    guide_test.write_text(guide_addition("tests/test_effects.py"), "utf-8")
    orbits = [free_orbit(peak) for peak in PEAKS_M]
    amplitudes = [a for _, a in orbits]
    env = dict(os.environ, NUMBA_CACHE_DIR=str(tmp_path_factory.mktemp("numba_cache")))
    given = {
        "folder": str(folder),
        "guide_test": str(guide_test),
        "amplitudes_m": amplitudes,
        "K": K,
        "Q": Q,
    }
    result = subprocess.run(
        [sys.executable, "-c", CHILD, json.dumps(given)],
        capture_output=True,
        text=True,
        cwd=ROOT,
        env=env,
        check=False,
    )
    assert result.returncode == 0, result.stderr
    report = json.loads(result.stdout.strip().splitlines()[-1])
    return report, np.array(amplitudes), np.array([1 / period for period, _ in orbits])


def test_the_new_module_joins_the_catalogue_and_the_numba_kernels(followed):
    report, _, _ = followed
    assert report["names"][-1] == "quintic_stiffness"
    assert report["index"] == len(report["names"]) - 1 == 16
    x = np.array([-1.3e-3, 2e-4, 9e-4])
    np.testing.assert_allclose(report["dispatched"], x**5, rtol=1e-15)
    np.testing.assert_allclose(report["feature"], x**5, rtol=1e-15)
    np.testing.assert_allclose(report["restoring"], K * x + Q * x**5, rtol=1e-14)
    assert report["in_paper_library"]
    assert report["guide_tests"]  # the guide's own test of the effect ran and passed
    np.testing.assert_allclose(report["sindy_column"], x**5, rtol=1e-15)


def test_both_harmonic_balances_and_the_graph_give_the_quintic_backbone(followed):
    report, amplitudes, exact_hz = followed
    single_hz = np.sqrt(K + 0.625 * Q * amplitudes**4) / (2 * np.pi)
    np.testing.assert_allclose(report["single_hz"], single_hz, rtol=1e-12)
    np.testing.assert_allclose(report["graph_hz"], single_hz, rtol=1e-12)
    np.testing.assert_allclose(report["describing_graph"], 0.625 * amplitudes**4, rtol=1e-14)
    # Not a polynomial of degree ≤ 3 (x⁵ of H harmonics reaches harmonic 5H): the fine AFT grid.
    assert report["n_time"] == max(2 * 16 * 9, 128)
    assert all(report["multi_converged"])
    np.testing.assert_allclose(report["multi_hz"], exact_hz, rtol=1e-9)
    # The single-harmonic balance misses the higher harmonics: the multi one must do better.
    assert np.all(np.abs(single_hz - exact_hz) > 100 * np.abs(report["multi_hz"] - exact_hz))


def test_the_new_module_joins_the_hidden_effect_study(followed):
    report, _, _ = followed
    # The rig builds a lab preset hiding it, last (catalogue order), from its own scenario.
    assert report["lab_hidden"][-1] == "lab-hidden-quintic-stiffness"
    preset = report["preset"]
    assert preset["hidden_effects"] == ["quintic_stiffness"]
    assert preset["truth"]["quintic_stiffness"] == pytest.approx(1e10 * report["k0"], rel=1e-15)
    assert "quintic_stiffness" not in preset["base"]
    assert set(preset["truth"]) - set(preset["base"]) == {"quintic_stiffness"}
    assert preset["description"].startswith("x⁵ hardens by about 5 % at 2 mm")
    assert "shaker" in preset["lab"]  # under the lab conditions of every hidden-effect preset
    # The studies judge it on the channel it names, the frequency: hardening of about 5 %.
    assert report["key_channel"] == "frequency_hz"
    # x⁵ stiffens nothing at rest: the truth keeps the base model's 101 Hz stiffness.
    assert (
        preset["truth"]["linear_stiffness"]
        == report["k0"]
        == pytest.approx((2 * np.pi * 101.0) ** 2, rel=1e-12)
    )
