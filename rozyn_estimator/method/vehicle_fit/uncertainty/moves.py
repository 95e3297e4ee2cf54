"""How a tolerance moves the vehicle, for either car: the values a tolerance key names, moved a
small step (the budgets' and the corners' calibration's common ground).

The full car's tolerances (:class:`~rozyn_estimator.tolerances.FullTolerances`) are the half
car's per axle: a share applies to both corners of that axle, a sensor offset to the ``x`` of
that axle's sensors; the half car's name its own fields (its front or rear corner, its front or
rear sensor). Either's corner values are :func:`values_of`: each corner's spring, damper, tyre
and unsprung mass, then the full car's anti-roll bars.
"""

from __future__ import annotations

import copy
from collections.abc import Callable, Sequence
from typing import Any, TypeVar

import numpy as np

from rozyn_estimator.body_model import AnyVehicle
from rozyn_estimator.tolerances import HEIGHT_KEYS

REL_STEP = 1e-5  # share of a value
ABS_STEP = 1e-6  # m, s or share of a gain
_QUADS = {"suspension_stiffness": "suspension_stiffness_npm", "suspension_damping": "suspension_damping_nspm",
          "tyre_stiffness": "tyre_stiffness_npm", "tyre_damping": "tyre_damping_nspm",
          "unsprung_mass": "unsprung_mass_kg"}

_AXLE_CORNERS = {"front": (0, 1), "rear": (2, 3)}  # the full car's corners on each axle
VehicleMove = Callable[[float], AnyVehicle]
V = TypeVar("V", bound=AnyVehicle)


def axle_channels(v: AnyVehicle, axle: str) -> tuple[int, ...]:
    """The vehicle's channel slots whose sensors take ``axle``'s tolerances (``front``, ``rear``):
    the full car's first two, the half car's first; the rest are the rear's."""
    if axle == "front":
        return v.FRONT_SLOTS
    return tuple(c for c in range(len(v.sensor_x_m)) if c not in v.FRONT_SLOTS)


def axle_of(v: AnyVehicle, channel: int) -> str:
    """``front`` or ``rear``: the axle of the vehicle's channel slot."""
    return "front" if channel in axle_channels(v, "front") else "rear"


def values_of(v: AnyVehicle) -> np.ndarray:
    """The corner values, flat: each corner's (suspension stiffness, damping, tyre stiffness,
    damping, unsprung mass) by quantity, then the full car's bars [N m/rad] (the directions of
    :func:`~rozyn_estimator.method.vehicle_fit.corner_matrices.corner_response_derivatives`)."""
    return v.corners.values


def moved_copy(v: AnyVehicle, **changes: Any) -> Any:
    """``v`` with values moved a tiny step, without the vehicle's validation (a few ms a time,
    the budgets' largest cost otherwise): the step cannot leave the valid range."""
    out = copy.copy(v)
    for name, value in changes.items():
        object.__setattr__(out, name, value)
    return out


def shifted_sensor(v: AnyVehicle, channel: int, h: float) -> AnyVehicle:
    """``v`` with the sensor of channel slot ``channel`` ``h`` metres further back."""
    return moved_copy(v, **v.sensor_shift(channel, h))


def vehicle_moves(v: V, key: str,
                  sensors: Sequence[int]) -> list[tuple[str, float, Callable[[float], V]]] | None:
    """(contribution name, step, the vehicle with the value moved by the step) of a tolerance
    key that moves the vehicle alike for both budgets: an axle's corner values, an anti-roll
    bar, the wheelbase, tracks and heights, each sensor's lateral position; None for the other
    keys (the sensors' offsets, gains and timing: each budget moves those its own way)."""
    if key in ("wheelbase_m", "track_front_m", "track_rear_m", *HEIGHT_KEYS):
        return [(key, ABS_STEP, lambda h: moved_copy(v, **{key: getattr(v, key) + h}))]
    if key in v.CORNER_FIELDS:  # a value of its own (the half car's corners, the full car's bars)
        value = getattr(v, key)
        return [] if value == 0 else [(key, REL_STEP, lambda h: moved_copy(v, **{key: value * (1 + h)}))]
    return _axle_moves(v, key, sensors)


def _axle_moves(v: V, key: str,
                sensors: Sequence[int]) -> list[tuple[str, float, Callable[[float], V]]] | None:
    """:func:`vehicle_moves` of the keys that name a share of an axle's corners' values and the
    sensors' lateral positions (the full car's tolerances)."""
    def scaled(quad: str, corners: tuple[int, ...], h: float) -> V:
        values = list(getattr(v, quad))
        for c in corners:
            values[c] *= 1.0 + h
        return moved_copy(v, **{quad: tuple(values)})

    def lateral(c: int) -> Callable[[float], V]:
        def move(h: float) -> V:
            ys = list(v.sensor_y_m)
            ys[c] += h
            return moved_copy(v, sensor_y_m=tuple(ys))
        return move

    axle = "front" if "_front" in key else "rear"
    quad = next((q for k, q in _QUADS.items() if key.startswith(k)), None)
    if quad is not None:
        return [(key, REL_STEP, lambda h: scaled(quad, _AXLE_CORNERS[axle], h))]
    if key == "sensor_lateral_m":
        return [(f"{key}[{v.channel_names[c]}]", ABS_STEP, lateral(c)) for c in sensors
                if v.channel_kinds[c] == "accel_z"]  # a gyro reads the same rotation anywhere
    return None
