"""The likelihood refinement's result, either car (:func:`~.refine.refine`)."""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from rozyn_estimator.method.likelihood.fitcheck import ModelFit
from rozyn_estimator.method.likelihood.score import SandwichRatio
from rozyn_estimator.method.refinement import LikelihoodResult
from rozyn_estimator.method.vehicle_fit.uncertainty.calibrate import VehicleCalibration


@dataclass(frozen=True)
class Refinement(LikelihoodResult):
    """Result of the likelihood refinement, either car: ``params`` the body's parameters (the full
    car's five in FULL_PARAM_NAMES order, the half car's three in PARAM_NAMES order),
    ``contributions`` per 1 u of each assumed value (as many)."""

    coherence_scale: float = 1.0  # the tracks' fitted separation over the front track (NaN: one track)
    budget_theta: np.ndarray | None = None  # the body parameters θ[:5] the contributions were taken at
    calibration: VehicleCalibration | None = None  # the sensors and corners as the data calibrated them
    sandwich: SandwichRatio | None = None  # the taper's sandwich over the model's std, where taken
    model_fit: ModelFit | None = None  # the goodness-of-fit check
    every_bin: bool = False  # S nearly singular at the optimum (floors at zero): the next window starts
    # with S at every Fourier bin

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


__all__ = ["Refinement"]
