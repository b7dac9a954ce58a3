"""The ``pm-joint`` command, subcommand by subcommand.

The campaign folder here is written by plain Python string formatting in the TRC
layout (as another program would), with the analytical steady state of linear
oscillators at phase resonance, so that the expected backbones and model are known
exactly. A campaign written by ``pm-joint rig`` through every stage is in
tests/test_cli_rig_campaign.py, the demo in tests/test_demo.py.
"""

import argparse
import json
import re
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest
from scipy.integrate import cumulative_trapezoid

from identification.model import JointModel
from pm_joint import cli
from pm_joint.cli import build_parser, main

FS = 10_000.0
ZETA = 0.005
LEVELS = [0.5, 0.8, 1.3, 2.0, 3.0, 4.5]  # shaker volts
SHAPE = np.sin(np.pi * np.linspace(0.15, 0.85, 5))[:, None] * np.array([0.9, 1.0, 0.9])


def _write_hand_made_record(folder: Path, name: str, f0: float, levels: list[float]) -> None:
    """A linear oscillator ẍ + 2ζω₀ẋ + ω₀²x = −a_base, stepped along its backbone.

    The relative displacement is x = a(t) cos ω₀t with a(t) held at the resonant
    amplitude of each level and moved between levels by raised-cosine ramps;
    the base acceleration is what the equation of motion needs for exactly that
    motion, so the record is consistent everywhere, ramps included.
    """
    omega = 2 * np.pi * f0
    hold_s, ramp_s = 1.0, 0.1
    t = np.arange(int(len(levels) * hold_s * FS)) / FS
    target = 2.0 * np.asarray(levels) / (2 * ZETA * omega**2)  # gain 2 m/s² per volt
    amplitude = np.full_like(t, target[0])
    rate = np.zeros_like(t)
    curvature = np.zeros_like(t)
    for k in range(1, len(levels)):
        s = np.clip((t - k * hold_s) / ramp_s, 0, 1)
        jump = target[k] - target[k - 1]
        amplitude += jump * 0.5 * (1 - np.cos(np.pi * s))
        inside = (s > 0) & (s < 1)
        rate += np.where(inside, jump * 0.5 * np.pi / ramp_s * np.sin(np.pi * s), 0)
        curvature += np.where(inside, jump * 0.5 * (np.pi / ramp_s) ** 2 * np.cos(np.pi * s), 0)
    sin, cos = np.sin(omega * t), np.cos(omega * t)
    relative_velocity = rate * cos - amplitude * omega * sin
    base_acceleration = (2 * ZETA * omega**2 * amplitude + 2 * omega * rate) * sin - (
        curvature + 2 * ZETA * omega * rate
    ) * cos
    base_velocity = -(2 * ZETA * omega * target[0]) + cumulative_trapezoid(
        base_acceleration, t, initial=0
    )
    shape = SHAPE.ravel() / SHAPE.ravel()[7]
    panel = shape[:, None] * relative_velocity + base_velocity
    phase = np.degrees(omega * t) % 360
    rows = np.column_stack([t, panel.T, base_velocity, base_velocity, np.full_like(t, f0), phase])
    lines = [",".join(f"{v:.9e}" for v in row) for row in rows]
    (folder / f"{name}.csv").write_text("\n".join(lines) + "\n")


@pytest.fixture(scope="module")
def hand_made(tmp_path_factory):
    folder = tmp_path_factory.mktemp("hand_made")
    steps = []
    for i, value in enumerate(LEVELS):  # holds after 0.1 s ramps
        steps += [f"{i * 1.0 + (0.1 if i else 0):.6f} {value}", f"{i + 1.0 - 1e-4:.6f} {value}"]
    (folder / "Config7_PRT_amplitude_steps.txt").write_text("\n".join(steps) + "\n")
    for k, f0 in enumerate([99.5, 100.0, 100.5], start=1):
        _write_hand_made_record(folder, f"Config7_PRT_Assemb{k}", f0, LEVELS)
    return folder


def test_every_subcommand_has_help(capsys):
    # The module runs as the command (one fresh process: each costs seconds of imports) ...
    done = subprocess.run([sys.executable, "-m", "pm_joint.cli", "effects", "--help"],
                          capture_output=True, text=True)  # fmt: skip
    assert done.returncode == 0, done.stderr
    assert "usage: pm-joint effects" in done.stdout
    # ... and every subcommand's help is printed and exits 0.
    for command in ("effects", "model", "rig", "backbones", "identify", "train-surrogate",
                    "criticize", "update", "report", "demo"):  # fmt: skip
        with pytest.raises(SystemExit) as info:
            main([command, "--help"])
        assert info.value.code == 0, command
        assert f"usage: pm-joint {command}" in capsys.readouterr().out


@pytest.mark.parametrize(
    ("argv", "reason"),
    [
        (["backbones", "/no/such/folder"], "campaign folder not found"),
        (["backbones", "."], "no TRC data files"),
        (["model", "--json", "/no/such/model.json"], "model.json"),
        (["update", "/no/such/folder", "--forward", "surrogate", "--out", "p.nc"], "--surrogate"),
    ],
)
def test_bad_input_exits_with_a_one_line_reason(argv, reason, capsys, tmp_path, monkeypatch):
    monkeypatch.chdir(tmp_path)  # "." is an empty folder
    assert main(argv) == 2
    err = capsys.readouterr().err.strip()
    assert len(err.splitlines()) == 1 and reason in err


def test_unknown_effect_is_refused(hand_made, capsys):
    with pytest.raises(SystemExit) as info:
        main(["identify", str(hand_made), "--effects", "linear_stiffness,nope", "--out", "m.json"])
    assert info.value.code == 2
    assert "unknown effect 'nope'" in capsys.readouterr().err


@pytest.mark.heavy
def test_hand_made_records_give_the_known_backbones_and_model(hand_made, tmp_path, capsys):
    csv = tmp_path / "backbones.csv"
    assert main(["backbones", str(hand_made), "--out", str(csv)]) == 0
    said = capsys.readouterr().out  # how the points were measured, counted
    assert "18 point(s) in 3 curve(s)" in said
    assert "0 of 18 point(s) more than ±5° from phase resonance" in said
    assert "0 of 18 point(s) not settled" in said and "0 sample(s) dropped as spikes" in said
    table = __import__("pandas").read_csv(csv)
    assert len(table) == 18
    for (_, curve), f0 in zip(table.groupby("curve"), [99.5, 100.0, 100.5], strict=True):
        np.testing.assert_allclose(curve["frequency_hz"], f0, rtol=1e-6)
        # the record's base velocity comes from the trapezoid rule: (ωΔt)²/12 ≈ 3e-4
        np.testing.assert_allclose(curve["damping_ratio"], ZETA, rtol=1e-3)

    model_path = tmp_path / "model.json"
    argv = [
        "identify",
        str(hand_made),
        "--effects",
        "linear_stiffness,viscous_damping,cubic_stiffness",
    ]
    assert main([*argv, "--out", str(model_path), "--records", "1"]) == 0
    model = JointModel.from_json(model_path)
    omega = 2 * np.pi * 99.5
    assert model.effects == ["linear_stiffness", "viscous_damping"]
    assert model.coefficient("linear_stiffness") == pytest.approx(omega**2, rel=1e-3)
    assert model.coefficient("viscous_damping") == pytest.approx(2 * ZETA * omega, rel=2e-2)

    crit = tmp_path / "crit"
    assert main(["criticize", str(hand_made), "--model", str(model_path), "--out", str(crit)]) == 0
    assert json.loads((crit / "criticism.json").read_text())["significant"] is False


def test_a_record_file_is_a_campaign_of_one(hand_made, tmp_path):
    csv = tmp_path / "one.csv"
    assert main(["backbones", str(hand_made / "Config7_PRT_Assemb2.csv"), "--out", str(csv)]) == 0
    table = __import__("pandas").read_csv(csv)
    assert len(table) == 6 and set(table["curve"]) == {"Config7_PRT_Assemb2"}
    np.testing.assert_allclose(table["frequency_hz"], 100.0, rtol=1e-6)


def test_the_cli_names_the_samplers_and_population_models_the_library_has():
    from pm_joint import cli, inference

    assert cli.SAMPLERS == inference.SAMPLERS
    assert cli.POPULATION_MODELS == inference.POPULATION_MODELS


def test_each_warning_is_printed_once():
    """Libraries reset Python's once-per-place memory (any catch_warnings block does): the
    same warning, raised three times from one place, is still printed once."""
    script = (
        "import warnings\n"
        "from pm_joint import cli\n"
        "def noisy(args):\n"
        "    for _ in range(3):\n"
        "        with warnings.catch_warnings():\n"
        "            pass\n"
        "        warnings.warn('object mode, again', UserWarning)\n"
        "    warnings.warn('another one', UserWarning)\n"
        "cli._cmd_effects = noisy\n"
        "raise SystemExit(cli.main(['effects']))\n"
    )
    done = subprocess.run([sys.executable, "-c", script], capture_output=True, text=True,
                          timeout=600)  # fmt: skip
    assert done.returncode == 0, done.stderr[-2000:]
    lines = done.stderr.splitlines()
    assert lines.count("pm-joint effects: UserWarning: object mode, again") == 1, lines
    assert lines.count("pm-joint effects: UserWarning: another one") == 1, lines


def _help_of(option: str) -> str:
    """The ``pm-joint update`` help of one option, as argparse holds it."""
    parser = build_parser()
    update = next(a for a in parser._actions if isinstance(a, argparse._SubParsersAction)).choices[
        "update"
    ]
    return next(a.help for a in update._actions if option in a.option_strings)


def _defaults_in_words(text: str) -> dict[tuple[str, str], str]:
    """``"V (p on f, p on f); W (p on f)"`` back into {(p, f): V}."""
    found = {}
    for value, pairs in re.findall(r"(\w+) \(([^()]*)\)", text):
        for population, forward in re.findall(r"(\w+) on (\w+)", pairs):
            found[population, forward] = value
    return found


def test_update_help_says_the_defaults_the_updating_uses():
    """The help is generated from SAMPLER_DEFAULTS; read back, it is the table, every pair."""
    from pm_joint.inference import SAMPLER_DEFAULTS
    from pm_joint.sampler_defaults import DEFAULT_FORWARD, sampler_reason

    for option, field in (("--sampler", "sampler"), ("--draws", "draws"), ("--tune", "tune")):
        said = _defaults_in_words(_help_of(option))
        table = {pair: str(getattr(d, field)) for pair, d in SAMPLER_DEFAULTS.items()}
        assert said == table, option
    forward = _help_of("--forward")
    for population, default in DEFAULT_FORWARD.items():
        assert f"{default} for {population}" in forward
        assert (population, default) in SAMPLER_DEFAULTS
    # The reason a report prints is the table's, for the table's sampler only.
    for (population, model), default in SAMPLER_DEFAULTS.items():
        assert default.reason in sampler_reason(population, model, default.sampler)
        other = next(s for s in cli.SAMPLERS if s != default.sampler)
        assert sampler_reason(population, model, other) == "chosen by the caller"


def test_the_help_check_reads_a_drifted_help_as_drifted():
    """The reader above is no echo of the generator: a hand-written help reads differently."""
    from pm_joint.inference import SAMPLER_DEFAULTS
    from pm_joint.sampler_defaults import default_help

    # The --draws help as it was written by hand before the table made it.
    drifted = (
        "draws per chain (default 30000 metropolis, 2000 matching on harmonic, 1000 hierarchical)"
    )
    assert _defaults_in_words(drifted) != {p: str(d.draws) for p, d in SAMPLER_DEFAULTS.items()}
    generated = f"draws per chain (default: {default_help('draws')})"
    assert _defaults_in_words(generated) == {p: str(d.draws) for p, d in SAMPLER_DEFAULTS.items()}
