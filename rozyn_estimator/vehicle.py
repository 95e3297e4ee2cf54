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

import numpy as np
import yaml

from rozyn_estimator.corners import Corners, corners_from
from rozyn_estimator.errors import ConfigError
from rozyn_estimator.parameters import build, check, param, spec_of
from rozyn_estimator.sensors import (
    Channel,
    SensorSet,
    half_car_channels,
    same_positions,
    sensors_from_mapping,
    sensors_from_parameters,
)
from rozyn_estimator.tolerances import Tolerances
from rozyn_estimator.yaml_file import load_yaml_file, one_line


@dataclass(frozen=True)
class Vehicle:
    """Half-car parameters (thesis Table 5-1 by default), SI units.

    ``sprung_mass_kg``, ``pitch_inertia_kgm2`` and ``cog_from_front_axle_m`` are what
    the estimator identifies; the sim uses them as the truth. Everything else is
    assumed known to the estimator, to its ``tolerances``.
    """

    PARAM_PREFIX: ClassVar[str] = "vehicle."
    ROLLS: ClassVar[bool] = False  # the body heaves and pitches (rozyn_estimator.body_model)
    CORNER_COUNT: ClassVar[int] = 2  # the front and the rear axle
    FRONT_SLOTS: ClassVar[tuple[int, ...]] = (0,)  # channel slots taking the front's tolerances
    CORNER_FIELDS: ClassVar[tuple[str, ...]] = tuple(  # the fields holding the corners' values
        f"{value}_{axle}_{unit}" for value, unit in (
            ("suspension_stiffness", "npm"), ("suspension_damping", "nspm"), ("tyre_stiffness", "npm"),
            ("tyre_damping", "nspm"), ("unsprung_mass", "kg")) for axle in ("front", "rear"))
    SENSOR_FIELDS: ClassVar[tuple[str, ...]] = ("sensor_front_offset_m", "sensor_rear_offset_m",
                                                "channel_x_m")  # the fields holding the sensors' positions

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
    cog_height_m: float = param(0.0, "centre of gravity above the road (0, with wheel_centre_height_m 0: "
                                "not given, and the weight's pitch moment through the geometry not carried; "
                                "rozyn_estimator.gravity)", unit="m", low=0.0)
    wheel_centre_height_m: float = param(0.0, "wheel centres above the road (the loaded tyres' radius; "
                                         "0: not given)", unit="m", low=0.0)
    tolerances: Tolerances = param(description="standard uncertainties of the assumed values",
                                   default_factory=Tolerances)
    # the sensors block (rozyn_estimator.sensors; None: the two accelerometers at the offsets above);
    # with_sensors places its channels at channel_x_m (the budget perturbs those) and its first two
    # also at the offsets (as a written file holds them)
    sensors: SensorSet | None = dataclasses.field(default=None)
    # a sensors block's channels' positions behind the front axle [m], in channels' order (with_sensors
    # places them; the budget moves them); empty without a block
    channel_x_m: tuple[float, ...] = dataclasses.field(default=())

    def __post_init__(self) -> None:
        check(self, _RULES)

    @property
    def cog_from_rear_axle_m(self) -> float:
        """lr = wheelbase - lf [m]."""
        return self.wheelbase_m - self.cog_from_front_axle_m

    @property
    def cog_lateral_m(self) -> float:
        """The half car's centre of gravity sits on its centreline: 0 [m]."""
        return 0.0

    @property
    def corners(self) -> Corners:
        """The front and rear axle, each lumped on the centreline (the one model's two corners)."""
        return corners_from((0.0, self.wheelbase_m), (0.0, 0.0),
                            (self.unsprung_mass_front_kg, self.unsprung_mass_rear_kg),
                            ((self.suspension_stiffness_front_npm, self.suspension_stiffness_rear_npm),
                             (self.suspension_damping_front_nspm, self.suspension_damping_rear_nspm)),
                            ((self.tyre_stiffness_front_npm, self.tyre_stiffness_rear_npm),
                             (self.tyre_damping_front_nspm, self.tyre_damping_rear_nspm)))

    @property
    def body_values(self) -> np.ndarray:
        """What the estimator identifies, in the likelihood's order: (m, I_yy, l_f) [kg, kg m², m]."""
        return np.array([self.sprung_mass_kg, self.pitch_inertia_kgm2, self.cog_from_front_axle_m])

    def with_body_values(self, values: np.ndarray) -> Vehicle:
        """A copy with :attr:`body_values` replaced (validated: ConfigError where they are not a car)."""
        m, iyy, lf = (float(x) for x in values)
        return self.replace(sprung_mass_kg=m, pitch_inertia_kgm2=iyy, cog_from_front_axle_m=lf)

    @property
    def coherence_track_m(self) -> float:
        """The track the two road tracks' coherence is scaled by: none, one track (0) [m]."""
        return 0.0

    def with_corner_sensors(self) -> Vehicle:
        """A copy with two accelerometers on the axles in place of any sensors block (the channels
        Rozyn's stage reads: :mod:`rozyn_estimator.method.imu`)."""
        return self.replace(sensors=None, sensor_front_offset_m=0.0, sensor_rear_offset_m=0.0)

    def sensor_shift(self, channel: int, h_m: float) -> dict[str, Any]:
        """The field changes that move the sensor of channel slot ``channel`` ``h_m`` further back."""
        if self.sensors is not None:
            return {"channel_x_m": tuple(x + h_m * (i == channel) for i, x in enumerate(self.channel_x_m))}
        field = ("sensor_front_offset_m", "sensor_rear_offset_m")[channel]
        return {field: getattr(self, field) + h_m}

    @property
    def sensor_x_m(self) -> tuple[float, ...]:
        """Each channel's position from the front axle, rearward [m]: the front and rear
        accelerometers', or a sensors block's channels'."""
        if self.sensors is not None:
            return self.channel_x_m
        return (self.sensor_front_offset_m, self.wheelbase_m + self.sensor_rear_offset_m)

    @property
    def channels(self) -> tuple[Channel, ...]:
        """The channels the model fits, at :attr:`sensor_x_m`: the front and rear accelerometers,
        or a block's (accelerometers front to rear, then gyros:
        :func:`~rozyn_estimator.sensors.half_car_channels`)."""
        x = self.sensor_x_m
        if self.sensors is None:
            return Channel("front", "accel_z", "", x[0]), Channel("rear", "accel_z", "", x[1])
        chans = half_car_channels(self.sensors, self.wheelbase_m)
        return tuple(dataclasses.replace(c, x_m=xi) for c, xi in zip(chans, x, strict=True))

    @property
    def channel_names(self) -> tuple[str, ...]:
        """How messages name the channels: ``front``/``rear``, or a sensors block's labels."""
        return ("front", "rear") if self.sensors is None else tuple(c.label for c in self.channels)

    @property
    def sensor_y_m(self) -> tuple[float, ...]:
        """The half car's sensors sit on its centreline: ``y = 0`` [m]."""
        return (0.0,) * len(self.sensor_x_m)

    @property
    def channel_kinds(self) -> tuple[str, ...]:
        """Each channel's kind: ``accel_z`` or a pitch gyro's ``gyro_y``."""
        return ("accel_z", "accel_z") if self.sensors is None else tuple(c.kind for c in self.channels)

    @property
    def channel_late(self) -> tuple[bool, ...]:
        """Each channel runs on the clock the timing tolerance (``sensor_time_offset_s``) puts
        late: the rear sensor's, or a block's sensors but the first's (one IMU: none)."""
        if self.sensors is None:
            return (False, True)
        first = self.channels[0].sensor
        return tuple(c.sensor != first for c in self.channels)

    @property
    def pitch_gyro(self) -> bool:
        """A sensors block with a pitch gyro (``gyro_y``)."""
        return self.sensors is not None and any(c.kind == "gyro_y" for c in self.sensors.channels)

    def with_sensors(self, sensors: SensorSet | None) -> Vehicle:
        """A copy with the sensors of a ``sensors`` block at their positions (the first two also
        as the offsets, as a written file holds them); ConfigError for a set the half car cannot use."""
        if sensors is None:
            return self.replace(sensors=None, channel_x_m=())
        chans = half_car_channels(sensors, self.wheelbase_m)
        tolerances = self.tolerances
        if all(c.kind == "gyro_y" for c in chans[1:]):  # a gyro reads the same pitch anywhere: no error
            tolerances = dataclasses.replace(tolerances, sensor_rear_offset_m=0.0)
        return self.replace(sensors=sensors, sensor_front_offset_m=chans[0].x_m,
                            sensor_rear_offset_m=chans[1].x_m - self.wheelbase_m,
                            channel_x_m=tuple(c.x_m for c in chans), tolerances=tolerances)

    def replace(self, **changes: Any) -> Vehicle:
        """A copy with some fields changed (validated)."""
        return dataclasses.replace(self, **changes)

    def to_dict(self) -> dict[str, Any]:
        """The fields (floats), ``tolerances`` (a mapping) and any ``sensors`` block, as a vehicle
        file holds them."""
        out: dict[str, Any] = {name: float(getattr(self, name)) for name in FIELD_UNITS}
        out["tolerances"] = self.tolerances.to_dict()
        if self.sensors is not None:
            out["sensors"] = self.sensors.to_dict()
        return out


HEIGHTS_RULE = ("wheel_centre_height_m", lambda v: (v.cog_height_m > 0) == (v.wheel_centre_height_m > 0),
                "give both heights (cog_height_m and wheel_centre_height_m, above the road) or neither")
_RULES = (
    HEIGHTS_RULE,
    ("cog_from_front_axle_m", lambda v: 0.0 < v.cog_from_front_axle_m < v.wheelbase_m,
     "must lie between the axles (0 < lf < wheelbase_m)"),
    ("channel_x_m",
     lambda v: not isinstance(v.sensors, SensorSet) or len(v.channel_x_m) == len(v.sensors.channels),
     "must hold one position per channel of the sensors block (Vehicle.with_sensors places them)"),
    ("sensors", lambda v: v.sensors is None or (isinstance(v.sensors, SensorSet) and bool(v.channels)),
     "must be a sensors block the half car can use (rozyn_estimator.sensors)"),
    ("sensor_rear_offset_m",
     lambda v: v.sensors is not None or v.sensor_x_m[1] - v.sensor_x_m[0] >= 0.25 * v.wheelbase_m,
     "the rear accelerometer must sit at least a quarter wheelbase behind the front one to see pitch "
     "(sensor_front_offset_m is measured from the front axle, sensor_rear_offset_m from the rear one)"),
)
FIELD_UNITS: Mapping[str, str] = {
    f.name: spec.unit for f in fields(Vehicle) if (spec := spec_of(f)) is not None and f.name != "tolerances"
}
"""The numeric keys a vehicle YAML may hold, with the unit each value is in (and ``tolerances``)."""


def vehicle_from_mapping(data: Mapping[str, Any], *, source: str = "vehicle") -> Vehicle:
    """Build a Vehicle from a mapping; unknown keys are refused (typos must not pass)."""
    values, sensors = split_vehicle_mapping(data, source)
    if values.get("model", "half") != "half":  # a full car's file says model: full (vehicle_full)
        raise ConfigError(f"{source}: model: a half-car vehicle has model half, got "
                          f"{one_line(repr(values['model']))} (full-car files are read by "
                          "rozyn_estimator.vehicle_full.load_any_vehicle)")
    values.pop("model", None)
    return built_vehicle(Vehicle, Tolerances, values, sensors, FIELD_UNITS, "vehicle parameter(s)",
                         ("sensor_front_offset_m", "sensor_rear_offset_m"), source)


def split_vehicle_mapping(data: Any, source: str) -> tuple[dict[str, Any], SensorSet | None]:
    """(the mapping's other keys, its ``sensors`` block read) of a vehicle file's mapping."""
    if not isinstance(data, Mapping):
        raise ConfigError(f"{source}: expected a mapping of vehicle parameters, got {type(data).__name__}")
    values = dict(data)
    sensors = sensors_from_mapping(values.pop("sensors"), source) if "sensors" in values else None
    return values, sensors


def built_vehicle(cls: Any, tolerances: Any, values: dict[str, Any], sensors: SensorSet | None,
                  known: Mapping[str, str], what: str, positions: tuple[str, ...], source: str) -> Any:
    """Either car's vehicle from a file's ``values`` (``model`` taken out) and ``sensors`` block.

    Args:
        cls: the vehicle class (:class:`Vehicle`, ``FullVehicle``).
        tolerances: its tolerances' class (``from_mapping`` reads the ``tolerances`` key).
        values: the file's keys but ``sensors`` and ``model``; unknown ones are refused.
        sensors: the ``sensors`` block, which places the sensors (None: the fields do).
        known: the keys ``values`` may hold besides ``tolerances`` (``cls``'s fields).
        what: what the message calls the keys (``vehicle parameter(s)``).
        positions: the fields the block places; a file may hold them too where they agree (a
            written file's do).
        source: the file, for messages.

    Raises:
        ConfigError: one line naming the file and the key.
    """
    given = {k: values.pop(k) for k in positions if sensors is not None and k in values}
    unknown = sorted(str(k) for k in set(values) - {*known, "tolerances"})
    if unknown:
        raise ConfigError(f"{source}: unknown {what} {_listed(unknown)}; known: {', '.join(known)}, model, "
                          "tolerances, sensors")
    try:
        if "tolerances" in values:
            values["tolerances"] = tolerances.from_mapping(values["tolerances"], source)
        vehicle = cls(**values)
        if sensors is None:
            return vehicle
        placed = vehicle.with_sensors(sensors)
        if any(not same_positions(v, getattr(placed, k)) for k, v in given.items()):
            raise ConfigError(f"{source}: give the sensors' positions in the sensors block or as "
                              f"{'/'.join(positions)}, not both")
        return placed
    except ConfigError as exc:
        raise ConfigError(one_line(str(exc) if str(exc).startswith(source) else f"{source}: {exc}")) from None


def _listed(names: list[str], shown: int = 10) -> str:
    """Names for a message: the first few, each cut short (a file may hold thousands)."""
    cut = [one_line(n, 60) for n in names[:shown]]
    more = f" and {len(names) - shown} more" if len(names) > shown else ""
    return ", ".join(cut) + more


MAX_VEHICLE_FILE_BYTES = 1 << 20  # a vehicle file is about 2 kB; a ROS 2 parameter file far below this


def load_vehicle(path: str | Path) -> Vehicle:
    """Load a vehicle YAML file.

    The file is either a flat mapping of the fields of :class:`Vehicle` or a ROS 2
    parameter file (``<node>: ros__parameters: vehicle: {...}``); missing fields keep
    their Table 5-1 defaults. At most :data:`MAX_VEHICLE_FILE_BYTES` are read (see
    :func:`load_yaml_file` for what else is refused).

    Raises:
        ConfigError: the file is missing, too large, not UTF-8, not YAML, or a field is
            invalid (one line naming the file and the field).
    """
    p = Path(path)
    data = load_yaml_file(p, max_bytes=MAX_VEHICLE_FILE_BYTES, what="vehicle file")
    return vehicle_from_mapping(_vehicle_section(data, str(p)), source=str(p))


def _vehicle_section(data: Any, source: str) -> Any:
    """Find the vehicle mapping in a flat file or a ROS 2 params file."""
    if data is None:
        return {}
    if isinstance(data, Mapping) and not (set(data) & {*FIELD_UNITS, "tolerances", "sensors"}):
        for node in data.values():
            params = node.get("ros__parameters") if isinstance(node, Mapping) else None
            if isinstance(params, Mapping) and isinstance(params.get("vehicle"), Mapping):
                return params["vehicle"]
        if isinstance(data.get("vehicle"), Mapping):
            return data["vehicle"]
        if set(data) == {"vehicle"} and data["vehicle"] is None:  # "vehicle:" with nothing under it
            return {}
    return data


def dump_vehicle(v: Vehicle) -> str:
    """The vehicle as a flat YAML mapping with units as comments."""
    return dumped(v, FIELD_UNITS)


def dumped(v: Any, units: Mapping[str, str], first: tuple[str, ...] = ()) -> str:
    """Either car's vehicle as a flat YAML mapping: ``first`` lines, the fields of ``units``
    (a per-corner tuple as a list) with their units as comments, the tolerances, the sensors block."""
    lines = list(first)
    for key, unit in units.items():
        value = getattr(v, key)
        shown = f"[{', '.join(repr(float(x)) for x in value)}]" if isinstance(value, tuple) else repr(value)
        lines.append(f"{key}: {shown}  # {unit}")
    lines.append("tolerances:  # standard uncertainties: shares of the values, or m, or s")
    lines += [f"  {k}: {value!r}" for k, value in v.tolerances.to_dict().items()]
    text = "\n".join(lines) + "\n"
    if v.sensors is not None:
        text += yaml.safe_dump({"sensors": v.sensors.to_dict()}, sort_keys=False)
    return text



def vehicle_from_parameters(values: Mapping[str, Any]) -> Vehicle:
    """The vehicle of a node: ``vehicle_file`` when set, else the ``vehicle.*`` values (each
    ``vehicle.tolerances.*`` one overrides its default)."""
    if values.get("vehicle_file"):
        return load_vehicle(values["vehicle_file"])
    vehicle: Vehicle = build(Vehicle(), {k: v for k, v in values.items() if k.startswith("vehicle.")})
    sensors = sensors_from_parameters(values)  # vehicle.sensors.* (a parameter file's sensors block)
    return vehicle if sensors is None else vehicle.with_sensors(sensors)


def config_from_parameters(default: Any, values: Mapping[str, Any]) -> Any:
    """A config dataclass with a ``vehicle`` field (the nodes'), built from flat ROS values:
    the vehicle from ``vehicle_file`` or ``vehicle.*``, the rest by name (ConfigError names
    the first invalid parameter)."""
    others = {k: v for k, v in values.items() if not k.startswith("vehicle.")}
    return dataclasses.replace(build(default, others), vehicle=vehicle_from_parameters(values))
