"""Everything that decides the estimator's output, as one record that travels in bags.

The recorder stores the :class:`EstimatorConfig` of the estimator node it records (its
vehicle, half or full car, window/schedule, pipeline, input topics, field and speed source,
output frame)
as JSON in the bag's ``custom_data`` under :data:`CUSTOM_DATA_KEY`, so ``rozyn replay``
reproduces the node's estimates without the user retyping its parameters. ROS-free.
"""

from __future__ import annotations

import dataclasses
import json
from collections.abc import Mapping
from dataclasses import dataclass
from typing import Any

from rozyn_estimator.errors import ConfigError
from rozyn_estimator.method import PipelineConfig
from rozyn_estimator.online.config import OnlineConfig
from rozyn_estimator.online.records import Layout, layout_of
from rozyn_estimator.parameters import build, check, param
from rozyn_estimator.sensors import sensors_from_mapping
from rozyn_estimator.tolerances import Tolerances
from rozyn_estimator.vehicle import Vehicle
from rozyn_estimator.vehicle_full import CORNERS, FullVehicle, any_vehicle_from_parameters

CUSTOM_DATA_KEY = "rozyn_estimator.estimator_config"
SPEED_TOPIC_TYPES = {  # speed_topic_type -> (message type, fields whose norm is the speed)
    "twist": ("geometry_msgs/msg/TwistStamped", ("twist.linear.x", "twist.linear.y")),
    "odometry": ("nav_msgs/msg/Odometry", ("twist.twist.linear.x", "twist.twist.linear.y")),
}


@dataclass(frozen=True)
class EstimatorConfig:
    """The estimator node's effective configuration (defaults: the node's defaults).

    The vehicle is the half car (``vehicle``; two sensors, ``front_topic`` and
    ``rear_topic``) unless ``full_vehicle`` is set: then it is that full car, and the
    sensors are the corners whose ``*_topic`` is not empty (three or four; ``vehicle`` and
    the half car's topics are unused). Topic names are absolute when recorded by the
    recorder (resolved in the node's namespace); relative names are taken from the root
    namespace.
    """

    vehicle: Vehicle = param(description="the vehicle (vehicle.* parameters)", default_factory=Vehicle)
    online: OnlineConfig = param(description="window and schedule", default_factory=OnlineConfig)
    pipeline: PipelineConfig = param(description="each update (pipeline.* parameters)",
                                     default_factory=PipelineConfig)
    front_topic: str = param("accel/front", "front accelerometer topic (sensor_msgs/Imu)", read_only=True)
    rear_topic: str = param("accel/rear", "rear accelerometer topic (sensor_msgs/Imu)", read_only=True)
    front_left_topic: str = param("accel/front_left", "full car: front left accelerometer topic "
                                  "(sensor_msgs/Imu); empty: no sensor there", read_only=True)
    front_right_topic: str = param("accel/front_right", "full car: front right accelerometer topic; empty: "
                                   "no sensor there", read_only=True)
    rear_left_topic: str = param("accel/rear_left", "full car: rear left accelerometer topic; empty: no "
                                 "sensor there", read_only=True)
    rear_right_topic: str = param("accel/rear_right", "full car: rear right accelerometer topic; empty: no "
                                  "sensor there", read_only=True)
    field: str = param("linear_acceleration.z", "numeric field of the Imu message that holds the vertical "
                       "acceleration (gravity included is fine: the mean is removed)", read_only=True)
    speed_topic: str = param("", "optional vehicle speed topic; empty: use speed_mps", read_only=True)
    speed_topic_type: str = param("twist", "type of speed_topic: twist (geometry_msgs/TwistStamped) or "
                                  "odometry (nav_msgs/Odometry); the speed is the norm of linear x, y",
                                  choices=tuple(SPEED_TOPIC_TYPES), read_only=True)
    frame_id: str = param("base_link", "frame of the published centre of gravity")
    front_axle_x_m: float = param(0.0, "x of the front axle in frame_id (com.x = front_axle_x_m - lf)",
                                  unit="m", low=-100.0, high=100.0)
    hardware_id: str = param("", "hardware_id of the diagnostic status; empty: the model's, half_car or "
                             "full_car")
    node_name: str = param("/estimator_node", "name of the diagnostic status", ros_name="")
    full_vehicle: FullVehicle | None = None  # the full car (vehicle.model full or a full-car vehicle_file)

    def __post_init__(self) -> None:
        check(self, (
            ("full_vehicle", lambda c: c.full_vehicle is None or isinstance(c.full_vehicle, FullVehicle),
             "must be a FullVehicle or None"),
            ("front_left_topic", lambda c: c.full_vehicle is None or len(c.sensors) >= 3,
             "a full car needs at least three of front_left_topic, front_right_topic, rear_left_topic, "
             "rear_right_topic"),
        ))

    def replace(self, **changes: Any) -> EstimatorConfig:
        return dataclasses.replace(self, **changes)

    @property
    def model(self) -> str:
        """``half`` or ``full``."""
        return "half" if self.full_vehicle is None else "full"

    @property
    def diagnostic_hardware_id(self) -> str:
        """The diagnostic status' hardware_id: the parameter when set, else the model's
        (``half_car`` or ``full_car``)."""
        return self.hardware_id or f"{self.model}_car"

    @property
    def model_vehicle(self) -> Vehicle | FullVehicle:
        """The vehicle the estimator runs: the full car when set, else the half car."""
        return self.vehicle if self.full_vehicle is None else self.full_vehicle

    @property
    def layout(self) -> Layout:
        """The channels and parameters of the estimator's updates."""
        return layout_of(self.model_vehicle, [c for c, _ in self.sensors])

    @property
    def sensors(self) -> tuple[tuple[str, str], ...]:
        """(channel, topic) of each channel in use: the half car's front and rear (or its
        vehicle's sensors block's channels, ``imu.accel_z`` …), or the full car's corners that
        have a topic (in ``front_left`` … ``rear_right`` order)."""
        vehicle = self.model_vehicle
        if vehicle.sensors is not None:  # the vehicle's sensors block names its topics
            return tuple((c.label, c.topic) for c in vehicle.channels)
        if self.full_vehicle is None:
            return (("front", self.front_topic), ("rear", self.rear_topic))
        topics = (self.front_left_topic, self.front_right_topic, self.rear_left_topic, self.rear_right_topic)
        return tuple((c, t) for c, t in zip(CORNERS, topics, strict=True) if t)

    @property
    def fields(self) -> tuple[str, ...]:
        """The ``sensor_msgs/Imu`` field each channel of :attr:`sensors` reads: ``field``, or a
        sensors block's channel's (``linear_acceleration.z``, ``angular_velocity.y``)."""
        if self.model_vehicle.sensors is not None:
            return tuple(c.field for c in self.model_vehicle.channels)
        return (self.field,) * len(self.sensors)

    @classmethod
    def from_parameters(cls, values: Mapping[str, Any]) -> EstimatorConfig:
        """The estimator node's interpretation of its parameter values (flat, dotted).

        The online settings are the top-level parameters named like the fields of
        :class:`OnlineConfig`; ``pipeline.*`` and ``vehicle.*``/``vehicle_file`` the rest (a
        full car when ``vehicle.model`` is ``full`` or the vehicle file says ``model: full``).
        Raises ConfigError naming the first invalid parameter.
        """
        others = {k: v for k, v in values.items() if not k.startswith("vehicle.")}
        config: EstimatorConfig = build(cls(), others)
        vehicle = any_vehicle_from_parameters(values)
        if isinstance(vehicle, FullVehicle):
            return config.replace(full_vehicle=vehicle)
        return config.replace(vehicle=vehicle)

    def to_json(self) -> str:
        data = dataclasses.asdict(self)
        if self.full_vehicle is None:
            del data["full_vehicle"]  # the half car's record as before the full car
        del data["vehicle"]["sensors"]  # as a vehicle file holds it, where given (as before, where not)
        del data["vehicle"]["channel_x_m"]  # the block's, placed again on reading
        if self.vehicle.sensors is not None:
            data["vehicle"]["sensors"] = self.vehicle.sensors.to_dict()
        if self.full_vehicle is not None:
            del data["full_vehicle"]["sensors"]
            if self.full_vehicle.sensors is not None:
                data["full_vehicle"]["sensors"] = self.full_vehicle.sensors.to_dict()
        return json.dumps(data, sort_keys=True)

    @classmethod
    def from_json(cls, text: str, ignored: list[str] | None = None) -> EstimatorConfig:
        """The record written by :meth:`to_json`; ConfigError names what is wrong.

        Settings this version does not know (a bag recorded by another version) are
        skipped and, given a list, their names appended to ``ignored``.
        """
        try:
            data = json.loads(text)
        except json.JSONDecodeError as exc:
            raise ConfigError(f"estimator configuration is not JSON: {exc}") from None
        vehicle = data.get("vehicle") if isinstance(data, dict) else None
        if isinstance(vehicle, dict) and "tolerances" not in vehicle:
            # recorded before vehicles had tolerances: replay as that estimator ran
            vehicle["tolerances"] = Tolerances.none().to_dict()
        ignored = [] if ignored is None else ignored
        full = data.pop("full_vehicle", None) if isinstance(data, dict) else None
        sensors = _take_block(vehicle, ("sensor_front_offset_m", "sensor_rear_offset_m"))
        config: EstimatorConfig = _from_dict(cls(), data, "estimator configuration", ignored)
        if sensors is not None:
            block = sensors_from_mapping(sensors, "estimator configuration.vehicle")
            config = config.replace(vehicle=config.vehicle.with_sensors(block))
        if full is None:
            return config
        where = "estimator configuration.full_vehicle"
        full_block = _take_block(full, ("sensor_x_m", "sensor_y_m"))
        full_vehicle = _from_dict(FullVehicle(), full, where, ignored)
        if full_block is not None:
            full_vehicle = full_vehicle.with_sensors(sensors_from_mapping(full_block, where))
        return config.replace(full_vehicle=full_vehicle)


def _take_block(vehicle: Any, placed: tuple[str, ...]) -> Any:
    """A recorded vehicle's ``sensors`` block (None: none), popped from it with the fields the
    block places (an IMU's positions alone make no vehicle: ``with_sensors`` sets them)."""
    if not isinstance(vehicle, dict):
        return None
    block = vehicle.pop("sensors", None)
    if block is not None:
        for key in placed:
            vehicle.pop(key, None)
    return block


def _from_dict(default: Any, data: Any, where: str, ignored: list[str]) -> Any:
    """A dataclass like ``default`` from a mapping (nested dataclasses, tuples)."""
    if not isinstance(data, dict):
        raise ConfigError(f"{where}: expected a mapping, got {data!r}")
    names = {f.name for f in dataclasses.fields(default)}
    ignored += [f"{where}.{name}" for name in sorted(set(data) - names)]
    values = {}
    for name, value in data.items():
        if name not in names:
            continue
        current = getattr(default, name)
        if dataclasses.is_dataclass(current):
            value = _from_dict(current, value, f"{where}.{name}", ignored)
        values[name] = value  # checked by the dataclass
    try:
        return dataclasses.replace(default, **values)
    except (TypeError, ValueError) as exc:
        raise ConfigError(f"{where}: {exc}") from None
