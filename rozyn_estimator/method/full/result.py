"""The full car's likelihood refinement's result (:func:`~rozyn_estimator.method.full.refine.refine_full`)."""

from __future__ import annotations

import math
from dataclasses import dataclass, field

import numpy as np

from rozyn_estimator.method.full.uncertainty.calibrate import VehicleCalibration
from rozyn_estimator.method.likelihood.fitcheck import ModelFit
from rozyn_estimator.method.likelihood.score import SandwichRatio


@dataclass(frozen=True)
class FullRefinement:
    """Result of the full car's likelihood refinement. ``params``/``covariance`` None unless ok."""

    status: str  # "ok" | "failed"
    reason: str = ""
    params: np.ndarray | None = None  # (5,) in FULL_PARAM_NAMES order
    covariance: np.ndarray | None = None  # (5, 5) the statistical part (the sandwich, the road's factors)
    theta: np.ndarray | None = None  # all fitted parameters (names in ``names``)
    names: tuple[str, ...] = ()
    neg_log_likelihood: float = math.nan  # ℓ at the optimum (constant terms dropped)
    iterations: int = 0
    starts: int = 0
    band_hz: tuple[float, float] = (math.nan, math.nan)
    noise_std_mps2: tuple[float, ...] = ()  # fitted white sensor noise per channel
    waviness: float = 2.0
    coherence_scale: float = 1.0  # the tracks' fitted separation over the front track
    contributions: dict[str, np.ndarray] = field(default_factory=dict)  # assumed value -> (5,) per 1 u
    budget_theta: np.ndarray | None = None  # the body parameters θ[:5] the contributions were taken at
    variance_factors: tuple[float, ...] = ()  # the non-stationary road's factors on the model's variances
    sandwich: SandwichRatio | None = None  # the taper's sandwich over the model's std (.score), where taken
    calibration: VehicleCalibration | None = None  # the sensors and corners as the data calibrated them
    model_fit: ModelFit | None = None  # the goodness-of-fit check (.fitcheck)
    information_lost: tuple[tuple[float, ...], ...] = ()  # per channel, per parameter (method.information)
    elapsed_ms: float = 0.0
    notes: tuple[str, ...] = ()

    @property
    def ok(self) -> bool:
        return self.status == "ok"

    def to_dict(self) -> dict[str, object]:
        return {"status": self.status, "reason": self.reason,
                "params": None if self.params is None else self.params.tolist(),
                "neg_log_likelihood": self.neg_log_likelihood, "iterations": self.iterations,
                "starts": self.starts, "band_hz": list(self.band_hz),
                "noise_std_mps2": list(self.noise_std_mps2),
                "waviness": self.waviness, "coherence_scale": self.coherence_scale,
                "variance_factors": list(self.variance_factors),
                "calibration": [] if self.calibration is None else
                [c.to_dict() for c in self.calibration.calibrations],
                "model_fit": None if self.model_fit is None else self.model_fit.to_dict(),
                "information_lost": [list(s) for s in self.information_lost],
                "elapsed_ms": self.elapsed_ms, "notes": list(self.notes)}


__all__ = ["FullRefinement"]
