"""Fixtures shared across test modules.

The oscillators and populations they are built from live in ``oscillators.py`` so that module-level
code (parametrisations, constants) can use them too.
"""

import numpy as np
import pytest
from oscillators import POPULATION_AMPLITUDES_M, duffing_population, scattered_duffing_population

from identification.measurements.backbone import BackboneSet


@pytest.fixture(scope="session")
def duffing_assemblies() -> BackboneSet:
    """25 noise-free harmonic-balance backbones, 1 % stiffness and 20 % cubic scatter."""
    return scattered_duffing_population(25, POPULATION_AMPLITUDES_M)


@pytest.fixture(scope="session")
def duffing_triplet() -> BackboneSet:
    """Three assemblies (stiffness ×0.99/1/1.01, k3 0.8/1/1.2e10) on 12 amplitudes, 0.05–1.5 mm."""
    return duffing_population(
        [0.99, 1.0, 1.01], [0.8e10, 1.0e10, 1.2e10], np.linspace(5e-5, 1.5e-3, 12)
    )


def pytest_collection_modifyitems(items: list[pytest.Item]) -> None:
    """The files holding a test marked ``heavy`` first, each file's tests in their order.

    ``make test`` hands whole files to its workers in this order (``--dist loadfile
    --no-loadscope-reorder``): the long files start at once, the many short ones fill in
    behind them, and no worker is left running a long file alone at the end.
    """
    heavy = {item.path for item in items if item.get_closest_marker("heavy")}
    items.sort(key=lambda item: item.path not in heavy)
