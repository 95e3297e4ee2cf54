"""Vehicle parameters of the 4-DOF half car and their YAML loading.

This is the one data module the plant (``sim_node``) and the observer
(``rozyn_estimator``) share. Defaults are the thesis' Table 5-1.

Coordinates: ``x`` is measured along the body from the front axle, positive rearward.
The front accelerometer sits ``sensor_front_offset_m`` behind the front axle, the rear
one ``sensor_rear_offset_m`` behind the rear axle (negative: ahead of it); both default
to 0 (on the axles). Pitch ``phi`` is positive nose up, so a point at ``x`` moves
``z(x) = z_cog + (lf - x) * phi``.
"""

from __future__ import annotations

import dataclasses
import math
from collections.abc import Mapping
from dataclasses import dataclass, fields
from pathlib import Path
from typing import Any

import yaml

from rozyn_estimator.errors import ConfigError

# Keys a vehicle YAML may hold, with the unit each value is in.
_UNITS = {
    "sprung_mass_kg": "kg",
    "pitch_inertia_kgm2": "kg*m^2",
    "cog_from_front_axle_m": "m",
    "wheelbase_m": "m",
    "unsprung_mass_front_kg": "kg",
    "unsprung_mass_rear_kg": "kg",
    "tyre_stiffness_front_npm": "N/m",
    "tyre_stiffness_rear_npm": "N/m",
    "tyre_damping_front_nspm": "N*s/m",
    "tyre_damping_rear_nspm": "N*s/m",
    "suspension_stiffness_front_npm": "N/m",
    "suspension_stiffness_rear_npm": "N/m",
    "suspension_damping_front_nspm": "N*s/m",
    "suspension_damping_rear_nspm": "N*s/m",
    "sensor_front_offset_m": "m",
    "sensor_rear_offset_m": "m",
}


_POSITIVE = frozenset(
    n for n in _UNITS if not n.startswith(("sensor_", "cog_", "tyre_damping"))
)


@dataclass(frozen=True)
class Vehicle:
    """Half-car parameters (thesis Table 5-1 by default), SI units.

    ``sprung_mass_kg``, ``pitch_inertia_kgm2`` and ``cog_from_front_axle_m`` are what
    the estimator identifies; the sim uses them as the truth. Everything else is
    assumed known to the estimator.
    """

    sprung_mass_kg: float = 1000.0
    pitch_inertia_kgm2: float = 2000.0
    cog_from_front_axle_m: float = 1.2
    wheelbase_m: float = 2.8
    unsprung_mass_front_kg: float = 40.0
    unsprung_mass_rear_kg: float = 65.0
    tyre_stiffness_front_npm: float = 200_000.0
    tyre_stiffness_rear_npm: float = 200_000.0
    tyre_damping_front_nspm: float = 50.0
    tyre_damping_rear_nspm: float = 50.0
    suspension_stiffness_front_npm: float = 45_000.0
    suspension_stiffness_rear_npm: float = 80_000.0
    suspension_damping_front_nspm: float = 2800.0
    suspension_damping_rear_nspm: float = 3500.0
    sensor_front_offset_m: float = 0.0
    sensor_rear_offset_m: float = 0.0

    def __post_init__(self) -> None:
        validate(self)

    @property
    def cog_from_rear_axle_m(self) -> float:
        """lr = wheelbase - lf [m]."""
        return self.wheelbase_m - self.cog_from_front_axle_m

    @property
    def sensor_x_m(self) -> tuple[float, float]:
        """(front, rear) sensor positions from the front axle, rearward [m]."""
        return (self.sensor_front_offset_m, self.wheelbase_m + self.sensor_rear_offset_m)

    def replace(self, **changes: float) -> Vehicle:
        """A copy with some fields changed (validated)."""
        return dataclasses.replace(self, **changes)

    def to_dict(self) -> dict[str, float]:
        return {f.name: float(getattr(self, f.name)) for f in fields(self)}


def validate(v: Vehicle) -> None:
    """Raise ConfigError naming the first invalid field of ``v``."""
    for f in fields(v):
        value = getattr(v, f.name)
        if isinstance(value, bool) or not isinstance(value, int | float):
            raise ConfigError(f"vehicle.{f.name}: expected a number, got {value!r}")
        if not math.isfinite(value):
            raise ConfigError(f"vehicle.{f.name}: must be finite, got {value!r}")
    for name in _UNITS:
        value = getattr(v, name)
        if name.startswith("tyre_damping") and value < 0.0:
            raise ConfigError(f"vehicle.{name}: must be >= 0 {_UNITS[name]}, got {value!r}")
        if name in _POSITIVE and value <= 0.0:
            raise ConfigError(f"vehicle.{name}: must be > 0 {_UNITS[name]}, got {value!r}")
    lf, wb = v.cog_from_front_axle_m, v.wheelbase_m
    if not 0.0 < lf < wb:
        raise ConfigError(
            f"vehicle.cog_from_front_axle_m: must lie between the axles "
            f"(0 < lf < wheelbase_m = {wb!r} m), got {lf!r}"
        )
    x_front, x_rear = v.sensor_x_m
    if x_rear - x_front < 0.25 * wb:
        raise ConfigError(
            "vehicle.sensor_front_offset_m / sensor_rear_offset_m: the rear accelerometer must "
            f"sit at least a quarter wheelbase behind the front one to see pitch; they are at "
            f"x = {x_front!r} m and {x_rear!r} m from the front axle"
        )


def vehicle_from_mapping(data: Mapping[str, Any], *, source: str = "vehicle") -> Vehicle:
    """Build a Vehicle from a mapping; unknown keys are refused (typos must not pass)."""
    if not isinstance(data, Mapping):
        raise ConfigError(f"{source}: expected a mapping of vehicle parameters, got {type(data).__name__}")
    unknown = sorted(set(data) - set(_UNITS))
    if unknown:
        raise ConfigError(
            f"{source}: unknown vehicle parameter(s) {', '.join(unknown)}; "
            f"known: {', '.join(_UNITS)}"
        )
    values: dict[str, float] = {}
    for key, value in data.items():
        if isinstance(value, bool) or not isinstance(value, int | float):
            raise ConfigError(f"{source}: vehicle.{key}: expected a number in {_UNITS[key]}, got {value!r}")
        values[key] = float(value)
    try:
        return Vehicle(**values)
    except ConfigError as exc:
        raise ConfigError(f"{source}: {exc}") from None


def load_vehicle(path: str | Path) -> Vehicle:
    """Load a vehicle YAML file.

    The file is either a flat mapping of the fields of :class:`Vehicle` or a ROS 2
    parameter file (``<node>: ros__parameters: vehicle: {...}``); missing fields keep
    their Table 5-1 defaults.

    Raises:
        ConfigError: the file is missing, is not YAML, or a field is invalid.
    """
    p = Path(path)
    try:
        text = p.read_text()
    except OSError as exc:
        raise ConfigError(f"{p}: cannot read vehicle file: {exc.strerror}") from None
    try:
        data = yaml.safe_load(text)
    except yaml.YAMLError as exc:
        raise ConfigError(f"{p}: not valid YAML: {exc}") from None
    return vehicle_from_mapping(_vehicle_section(data, str(p)), source=str(p))


def _vehicle_section(data: Any, source: str) -> Any:
    """Find the vehicle mapping in a flat file or a ROS 2 params file."""
    if data is None:
        return {}
    if isinstance(data, Mapping) and not (set(data) & set(_UNITS)):
        for node in data.values():
            params = node.get("ros__parameters") if isinstance(node, Mapping) else None
            if isinstance(params, Mapping) and isinstance(params.get("vehicle"), Mapping):
                return params["vehicle"]
        if isinstance(data.get("vehicle"), Mapping):
            return data["vehicle"]
    return data


def dump_vehicle(v: Vehicle) -> str:
    """The vehicle as a flat YAML mapping with units as comments."""
    lines = [f"{k}: {getattr(v, k)!r}  # {_UNITS[k]}" for k in _UNITS]
    return "\n".join(lines) + "\n"


FIELD_UNITS: Mapping[str, str] = _UNITS
