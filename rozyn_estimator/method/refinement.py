"""What the likelihood refinement returns, for either car: :class:`LikelihoodResult`, the fields
of its result (:class:`~rozyn_estimator.method.vehicle_fit.result.Refinement` adds the model check,
the sandwich ratio and the calibration, whose types live with the likelihood)."""

from __future__ import annotations

import math
from dataclasses import dataclass, field

import numpy as np


@dataclass(frozen=True)
class LikelihoodResult:
    """A refinement's outcome. ``params``/``covariance`` None unless ok."""

    status: str  # "ok" | "failed"
    reason: str = ""
    params: np.ndarray | None = None  # the body's parameters (the car's PARAM_NAMES order)
    covariance: np.ndarray | None = None  # their statistical covariance (the sandwich, the road's factors)
    theta: np.ndarray | None = None  # all fitted parameters (names in ``names``)
    names: tuple[str, ...] = ()
    neg_log_likelihood: float = math.nan  # ℓ at the optimum (constant terms dropped)
    iterations: int = 0
    starts: int = 0
    band_hz: tuple[float, float] = (math.nan, math.nan)
    noise_std_mps2: tuple[float, ...] = ()  # fitted white sensor noise per channel
    waviness: float = 2.0
    variance_factors: tuple[float, ...] = ()  # the non-stationary road's factors on the model's variances
    contributions: dict[str, np.ndarray] = field(default_factory=dict)  # assumed value -> (params,) per 1 u
    information_lost: tuple[tuple[float, ...], ...] = ()  # per channel, per parameter (method.information)
    elapsed_ms: float = 0.0
    notes: tuple[str, ...] = ()

    @property
    def ok(self) -> bool:
        return self.status == "ok"


__all__ = ["LikelihoodResult"]
