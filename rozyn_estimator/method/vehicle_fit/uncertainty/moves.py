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

from rozyn_estimator.body_model import AnyVehicle, corners_of
from rozyn_estimator.method.vehicle_fit.corner_matrices import CORNER_VALUES
from rozyn_estimator.tolerances import HEIGHT_KEYS
from rozyn_estimator.vehicle_full import FullVehicle

REL_STEP = 1e-5  # share of a value
ABS_STEP = 1e-6  # m, s or share of a gain
_QUADS = {"suspension_stiffness": "suspension_stiffness_npm", "suspension_damping": "suspension_damping_nspm",
          "tyre_stiffness": "tyre_stiffness_npm", "tyre_damping": "tyre_damping_nspm",
          "unsprung_mass": "unsprung_mass_kg"}
AXLE = {"front": (0, 1), "rear": (2, 3)}
_HALF_AXLE = {"front": (0,), "rear": (1,)}
# the half car's corner values: its tolerance keys are its fields
_HALF_CORNERS = tuple(f"{name.rsplit('_', 1)[0]}_{axle}_{name.rsplit('_', 1)[1]}"
                      for name in CORNER_VALUES[:5] for axle in ("front", "rear"))
_HALF_SENSORS = ("sensor_front_offset_m", "sensor_rear_offset_m")

VehicleMove = Callable[[float], AnyVehicle]
V = TypeVar("V", bound=AnyVehicle)


def axle_channels(v: AnyVehicle, axle: str) -> tuple[int, ...]:
    """The vehicle's channel slots on ``axle`` (``front``, ``rear``): the full car's two corners',
    the half car's one."""
    return (AXLE if isinstance(v, FullVehicle) else _HALF_AXLE)[axle]


def axle_of(v: AnyVehicle, channel: int) -> str:
    """``front`` or ``rear``: the axle of the vehicle's channel slot."""
    return "front" if channel in axle_channels(v, "front") else "rear"


def corner_fields(v: AnyVehicle) -> tuple[str, ...]:
    """The vehicle's fields that hold its corner values."""
    return CORNER_VALUES if isinstance(v, FullVehicle) else _HALF_CORNERS


def sensor_fields(v: AnyVehicle) -> tuple[str, ...]:
    """The vehicle's fields that hold its sensors' positions."""
    return ("sensor_x_m", "sensor_y_m") if isinstance(v, FullVehicle) else _HALF_SENSORS


def values_of(v: AnyVehicle) -> np.ndarray:
    """The corner values, flat: each corner's (suspension stiffness, damping, tyre stiffness,
    damping, unsprung mass) by quantity, then the full car's bars [N m/rad] (the directions of
    :func:`~rozyn_estimator.method.vehicle_fit.corner_matrices.corner_response_derivatives`)."""
    c = corners_of(v)
    bars = [v.anti_roll_stiffness_front_nmprad, v.anti_roll_stiffness_rear_nmprad] \
        if isinstance(v, FullVehicle) else []
    return np.concatenate([c.suspension_stiffness_npm, c.suspension_damping_nspm, c.tyre_stiffness_npm,
                           c.tyre_damping_nspm, c.unsprung_mass_kg, bars]).astype(float)


def moved_copy(v: AnyVehicle, **changes: Any) -> Any:
    """``v`` with values moved a tiny step, without the vehicle's validation (a few ms a time,
    the budgets' largest cost otherwise): the step cannot leave the valid range."""
    out = copy.copy(v)
    for name, value in changes.items():
        object.__setattr__(out, name, value)
    return out


def shifted_sensor(v: AnyVehicle, channel: int, h: float) -> AnyVehicle:
    """``v`` with the sensor of channel slot ``channel`` ``h`` metres further back."""
    if not isinstance(v, FullVehicle):
        field = _HALF_SENSORS[channel]
        return moved_copy(v, **{field: getattr(v, field) + h})
    xs = list(v.sensor_x_m)
    xs[channel] += h
    return moved_copy(v, sensor_x_m=tuple(xs))


def vehicle_moves(v: V, key: str,
                  sensors: Sequence[int]) -> list[tuple[str, float, Callable[[float], V]]] | None:
    """(contribution name, step, the vehicle with the value moved by the step) of a tolerance
    key that moves the vehicle alike for both budgets: an axle's corner values, an anti-roll
    bar, the wheelbase, tracks and heights, each sensor's lateral position; None for the other
    keys (the sensors' offsets, gains and timing: each budget moves those its own way)."""
    if key in ("wheelbase_m", "track_front_m", "track_rear_m", *HEIGHT_KEYS):
        return [(key, ABS_STEP, lambda h: moved_copy(v, **{key: getattr(v, key) + h}))]
    if not isinstance(v, FullVehicle):
        if key in _HALF_CORNERS:
            return [(key, REL_STEP, lambda h: moved_copy(v, **{key: getattr(v, key) * (1 + h)}))]
        return None
    return _full_moves(v, key, sensors)  # type: ignore[return-value]  # V is FullVehicle here


def _full_moves(v: FullVehicle, key: str,
                sensors: Sequence[int]) -> list[tuple[str, float, VehicleMove]] | None:
    """:func:`vehicle_moves` of the full car's keys."""
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
        return [(key, REL_STEP, lambda h: scaled(quad, AXLE[axle], h))]
    if key.startswith("anti_roll"):
        bar = getattr(v, key)
        return [] if bar == 0 else [(key, REL_STEP, lambda h: moved_copy(v, **{key: bar * (1 + h)}))]
    if key == "sensor_lateral_m":
        return [(f"{key}[{v.channel_names[c]}]", ABS_STEP, lateral(c)) for c in sensors
                if v.channel_kinds[c] == "accel_z"]  # a gyro reads the same rotation anywhere
    return None
