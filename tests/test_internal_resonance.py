"""A published 1:2 internal resonance: Nayfeh & Mook's saturation, by the N-mode balance.

Nayfeh, A. H. and Mook, D. T. (1979; Wiley Classics 1995), *Nonlinear Oscillations*,
§6.5 (systems with quadratic nonlinearities, 1:2 internal resonance) and §6.5.1 "The
saturation phenomenon"; restated as example 4 of the OSCILATE package (Vincent, V.,
"Coupled quadratic oscillators in 1:2 internal resonance"). The system, in the form of
that restatement::

    ü1 + 2μ1 u̇1 + ω1² u1 + α1 u1 u2 = 0
    ü2 + 2μ2 u̇2 + ω2² u2 + α2 u1²    = F cos Ωt,     ω2 = 2ω1 + σ1,  Ω = ω2 + σ2

(the book writes the quadratic terms on the right-hand side with the opposite sign and
an ε in front of μ, α, σ and F; a change of sign of u2 and F maps one onto the other, so
the amplitudes below are the book's). The published result is the saturation: above a
threshold force, the directly excited mode's amplitude stops growing and the extra
energy goes to the indirectly excited mode 1, which answers at Ω/2.

First-order multiple scales (derived here; the book's §6.5.1 result): with
``u_n = a_n cos(…)`` and ``ν = (σ1 + σ2)/2 = Ω/2 − ω1``, the modulation equations'
steady states on the coupled branch are

* ``a2 = (2ω1/α1)·[4μ1² + (σ1 + σ2)²]^½ = (4ω1/α1)·(ν² + μ1²)^½``, whatever ``F``;
* ``a1² = p·α1·a2 / (α2·ω1)``, ``p`` the positive root of
  ``(ν² + μ1²) p² + 2 ω2 a2 (μ1μ2 − νσ2) p + ω2² a2² (σ2² + μ2²) − F²/4 = 0``;
* phases: ``u1 = a1 cos(Ωt/2 − (γ1 + γ2)/2)``, ``u2 = a2 cos(Ωt − γ2)`` with
  ``cos γ1 = 4ω1ν/(α1 a2)``, ``sin γ1 = −4ω1μ1/(α1 a2)``,
  ``(F/2) cos γ2 = p ν − ω2 a2 σ2``, ``(F/2) sin γ2 = ω2 μ2 a2 + p μ1``;

and below the threshold ``F_c = 2 ω2 a2 (σ2² + μ2²)^½`` (where ``p = 0``) only the
uncoupled branch ``a1 = 0``, ``a2 = F / (2 ω2 (σ2² + μ2²)^½)`` exists. Its error is of
the next order, O(ε) relative, with ε the size of μ, σ and of the amplitudes.

Checked here, against those closed forms and against a time integration written in this
file (scipy's DOP853 on the two equations above, no package kernel):

* the saturation curve ``a2(F)`` and the growth ``a1(F)`` over 0.5–3 × F_c at ε = 0.004
  (where a1 stays of order ε, as the expansion assumes): the balance within 5ε relative
  of the closed form (mode 1 below the threshold: zero);
* at ε = 0.02, below and above the threshold, the balance against the integration's
  steady state: 1e-4 relative on mode 1's frequency (locked at Ω/2) and 1e-3 relative on
  both amplitudes.
"""

from __future__ import annotations

import numpy as np
import pytest
from scipy.integrate import solve_ivp

from identification.multimode import Coupling, HarmonicSettings, ModalModel, Mode, forced_response

ALPHA = (1.0, 1.0)
HARMONICS = 4


class Case:
    """The ε-scaled case: ω1 = 1, μ1 = μ2 = ε, σ1 = ε, σ2 = ε/2 (α1 = α2 = 1)."""

    def __init__(self, eps: float) -> None:
        self.eps = eps
        self.w1, self.mu = 1.0, eps
        self.w2 = 2.0 + eps
        self.big_omega = self.w2 + 0.5 * eps
        self.nu = self.big_omega / 2 - self.w1
        self.sigma2 = self.big_omega - self.w2
        self.saturation = 4 * self.w1 * np.hypot(self.nu, self.mu) / ALPHA[0]
        self.threshold = 2 * self.w2 * self.saturation * np.hypot(self.sigma2, self.mu)

    def model(self) -> ModalModel:
        # F cos Ωt on mode 2 alone: participations (0, 1), base acceleration −F cos Ωt.
        return ModalModel(
            modes=(Mode(self.w1 / (2 * np.pi), self.mu / self.w1, 0.0),
                   Mode(self.w2 / (2 * np.pi), self.mu / self.w2, 1.0)),
            joint_shapes=(),
            couplings=(Coupling(1, (1, 1), ALPHA[0]), Coupling(2, (2, 0), ALPHA[1])),
        )  # fmt: skip

    def closed_form(self, force: float) -> tuple[float, float, float, float]:
        """``(a1, a2, phase1, phase2)`` of the multiple-scales steady state (module notes):
        ``u1 = a1 cos(Ωt/2 − phase1)``, ``u2 = a2 cos(Ωt − phase2)``."""
        mu, nu, s2, w1, w2 = self.mu, self.nu, self.sigma2, self.w1, self.w2
        if force <= self.threshold:
            a2 = force / (2 * w2 * np.hypot(s2, mu))
            return 0.0, a2, 0.0, np.arctan2(mu, -s2)
        a2 = self.saturation
        qa = nu**2 + mu**2
        qb = 2 * w2 * a2 * (mu * mu - nu * s2)
        qc = (w2 * a2) ** 2 * (s2**2 + mu**2) - force**2 / 4
        p = (-qb + np.sqrt(qb * qb - 4 * qa * qc)) / (2 * qa)
        a1 = np.sqrt(p * ALPHA[0] * a2 / (ALPHA[1] * w1))
        gamma1 = np.arctan2(-4 * w1 * mu, 4 * w1 * nu)
        gamma2 = np.arctan2(w2 * mu * a2 + p * mu, p * nu - w2 * a2 * s2)
        return a1, a2, (gamma1 + gamma2) / 2, gamma2

    def start(self, force: float) -> np.ndarray:
        """Balance coefficients ``(2, 2H+1)`` of the closed form (fundamental Ω/2)."""
        a1, a2, phase1, phase2 = self.closed_form(force)
        c = np.zeros((2, 2 * HARMONICS + 1))
        c[0, 1:3] = a1 * np.cos(phase1), a1 * np.sin(phase1)
        c[1, 3:5] = a2 * np.cos(phase2), a2 * np.sin(phase2)
        return c

    def balance(self, forces: np.ndarray):
        """The balance along ``forces`` at Ω (each force starting from the last), from the
        closed form of the first; the forcing is the 2nd harmonic of the fundamental Ω/2."""
        forces = np.asarray(forces, dtype=float)
        return forced_response(
            self.model(), np.full(forces.size, self.big_omega / (2 * np.pi)), -forces,
            forcing_harmonic=2, start=self.start(forces[0]),
            settings=HarmonicSettings(HARMONICS, tol=1e-12),
        )  # fmt: skip

    def integrate(self, force: float, n_periods: int, n_last: int = 8):
        """DOP853 from the closed form (mode 1 seeded at 1e-3 of the saturation amplitude
        where it is zero) over ``n_periods`` periods of Ω/2; the last ``n_last`` sampled."""
        w1, w2, mu, (al1, al2), big = self.w1, self.w2, self.mu, ALPHA, self.big_omega

        def rhs(t, s):
            u1, u2, v1, v2 = s
            return [v1, v2, -2 * mu * v1 - w1**2 * u1 - al1 * u1 * u2,
                    -2 * mu * v2 - w2**2 * u2 - al2 * u1**2 + force * np.cos(big * t)]  # fmt: skip

        a1, a2, p1, p2 = self.closed_form(force)
        a1 = max(a1, 1e-3 * self.saturation)
        state = [a1 * np.cos(-p1), a2 * np.cos(-p2),
                 -a1 * big / 2 * np.sin(-p1), -a2 * big * np.sin(-p2)]  # fmt: skip
        period = 4 * np.pi / big
        n_per = 256
        t_end = n_periods * period
        t = t_end - n_last * period + np.arange(n_last * n_per) * period / n_per
        run = solve_ivp(rhs, (0, t_end), state, method="DOP853", rtol=1e-11, atol=1e-14,
                        t_eval=t)  # fmt: skip
        assert run.success
        return t, run.y[:2]


def _amplitudes(sol) -> np.ndarray:
    """``(n, 2)``: mode 1's fundamental (Ω/2) and mode 2's 2nd harmonic (Ω)."""
    c = sol.coefficients
    return np.column_stack([np.hypot(c[:, 0, 1], c[:, 0, 2]), np.hypot(c[:, 1, 3], c[:, 1, 4])])


def test_saturation_and_the_growth_of_the_indirectly_excited_mode():
    """a2(F) follows the linear response to F_c, then stays at the saturation amplitude;
    a1(F) grows from zero there: the balance within 5ε of the closed form all along."""
    case = Case(0.004)
    above = case.threshold * np.array([1.1, 1.3, 1.6, 2.0, 2.5, 3.0])
    sol = case.balance(above)
    assert sol.converged.all()
    balanced = _amplitudes(sol)
    closed = np.array([case.closed_form(f)[:2] for f in above])
    np.testing.assert_allclose(balanced, closed, rtol=5 * case.eps)
    # the saturation: almost thrice the force moves mode 2 by O(ε), mode 1 more than doubles
    assert abs(balanced[-1, 1] / balanced[0, 1] - 1) < 5 * case.eps
    assert balanced[-1, 0] > 2 * balanced[0, 0]
    # below the threshold: the uncoupled branch, mode 1 at rest, mode 2 linear in F
    below = case.threshold * np.array([0.5, 0.9])
    sol = case.balance(below)
    assert sol.converged.all()
    balanced = _amplitudes(sol)
    assert np.all(balanced[:, 0] < 1e-9 * case.saturation)
    closed = np.array([case.closed_form(f)[1] for f in below])
    np.testing.assert_allclose(balanced[:, 1], closed, rtol=5 * case.eps)


def _spectral_line(t: np.ndarray, u: np.ndarray, omega: float) -> tuple[float, float]:
    """Amplitude at ``omega`` over whole periods, and the frequency (rad/s) of the largest
    line near it refined by a parabola on a 16× zero-padded spectrum's log-magnitude."""
    amplitude = 2 * abs(np.mean(u * np.exp(-1j * omega * t)))
    n = 16 * t.size
    spectrum = np.abs(np.fft.rfft(u * np.hanning(t.size), n))
    w = 2 * np.pi * np.fft.rfftfreq(n, t[1] - t[0])
    near = np.flatnonzero(np.abs(w - omega) < 0.25 * omega)
    k = near[np.argmax(spectrum[near])]
    a, b, c = np.log(spectrum[k - 1 : k + 2])
    peak = w[k] + 0.5 * (a - c) / (a - 2 * b + c) * (w[1] - w[0])
    return amplitude, peak


@pytest.mark.parametrize("factor", [0.6, 2.0, 4.0])
def test_balance_matches_time_integration(factor):
    """At ε = 0.02 the integration (from the closed form, 160 periods of Ω/2: μt ≈ 40)
    settles on the balance's orbit: mode 1 at Ω/2 (or at rest below the threshold)."""
    case = Case(0.02)
    force = factor * case.threshold
    sol = case.balance([force])
    assert sol.converged[0]
    balanced = _amplitudes(sol)[0]
    t, (u1, u2) = case.integrate(force, n_periods=160)
    half = case.big_omega / 2
    a1, w1 = _spectral_line(t, u1, half)
    a2, w2 = _spectral_line(t, u2, case.big_omega)
    assert a2 == pytest.approx(balanced[1], rel=1e-3)
    assert w2 == pytest.approx(2 * np.pi * sol.frequency_hz[0] * 2, rel=1e-4)
    if factor < 1:
        assert balanced[0] < 1e-9 * case.saturation
        assert a1 < 1e-6 * case.saturation  # the seed died out: no coupled branch
        return
    assert a1 == pytest.approx(balanced[0], rel=1e-3)
    assert w1 == pytest.approx(2 * np.pi * sol.frequency_hz[0], rel=1e-4)
