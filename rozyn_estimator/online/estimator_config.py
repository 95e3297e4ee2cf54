"""Everything that decides the estimator's output, as one record that travels in bags.

The recorder stores the :class:`EstimatorConfig` of the estimator node it records (its
vehicle, window/schedule, pipeline, input topics, field and speed source, output frame)
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
from rozyn_estimator.parameters import check, param
from rozyn_estimator.tolerances import Tolerances
from rozyn_estimator.vehicle import Vehicle, config_from_parameters

CUSTOM_DATA_KEY = "rozyn_estimator.estimator_config"
SPEED_TOPIC_TYPES = {  # speed_topic_type -> (message type, fields whose norm is the speed)
    "twist": ("geometry_msgs/msg/TwistStamped", ("twist.linear.x", "twist.linear.y")),
    "odometry": ("nav_msgs/msg/Odometry", ("twist.twist.linear.x", "twist.twist.linear.y")),
}


@dataclass(frozen=True)
class EstimatorConfig:
    """The estimator node's effective configuration (defaults: the node's defaults).

    Topic names are absolute when recorded by the recorder (resolved in the node's
    namespace); relative names are taken from the root namespace.
    """

    vehicle: Vehicle = param(description="the vehicle (vehicle.* parameters)", default_factory=Vehicle)
    online: OnlineConfig = param(description="window and schedule", default_factory=OnlineConfig)
    pipeline: PipelineConfig = param(description="each update (pipeline.* parameters)",
                                     default_factory=PipelineConfig)
    front_topic: str = param("accel/front", "front accelerometer topic (sensor_msgs/Imu)", read_only=True)
    rear_topic: str = param("accel/rear", "rear accelerometer topic (sensor_msgs/Imu)", read_only=True)
    field: str = param("linear_acceleration.z", "numeric field of the Imu message that holds the vertical "
                       "acceleration (gravity included is fine: the mean is removed)", read_only=True)
    speed_topic: str = param("", "optional vehicle speed topic; empty: use speed_mps", read_only=True)
    speed_topic_type: str = param("twist", "type of speed_topic: twist (geometry_msgs/TwistStamped) or "
                                  "odometry (nav_msgs/Odometry); the speed is the norm of linear x, y",
                                  choices=tuple(SPEED_TOPIC_TYPES), read_only=True)
    frame_id: str = param("base_link", "frame of the published centre of gravity")
    front_axle_x_m: float = param(0.0, "x of the front axle in frame_id (com.x = front_axle_x_m - lf)",
                                  unit="m", low=-100.0, high=100.0)
    hardware_id: str = param("half_car", "hardware_id of the diagnostic status")
    node_name: str = param("/estimator_node", "name of the diagnostic status", ros_name="")

    def __post_init__(self) -> None:
        check(self)

    def replace(self, **changes: Any) -> EstimatorConfig:
        return dataclasses.replace(self, **changes)

    @classmethod
    def from_parameters(cls, values: Mapping[str, Any]) -> EstimatorConfig:
        """The estimator node's interpretation of its parameter values (flat, dotted).

        The online settings are the top-level parameters named like the fields of
        :class:`OnlineConfig`; ``pipeline.*`` and ``vehicle.*``/``vehicle_file`` the rest.
        Raises ConfigError naming the first invalid parameter.
        """
        config: EstimatorConfig = config_from_parameters(cls(), values)
        return config

    def to_json(self) -> str:
        return json.dumps(dataclasses.asdict(self), sort_keys=True)

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
        return _from_dict(cls(), data, "estimator configuration", [] if ignored is None else ignored)


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
