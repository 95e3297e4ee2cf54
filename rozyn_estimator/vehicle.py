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
from collections.abc import Mapping
from dataclasses import dataclass, fields
from pathlib import Path
from typing import Any, ClassVar

import yaml

from rozyn_estimator.errors import ConfigError
from rozyn_estimator.parameters import build, check, param, spec_of
from rozyn_estimator.tolerances import Tolerances


@dataclass(frozen=True)
class Vehicle:
    """Half-car parameters (thesis Table 5-1 by default), SI units.

    ``sprung_mass_kg``, ``pitch_inertia_kgm2`` and ``cog_from_front_axle_m`` are what
    the estimator identifies; the sim uses them as the truth. Everything else is
    assumed known to the estimator, to its ``tolerances``.
    """

    PARAM_PREFIX: ClassVar[str] = "vehicle."

    sprung_mass_kg: float = param(1000.0, "sprung mass (the simulator's truth)", unit="kg",
                                  low=0.0, open_low=True)
    pitch_inertia_kgm2: float = param(2000.0, "pitch moment of inertia of the sprung mass (the simulator's "
                                      "truth)", unit="kg*m^2", low=0.0, open_low=True)
    cog_from_front_axle_m: float = param(1.2, "centre of gravity behind the front axle (the simulator's "
                                         "truth)", unit="m")
    wheelbase_m: float = param(2.8, "wheelbase", unit="m", low=0.0, open_low=True)
    unsprung_mass_front_kg: float = param(40.0, "unsprung mass of the front corner", unit="kg",
                                          low=0.0, open_low=True)
    unsprung_mass_rear_kg: float = param(65.0, "unsprung mass of the rear corner", unit="kg",
                                         low=0.0, open_low=True)
    tyre_stiffness_front_npm: float = param(200_000.0, "front tyre vertical stiffness", unit="N/m",
                                            low=0.0, open_low=True)
    tyre_stiffness_rear_npm: float = param(200_000.0, "rear tyre vertical stiffness", unit="N/m",
                                           low=0.0, open_low=True)
    tyre_damping_front_nspm: float = param(50.0, "front tyre damping", unit="N*s/m", low=0.0)
    tyre_damping_rear_nspm: float = param(50.0, "rear tyre damping", unit="N*s/m", low=0.0)
    suspension_stiffness_front_npm: float = param(45_000.0, "front suspension stiffness", unit="N/m",
                                                  low=0.0, open_low=True)
    suspension_stiffness_rear_npm: float = param(80_000.0, "rear suspension stiffness", unit="N/m",
                                                 low=0.0, open_low=True)
    suspension_damping_front_nspm: float = param(2800.0, "front suspension damping", unit="N*s/m",
                                                 low=0.0, open_low=True)
    suspension_damping_rear_nspm: float = param(3500.0, "rear suspension damping", unit="N*s/m",
                                                low=0.0, open_low=True)
    sensor_front_offset_m: float = param(0.0, "front accelerometer behind the front axle", unit="m")
    sensor_rear_offset_m: float = param(0.0, "rear accelerometer behind the rear axle (negative: ahead of "
                                        "it)", unit="m")
    tolerances: Tolerances = param(description="standard uncertainties of the assumed values",
                                   default_factory=Tolerances)

    def __post_init__(self) -> None:
        check(self, _RULES)

    @property
    def cog_from_rear_axle_m(self) -> float:
        """lr = wheelbase - lf [m]."""
        return self.wheelbase_m - self.cog_from_front_axle_m

    @property
    def sensor_x_m(self) -> tuple[float, float]:
        """(front, rear) sensor positions from the front axle, rearward [m]."""
        return (self.sensor_front_offset_m, self.wheelbase_m + self.sensor_rear_offset_m)

    def replace(self, **changes: Any) -> Vehicle:
        """A copy with some fields changed (validated)."""
        return dataclasses.replace(self, **changes)

    def to_dict(self) -> dict[str, Any]:
        """The fields (floats) and ``tolerances`` (a mapping), as a vehicle file holds them."""
        out: dict[str, Any] = {name: float(getattr(self, name)) for name in FIELD_UNITS}
        out["tolerances"] = self.tolerances.to_dict()
        return out


_RULES = (
    ("cog_from_front_axle_m", lambda v: 0.0 < v.cog_from_front_axle_m < v.wheelbase_m,
     "must lie between the axles (0 < lf < wheelbase_m)"),
    ("sensor_rear_offset_m", lambda v: v.sensor_x_m[1] - v.sensor_x_m[0] >= 0.25 * v.wheelbase_m,
     "the rear accelerometer must sit at least a quarter wheelbase behind the front one to see pitch "
     "(sensor_front_offset_m is measured from the front axle, sensor_rear_offset_m from the rear one)"),
)
FIELD_UNITS: Mapping[str, str] = {
    f.name: spec.unit for f in fields(Vehicle) if (spec := spec_of(f)) is not None and f.name != "tolerances"
}
"""The numeric keys a vehicle YAML may hold, with the unit each value is in (and ``tolerances``)."""


def vehicle_from_mapping(data: Mapping[str, Any], *, source: str = "vehicle") -> Vehicle:
    """Build a Vehicle from a mapping; unknown keys are refused (typos must not pass)."""
    if not isinstance(data, Mapping):
        raise ConfigError(f"{source}: expected a mapping of vehicle parameters, got {type(data).__name__}")
    unknown = sorted(str(k) for k in set(data) - {*FIELD_UNITS, "tolerances"})
    if unknown:
        raise ConfigError(
            f"{source}: unknown vehicle parameter(s) {', '.join(unknown)}; "
            f"known: {', '.join(FIELD_UNITS)}, tolerances"
        )
    values = dict(data)
    try:
        if "tolerances" in values:
            values["tolerances"] = Tolerances.from_mapping(values["tolerances"], source)
        return Vehicle(**values)
    except ConfigError as exc:
        text = str(exc)
        raise ConfigError(text if text.startswith(source) else f"{source}: {text}") from None


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
    if isinstance(data, Mapping) and not (set(data) & {*FIELD_UNITS, "tolerances"}):
        for node in data.values():
            params = node.get("ros__parameters") if isinstance(node, Mapping) else None
            if isinstance(params, Mapping) and isinstance(params.get("vehicle"), Mapping):
                return params["vehicle"]
        if isinstance(data.get("vehicle"), Mapping):
            return data["vehicle"]
    return data


def dump_vehicle(v: Vehicle) -> str:
    """The vehicle as a flat YAML mapping with units as comments."""
    lines = [f"{k}: {getattr(v, k)!r}  # {unit}" for k, unit in FIELD_UNITS.items()]
    lines.append("tolerances:  # standard uncertainties: shares of the values, or m, or s")
    lines += [f"  {k}: {value!r}" for k, value in v.tolerances.to_dict().items()]
    return "\n".join(lines) + "\n"



def vehicle_from_parameters(values: Mapping[str, Any]) -> Vehicle:
    """The vehicle of a node: ``vehicle_file`` when set, else the ``vehicle.*`` values (each
    ``vehicle.tolerances.*`` one overrides its default)."""
    if values.get("vehicle_file"):
        return load_vehicle(values["vehicle_file"])
    vehicle: Vehicle = build(Vehicle(), {k: v for k, v in values.items() if k.startswith("vehicle.")})
    return vehicle


def config_from_parameters(default: Any, values: Mapping[str, Any]) -> Any:
    """A config dataclass with a ``vehicle`` field (the nodes'), built from flat ROS values:
    the vehicle from ``vehicle_file`` or ``vehicle.*``, the rest by name (ConfigError names
    the first invalid parameter)."""
    others = {k: v for k, v in values.items() if not k.startswith("vehicle.")}
    return dataclasses.replace(build(default, others), vehicle=vehicle_from_parameters(values))
