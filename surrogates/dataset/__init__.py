"""Training data for backbone surrogates: parameter sets → backbones on a fixed grid.

A surrogate maps a parameter vector to a backbone sampled at fixed
**excitation levels** (base-acceleration amplitudes, m/s²), the way a
phase-resonance test steps its shaker, or on fixed response amplitudes
(:mod:`surrogates.grid`): the grid is the input side of
:class:`~surrogates.runtime.SurrogateSpec`. This package builds such datasets,
one step a module:

1. **Design** (:mod:`~surrogates.dataset.design`): the parameter box, a seeded
   quasi-random design over it (:func:`sample_parameters`) and by default the
   ``n_levels`` levels that hold the nominal model at amplitudes spaced
   geometrically over a range (:func:`nominal_levels`).
2. **Generation** (:mod:`~surrogates.dataset.generation`): the analytical
   backbones of every set, by harmonic balance inverted onto the levels or by
   the time-domain PLL (:func:`generate_dataset`).
3. **Measured curves** (:mod:`~surrogates.dataset.measured`): each measured curve,
   labelled with the parameters of its own fit (:func:`record_labels`), put on
   the grid (:func:`add_measured`).
4. **The record** (:mod:`~surrogates.dataset.container`): :class:`BackboneDataset`,
   its splits, loss weights and ``.npz`` file with provenance and content hash.
"""

from surrogates.dataset.container import (
    ANALYTICAL,
    FORMAT,
    FORMAT_VERSION,
    MEASURED_PREFIX,
    SPLITS,
    BackboneDataset,
)
from surrogates.dataset.design import nominal_levels, sample_parameters
from surrogates.dataset.generation import NonMonotone, Representation, generate_dataset
from surrogates.dataset.measured import add_measured, record_labels

__all__ = [
    "ANALYTICAL",
    "FORMAT",
    "FORMAT_VERSION",
    "MEASURED_PREFIX",
    "SPLITS",
    "BackboneDataset",
    "NonMonotone",
    "Representation",
    "add_measured",
    "generate_dataset",
    "nominal_levels",
    "record_labels",
    "sample_parameters",
]
