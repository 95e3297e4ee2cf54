"""``estimator_node``: thin rclpy glue around :class:`~rozyn_estimator.online.estimator.OnlineEstimator`.

Subscribes to the accelerometers' ``sensor_msgs/Imu`` topics (the half car's front and rear,
or the full car's three or four corners when its vehicle is a full car), feeds the online
estimator from the callbacks (a dict lookup and a list append per message), runs due
updates on a worker thread and publishes ``inertia``, ``inertia/covariance`` and
``/diagnostics``. No algorithm lives here.

Stopping (:meth:`EstimatorNode.finish`, called by the spin loop after a signal, and by
``destroy_node``) is ordered: under the lock the worker publishes with, the node stops
taking samples and publishing updates; an update being computed finishes and is
dropped, updates not yet started are cancelled, the worker is joined. Only then may the
node be destroyed and the context shut down, so nothing ever publishes on a context
that is shutting down.
"""

from __future__ import annotations

import functools
import sys
import threading
import time
from collections import deque
from collections.abc import Callable, Sequence
from concurrent.futures import Future, ThreadPoolExecutor
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
from rozyn_estimator.online import EstimatorConfig, Health, Job, OnlineEstimator, Update
from rozyn_estimator.parameters import build, check, param
from rozyn_estimator.ros import glue as ros_common
from rozyn_estimator.ros import messages as ros_io

NODE_NAME = "estimator_node"
MAX_WAITING = 1  # due updates queued behind the one computing (older ones are skipped)
INERTIA_TOPIC, COVARIANCE_TOPIC = "inertia", "inertia/covariance"  # relative: remappable


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
        self.online = OnlineEstimator.from_config(cfg)
        self._getters = [ros_io.field_getter(f, Imu) for f in cfg.fields]  # one per channel
        self._worker = ThreadPoolExecutor(max_workers=1, thread_name_prefix="rozyn-update")
        self._pending: deque[Future[None]] = deque()  # submitted updates, in due order
        self._publish_lock = threading.Lock()  # the worker publishes, and finish() stops, under it
        self._stopping = False
        self._computing: Job | None = None  # the job the worker is on
        sensors = cfg.sensors  # (channel, topic) of each channel (an IMU's share a topic)
        self._arrival = [time.monotonic()] * len(sensors)  # when each sensor was last heard (wall clock)
        self.finished = False
        self.updates_published = 0
        self.updates_skipped = 0  # due updates dropped unstarted because the worker was behind
        self.received = [0] * len(sensors)  # Imu messages that reached the callbacks, per sensor
        self.on_update: Callable[[Update], None] | None = None  # called (in the worker) after publishing
        qos = QoSProfile(depth=self.options.qos_depth, reliability=ReliabilityPolicy.BEST_EFFORT)
        by_topic: dict[str, list[int]] = {}
        for k, (_, topic) in enumerate(sensors):
            by_topic.setdefault(topic, []).append(k)
        for topic, channels in by_topic.items():
            self.create_subscription(Imu, topic, functools.partial(self._on_imu, channels), qos)
        self._subscribe_speed(qos)
        self.pub_inertia = self.create_publisher(InertiaStamped, INERTIA_TOPIC, 10)
        self.pub_covariance = self.create_publisher(Float64MultiArray, COVARIANCE_TOPIC, 10)
        self.pub_diagnostics = self.create_publisher(DiagnosticArray, "/diagnostics", 10)
        self.create_timer(self.options.diagnostics_period_s, self._publish_health)
        self.add_on_set_parameters_callback(self._on_set_parameters)
        self.get_logger().info(
            f"estimating the {cfg.model} car from {self._sources()}, "
            f"window {cfg.online.window_s:g} s, update every {cfg.online.update_period_s:g} s"
        )

    # ------------------------------------------------------------ parameters
    def _declare_parameters(self) -> None:
        names = ros_common.declare_config(self, NodeOptions())
        names += ros_common.declare_config(self, EstimatorConfig(), skip="vehicle.")
        self._param_names = [*names, *ros_common.declare_vehicle(self)]

    def _values(self, changes: Sequence[Parameter] = ()) -> dict[str, Any]:
        values = ros_common.values_of(self, self._param_names)
        values.update({p.name: p.value for p in changes})
        return values

    def _config(self, values: dict[str, Any]) -> EstimatorConfig:
        """The node's configuration, its field checked against Imu; ConfigError otherwise."""
        config = EstimatorConfig.from_parameters(values)
        for f in config.fields:
            ros_io.field_getter(f, Imu)
        return config

    def _on_set_parameters(self, changes: list[Parameter]) -> SetParametersResult:
        try:
            config = self._config(self._values(changes))
        except ConfigError as exc:
            return SetParametersResult(successful=False, reason=str(exc))
        self.config = config
        self.online.reconfigure(config.model_vehicle, config.online, config.pipeline)
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

    def _sources(self) -> str:
        """``accel/front, accel/rear (linear_acceleration.z)``, or each channel's topic and field."""
        cfg = self.config
        if len(set(cfg.fields)) == 1:
            return f"{', '.join(t for _, t in cfg.sensors)} ({cfg.fields[0]})"
        sources = zip(cfg.sensors, cfg.fields, strict=True)
        return ", ".join(f"{name} ({topic} {f})" for (name, topic), f in sources)

    def _on_imu(self, channels: list[int], msg: Imu) -> None:
        if self._stopping:
            return
        stamp_ns = ros_io.stamp_ns(msg.header.stamp)
        for channel in channels:
            self.received[channel] += 1
            try:
                value = float(self._getters[channel](msg))
            except (AttributeError, TypeError, ValueError):
                self.online.drop(channel, f"field {self.config.fields[channel]} not numeric")
                continue
            self._arrival[channel] = time.monotonic()
            for job in self.online.add(channel, stamp_ns, value):
                self._submit(job)

    def _submit(self, job: Job) -> None:
        """Queue an update; of those waiting behind the one computing only the newest is
        kept, so a node that cannot keep up stays live and its memory bounded."""
        waiting = [f for f in self._pending if not (f.running() or f.done())]
        for future in waiting[: max(0, len(waiting) + 1 - MAX_WAITING)]:
            if future.cancel():
                self.updates_skipped += 1
                self.get_logger().warning(
                    f"updates take longer than {self.config.online.update_period_s:g} s of message time: "
                    f"skipping the older waiting one ({self.updates_skipped} so far)",
                    throttle_duration_sec=10.0,
                )
        self._pending.append(self._worker.submit(self._run, job))

    @property
    def pending_updates(self) -> int:
        """Due updates not yet published (queued or computing)."""
        while self._pending and self._pending[0].done():  # the one worker ends them in order
            self._pending.popleft()
        return len(self._pending)

    # --------------------------------------------------------------- outputs
    def _run(self, job: Job) -> None:
        """One update, in the worker: compute, then publish unless the node is stopping."""
        with self._publish_lock:
            if self._stopping:
                return
            self._computing = job
        try:
            update = self.online.compute(job)
            with self._publish_lock:
                if self._stopping:
                    return
                self._publish_update(update)
            if self.on_update is not None:
                self.on_update(update)
        except Exception as exc:  # a bug must not kill the node silently
            self.get_logger().error(f"update at {job.due_ns / 1e9:.3f} s failed: {exc!r}")
        finally:
            self._computing = None

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
        health = self.online.report(silent_s=[wall - arrival for arrival in self._arrival])
        values = {**health.values, "updates_skipped": str(self.updates_skipped)}
        health = Health(health.level, health.message, values)
        hardware_id = self.config.diagnostic_hardware_id
        self.pub_diagnostics.publish(
            ros_io.diagnostic_array(health, self.get_fully_qualified_name(), hardware_id, now)
        )

    def finish(self, executor: Any = None) -> int:
        """Stop: take no more samples, publish nothing more, let an update being computed
        end unpublished, cancel those not started, join the worker (idempotent).

        Args:
            executor: unused (the spin loop's protocol).

        Returns:
            0 (the exit status).
        """
        with self._publish_lock:  # a publish in progress completes first
            if self._stopping:
                return 0
            self._stopping = True
            computing = self._computing
        queued = self.pending_updates - (computing is not None)
        if computing is not None or queued > 0:
            what = f"during the update at {computing.due_ns / 1e9:.3f} s (its result is not published)" \
                if computing is not None else "between updates"
            self.get_logger().info(f"stopping {what}; {max(queued, 0)} due updates not started are dropped")
        self._worker.shutdown(wait=True, cancel_futures=True)
        return 0

    def destroy_node(self) -> None:
        self.finish()
        super().destroy_node()


def main(args: Sequence[str] | None = None) -> int:
    return ros_common.spin_node(EstimatorNode, args)


if __name__ == "__main__":
    sys.exit(main())
