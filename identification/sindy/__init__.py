"""SINDy identification of a joint model from phase-resonance records.

The model is ``ẍ + Σ c_i φ_i(x, ẋ) = −a_base`` (:class:`~identification.model.JointModel`)
with ``x`` the centre displacement relative to the base. Everything the regression
needs is in the absolute acceleration ``y = ẍ + a_base = −Σ c_i φ_i``, so the
identification is one sparse regression of ``y`` on the library columns
``φ_i(x, ẋ)`` (catalogue effects, :mod:`identification.effects`). The modules, in
the order they build on each other: :mod:`.library` (columns, shape grids,
collinearity), :mod:`.regression` (thresholded least squares on Gram matrices),
:mod:`.design` (scaled per-fold Gram matrices), :mod:`.admissibility`,
:mod:`.selection` (threshold paths, cross-validation or BIC, pruning),
:mod:`.report` (:class:`Identification`), :mod:`.identify` (the entry points),
:mod:`.validation` and :mod:`.plots`.
"""

from identification.sindy.admissibility import admissible
from identification.sindy.identify import (
    BetterSupportWarning,
    DriveFrequencyWarning,
    identify,
    identify_arrays,
    identify_kinematics,
    record_kinematics,
)
from identification.sindy.kinematics import sensor_kinematics
from identification.sindy.library import (
    EQ3_SYMBOLS,
    GROUPS,
    PAPER_LIBRARY,
    POLYNOMIAL_LIBRARY,
    CollinearityWarning,
    LibraryTerm,
    RankDeficientLibraryError,
    design_matrix,
    mean_offset,
)
from identification.sindy.plots import plot_validation
from identification.sindy.report import Identification
from identification.sindy.selection import ThresholdPath
from identification.sindy.validation import (
    ErrorStatistics,
    Validation,
    backbone_error,
    comparison_table,
    validate,
)

__all__ = [
    "EQ3_SYMBOLS",
    "GROUPS",
    "PAPER_LIBRARY",
    "POLYNOMIAL_LIBRARY",
    "BetterSupportWarning",
    "CollinearityWarning",
    "DriveFrequencyWarning",
    "ErrorStatistics",
    "Identification",
    "LibraryTerm",
    "RankDeficientLibraryError",
    "ThresholdPath",
    "Validation",
    "admissible",
    "backbone_error",
    "comparison_table",
    "design_matrix",
    "identify",
    "identify_arrays",
    "identify_kinematics",
    "mean_offset",
    "plot_validation",
    "record_kinematics",
    "sensor_kinematics",
    "validate",
]
