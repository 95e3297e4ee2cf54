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

import copy
from collections.abc import Callable, Sequence
from typing import Any

import numpy as np

from rozyn_estimator.method.budget import GROUPS, Budget
from rozyn_estimator.method.full.fit import FULL_PARAM_NAMES, fit_full_inertia
from rozyn_estimator.method.identification import IdentificationError, Mode
from rozyn_estimator.tolerances import HEIGHT_KEYS
from rozyn_estimator.vehicle_full import FullVehicle

_REL_STEP = 1e-5  # share of a value
ABS_STEP = 1e-6  # m, s or share of a gain
_GROUPS = {**GROUPS, "track": "tracks", "anti_roll": "anti-roll bars", "sensor_lateral": "sensor positions",
           "gyro_misalignment": "gyro turns"}
_QUADS = {"suspension_stiffness": "suspension_stiffness_npm", "suspension_damping": "suspension_damping_nspm",
          "tyre_stiffness": "tyre_stiffness_npm", "tyre_damping": "tyre_damping_nspm",
          "unsprung_mass": "unsprung_mass_kg"}
AXLE = {"front": (0, 1), "rear": (2, 3)}


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


VehicleMove = Callable[[float], FullVehicle]
Move = Callable[[float], tuple[FullVehicle, Callable[[Mode], Mode]]]


def moved_copy(v: FullVehicle, **changes: Any) -> FullVehicle:
    """``v`` with values moved a tiny step, without FullVehicle's validation (a few ms a time,
    the budgets' largest cost otherwise): the step cannot leave the valid range."""
    out = copy.copy(v)
    for name, value in changes.items():
        object.__setattr__(out, name, value)
    return out


def vehicle_moves(v: FullVehicle, key: str,
                  sensors: Sequence[int]) -> list[tuple[str, float, VehicleMove]] | None:
    """(contribution name, step, the vehicle with the value moved by the step) of a tolerance
    key that moves the vehicle alike for both budgets: an axle's corner values, an anti-roll
    bar, the wheelbase and tracks, each sensor's lateral position; None for the other keys
    (the sensors' offsets, gains and timing: each budget moves those its own way)."""
    def scaled(quad: str, corners: tuple[int, ...], h: float) -> FullVehicle:
        values = list(getattr(v, quad))
        for c in corners:
            values[c] *= 1.0 + h
        return moved_copy(v, **{quad: tuple(values)})

    def lateral(c: int) -> VehicleMove:
        def move(h: float) -> FullVehicle:
            ys = list(v.sensor_y_m)
            ys[c] += h
            return moved_copy(v, sensor_y_m=tuple(ys))
        return move

    axle = "front" if "_front" in key else "rear"
    quad = next((q for k, q in _QUADS.items() if key.startswith(k)), None)
    if quad is not None:
        return [(key, _REL_STEP, lambda h: scaled(quad, AXLE[axle], h))]
    if key.startswith("anti_roll"):
        bar = getattr(v, key)
        return [] if bar == 0 else [(key, _REL_STEP, lambda h: moved_copy(v, **{key: bar * (1 + h)}))]
    if key in ("wheelbase_m", "track_front_m", "track_rear_m", *HEIGHT_KEYS):
        return [(key, ABS_STEP, lambda h: moved_copy(v, **{key: getattr(v, key) + h}))]
    if key == "sensor_lateral_m":
        return [(f"{key}[{v.channel_names[c]}]", ABS_STEP, lateral(c)) for c in sensors
                if v.channel_kinds[c] == "accel_z"]  # a gyro reads the same rotation anywhere
    return None


def _moves(v: FullVehicle, key: str, sensors: Sequence[int]) -> list[tuple[str, float, Move]]:
    """(contribution name, step, the vehicle and the sensing with the value moved by the step)."""
    def same(md: Mode) -> Mode:
        return md

    def unsensed(move: VehicleMove) -> Move:
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
