"""How the refined (m, I, lf) move with the values the fit assumes: the systematic part of
the uncertainty budget.

The fit's optimum θ̂ minimises ℓ(θ; β) for the assumed values β (suspension, tyres,
unsprung masses, wheelbase, sensor positions, and the sensors' gains and delay when they
are not self-calibrated). By the implicit-function theorem (GUM, JCGM 100 §5.1.3)

    dθ̂/dβ = -H_θθ⁻¹ H_θβ,   H_θθ = Σ_k Re tr(S⁻¹ ∂_θS S⁻¹ ∂_θS) (+ the prior),
                            H_θβ = Σ_k Re tr(S⁻¹ ∂_θS S⁻¹ ∂_βS),

the expected (Fisher) information and cross-information at θ̂: the sensitivity of the
estimator itself, not of one noisy realisation of it. ``∂_βS`` is a forward difference of
the model with ``β`` moved by a small step (the model recomputed, nothing re-fitted), and
``d(m, I, lf)/dβ = J(θ̂) dθ̂/dβ`` plus, for the wheelbase, the direct ``∂lf/∂L`` (θ holds
``lf/L``). A test checks these against the shift of the whole refinement when a value
really changes.

The information is the objective's own at θ̂ (already computed for the covariance); each
``∂_βS`` costs two evaluations of the model without derivatives. They are the model's
sensitivities at θ̂, not the data's: they change about as much as θ̂ does, so a warm update
keeps the previous window's (:func:`sensitivities_near`) while its body parameters (ln m,
ln I, logit lf/L) have moved less than 0.01 (as the full car's budget does), for the same
vehicle and settings.
"""

from __future__ import annotations

import dataclasses
from collections.abc import Callable, Sequence
from dataclasses import dataclass

import numpy as np

from rozyn_estimator.method.likelihood.config import LikelihoodConfig
from rozyn_estimator.method.likelihood.covariance import inverse_information, kept
from rozyn_estimator.method.likelihood.model import HalfCarSpectrum
from rozyn_estimator.method.likelihood.objective import WhittleObjective, whitened
from rozyn_estimator.tolerances import HEIGHT_KEYS, RELATIVE_FIELDS
from rozyn_estimator.vehicle import Vehicle

_REL_STEP = 1e-4  # relative step of a stiffness, damping or mass
_ABS_STEP = {"wheelbase_m": 1e-4, "sensor_front_offset_m": 1e-4, "sensor_rear_offset_m": 1e-4,
             "cog_height_m": 1e-4, "wheel_centre_height_m": 1e-4,
             "sensor_gain_front": 1e-4, "sensor_gain_rear": 1e-4, "sensor_time_offset_s": 1e-6}
GEOMETRY = ("wheelbase_m", "sensor_front_offset_m", "sensor_rear_offset_m", *HEIGHT_KEYS)
SENSORS = ("sensor_gain_front", "sensor_gain_rear", "sensor_time_offset_s")
ASSUMED = (*RELATIVE_FIELDS, *GEOMETRY, *SENSORS)  # every value a sensitivity can be asked for
_MOVE = 0.01  # a warm update keeps the sensitivities while ln m, ln I, logit(lf/L) move less


@dataclass(frozen=True)
class Sensitivities:
    """d(m, I, lf)/dβ per assumed value and where they were taken: the body parameters θ[:3],
    the vehicle and the settings."""

    per_unit: dict[str, np.ndarray]  # key -> (3,) per unit of the value
    body: np.ndarray  # (ln m, ln I, logit lf/L) they were taken at
    vehicle: Vehicle
    config: LikelihoodConfig


def sensitivities_near(
    objective: WhittleObjective, model: HalfCarSpectrum, theta: np.ndarray, keys: Sequence[str],
    vehicle: Vehicle, config: LikelihoodConfig, previous: Sensitivities | None = None,
) -> Sensitivities:
    """:func:`sensitivities` at θ, or ``previous`` (the last window's) when they were taken for
    the same values, vehicle and settings at body parameters within ``_MOVE`` of θ's."""
    if (previous is not None and set(previous.per_unit) == set(keys) and previous.vehicle == vehicle
            and previous.config == config and np.max(np.abs(theta[:3] - previous.body)) < _MOVE):
        return previous
    return Sensitivities(sensitivities(objective, model, theta, keys), theta[:3].copy(), vehicle, config)


def sensitivities(
    objective: WhittleObjective, model: HalfCarSpectrum, theta: np.ndarray, keys: Sequence[str]
) -> dict[str, np.ndarray]:
    """d(m, I, lf)/dβ at the optimum for each assumed value ``β`` named in ``keys`` (a
    vehicle field or a sensor key of :mod:`rozyn_estimator.tolerances`), per unit of β
    (N/m, kg, m, a share of the gain, s).

    Raises:
        CovarianceError: the information at θ̂ is not positive definite.
    """
    if not keys:
        return {}
    info = objective.fisher(theta)  # the prior's included
    S, _ = objective.model_at(theta)
    rows = objective.whitened_rows(theta)
    keep = kept(objective, model, theta, info)
    solve = inverse_information(info[np.ix_(keep, keep)])
    jac = model.physical_jacobian(theta)[:, keep]
    p = model.physical(theta)[2] / model.wheelbase_m
    out = {}
    for key in keys:
        dS_beta = _model_derivative(model, theta, key, S, objective.restrict)
        cross = rows[keep] @ whitened(S, dS_beta[None])[0]  # Σ_k tr(S⁻¹ ∂_θS S⁻¹ ∂_βS)
        out[key] = -jac @ (solve @ cross)
        if key == "wheelbase_m":
            out[key][2] += p  # lf = (lf/L) L: θ holds the share
    return out


def _model_derivative(
    model: HalfCarSpectrum, theta: np.ndarray, key: str, S: np.ndarray,
    restrict: Callable[[np.ndarray], np.ndarray],
) -> np.ndarray:
    """∂S/∂β (as the fit sees it: ``restrict``) by a forward difference of the model at θ
    (``S`` the model there, restricted; the step is 1e-4 of the value: the difference's own
    error, O(step), is far below what it feeds)."""
    v = model.vehicle
    h = _REL_STEP * getattr(v, key) if key in RELATIVE_FIELDS else _ABS_STEP[key]
    _perturbed(model, v, key, h)
    try:
        moved = model.spectrum(theta, derivatives=False)[0]
    finally:
        model.set_vehicle(v)
    return (restrict(moved) - S) / h


def _perturbed(model: HalfCarSpectrum, v: Vehicle, key: str, delta: float) -> None:
    """Set the model's assumed values to ``v``'s with ``key`` moved by ``delta``."""
    if key == "sensor_time_offset_s":
        model.set_vehicle(v, time_offset_s=delta)
    elif key == "sensor_gain_rear":
        model.set_vehicle(v, rear_gain=1.0 + delta)
    elif key == "sensor_gain_front":  # the front's gain against the rear's (the common scale is σ²'s)
        model.set_vehicle(v, rear_gain=1.0 / (1.0 + delta))
    else:
        model.set_vehicle(dataclasses.replace(v, **{key: getattr(v, key) + delta}))
