"""After the fit: the published estimate's uncertainty, as an uncertainty budget.

- The values the data can calibrate (``self_calibrate``) — the sensors' relative gain and
  delay (fitted with θ), the suspension, tyres, unsprung masses and sensor positions (one
  step of the augmented posterior, :mod:`rozyn_estimator.method.likelihood.uncertainty.augment`) —
  contribute what their tolerances still contribute after the data have narrowed them:
  each prior's part of the posterior covariance.
- The values left assumed (the wheelbase; everything when ``self_calibrate`` is off)
  contribute their sensitivity times their tolerance
  (:mod:`rozyn_estimator.method.likelihood.uncertainty.sensitivity`).
- The data's own part is the sandwich covariance with its time blocks
  (:mod:`rozyn_estimator.method.likelihood.covariance`).

Without tolerances nothing is added: the estimate and its covariance are the fit's.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from rozyn_estimator.method.likelihood.config import LikelihoodConfig
from rozyn_estimator.method.likelihood.covariance import sandwich_covariance
from rozyn_estimator.method.likelihood.model import HalfCarSpectrum
from rozyn_estimator.method.likelihood.objective import WhittleObjective
from rozyn_estimator.method.likelihood.score import SandwichRatio
from rozyn_estimator.method.likelihood.uncertainty.augment import calibrate, plan
from rozyn_estimator.method.likelihood.uncertainty.calibration import (
    CALIBRATED,
    POSITION_KEYS,
    Calibration,
    calibration,
)
from rozyn_estimator.method.likelihood.uncertainty.sensitivity import Sensitivities, sensitivities_near
from rozyn_estimator.vehicle import Vehicle


@dataclass(frozen=True)
class Uncertainty:
    """The estimate after calibration, the data's covariance and the tolerances' contributions."""

    params: np.ndarray  # (m, I, lf)
    covariance: np.ndarray  # (3, 3) the data's part
    factors: np.ndarray  # the time blocks' factors on the data's variances
    contributions: dict[str, np.ndarray]  # tolerance key -> (3,) its part, one standard uncertainty
    calibration: tuple[Calibration, ...]
    objective: WhittleObjective  # the (calibrated) posterior's
    theta: np.ndarray  # its parameters at the estimate
    sensitivities: Sensitivities  # of the values left assumed (the next window's may reuse them)
    sandwich: SandwichRatio  # the model sandwich's ratio (the next window's may reuse it)
    converged: bool = True  # False: the calibration's optimiser stopped at its iteration limit


def uncertainty(
    objective: WhittleObjective, model: HalfCarSpectrum, theta: np.ndarray, vehicle: Vehicle,
    cfg: LikelihoodConfig, accel: np.ndarray, previous: Sensitivities | None = None,
    previous_sandwich: SandwichRatio | None = None,
) -> Uncertainty:
    """The budget of the fit's optimum ``theta`` (raises CovarianceError when there is none);
    ``previous`` and ``previous_sandwich``: the last window's sensitivities and sandwich ratio
    (kept while θ has barely moved)."""
    todo = plan(vehicle, model)
    stds: dict[str, float] = {}
    start = stepped = theta
    converged = True
    if cfg.self_calibrate and todo.any:
        aug = calibrate(objective, model, theta, vehicle, todo, cfg.max_iter)
        objective, model, start, stepped, stds = aug.objective, aug.model, aug.point, aug.stepped, aug.stds
        converged = aug.converged
    cov, factors, parts, ratio = sandwich_covariance(objective, model, start, cfg, accel, previous_sandwich,
                                                     (vehicle, cfg))
    contributions = {(CALIBRATED.get(name) or POSITION_KEYS[name]): c for name, c in parts.items()}
    assumed = _assumed(vehicle, cfg, set(contributions))
    sens = sensitivities_near(objective, model, start, list(assumed), vehicle, cfg, previous)
    contributions |= {key: sens.per_unit[key] * u for key, u in assumed.items()}
    found = calibration(objective, model, start, stepped, stds)
    return Uncertainty(model.physical(stepped), cov, factors, contributions, found, objective, stepped, sens,
                       ratio, converged)


def _assumed(vehicle: Vehicle, cfg: LikelihoodConfig, calibrated: set[str]) -> dict[str, float]:
    """The toleranced values the estimate rests on as assumed (neither calibrated nor fitted
    freely), with their tolerances in their own units."""
    if "sensor_gain_ratio" in calibrated:
        calibrated |= {"sensor_gain_front", "sensor_gain_rear"}
    if cfg.estimate_suspension:
        calibrated |= {key for key in CALIBRATED.values() if key.startswith("suspension_")}
    return {key: u for key, u in vehicle.tolerances.absolute(vehicle).items() if key not in calibrated}
