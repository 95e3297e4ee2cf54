"""Everything that decides the estimator's output, as one record that travels in bags.

The recorder stores the :class:`EstimatorConfig` of the estimator node it records (its
vehicle, window/schedule, pipeline, input topics, field and speed source, output frame)
as JSON in the bag's ``custom_data`` under :data:`CUSTOM_DATA_KEY`, so ``rozyn replay``
reproduces the node's estimates without the user retyping its parameters. ROS-free.
"""

from __future__ import annotations

import dataclasses
import json
from dataclasses import dataclass
from typing import Any

from rozyn_estimator import parameters as params
from rozyn_estimator.errors import ConfigError
from rozyn_estimator.method.pipeline import PipelineConfig
from rozyn_estimator.online.estimator import OnlineConfig
from rozyn_estimator.vehicle import Vehicle

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

    vehicle: Vehicle = dataclasses.field(default_factory=Vehicle)
    online: OnlineConfig = dataclasses.field(default_factory=OnlineConfig)
    pipeline: PipelineConfig = dataclasses.field(default_factory=PipelineConfig)
    front_topic: str = "accel/front"
    rear_topic: str = "accel/rear"
    field: str = "linear_acceleration.z"
    speed_topic: str = ""  # empty: online.speed_mps (0: unknown)
    speed_topic_type: str = "twist"  # see SPEED_TOPIC_TYPES
    frame_id: str = "base_link"
    front_axle_x_m: float = 0.0
    hardware_id: str = "half_car"
    node_name: str = "/estimator_node"  # name of the diagnostic status

    def __post_init__(self) -> None:
        if self.speed_topic_type not in SPEED_TOPIC_TYPES:
            choices = ", ".join(SPEED_TOPIC_TYPES)
            raise ConfigError(f"speed_topic_type: must be one of {choices}, got {self.speed_topic_type!r}")

    def replace(self, **changes: Any) -> EstimatorConfig:
        return dataclasses.replace(self, **changes)

    @classmethod
    def from_parameters(cls, values: dict[str, Any]) -> EstimatorConfig:
        """The estimator node's interpretation of its parameter values (flat, dotted).

        The online settings are the top-level parameters named like the fields of
        :class:`OnlineConfig`; ``pipeline.*`` and ``vehicle.*``/``vehicle_file`` the rest.
        Raises ConfigError naming the first invalid parameter.
        """
        default = cls()
        online = OnlineConfig(
            **{
                f.name: params.number(f.name, values.get(f.name, getattr(default.online, f.name)))
                for f in dataclasses.fields(OnlineConfig)
            }
        )
        plain = {
            f.name: values.get(f.name, getattr(default, f.name))
            for f in dataclasses.fields(cls)
            if f.name not in ("vehicle", "online", "pipeline")
        }
        plain["front_axle_x_m"] = params.number("front_axle_x_m", plain["front_axle_x_m"])
        params.check_choice("speed_topic_type", plain["speed_topic_type"], SPEED_TOPIC_TYPES)
        return cls(
            vehicle=params.vehicle_from_parameters(values),
            online=online,
            pipeline=params.build_config("pipeline", default.pipeline, values),
            **plain,
        )

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
        elif isinstance(current, tuple):
            value = tuple(value)
        values[name] = value
    try:
        return dataclasses.replace(default, **values)
    except (TypeError, ValueError) as exc:
        raise ConfigError(f"{where}: {exc}") from None
