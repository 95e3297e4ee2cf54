"""The body's sensors as data: where each sits and which channels of its ``sensor_msgs/Imu`` it gives.

A vehicle file may hold a ``sensors`` block (REP 103/145: x forward, y left, z up)::

    sensors:
      names: [imu]
      imu:
        topic: /imu/data            # sensor_msgs/msg/Imu
        x_m: 1.5                    # behind the front axle
        y_m: 0.0                    # left of the centreline
        channels: [accel_z, gyro_y]

A channel is one number of the message: ``accel_z`` (``linear_acceleration.z``, the vertical
specific force, +g at rest), ``gyro_y`` (``angular_velocity.y``, the pitch rate, positive when
the nose dips), ``gyro_x`` (``angular_velocity.x``, the roll rate, positive when the left side
rises). Without the block a half car has today's two accelerometers (``front_topic`` at
``sensor_front_offset_m``, ``rear_topic`` at ``sensor_rear_offset_m``), which is the block's
preset. This module holds the data and checks what the half car can use; the model reads the
channels through :func:`rozyn_estimator.body_model.sensor_rows`.
"""

from __future__ import annotations

import functools
import math
from collections.abc import Mapping, Sequence
from dataclasses import dataclass
from typing import Any

import numpy as np

from rozyn_estimator.errors import ConfigError

CHANNEL_FIELDS: Mapping[str, str] = {
    "accel_z": "linear_acceleration.z",
    "gyro_x": "angular_velocity.x",
    "gyro_y": "angular_velocity.y",
}
"""Each channel kind and the ``sensor_msgs/Imu`` field it reads."""
CHANNEL_UNITS: Mapping[str, str] = {"accel_z": "m/s^2", "gyro_x": "rad/s", "gyro_y": "rad/s"}
_SENSOR_KEYS = ("topic", "x_m", "y_m", "channels")
MAX_SENSORS = 16


@dataclass(frozen=True)
class Sensor:
    """One body sensor publishing ``sensor_msgs/Imu``."""

    name: str  # the sensor's name in the vehicle file (and in diagnostics)
    topic: str  # its sensor_msgs/msg/Imu topic
    x_m: float  # behind the front axle [m]
    y_m: float = 0.0  # left of the centreline [m]
    channels: tuple[str, ...] = ("accel_z",)  # of CHANNEL_FIELDS, in the order given


@dataclass(frozen=True)
class Channel:
    """One channel the estimator fits: a sensor's accel_z or gyro."""

    sensor: str  # the sensor's name
    kind: str  # accel_z, gyro_x or gyro_y
    topic: str  # the sensor's topic
    x_m: float  # the sensor's position behind the front axle [m]
    y_m: float = 0.0  # its position left of the centreline [m]

    @property
    def field(self) -> str:
        """The ``sensor_msgs/Imu`` field the channel reads."""
        return CHANNEL_FIELDS[self.kind]

    @property
    def label(self) -> str:
        """``imu.gyro_y``: how diagnostics and errors name it."""
        return f"{self.sensor}.{self.kind}"


@dataclass(frozen=True)
class SensorSet:
    """The sensors of a vehicle file's ``sensors`` block, in the order of ``names``."""

    sensors: tuple[Sensor, ...]

    @property
    def channels(self) -> tuple[Channel, ...]:
        """Every sensor's channels, sensor by sensor."""
        return tuple(Channel(s.name, kind, s.topic, s.x_m, s.y_m)
                     for s in self.sensors for kind in s.channels)

    def to_dict(self) -> dict[str, Any]:
        """The block as a vehicle file holds it."""
        out: dict[str, Any] = {"names": [s.name for s in self.sensors]}
        for s in self.sensors:
            out[s.name] = {"topic": s.topic, "x_m": s.x_m, "y_m": s.y_m, "channels": list(s.channels)}
        return out

    def describe(self) -> str:
        """``imu (/imu/data, x 1.50 m): accel_z, gyro_y``: one line for a log (``y`` where not 0)."""
        return "; ".join(f"{s.name} ({s.topic}, x {s.x_m:.2f} m{f', y {s.y_m:.2f} m' if s.y_m else ''}): "
                         f"{', '.join(s.channels)}" for s in self.sensors)


def sensors_from_mapping(data: Any, source: str = "sensors") -> SensorSet:
    """The ``sensors`` block of a vehicle file; ConfigError naming what is wrong."""
    where = f"{source}: sensors"
    if not isinstance(data, Mapping):
        raise ConfigError(f"{where}: expected a mapping with names and one entry per name, got "
                          f"{type(data).__name__}")
    names = data.get("names")
    if not isinstance(names, list) or not names or not all(isinstance(n, str) and n for n in names):
        raise ConfigError(f"{where}: names must be a non-empty list of sensor names, e.g. names: [imu]")
    if len(names) > MAX_SENSORS or len(set(names)) != len(names):
        raise ConfigError(f"{where}: names must be distinct and at most {MAX_SENSORS}, got {len(names)}")
    unknown = sorted(str(k) for k in set(data) - {"names", *names})
    if unknown:
        raise ConfigError(f"{where}: {', '.join(unknown[:5])} not in names {names}")
    return SensorSet(tuple(_sensor(name, data.get(name), f"{where}.{name}") for name in names))


def _sensor(name: str, entry: Any, where: str) -> Sensor:
    if not isinstance(entry, Mapping):
        raise ConfigError(f"{where}: expected a mapping of {', '.join(_SENSOR_KEYS)}")
    unknown = sorted(str(k) for k in set(entry) - set(_SENSOR_KEYS))
    if unknown:
        raise ConfigError(f"{where}: unknown key(s) {', '.join(unknown[:5])}; known: "
                          f"{', '.join(_SENSOR_KEYS)}")
    topic = entry.get("topic")
    if not isinstance(topic, str) or not topic.strip():
        raise ConfigError(f"{where}.topic: a sensor_msgs/msg/Imu topic name is required")
    position = []
    for key in ("x_m", "y_m"):
        value = entry.get(key, 0.0 if key == "y_m" else None)
        if isinstance(value, bool) or not isinstance(value, int | float) or not math.isfinite(value) \
                or abs(value) > 100.0:
            raise ConfigError(f"{where}.{key}: expected a position in metres (|value| <= 100), got {value!r}")
        position.append(float(value))
    channels = entry.get("channels", ["accel_z"])
    if not isinstance(channels, list) or not channels or len(set(map(str, channels))) != len(channels) \
            or any(c not in CHANNEL_FIELDS for c in channels):
        raise ConfigError(f"{where}.channels: a list of distinct channels of {', '.join(CHANNEL_FIELDS)}, "
                          f"got {channels!r}")
    return Sensor(name, topic.strip(), position[0], position[1], tuple(channels))


def unit_suffix(label: str) -> str:
    """``radps`` for a gyro channel's label (``imu.gyro_y``), else ``mps2`` (accelerometers, and
    the preset's ``front``/``rear``): for keys that carry a channel's unit."""
    kind = label.rpartition(".")[2]
    return "radps" if CHANNEL_UNITS.get(kind) == "rad/s" else "mps2"


SENSOR_PARAMETER_PREFIX = "vehicle.sensors."
SENSORS_PARAMETER_HELP = ("the sensors block's sensor names (a parameter file's nested vehicle: sensors: "
                          "block; each name's topic, x_m, y_m, channels as vehicle.sensors.<name>.*; empty: "
                          "front and rear accelerometers)")


def sensor_parameter_names(names: Sequence[str]) -> list[str]:
    """The flat ROS parameter names of a sensors block with sensors ``names`` (a parameter
    file's nested ``vehicle: sensors: …`` arrives as these)."""
    return [f"{SENSOR_PARAMETER_PREFIX}{n}.{key}" for n in names for key in _SENSOR_KEYS]


def sensors_from_parameters(values: Mapping[str, Any]) -> SensorSet | None:
    """The sensors block of flat ROS values (``vehicle.sensors.names`` and, per name,
    ``vehicle.sensors.<name>.topic`` …; values not set are None); None without names."""
    names = values.get(f"{SENSOR_PARAMETER_PREFIX}names")
    if names is None or (isinstance(names, list | tuple) and not names):
        return None
    block: dict[str, Any] = {"names": list(names) if isinstance(names, list | tuple) else names}
    for n in block["names"] if isinstance(block["names"], list) else []:
        entry = {key: values.get(f"{SENSOR_PARAMETER_PREFIX}{n}.{key}") for key in _SENSOR_KEYS}
        block[n] = {k: list(v) if isinstance(v, tuple) else v for k, v in entry.items() if v is not None}
    return sensors_from_mapping(block, "vehicle parameters")


@functools.lru_cache(maxsize=64)  # the model reads a vehicle's channels at every move of its budget
def half_car_channels(sensors: SensorSet, wheelbase_m: float) -> tuple[Channel, ...]:
    """The channels the half car fits: the block's accelerometers front to rear, then its pitch
    gyros; ConfigError (one line naming what is missing) for a set that cannot identify the
    mass, the pitch inertia and the CoG.

    The half car has no roll: its sensors sit on the centreline and give no ``gyro_x``. Its
    channels must see heave (an accelerometer) and pitch (a pitch gyro, or accelerometers at
    least a quarter wheelbase apart); any number of channels beyond that adds to what it sees.
    """
    off_line = [s.name for s in sensors.sensors if s.y_m != 0.0]
    if off_line:
        raise ConfigError(f"sensors: {', '.join(off_line)} sits off the centreline (y_m != 0), where it sees "
                          "roll, and the half car does not roll: give y_m: 0, or describe the car as a full "
                          "car (model: full), whose model carries the roll (with a gyro_x channel)")
    chans = sensors.channels
    rolls = [c.label for c in chans if c.kind == "gyro_x"]
    if rolls:
        raise ConfigError(f"sensors: {', '.join(rolls)}: the half car does not roll; leave gyro_x out (or "
                          "describe the car as a full car, model: full)")
    accels = sorted((c for c in chans if c.kind == "accel_z"), key=lambda c: c.x_m)
    gyros = [c for c in chans if c.kind == "gyro_y"]
    if not accels:
        raise ConfigError("sensors: a pitch gyro sees pitch but not heave, so not the mass: add an accel_z "
                          "channel")
    if len(accels) == 1 and not gyros:
        raise ConfigError(f"sensors: one accelerometer ({accels[0].label}) sees heave but not pitch: add a "
                          "gyro_y channel or a second accelerometer a quarter wheelbase away or more")
    front, rear = accels[0], accels[-1]
    if not gyros and rear.x_m - front.x_m < 0.25 * wheelbase_m:
        raise ConfigError(f"sensors: {front.label} and {rear.label} sit {rear.x_m - front.x_m:.2f} m apart: "
                          f"accelerometers must be a quarter wheelbase ({0.25 * wheelbase_m:.2f} m) "
                          "apart or more to see pitch (or add a gyro_y channel)")
    return (*accels, *gyros)


def same_positions(given: Any, placed: Sequence[float] | float) -> bool:
    """A file's positions (a list, or one number) are the ones its sensors block places."""
    if not isinstance(placed, Sequence):
        given, placed = [given], [placed]
    try:
        return len(given) == len(placed) and all(abs(float(a) - b) <= 1e-9
                                                 for a, b in zip(given, placed, strict=True))
    except (TypeError, ValueError):
        return False


@functools.lru_cache(maxsize=64)  # the model reads a vehicle's channels at every move of its budget
def full_car_channels(sensors: SensorSet, wheelbase_m: float, track_m: float) -> tuple[Channel, ...]:
    """The channels the full car fits (every channel of the block, in its order); ConfigError
    (one line naming what is missing) for a set that cannot identify heave, pitch and roll.

    Each channel reads one motion of the rigid body ``(z, pitch, roll)``: an accelerometer at
    ``(x, y)`` the acceleration of ``z - x pitch + y roll``, ``gyro_y`` the pitch rate,
    ``gyro_x`` the roll rate. The set must see all three, each well apart: the rows, with ``x``
    in wheelbases and ``y`` in tracks, must have a smallest singular value of at least 0.1
    (two accelerometers a quarter wheelbase apart along the body and one a quarter track
    across from their line pass). Any number of channels from three: the likelihood is one over
    all of them.
    """
    chans = sensors.channels
    accels = [c for c in chans if c.kind == "accel_z"]
    if not accels:
        raise ConfigError("sensors: gyros see pitch and roll but not heave, so not the mass: add an accel_z "
                          "channel")
    rows = []
    for c in chans:
        rows.append({"accel_z": (1.0, -c.x_m / wheelbase_m, c.y_m / track_m), "gyro_y": (0.0, 1.0, 0.0),
                     "gyro_x": (0.0, 0.0, 1.0)}[c.kind])
    missing, named = _unseen_motion(rows), ", ".join(c.label for c in chans)
    if missing == "pitch":
        raise ConfigError(f"sensors: {named} see heave but not pitch: add a gyro_y "
                          "channel or accelerometers a quarter wheelbase apart along the body")
    if missing == "roll":
        raise ConfigError(f"sensors: {named} see heave but not roll: add a gyro_x "
                          "channel or an accelerometer a quarter track across from the others")
    if missing == "both":
        raise ConfigError(f"sensors: {named} see heave but neither pitch nor roll: "
                          "add gyro_x and gyro_y channels, or accelerometers apart along and across the body")
    if missing:
        raise ConfigError(f"sensors: {named} do not tell heave, pitch and roll "
                          "apart: place the accelerometers further apart or add gyro_x and gyro_y")
    return chans


def _unseen_motion(rows: list[tuple[float, float, float]]) -> str:
    """``pitch``/``roll`` when the rows (scaled as :func:`full_car_channels`) miss one of them,
    ``both``/``mixed`` when they cannot tell the motions apart otherwise, else empty."""
    a = np.asarray(rows, dtype=float)
    if np.linalg.svd(a, compute_uv=False).min(initial=np.inf) >= 0.1 and a.shape[0] >= 3:
        return ""
    heave_pitch = np.linalg.matrix_rank(a[:, :2], tol=0.1) == 2
    heave_roll = np.linalg.matrix_rank(a[:, [0, 2]], tol=0.1) == 2
    if not heave_pitch and heave_roll:
        return "pitch"
    if heave_pitch and not heave_roll:
        return "roll"
    return "mixed" if heave_pitch else "both"


__all__ = [
    "CHANNEL_FIELDS",
    "CHANNEL_UNITS",
    "SENSORS_PARAMETER_HELP",
    "SENSOR_PARAMETER_PREFIX",
    "Channel",
    "Sensor",
    "SensorSet",
    "full_car_channels",
    "half_car_channels",
    "same_positions",
    "sensor_parameter_names",
    "sensors_from_mapping",
    "sensors_from_parameters",
]
