"""QoS profiles as rosbag2 stores them (``offered_qos_profiles``, metadata version 9).

ROS-free: the recorder node converts rclpy's profiles to :class:`Qos`; :class:`BagWriter
<rozyn_estimator.bag.writer.BagWriter>` writes them to ``metadata.yaml`` and to the MCAP
channel metadata.
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass
from typing import Any

import yaml

INFINITE_NS = 9_223_372_036_854_775_807  # rmw's "infinite" duration, as DDS discovery reports it
NS = 1_000_000_000


@dataclass(frozen=True)
class Qos:
    """A QoS profile as rosbag2 stores it (``offered_qos_profiles``, version 9).

    Policies are rosbag2's lower-case names (``keep_last``, ``best_effort``,
    ``transient_local``, ``automatic``, ``unknown`` …); durations in nanoseconds.
    """

    history: str = "keep_last"
    depth: int = 10
    reliability: str = "reliable"
    durability: str = "volatile"
    deadline_ns: int = INFINITE_NS
    lifespan_ns: int = INFINITE_NS
    liveliness: str = "automatic"
    liveliness_lease_duration_ns: int = INFINITE_NS
    avoid_ros_namespace_conventions: bool = False

    def to_yaml_dict(self) -> dict[str, Any]:
        """The mapping rosbag2 writes for one profile.

        Returns:
            The policies by rosbag2's key names, durations as ``{sec, nsec}``.
        """

        def duration(ns: int) -> dict[str, int]:
            return {"sec": ns // NS, "nsec": ns % NS}

        return {
            "history": self.history,
            "depth": self.depth,
            "reliability": self.reliability,
            "durability": self.durability,
            "deadline": duration(self.deadline_ns),
            "lifespan": duration(self.lifespan_ns),
            "liveliness": self.liveliness,
            "liveliness_lease_duration": duration(self.liveliness_lease_duration_ns),
            "avoid_ros_namespace_conventions": self.avoid_ros_namespace_conventions,
        }


SENSOR_QOS = Qos(depth=5, reliability="best_effort")  # rclpy's qos_profile_sensor_data
LATCHED_QOS = Qos(depth=1, durability="transient_local")


def qos_yaml(qos: Sequence[Qos]) -> str:
    """The ``offered_qos_profiles`` text of an MCAP channel (empty for no profile).

    Args:
        qos: the profiles offered on the topic.

    Returns:
        A YAML list of :meth:`Qos.to_yaml_dict` mappings, or ``""``.
    """
    return yaml.safe_dump([q.to_yaml_dict() for q in qos], sort_keys=False).strip() if qos else ""
