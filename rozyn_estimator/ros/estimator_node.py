"""``estimator_node``: thin rclpy glue around :class:`~rozyn_estimator.online.estimator.OnlineEstimator`.

Subscribes to two ``sensor_msgs/Imu`` topics, feeds the online estimator from the
callbacks (a dict lookup and a list append per message), runs due updates on a worker
thread and publishes ``inertia``, ``inertia/covariance`` and ``/diagnostics``. No
algorithm lives here.
"""

from __future__ import annotations

import sys
import time
from collections.abc import Sequence
from concurrent.futures import ThreadPoolExecutor
from dataclasses import dataclass
from typing import Any

from diagnostic_msgs.msg import DiagnosticArray
from geometry_msgs.msg import InertiaStamped, TwistStamped
from nav_msgs.msg import Odometry
from rcl_interfaces.msg import SetParametersResult
from rclpy.node import Node
from rclpy.parameter import Parameter
from rclpy.qos import QoSProfile, ReliabilityPolicy
from sensor_msgs.msg import Imu
from std_msgs.msg import Float64MultiArray

from rozyn_estimator.errors import ConfigError
from rozyn_estimator.online import EstimatorConfig, Job, OnlineEstimator, Update
from rozyn_estimator.parameters import build, check, param
from rozyn_estimator.ros import glue as ros_common
from rozyn_estimator.ros import messages as ros_io

NODE_NAME = "estimator_node"


@dataclass(frozen=True)
class NodeOptions:
    """The estimator node's own parameters (the estimate does not depend on them)."""

    qos_depth: int = param(100, "subscription queue depth (best effort, volatile: sensor-data QoS)",
                           low=1, high=100_000, read_only=True)
    diagnostics_period_s: float = param(1.0, "period of /diagnostics between updates", unit="s",
                                        low=0.05, high=60.0, read_only=True)

    def __post_init__(self) -> None:
        check(self)


class EstimatorNode(Node):
    """The estimator node; raises ConfigError on invalid parameters at start-up."""

    NAME = NODE_NAME

    def __init__(self, **kwargs: Any) -> None:
        super().__init__(self.NAME, **kwargs)
        self._declare_parameters()
        values = self._values()
        self.options: NodeOptions = build(NodeOptions(), values)
        self.config = self._config(values)
        cfg = self.config
        self.online = OnlineEstimator(
            cfg.vehicle, cfg.online, cfg.pipeline, (cfg.front_topic, cfg.rear_topic)
        )
        self._getter = ros_io.field_getter(cfg.field, Imu)
        self._worker = ThreadPoolExecutor(max_workers=1, thread_name_prefix="rozyn-update")
        self._arrival = [time.monotonic()] * 2  # when each sensor was last heard (wall clock)
        self.finished = False
        self.updates_published = 0
        self.pending_updates = 0  # due updates not yet published
        qos = QoSProfile(depth=self.options.qos_depth, reliability=ReliabilityPolicy.BEST_EFFORT)
        self.create_subscription(Imu, cfg.front_topic, lambda m: self._on_imu(0, m), qos)
        self.create_subscription(Imu, cfg.rear_topic, lambda m: self._on_imu(1, m), qos)
        self._subscribe_speed(qos)
        self.pub_inertia = self.create_publisher(InertiaStamped, "inertia", 10)
        self.pub_covariance = self.create_publisher(Float64MultiArray, "inertia/covariance", 10)
        self.pub_diagnostics = self.create_publisher(DiagnosticArray, "/diagnostics", 10)
        self.create_timer(self.options.diagnostics_period_s, self._publish_health)
        self.add_on_set_parameters_callback(self._on_set_parameters)
        self.get_logger().info(
            f"estimating from {cfg.front_topic} and {cfg.rear_topic} ({cfg.field}), window "
            f"{cfg.online.window_s:g} s, update every {cfg.online.update_period_s:g} s"
        )

    # ------------------------------------------------------------ parameters
    def _declare_parameters(self) -> None:
        names = ros_common.declare_config(self, NodeOptions())
        names += ros_common.declare_config(self, EstimatorConfig())
        self._param_names = [*names, ros_common.declare_vehicle_file(self)]

    def _values(self, changes: Sequence[Parameter] = ()) -> dict[str, Any]:
        values = ros_common.values_of(self, self._param_names)
        values.update({p.name: p.value for p in changes})
        return values

    def _config(self, values: dict[str, Any]) -> EstimatorConfig:
        """The node's configuration, its field checked against Imu; ConfigError otherwise."""
        config = EstimatorConfig.from_parameters(values)
        ros_io.field_getter(config.field, Imu)
        return config

    def _on_set_parameters(self, changes: list[Parameter]) -> SetParametersResult:
        try:
            config = self._config(self._values(changes))
        except ConfigError as exc:
            return SetParametersResult(successful=False, reason=str(exc))
        self.config = config
        self.online.reconfigure(config.vehicle, config.online, config.pipeline)
        return SetParametersResult(successful=True)

    # ---------------------------------------------------------------- inputs
    def _subscribe_speed(self, qos: QoSProfile) -> None:
        topic = self.config.speed_topic
        if not topic:
            return
        msg_type = TwistStamped if self.config.speed_topic_type == "twist" else Odometry

        def on_speed(msg: Any) -> None:
            lin = msg.twist.linear if msg_type is TwistStamped else msg.twist.twist.linear
            self.online.add_speed(ros_io.stamp_ns(msg.header.stamp), float((lin.x**2 + lin.y**2) ** 0.5))

        self.create_subscription(msg_type, topic, on_speed, qos)

    def _on_imu(self, channel: int, msg: Imu) -> None:
        try:
            value = float(self._getter(msg))
        except (AttributeError, TypeError, ValueError):
            self.online.drop(channel, f"field {self.config.field} not numeric")
            return
        self._arrival[channel] = time.monotonic()
        for job in self.online.add(channel, ros_io.stamp_ns(msg.header.stamp), value):
            self.pending_updates += 1
            self._worker.submit(self._run, job)

    # --------------------------------------------------------------- outputs
    def _run(self, job: Job) -> None:
        try:
            update = self.online.compute(job)
            self._publish_update(update)
        except Exception as exc:  # a bug must not kill the node silently
            self.get_logger().error(f"update at {job.due_ns / 1e9:.3f} s failed: {exc!r}")
        finally:
            self.pending_updates -= 1

    def _publish_update(self, update: Update) -> None:
        if update.published:
            cfg = self.config
            self.pub_inertia.publish(ros_io.inertia_msg(update, cfg.frame_id, cfg.front_axle_x_m))
            if update.covariance is not None:
                self.pub_covariance.publish(ros_io.covariance_msg(update))
            self.updates_published += 1
        self._publish_health()

    def _publish_health(self) -> None:
        now = self.get_clock().now().nanoseconds
        wall = time.monotonic()
        health = self.online.report(silent_s=(wall - self._arrival[0], wall - self._arrival[1]))
        self.pub_diagnostics.publish(
            ros_io.diagnostic_array(health, self.get_fully_qualified_name(), self.config.hardware_id, now)
        )

    def destroy_node(self) -> None:
        self._worker.shutdown(wait=True, cancel_futures=True)
        super().destroy_node()


def main(args: Sequence[str] | None = None) -> int:
    return ros_common.spin_node(EstimatorNode, args)


if __name__ == "__main__":
    sys.exit(main())
