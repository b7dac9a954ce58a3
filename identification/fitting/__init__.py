"""Fitting a JointModel to measured backbones.

The one way in is :class:`~identification.fitting.fitter.Fitter` (the data and the
fitting options bound once; ``method_for``, ``evaluate``, ``fit``, ``predict``); the
criticism, the studies and the CLI go through it. Its parts: the likelihood's data
(:mod:`.data`, :mod:`.covariance`), the least-squares fit and its
:class:`~identification.fitting.least_squares.FitResult` (:mod:`.least_squares`) and
the predictions in the channel layout (:mod:`.prediction`).
"""

from identification.fitting.fitter import Fitter
from identification.fitting.least_squares import FitOutcome, FitResult

__all__ = ["FitOutcome", "FitResult", "Fitter"]
