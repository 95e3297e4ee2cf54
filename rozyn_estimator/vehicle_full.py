"""Vehicle parameters of the 7-DOF full car and their YAML loading (the half car's
:mod:`rozyn_estimator.vehicle` reused: YAML safety, messages, tolerances, the sensors block).

Coordinates and signs:

- ``x`` along the body from the front axle, positive rearward (as the half car); ``y``
  lateral, positive to the left (REP 103); ``z`` up.
- Pitch ``phi`` positive nose up, as the half car (minus REP 103's pitch about +y);
  roll ``theta`` positive left side up: REP 103's roll, right-handed about +x forward.
  A body point at ``(x, y)`` moves ``z + (lf - x) phi + (y - y_cog) theta`` (small angles).
- Corners in the order FL, FR, RL, RR; every per-corner tuple and every four-channel
  array follows it. The left wheels sit at ``y = +track/2``, the right ones at ``-track/2``.

Defaults: Table 5-1's car with each axle's values split over its two corners, so that
:func:`centreline_half_car` of the defaults is the default :class:`Vehicle` (why and the
rest: docs/simulator.md, "Full car").

Anti-roll bars are given as the roll stiffness each adds to its axle, in N*m/rad
(:class:`rozyn_estimator.corners.Bar`).
"""

from __future__ import annotations

import dataclasses
from collections.abc import Mapping
from dataclasses import dataclass, fields
from pathlib import Path
from typing import Any, ClassVar

import numpy as np

from rozyn_estimator.corners import Bar, Corners, corners_from
from rozyn_estimator.errors import ConfigError
from rozyn_estimator.parameters import Param, build, check, param, spec_of
from rozyn_estimator.sensors import (
    Channel,
    SensorSet,
    full_car_channels,
    sensors_from_parameters,
)
from rozyn_estimator.tolerances import FullTolerances
from rozyn_estimator.vehicle import (
    HEIGHTS_RULE,
    MAX_VEHICLE_FILE_BYTES,
    Vehicle,
    _vehicle_section,
    built_vehicle,
    dumped,
    split_vehicle_mapping,
    vehicle_from_mapping,
    vehicle_from_parameters,
)
from rozyn_estimator.yaml_file import load_yaml_file, one_line

CORNERS = ("front_left", "front_right", "rear_left", "rear_right")
MODELS = ("half", "full")
MODEL_PARAM = Param("vehicle model: half (front and rear accelerometers, the vehicle.* parameters of the "
                    "half car) or full (corner accelerometers, those of the full car); a vehicle_file's own "
                    "model: key decides for it", choices=MODELS, read_only=True)
"""The nodes' ``vehicle.model`` parameter (default ``half``)."""
Quad = tuple[float, float, float, float]
Slots = tuple[float, ...]  # the sensors' positions: four corners', or a sensors block's channels'
_POSITIVE: dict[str, Any] = {"low": 0.0, "open_low": True, "length": 4}


@dataclass(frozen=True)
class FullVehicle:
    """Full-car parameters, SI units; see the module's docstring for coordinates and defaults.

    ``sprung_mass_kg``, ``roll_inertia_kgm2``, ``pitch_inertia_kgm2``,
    ``cog_from_front_axle_m`` and ``cog_lateral_m`` are the simulator's truth (what a
    full-car estimator identifies); the rest is assumed known, to its ``tolerances``.
    The body's principal axes are taken as x and y (no product of inertia).

    Example:
        >>> v = FullVehicle(cog_lateral_m=0.05)
        >>> v.corner_y_m
        (0.75, -0.75, 0.75, -0.75)
        >>> centreline_half_car(FullVehicle()) == Vehicle()
        True
    """

    PARAM_PREFIX: ClassVar[str] = "vehicle."
    ROLLS: ClassVar[bool] = True  # the body heaves, pitches and rolls (rozyn_estimator.body_model)
    CORNER_COUNT: ClassVar[int] = 4  # FL, FR, RL, RR
    FRONT_SLOTS: ClassVar[tuple[int, ...]] = (0, 1)  # channel slots taking the front's tolerances
    CORNER_FIELDS: ClassVar[tuple[str, ...]] = (  # the fields holding the corners' and bars' values
        "suspension_stiffness_npm", "suspension_damping_nspm", "tyre_stiffness_npm", "tyre_damping_nspm",
        "unsprung_mass_kg", "anti_roll_stiffness_front_nmprad", "anti_roll_stiffness_rear_nmprad")
    SENSOR_FIELDS: ClassVar[tuple[str, ...]] = ("sensor_x_m", "sensor_y_m")  # the sensors' positions

    sprung_mass_kg: float = param(1000.0, "sprung mass (the simulator's truth)", unit="kg", low=0.0,
                                  open_low=True)
    pitch_inertia_kgm2: float = param(2000.0, "pitch moment of inertia of the sprung mass (the simulator's "
                                      "truth)", unit="kg*m^2", low=0.0, open_low=True)
    roll_inertia_kgm2: float = param(400.0, "roll moment of inertia of the sprung mass about its centre of "
                                     "gravity (the simulator's truth)", unit="kg*m^2", low=0.0, open_low=True)
    cog_from_front_axle_m: float = param(1.2, "centre of gravity behind the front axle (the simulator's "
                                         "truth)", unit="m")
    cog_lateral_m: float = param(0.0, "centre of gravity left of the centreline (negative: right of it; the "
                                 "simulator's truth)", unit="m")
    wheelbase_m: float = param(2.8, "wheelbase", unit="m", low=0.0, open_low=True)
    track_front_m: float = param(1.5, "front track width (between the wheels' centres)", unit="m", low=0.0,
                                 open_low=True)
    track_rear_m: float = param(1.5, "rear track width", unit="m", low=0.0, open_low=True)
    unsprung_mass_kg: Quad = param((20.0, 20.0, 32.5, 32.5), "unsprung mass of each corner (FL, FR, RL, RR)",
                                   unit="kg", **_POSITIVE)
    tyre_stiffness_npm: Quad = param((100_000.0,) * 4, "tyre vertical stiffness of each corner", unit="N/m",
                                     **_POSITIVE)
    tyre_damping_nspm: Quad = param((25.0,) * 4, "tyre damping of each corner", unit="N*s/m", low=0.0,
                                    length=4)
    suspension_stiffness_npm: Quad = param((22_500.0, 22_500.0, 40_000.0, 40_000.0), "suspension stiffness "
                                           "of each corner (at the wheel)", unit="N/m", **_POSITIVE)
    suspension_damping_nspm: Quad = param((1400.0, 1400.0, 1750.0, 1750.0), "suspension damping of each "
                                          "corner (at the wheel)", unit="N*s/m", **_POSITIVE)
    anti_roll_stiffness_front_nmprad: float = param(0.0, "roll stiffness the front anti-roll bar adds (0: "
                                                    "none)", unit="N*m/rad", low=0.0)
    anti_roll_stiffness_rear_nmprad: float = param(0.0, "roll stiffness the rear anti-roll bar adds (0: "
                                                   "none)", unit="N*m/rad", low=0.0)
    sensor_x_m: Slots = param((0.0, 0.0, 2.8, 2.8), "accelerometers (FL, FR, RL, RR) behind the front axle "
                              "(a sensors block: its channels')", unit="m")
    sensor_y_m: Slots = param((0.75, -0.75, 0.75, -0.75), "accelerometers (FL, FR, RL, RR) left of the "
                              "centreline (a sensors block: its channels')", unit="m")
    cog_height_m: float = param(0.0, "centre of gravity above the road (0, with wheel_centre_height_m 0: "
                                "not given, and the weight's pitch and roll moments through the geometry not "
                                "carried; rozyn_estimator.gravity)", unit="m", low=0.0)
    wheel_centre_height_m: float = param(0.0, "wheel centres above the road (the loaded tyres' radius; "
                                         "0: not given)", unit="m", low=0.0)
    tolerances: FullTolerances = param(description="standard uncertainties of the assumed values",
                                       default_factory=FullTolerances)
    # the sensors block (rozyn_estimator.sensors; None: the four corner accelerometers). Its
    # channels take sensor_x_m/sensor_y_m's first slots (with_sensors): the budget perturbs those.
    sensors: SensorSet | None = dataclasses.field(default=None)

    def __post_init__(self) -> None:
        check(self, _RULES)

    @property
    def cog_from_rear_axle_m(self) -> float:
        """lr = wheelbase - lf [m]."""
        return self.wheelbase_m - self.cog_from_front_axle_m

    @property
    def corners(self) -> Corners:
        """The four corners and the two bars (each axle's, zero where there is none)."""
        bars = (Bar(0, self.track_front_m, self.anti_roll_stiffness_front_nmprad),
                Bar(2, self.track_rear_m, self.anti_roll_stiffness_rear_nmprad))
        return corners_from(self.corner_x_m, self.corner_y_m, self.unsprung_mass_kg,
                            (self.suspension_stiffness_npm, self.suspension_damping_nspm),
                            (self.tyre_stiffness_npm, self.tyre_damping_nspm), bars)

    @property
    def body_values(self) -> np.ndarray:
        """What the estimator identifies, in the likelihood's order: (m, I_xx, I_yy, l_f, y_c)
        [kg, kg m², kg m², m, m]."""
        return np.array([self.sprung_mass_kg, self.roll_inertia_kgm2, self.pitch_inertia_kgm2,
                         self.cog_from_front_axle_m, self.cog_lateral_m])

    def with_body_values(self, values: np.ndarray) -> FullVehicle:
        """A copy with :attr:`body_values` replaced (validated: ConfigError where they are not a car)."""
        m, ixx, iyy, lf, yc = (float(x) for x in values)
        return self.replace(sprung_mass_kg=m, roll_inertia_kgm2=ixx, pitch_inertia_kgm2=iyy,
                            cog_from_front_axle_m=lf, cog_lateral_m=yc)

    @property
    def coherence_track_m(self) -> float:  # the two road tracks' coherence's scale: the front track [m]
        return self.track_front_m

    def with_corner_sensors(self) -> FullVehicle:
        """A copy with accelerometers above the wheels for any sensors block (Rozyn's stage's: method.imu)."""
        return self.replace(sensors=None, sensor_x_m=self.corner_x_m, sensor_y_m=self.corner_y_m)

    def sensor_shift(self, channel: int, h_m: float) -> dict[str, Slots]:
        """The field changes that move the sensor of channel slot ``channel`` ``h_m`` further back."""
        return {"sensor_x_m": tuple(x + h_m * (i == channel) for i, x in enumerate(self.sensor_x_m))}

    @property
    def corner_x_m(self) -> Quad:
        """The corners' ``x`` (FL, FR, RL, RR) behind the front axle [m]."""
        return (0.0, 0.0, self.wheelbase_m, self.wheelbase_m)

    @property
    def corner_y_m(self) -> Quad:
        """The corners' ``y`` (FL, FR, RL, RR), positive left [m]."""
        f, r = 0.5 * self.track_front_m, 0.5 * self.track_rear_m
        return (f, -f, r, -r)

    @property
    def channels(self) -> tuple[Channel, ...]:
        """The four corner accelerometers (named for their corners), or a sensors block's channels
        (:func:`~rozyn_estimator.sensors.full_car_channels`) at their slots of ``sensor_x_m``/``_y_m``."""
        if self.sensors is None:
            return tuple(Channel(c, "accel_z", "", x, y)
                         for c, x, y in zip(CORNERS, self.sensor_x_m, self.sensor_y_m, strict=True))
        chans = full_car_channels(self.sensors, self.wheelbase_m, self.track_front_m)
        return tuple(dataclasses.replace(c, x_m=self.sensor_x_m[i], y_m=self.sensor_y_m[i])
                     for i, c in enumerate(chans))

    @property
    def channel_names(self) -> tuple[str, ...]:  # how messages name the channels: corners or labels
        return CORNERS if self.sensors is None else tuple(c.label for c in self.channels)

    @property
    def channel_kinds(self) -> tuple[str, ...]:  # each slot's channel: accel_z, gyro_x or gyro_y
        return ("accel_z",) * 4 if self.sensors is None else tuple(c.kind for c in self.channels)

    @property
    def channel_late(self) -> tuple[bool, ...]:
        """Each slot's channel runs on the clock the timing tolerance (``sensor_time_offset_s``)
        puts late: the rear corners', or a block's sensors but the first (one IMU: none)."""
        if self.sensors is None:
            return (False, False, True, True)
        first = self.sensors.sensors[0].name
        return tuple(c.sensor != first for c in self.channels)

    def with_sensors(self, sensors: SensorSet | None) -> FullVehicle:
        """A copy with a ``sensors`` block: channel ``i`` at slot ``i`` of ``sensor_x_m``/``_y_m``
        (at least four slots: the rest repeat the last); one sensor has one clock (no timing tolerance)."""
        if sensors is None:
            return self.replace(sensors=None)
        chans = full_car_channels(sensors, self.wheelbase_m, self.track_front_m)
        slots = [*chans, *[chans[-1]] * max(0, 4 - len(chans))]
        tolerances = self.tolerances
        if len(sensors.sensors) == 1:
            tolerances = dataclasses.replace(tolerances, sensor_time_offset_s=0.0)
        return self.replace(sensors=sensors, sensor_x_m=tuple(c.x_m for c in slots),
                            sensor_y_m=tuple(c.y_m for c in slots), tolerances=tolerances)

    @property
    def is_symmetric(self) -> bool:
        """Left and right alike (values, CoG): heave and pitch do not couple with roll, and
        :func:`centreline_half_car` is exact."""
        pairs = (self.unsprung_mass_kg, self.tyre_stiffness_npm, self.tyre_damping_nspm,
                 self.suspension_stiffness_npm, self.suspension_damping_nspm)
        return self.cog_lateral_m == 0.0 and all(p[0] == p[1] and p[2] == p[3] for p in pairs)

    def replace(self, **changes: Any) -> FullVehicle:
        """A copy with some fields changed (validated)."""
        return dataclasses.replace(self, **changes)

    def to_dict(self) -> dict[str, Any]:
        """``model: full``, the fields (floats, lists of four) and ``tolerances``, as a vehicle file
        holds them."""
        out: dict[str, Any] = {"model": "full"}
        for name in FULL_FIELD_UNITS:
            value = getattr(self, name)
            out[name] = [float(x) for x in value] if isinstance(value, tuple) else float(value)
        out["tolerances"] = self.tolerances.to_dict()
        if self.sensors is not None:
            out["sensors"] = self.sensors.to_dict()
        return out


def _spans(v: FullVehicle) -> tuple[float, float]:
    """(the rear sensors' mean x less the front ones', the left ones' mean y less the right ones')."""
    x, y = v.sensor_x_m, v.sensor_y_m
    return (x[2] + x[3] - x[0] - x[1]) / 2, (y[0] + y[2] - y[1] - y[3]) / 2


def _slots(v: FullVehicle) -> int:
    """How many sensor positions the vehicle holds: four corners', or one per channel of its block
    (at least four)."""
    return 4 if v.sensors is None else max(4, len(v.sensors.channels))


_RULES = (
    HEIGHTS_RULE,
    ("sensor_x_m", lambda v: len(v.sensor_x_m) == _slots(v),
     "must hold four positions (FL, FR, RL, RR), or one per channel of the sensors block (at least four)"),
    ("sensor_y_m", lambda v: len(v.sensor_y_m) == len(v.sensor_x_m),
     "must hold as many positions as sensor_x_m"),
    ("cog_from_front_axle_m", lambda v: 0.0 < v.cog_from_front_axle_m < v.wheelbase_m,
     "must lie between the axles (0 < lf < wheelbase_m)"),
    ("cog_lateral_m", lambda v: abs(v.cog_lateral_m) < 0.5 * min(v.track_front_m, v.track_rear_m),
     "must lie between the wheels (|y_cog| < half the narrower track)"),
    ("sensors", lambda v: v.sensors is None or (isinstance(v.sensors, SensorSet) and bool(v.channels)),
     "must be a sensors block the full car can use (rozyn_estimator.sensors)"),
    ("sensor_x_m", lambda v: v.sensors is not None or _spans(v)[0] >= 0.25 * v.wheelbase_m,
     "the rear accelerometers (RL, RR) must sit on average at least a quarter wheelbase behind the front "
     "ones (FL, FR) to see pitch"),
    ("sensor_y_m", lambda v: v.sensors is not None or _spans(v)[1] >= 0.25 * v.track_front_m,
     "the left accelerometers (FL, RL) must sit on average at least a quarter front track left of the right "
     "ones (FR, RR) to see roll"),
)
FULL_FIELD_UNITS: Mapping[str, str] = {
    f.name: spec.unit for f in fields(FullVehicle)
    if (spec := spec_of(f)) is not None and f.name != "tolerances"
}
"""The keys a full-car vehicle file may hold besides ``model`` and ``tolerances``, with their units."""


def centreline_half_car(v: FullVehicle) -> Vehicle:
    """The half car whose heave and pitch are the symmetric full car's, exactly.

    Each axle's values are the sums of its two corners' (the thesis' half car lumps an
    axle's wheels); mass, pitch inertia and CoG are the full car's. Its sensors sit at the
    mean ``x`` of the front (FL, FR) and of the rear (RL, RR) accelerometers: the mean of a
    left and a right sensor at equal ``|y|`` reads the centreline. Driven by the mean of
    the left and right road tracks it gives the full car's heave and pitch
    (``test_fullcar``). Anti-roll bars and tracks act on roll only.

    Raises:
        ConfigError: ``v`` is not symmetric (then heave and pitch couple with roll and no
            half car describes them).
    """
    if not v.is_symmetric or v.sensors is not None:
        raise ConfigError("vehicle: a centreline half car needs a symmetric full car (equal left and right "
                          "corners, cog_lateral_m 0) with its corner accelerometers")

    def axles(values: Quad) -> tuple[float, float]:
        return values[0] + values[1], values[2] + values[3]

    x = v.sensor_x_m
    return Vehicle(
        sprung_mass_kg=v.sprung_mass_kg, pitch_inertia_kgm2=v.pitch_inertia_kgm2,
        cog_from_front_axle_m=v.cog_from_front_axle_m, wheelbase_m=v.wheelbase_m,
        **_axle_fields("unsprung_mass_{}_kg", axles(v.unsprung_mass_kg)),
        **_axle_fields("tyre_stiffness_{}_npm", axles(v.tyre_stiffness_npm)),
        **_axle_fields("tyre_damping_{}_nspm", axles(v.tyre_damping_nspm)),
        **_axle_fields("suspension_stiffness_{}_npm", axles(v.suspension_stiffness_npm)),
        **_axle_fields("suspension_damping_{}_nspm", axles(v.suspension_damping_nspm)),
        sensor_front_offset_m=(x[0] + x[1]) / 2, sensor_rear_offset_m=(x[2] + x[3]) / 2 - v.wheelbase_m,
        cog_height_m=v.cog_height_m, wheel_centre_height_m=v.wheel_centre_height_m,
        tolerances=v.tolerances.half_car(),
    )


def _axle_fields(pattern: str, values: tuple[float, float]) -> dict[str, Any]:
    return {pattern.format("front"): values[0], pattern.format("rear"): values[1]}


def full_vehicle_from_mapping(data: Mapping[str, Any], *, source: str = "vehicle") -> FullVehicle:
    """Build a FullVehicle from a mapping (``model: full`` optional); unknown keys are refused."""
    values, sensors = split_vehicle_mapping(data, source)
    model = values.pop("model", "full")
    if model != "full":
        raise ConfigError(f"{source}: model: expected full for a full-car vehicle, got "
                          f"{one_line(repr(model))}")
    full: FullVehicle = built_vehicle(FullVehicle, FullTolerances, values, sensors, FULL_FIELD_UNITS,
                                      "full-car vehicle parameter(s)", ("sensor_x_m", "sensor_y_m"), source)
    return full


def any_vehicle_from_mapping(data: Mapping[str, Any], *, source: str = "vehicle") -> Vehicle | FullVehicle:
    """A :class:`FullVehicle` when the mapping says ``model: full``, else a half-car :class:`Vehicle`
    (``model: half`` or no ``model``: the half car stays the default)."""
    model = data.get("model", "half") if isinstance(data, Mapping) else "half"
    if model not in MODELS:
        raise ConfigError(f"{source}: model: must be one of {', '.join(MODELS)}, got {one_line(repr(model))}")
    if model == "full":
        return full_vehicle_from_mapping(data, source=source)
    return vehicle_from_mapping(data, source=source)


def load_any_vehicle(path: str | Path) -> Vehicle | FullVehicle:
    """Load a vehicle file, half car or (with ``model: full``) full car.

    The file is a flat mapping or a ROS 2 parameter file, read as safely as
    :func:`rozyn_estimator.vehicle.load_vehicle` reads it; missing fields keep their defaults.

    Raises:
        ConfigError: the file is missing, malformed, or a field is invalid or unknown (one
            line naming the file and the field).
    """
    p = Path(path)
    data = load_yaml_file(p, max_bytes=MAX_VEHICLE_FILE_BYTES, what="vehicle file")
    return any_vehicle_from_mapping(_vehicle_section(data, str(p)), source=str(p))


def any_vehicle_from_parameters(values: Mapping[str, Any]) -> Vehicle | FullVehicle:
    """The vehicle of a node from its flat parameter values: ``vehicle_file`` when set (a full
    car when the file says ``model: full``), else the ``vehicle.*`` values of the model
    ``vehicle.model`` names (``half`` by default).

    Raises:
        ConfigError: an invalid value or file, or ``vehicle.model`` full with a half car's
            vehicle file.
    """
    model = values.get("vehicle.model", "half")
    if model not in MODELS:
        raise ConfigError(f"vehicle.model: must be one of {', '.join(MODELS)}, got {one_line(repr(model))}")
    if values.get("vehicle_file"):
        vehicle = load_any_vehicle(values["vehicle_file"])
        if model == "full" and not isinstance(vehicle, FullVehicle):
            path = one_line(str(values["vehicle_file"]))
            raise ConfigError(f"vehicle.model is full but vehicle_file {path} is a half car's (a full car's "
                              "file says model: full)")
        return vehicle
    if model == "full":
        given = {k: v for k, v in values.items() if k.startswith("vehicle.") and
                 not k.startswith("vehicle.sensors.")}
        full: FullVehicle = build(FullVehicle(), given)
        sensors = sensors_from_parameters(values)  # vehicle.sensors.* (a parameter file's sensors block)
        return full if sensors is None else full.with_sensors(sensors)
    return vehicle_from_parameters(values)


def load_full_vehicle(path: str | Path) -> FullVehicle:
    """Load a full-car vehicle file (it must say ``model: full``).

    Raises:
        ConfigError: as :func:`load_any_vehicle`, or the file is a half car's.
    """
    vehicle = load_any_vehicle(path)
    if not isinstance(vehicle, FullVehicle):
        raise ConfigError(f"{one_line(str(path))}: a half-car vehicle file; a full car's says model: full "
                          "(see config/vehicle_full.yaml)")
    return vehicle


def dump_full_vehicle(v: FullVehicle) -> str:
    """The vehicle as a flat YAML mapping (``model: full`` first) with units as comments."""
    return dumped(v, FULL_FIELD_UNITS, ("model: full",))


__all__ = ["CORNERS", "FULL_FIELD_UNITS", "MODEL_PARAM", "FullTolerances", "FullVehicle",
           "any_vehicle_from_mapping", "any_vehicle_from_parameters", "centreline_half_car",
           "dump_full_vehicle", "full_vehicle_from_mapping", "load_any_vehicle", "load_full_vehicle"]
