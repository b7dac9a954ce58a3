"""Phase-locked-loop (PLL) phase-resonance simulator for models of N modes.

The one-mode simulator's loop (:mod:`identification.analytical.pll`) on a
:class:`~identification.multimode.model.ModalModel`, locking one target mode,
with multi-point sensors and every mode's participation per harmonic:

:mod:`~identification.multimode.pll.kernel`
    The numba core: modal equations, RK4 step, one level's hold.
:mod:`~identification.multimode.pll.closed_loop`
    Inputs, gains, results (:func:`simulate_modal_pll`, :func:`modal_pll_backbones`,
    :class:`ModalPLLResult`, :class:`ModalPLLTimeSeries`).
"""

from identification.multimode.pll.closed_loop import (
    ModalPLLResult,
    ModalPLLTimeSeries,
    modal_pll_backbones,
    simulate_modal_pll,
)

__all__ = ["ModalPLLResult", "ModalPLLTimeSeries", "modal_pll_backbones", "simulate_modal_pll"]
