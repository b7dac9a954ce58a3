"""Best-fitting distribution families for samples (MATLAB's fitmethis, in scipy).

The paper compares measured and sampled frequencies at low, mid and high
amplitude through fitted PDFs. Here each candidate family of scipy.stats is
fitted by maximum likelihood and the families are ranked by an information
criterion; :func:`distances` gives the two-sample Kolmogorov–Smirnov and
Wasserstein distances between samples.
"""

from __future__ import annotations

import warnings
from collections.abc import Mapping
from dataclasses import dataclass
from typing import Any

import numpy as np
from numpy.typing import ArrayLike
from scipy import stats

__all__ = [
    "CANDIDATES",
    "UNBOUNDED_CANDIDATES",
    "DistributionFit",
    "distances",
    "fit_best",
    "fit_family",
]

#: Candidate families: symmetric, skewed either way, heavy-tailed and bounded-below.
CANDIDATES: tuple[str, ...] = (
    "norm",
    "logistic",
    "t",
    "gumbel_r",
    "gumbel_l",
    "lognorm",
    "gamma",
    "weibull_min",
)

#: Families whose support is the whole real line. A likelihood built from a
#: handful of curves must not put a hard edge where the smallest measured
#: value happened to fall, which a fitted location of lognorm, gamma or
#: weibull_min does.
UNBOUNDED_CANDIDATES: tuple[str, ...] = ("norm", "logistic", "t", "gumbel_r", "gumbel_l")


@dataclass(frozen=True)
class DistributionFit:
    """A fitted scipy.stats family with its information criteria."""

    family: str
    params: tuple[float, ...]
    loglik: float
    aic: float
    bic: float
    aicc: float

    @property
    def dist(self) -> stats.rv_continuous:
        """The frozen scipy.stats distribution."""
        return getattr(stats, self.family)(*self.params)

    def to_dict(self) -> dict[str, Any]:
        return {
            "family": self.family,
            "params": [float(p) for p in self.params],
            "loglik": self.loglik,
            "aic": self.aic,
            "bic": self.bic,
            "aicc": self.aicc,
        }

    @classmethod
    def from_dict(cls, data: Mapping[str, Any]) -> DistributionFit:
        """Inverse of :meth:`to_dict`."""
        return cls(
            family=data["family"],
            params=tuple(float(p) for p in data["params"]),
            **{k: float(data[k]) for k in ("loglik", "aic", "bic", "aicc")},
        )


def _clean(samples: ArrayLike, what: str) -> np.ndarray:
    x = np.asarray(samples, dtype=float).ravel()
    if x.size < 3:
        raise ValueError(f"{what}: need at least 3 samples to fit a distribution, got {x.size}")
    if not np.all(np.isfinite(x)):
        raise ValueError(f"{what}: samples contain NaN or inf")
    if np.ptp(x) == 0:
        raise ValueError(f"{what}: all samples are equal ({x[0]}); no spread to fit")
    return x


def fit_family(samples: ArrayLike, family: str) -> DistributionFit:
    """Maximum-likelihood fit of one scipy.stats family."""
    x = _clean(samples, family)
    dist = getattr(stats, family)
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", RuntimeWarning)  # optimiser probes outside the support
        params = dist.fit(x)
        loglik = float(np.sum(dist.logpdf(x, *params)))
    k = len(params)
    if not np.isfinite(loglik):
        loglik = -np.inf
    aic = 2 * k - 2 * loglik
    # small-sample correction; undefined (inf) when there are too few samples for k
    aicc = aic + 2 * k * (k + 1) / (x.size - k - 1) if x.size > k + 1 else np.inf
    return DistributionFit(
        family=family,
        params=tuple(float(p) for p in params),
        loglik=loglik,
        aic=aic,
        bic=k * np.log(x.size) - 2 * loglik,
        aicc=aicc,
    )


def fit_best(
    samples: ArrayLike,
    candidates: tuple[str, ...] = CANDIDATES,
    criterion: str = "aic",
) -> list[DistributionFit]:
    """Fit every candidate family; return the fits ranked best first.

    Parameters
    ----------
    samples
        One-dimensional samples (at least 3, finite, not all equal).
    candidates
        scipy.stats family names.
    criterion
        ``"aic"``, ``"aicc"`` (small-sample corrected) or ``"bic"``.

    Returns
    -------
    The fits ranked best first. With ``"aicc"`` and too few samples for every
    candidate (AICc needs more samples than parameters + 1), the normal
    distribution alone is returned: there is no evidence to choose a shape.
    """
    if criterion not in ("aic", "aicc", "bic"):
        raise ValueError(f"criterion must be 'aic', 'aicc' or 'bic', got {criterion!r}")
    x = _clean(samples, "fit_best")
    fits = sorted(
        (fit_family(x, family) for family in candidates), key=lambda f: getattr(f, criterion)
    )
    if not np.isfinite(getattr(fits[0], criterion)):
        return [fit_family(x, "norm")]
    return fits


def distances(a: ArrayLike, b: ArrayLike) -> dict[str, float]:
    """Two-sample Kolmogorov–Smirnov statistic and p-value, and Wasserstein distance."""
    a = _clean(a, "distances (first sample)")
    b = _clean(b, "distances (second sample)")
    ks = stats.ks_2samp(a, b)
    return {
        "ks_statistic": float(ks.statistic),
        "ks_pvalue": float(ks.pvalue),
        "wasserstein": float(stats.wasserstein_distance(a, b)),
    }
