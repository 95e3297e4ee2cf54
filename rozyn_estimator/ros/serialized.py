"""The estimator's outputs as serialised messages for a bag, without DDS.

``rozyn replay`` writes what the node would have published: the messages are built by
the node's own converters (:mod:`rozyn_estimator.ros.messages`) and serialised by rclpy's
typesupport (``rclpy.serialization``: no ``rclpy.init``, no DDS), so they are the very
bytes the node puts on the wire. rclpy is imported only when this module is.
"""

from __future__ import annotations

from collections.abc import Sequence

from rclpy.serialization import serialize_message

from rozyn_estimator.bag import Qos, absolute_topic
from rozyn_estimator.online import EstimatorConfig, Health, Update
from rozyn_estimator.ros import messages as ros_io

# The node's publishers: (topic, type, offered QoS) — reliable, volatile, depth 10.
OUTPUT_TOPICS: tuple[tuple[str, str, Qos], ...] = (
    ("/inertia", "geometry_msgs/msg/InertiaStamped", Qos(depth=10)),
    ("/inertia/covariance", "std_msgs/msg/Float64MultiArray", Qos(depth=10)),
    ("/diagnostics", "diagnostic_msgs/msg/DiagnosticArray", Qos(depth=10)),
)


def update_messages(update: Update, health: Health, config: EstimatorConfig) -> Sequence[tuple[str, bytes]]:
    """(topic, CDR bytes) the node publishes for one update, in its order.

    ``inertia`` and ``inertia/covariance`` when there is an estimate, then
    ``/diagnostics`` stamped with the update's stamp.
    """
    out = []
    if update.published:
        msg = ros_io.inertia_msg(update, config.frame_id, config.front_axle_x_m)
        out.append(("/inertia", serialize_message(msg)))
        if update.covariance is not None:
            out.append(("/inertia/covariance", serialize_message(ros_io.covariance_msg(update))))
    diag = ros_io.diagnostic_array(
        health, absolute_topic(config.node_name), config.diagnostic_hardware_id, update.stamp_ns
    )
    out.append(("/diagnostics", serialize_message(diag)))
    return out
