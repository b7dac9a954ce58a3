"""#26's acceptance with drift on: PLL campaigns of two modes whose linear frequencies drift.

The campaigns are those of ``tests/test_modal_pll_acceptance.py`` (same system, shaker, noise,
sensors, loop, levels set from the undrifted backbone), written by the independent simulator
with a :class:`~independent.modal_pll.FrequencyDrift`: every mode's linear frequency moves
linearly in time by ``δ_c`` over the campaign (one record covering it), its linear stiffness
scaled by ``(1 + δ)²`` and its viscous coefficient kept. Read by ``pm-joint backbones FOLDER
--modes 2 --out FILE``, which knows nothing of the drift.

The rules, fixed before the first run and derived, not fitted (``δ_c`` the drift's size,
``ρ = |δ_c|/T`` its rate over the record's duration ``T``, at each hold ``a`` the measured
amplitude, ``f, D`` the undrifted truth's frequency and power-balance damping there,
``r = f_lin/f`` with ``f_lin`` the locked mode's undrifted linear frequency, ``ω = 2πf``):

1. *Within the drift's size, against the undrifted truth* (the issue's sentence).
   Frequency: ``|f̂/f − 1| ≤ 5e-4 + b_f + D·ρω/k_i`` with
   ``b_f = max over δ = ±|δ_c| of |√(1 + ((1 + δ)² − 1) r²) − 1|``: one mode's backbone
   ``ω_d² = ω² + ((1 + δ)² − 1) ω_lin²`` (the linear stiffness moves, the nonlinear terms
   stay); ``D·ρω/k_i`` is the loop's lag — a PI law tracks the ramp ``ρω`` of the resonance
   with a phase error ``e = ρω/k_i``, which a resonance of damping ``D`` turns into a
   frequency offset ``D·e``. Damping: ``|D̂/D − 1| ≤ 0.02 + b_f/(1 − b_f) + 3ρ/(2Dω) + e²/2``:
   the linear part ``c/(2ω)`` and a viscous cubic part (``∝ ω``) move by at most the
   frequency's relative change; a stiffness that changes at rate ``k̇`` puts
   ``¼ k̇ a² + k a ȧ`` of the input power into the oscillator (with ``|ȧ/a| ≤ |ω̇/ω|`` at
   constant level, at most ``3ρ/(2Dω)`` of the damping); the loop's phase error ``e`` changes
   the quadrature power by ``1 − cos e``.
2. *Within the drift's size over each hold, against the drifted truth*: the truth of the
   system drifted to ``δ`` (frequencies ``(1 + δ) f_i``, damping ratios ``ζ_i/(1 + δ)``) at
   the drift of the hold's start and end brackets the reading, widened by the no-drift
   tolerances and the rate terms above (the library's fit window lies inside the hold).
3. *The drift acts*: at the last hold the frequency read differs from the undrifted truth by
   more than the no-drift tolerance (a simulator that ignored the drift fails here).

Seeds ``1_000_001`` and ``1_000_002`` (held out): the rules above were written before any run.
The shared system comes from the no-drift acceptance module (pytest puts ``tests/`` on the path).
"""

from __future__ import annotations

import numpy as np
import pandas as pd
import pytest
from test_modal_pll_acceptance import (
    DAMPING_RTOL,
    F_HZ,
    FREQUENCY_RTOL,
    HOLD_S,
    SHAKER,
    SHAPES,
    ZETA,
    _system,
)

from independent.decays import ModalSystem
from independent.modal_pll import FrequencyDrift, LoopSettings, pll_record, write_trc_campaign
from independent.modal_resonance import modal_phase_resonance
from pm_joint.cli import main as cli

HELD_OUT_SEED = 1_000_000


def _drifted(delta: float) -> ModalSystem:
    """The test system with its linear stiffnesses scaled by ``(1 + δ)²``, ``2ζω`` kept."""
    system = _system()
    return ModalSystem(tuple(f * (1 + delta) for f in F_HZ), tuple(z / (1 + delta) for z in ZETA),
                       joint_shape=system.joint_shape, joint_terms=system.joint_terms,
                       couplings=system.couplings)  # fmt: skip


def _truth(delta: float, mode: int, amplitude_m: float) -> tuple[float, float]:
    truth = modal_phase_resonance(_drifted(delta), mode, [amplitude_m], distortion=SHAKER)
    assert truth.converged.all()
    return float(truth.frequency_hz[0]), float(truth.damping_ratio[0])


@pytest.mark.parametrize(("mode", "amplitudes_m", "drift_size"),
                         [(1, (2e-4, 8e-4), 0.005), (2, (1e-4, 4e-4), -0.005)])  # fmt: skip
def test_pll_campaign_with_drift_reads_within_the_drifts_size(tmp_path, mode, amplitudes_m,
                                                              drift_size):  # fmt: skip
    settings = LoopSettings(hold_s=HOLD_S[mode])
    drift = FrequencyDrift(frequency_over_campaign=drift_size)
    levels = modal_phase_resonance(_system(), mode, amplitudes_m,
                                   distortion=SHAKER).base_acceleration_m_s2  # fmt: skip
    record = pll_record(_system(), mode, levels, SHAPES, distortion=SHAKER, settings=settings,
                        seed=HELD_OUT_SEED + mode, drift=drift)  # fmt: skip
    folder = write_trc_campaign(tmp_path / f"mode{mode}", [record], SHAPES, F_HZ)[0].parent
    out = tmp_path / f"mode{mode}.csv"
    assert cli(["backbones", str(folder), "--modes", "2", "--out", str(out)]) == 0
    rows = pd.read_csv(out)
    mine = rows[(rows["mode"] == mode) & rows["frequency_hz"].notna()]
    assert len(mine) == len(amplitudes_m)
    # Each hold's part of the record (holds in test order), as fractions of its duration.
    period = settings.ramp_s + settings.hold_s
    duration = period * len(amplitudes_m)
    rate = abs(drift_size) / duration
    f_lin = F_HZ[mode - 1]
    errors = []
    for k, (a_mm, f_read, d_read) in enumerate(
        zip(mine["amplitude_mm"], mine["frequency_hz"], mine["damping_ratio"], strict=True)
    ):
        a_m = a_mm / 1e3
        f, d = _truth(0.0, mode, a_m)
        omega = 2 * np.pi * f
        r = f_lin / f
        b_f = max(abs(np.sqrt(1 + ((1 + s) ** 2 - 1) * r**2) - 1)
                  for s in (abs(drift_size), -abs(drift_size)))  # fmt: skip
        lag_rad = rate * omega / settings.ki_rad_s2
        f_rate, d_rate = d * lag_rad, 1.5 * rate / (d * omega) + lag_rad**2 / 2
        # Rule 1: against the undrifted truth, within the drift's size.
        f_err, d_err = abs(f_read / f - 1), abs(d_read / d - 1)
        f_bound = FREQUENCY_RTOL + b_f + f_rate
        d_bound = DAMPING_RTOL + b_f / (1 - b_f) + d_rate
        # Rule 2: bracketed by the truth drifted to the hold's start and end.
        span = [(k * period + settings.ramp_s) / duration, (k + 1) * period / duration]
        ends = [_truth(drift_size * x, mode, a_m) for x in span]
        f_lo, f_hi = min(e[0] for e in ends), max(e[0] for e in ends)
        d_lo, d_hi = min(e[1] for e in ends), max(e[1] for e in ends)
        f_in = (
            f_lo * (1 - FREQUENCY_RTOL - f_rate) <= f_read <= f_hi * (1 + FREQUENCY_RTOL + f_rate)
        )
        d_tol = DAMPING_RTOL + d_rate
        d_in = d_lo * (1 - d_tol) <= d_read <= d_hi * (1 + d_tol)
        errors.append((f_err, d_err))
        print(f"mode {mode}, hold {k + 1} at {a_mm:.4f} mm (δ {drift_size * span[0]:+.5f} to "
              f"{drift_size * span[1]:+.5f}): frequency error {f_err:.2e} (bound {f_bound:.2e}), "
              f"damping error {d_err:.2e} (bound {d_bound:.2e}); drifted truth "
              f"[{f_lo:.4f}, {f_hi:.4f}] Hz read {f_read:.4f}, [{d_lo:.6f}, {d_hi:.6f}] "
              f"read {d_read:.6f}")  # fmt: skip
        assert f_err <= f_bound and d_err <= d_bound
        assert f_in and d_in
    # Rule 3: the last hold's frequency is beyond the no-drift tolerance.
    assert errors[-1][0] > FREQUENCY_RTOL
