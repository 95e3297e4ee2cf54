"""The full car's uncertainty budget for Rozyn's stage: the jackknife's statistical part and
what every toleranced value contributes (GUM type B), as :mod:`rozyn_estimator.method.budget`
does for the half car: the linear fit repeated on the same measured modes with the value
moved a small step, times its tolerance.

The full car's tolerances (:class:`~rozyn_estimator.vehicle_full.FullTolerances`) are the
half car's per axle (a share applies to both corners of that axle; a sensor offset to the
``x`` of that axle's sensors) plus the tracks, the anti-roll bars and the sensors' lateral
positions (each sensor's on its own: independent errors, one contribution each).
"""

from __future__ import annotations

from collections.abc import Callable, Sequence

import numpy as np

from rozyn_estimator.method.budget import GROUPS, Budget
from rozyn_estimator.method.full.fit import FULL_PARAM_NAMES, fit_full_inertia
from rozyn_estimator.method.full.uncertainty.moves import (
    ABS_STEP,
    AXLE,
    moved_copy,
    vehicle_moves,
)
from rozyn_estimator.method.identification import IdentificationError, Mode
from rozyn_estimator.vehicle_full import FullVehicle

_GROUPS = {**GROUPS, "track": "tracks", "anti_roll": "anti-roll bars", "sensor_lateral": "sensor positions",
           "gyro_misalignment": "gyro turns"}


class FullBudget(Budget):
    """The half car's :class:`~rozyn_estimator.method.budget.Budget` over the full car's five
    parameters and its own tolerances (tracks, anti-roll bars, lateral sensor positions)."""

    NAMES = FULL_PARAM_NAMES

    @staticmethod
    def group(key: str) -> str:
        return next((label for prefix, label in _GROUPS.items() if key.startswith(prefix)), key)


def full_contributions(v: FullVehicle, modes: Sequence[Mode], sensors: Sequence[int], params: np.ndarray,
                       model: str) -> dict[str, np.ndarray]:
    """Contributions ``c_j`` (5,) of each toleranced value of ``v`` to the fit's estimate."""
    out = {}
    for key, tol in v.tolerances.applying(v).items():
        for name, step, move in _moves(v, key, sensors):
            try:
                vehicle, sensed = move(step)
                moved = fit_full_inertia(vehicle, [sensed(md) for md in modes], sensors, model)
            except IdentificationError:  # at the edge of the physical range: the stage's result stands
                continue
            out[name] = (moved - params) / step * tol
    return out


Move = Callable[[float], tuple[FullVehicle, Callable[[Mode], Mode]]]


def _moves(v: FullVehicle, key: str, sensors: Sequence[int]) -> list[tuple[str, float, Move]]:
    """(contribution name, step, the vehicle and the sensing with the value moved by the step)."""
    def same(md: Mode) -> Mode:
        return md

    def unsensed(move: Callable[[float], FullVehicle]) -> Move:
        return lambda h: (move(h), same)

    def sensed(corners: tuple[int, ...], factor: Callable[[Mode], complex]) -> Callable[[Mode], Mode]:
        cols = [j for j, s in enumerate(sensors) if s in corners]

        def apply(md: Mode) -> Mode:
            shape = list(md.shape)
            for j in cols:
                shape[j] *= factor(md)
            return Mode(md.eigenvalue, tuple(shape), md.amplitude)
        return apply

    alike = vehicle_moves(v, key, sensors)
    if alike is not None:
        return [(name, step, unsensed(move)) for name, step, move in alike]
    axle = "front" if "_front" in key else "rear"
    if key in ("sensor_front_offset_m", "sensor_rear_offset_m"):
        def shifted(h: float) -> FullVehicle:
            xs = list(v.sensor_x_m)
            for c in AXLE[axle]:
                xs[c] += h
            return moved_copy(v, sensor_x_m=tuple(xs))
        return [(key, ABS_STEP, unsensed(shifted))]
    if key.startswith("sensor_gain"):
        # the estimator undoes the gain it assumes: the measured shape divided by (1 + h)
        return [(key, ABS_STEP, lambda h: (v, sensed(AXLE[axle], lambda md: 1.0 / (1.0 + h))))]
    if key == "sensor_time_offset_s":  # the rear sensors late by h: their components turned by e^(sh)
        return [(key, ABS_STEP,
                 lambda h: (v, sensed(AXLE["rear"], lambda md: complex(np.exp(md.eigenvalue * h)))))]
    return []
