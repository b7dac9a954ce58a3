"""Models of several modes coupled through the joint, and their periodic solutions.

* :mod:`.model`: :class:`ModalModel` (modal oscillators, joint elements built from
  catalogue effects, polynomial modal couplings) and its versioned JSON form;
* :mod:`.balance`: the multi-harmonic balance residual with alternating
  frequency–time (AFT) and its Jacobian, batched over parameter sets;
* :mod:`.solve`: forced responses, phase-resonant backbones and nonlinear modes
  (extended periodic motion concept) by Newton's method;
* :mod:`.continuation`: a nonlinear mode followed along amplitude by
  pseudo-arclength continuation, with its internal resonances found and reported;
* :mod:`.pll`: the virtual phase-resonance test (PLL) locking one mode, with
  multi-point sensors and every mode's participation per harmonic.
"""

from identification.multimode.model import Coupling, JointElement, ModalModel, Mode
from identification.multimode.pll import (
    ModalPLLResult,
    ModalPLLTimeSeries,
    modal_pll_backbones,
    simulate_modal_pll,
)
from identification.multimode.solve import (
    HarmonicSettings,
    ModalSolution,
    energy_shares,
    forced_response,
    nonlinear_modes,
    phase_resonance,
)

__all__ = [
    "Coupling",
    "HarmonicSettings",
    "JointElement",
    "ModalModel",
    "ModalPLLResult",
    "ModalPLLTimeSeries",
    "ModalSolution",
    "Mode",
    "energy_shares",
    "forced_response",
    "modal_pll_backbones",
    "nonlinear_modes",
    "phase_resonance",
    "simulate_modal_pll",
]
