"""The effects' fit facts reproduce today's per-effect branches of the fits and the criticism.

``identification.fitting.fit.default_shape_grid`` / ``shape_bounds`` and
``identification.criticism.criticism._specifics`` still hold one branch per
effect; each effect module now carries the same facts (``Effect.shape_grid``,
``Effect.shape_bounds``, ``Effect.fitted_reading`` of a
:class:`~identification.effects.FitScale`). This comparison pins them equal for
every effect until the fits and the criticism call the effects; it goes with
the old functions when they are wired.
"""

import math

import numpy as np
import pytest

from identification.criticism.criticism import _specifics
from identification.effects import CATALOGUE, FitScale
from identification.fitting.fit import _stiffness, default_shape_grid, fit_data, shape_bounds
from identification.measurements.backbone import Backbone, BackboneSet
from identification.model import JointModel

#: Every catalogue effect (a plain coefficient of 1), hardening, with a stuck Jenkins spring
#: of 1/8 of the stiffness and its shape parameters away from their defaults.
EVERY_EFFECT = {name: 1.0 for name in CATALOGUE} | {
    "linear_stiffness": 4e5,
    "cubic_stiffness": 1e10,
    "stribeck_friction": {"coefficient": 0.2, "v_s": 0.02},
    "tanh_saturation": {"coefficient": 50.0, "x_s": 1e-3},
    "exponential": {"coefficient": 10.0, "x_s": 1.5e-3},
    "microslip": {"coefficient": 1.0, "k_t": 5e4, "F_s": 2.0},
}


def measured_curves() -> BackboneSet:
    """Two curves over different amplitude ranges, softening, as a test gives them."""
    a1 = np.geomspace(4e-5, 1.2e-3, 7)
    a2 = np.geomspace(7e-5, 1.9e-3, 9)
    return BackboneSet(
        [
            Backbone(a1, 101.3 - 900 * a1, 0.004 + 2 * a1, label="c0"),
            Backbone(a2, 99.1 - 700 * a2, 0.005 + 1 * a2, label="c1"),
        ]
    )


def models() -> list[JointModel]:
    every = JointModel(EVERY_EFFECT)
    return [
        every,
        every.replace(cubic_stiffness=-3e9),  # softening words
        every.replace(microslip__F_s=1.0e-3),  # slipping over the whole test
        # No positive stiffness in the model: the fits take it from the data.
        every.without("linear_stiffness").replace(microslip=-1.0),
    ]


def scale_of(model: JointModel, data) -> FitScale:
    frequency = data.values[:, data.column("frequency_hz")]
    return FitScale.from_measurements(data.amplitude_m, frequency, _stiffness(model, data))


@pytest.mark.parametrize("index", range(len(models())))
def test_effect_facts_give_todays_grids_bounds_and_words(index):
    model = models()[index]
    data = fit_data(measured_curves())
    scale = scale_of(model, data)
    for term in model.terms:
        effect = CATALOGUE[term.effect]
        old_grid = default_shape_grid(term.effect, data, model)
        new_grid = effect.shape_grid(scale)
        assert old_grid.keys() == new_grid.keys(), term.effect
        for shape in old_grid:
            np.testing.assert_array_equal(new_grid[shape], old_grid[shape])
        bounds = effect.shape_bounds(scale)
        for shape in term.shape:
            name = f"{term.effect}.{shape}"
            if name not in model.parameter_names:
                continue  # v_reg: a numerical device, never fitted
            value = model.parameters[name]
            fallback = (value * math.exp(-30), value * math.exp(30))
            assert shape_bounds(name, data, model) == bounds.get(shape, fallback), name
        if model.linear_stiffness > 0:  # today's words divide by it
            words = effect.fitted_reading(term.coefficient, term.shape, scale)
            assert words == _specifics(term.effect, model, data), term.effect


def test_the_comparison_sees_every_branch():
    # Each per-effect branch of today's functions is reached above, both microslip
    # readings included, so the equality cannot hold vacuously.
    data = fit_data(measured_curves())
    words = {_specifics("microslip", m, data) for m in models() if "microslip" in m.effects}
    assert any("slipping over the whole test" in w for w in words)
    assert any(w.startswith(" (slip from about") for w in words)
    grids = {e for m in models() for e in m.effects if default_shape_grid(e, data, m)}
    assert grids == {"microslip", "stribeck_friction", "tanh_saturation", "exponential"}
