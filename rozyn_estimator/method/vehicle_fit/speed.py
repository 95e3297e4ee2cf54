"""The full car's speed check: :func:`rozyn_estimator.method.likelihood.speedcheck.check_speed`
on the full car's likelihood (the rear wheels meet the front wheels' roads a wheelbase later)."""

from __future__ import annotations

from collections.abc import Callable

import numpy as np

from rozyn_estimator.method.likelihood.config import LikelihoodConfig
from rozyn_estimator.method.likelihood.speedcheck import SpeedCheck, check_speed
from rozyn_estimator.method.vehicle_fit.spectrum import VehicleSpectrum
from rozyn_estimator.method.vehicle_fit.whittle import WhittleObjective, scoring


def speed_models(model: VehicleSpectrum) -> Callable[[float], VehicleSpectrum]:
    """``model`` as it is now (its vehicle and assumed sensors: a snapshot, later calibrations
    do not reach it) with its speed scaled by a factor."""
    settings = model.settings | {"vehicle": model.vehicle}
    speed = np.asarray(model.speed_mps, dtype=float)
    return lambda c: VehicleSpectrum(freq_hz=model.freq_hz, **(settings | {"speed_mps": speed * c}))


def check_full_speed(models: Callable[[float], VehicleSpectrum], periodogram: np.ndarray, counts: np.ndarray,
                     cfg: LikelihoodConfig, theta: np.ndarray, value: float, window_s: float) -> SpeedCheck:
    """The speed's check at the uncalibrated fit's optimum ``theta`` (negative log likelihood
    ``value``) of the grouped ``periodogram`` (``counts`` bins in each mean) of a ``window_s``
    window."""
    def objective(c: float) -> WhittleObjective:
        return WhittleObjective(models(c), periodogram, counts)

    def refit(c: float, at: np.ndarray) -> tuple[np.ndarray, float] | None:
        res = scoring(objective(c), at, cfg.tol, cfg.max_iter)
        return (res.x, float(res.fun)) if np.isfinite(res.fun) else None

    return check_speed(lambda c, at: objective(c).fun(at), refit, theta, value, window_s)
