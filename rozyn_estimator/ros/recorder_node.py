"""``bag_recorder``: record topics of a running ROS 2 system to a rosbag2 MCAP bag.

Generic: any topic, any type, recorded as the raw CDR bytes received (``raw=True``
subscriptions), with the receive time on the node's clock (sim time when
``use_sim_time`` is set) as log time. Topics are found in the ROS graph and keep being
looked for, so topics that appear late are recorded from their first publisher on. Like
``ros2 bag record``, the subscription adapts to the publishers' offered QoS: reliable
only if every publisher is, transient local only if every publisher is (latched topics
such as ``sim/ground_truth`` arrive even if published before the recorder started); the
offered profiles and type hashes go to ``metadata.yaml``.

The configuration of the estimator node (parameter ``estimator_node``) is fetched from
its parameter services when it appears and stored in the bag (``custom_data``), and its
input topics are recorded too, so ``rozyn replay BAG`` reproduces its estimates.

SIGINT or SIGTERM: the messages already received are written (the subscriptions are
drained first), the bag is closed and its path printed; exit status 0. Messages are
written by a thread of their own that flushes every ``flush_period_s``, so even a
recorder killed without warning (SIGKILL, power loss) loses at most that much: the rest
is read back with ``rozyn replay --salvage``.
"""

from __future__ import annotations

import functools
import importlib
import sys
import time
from collections.abc import Sequence
from dataclasses import dataclass
from datetime import UTC, datetime
from pathlib import Path
from typing import Any

from rcl_interfaces.srv import GetParameters, ListParameters
from rclpy.clock import Clock, ClockType
from rclpy.expand_topic_name import expand_topic_name
from rclpy.node import Node
from rclpy.parameter import parameter_value_to_python
from rclpy.qos import DurabilityPolicy, HistoryPolicy, QoSProfile, ReliabilityPolicy

from rozyn_estimator.bag import BagWriter, Qos, QueuedBagWriter
from rozyn_estimator.errors import BagError
from rozyn_estimator.online import CUSTOM_DATA_KEY, EstimatorConfig
from rozyn_estimator.parameters import build, check, param
from rozyn_estimator.ros import glue as ros_common

NODE_NAME = "bag_recorder"
DEFAULT_TOPICS = (
    "accel/front",
    "accel/rear",
    "accel/front_left",
    "accel/front_right",
    "accel/rear_left",
    "accel/rear_right",
    "sim/ground_truth",
    "sim/speed",
    "inertia",
    "inertia/covariance",
    "/diagnostics",
    "/clock",
)
NS = 1_000_000_000
TOPIC_PARAMETERS = ("front_topic", "rear_topic", "front_left_topic", "front_right_topic", "rear_left_topic",
                    "rear_right_topic")  # the estimator's accelerometer topics


@dataclass(frozen=True)
class RecorderOptions:
    """bag_recorder's parameters (all read-only)."""

    topics: tuple[str, ...] = param(DEFAULT_TOPICS, "topics to record (relative names resolve in this node's "
                                    "namespace)", read_only=True)
    all_topics: bool = param(False, "record every topic that has a publisher (hidden topics excepted)",
                             read_only=True)
    output: str = param("", "bag directory to create; empty: <bag_root>/<name>-<UTC time>", read_only=True)
    bag_root: str = param("bags", "where bags go when output is empty", read_only=True)
    name: str = param("run", "first part of the bag's name when output is empty", read_only=True)
    qos_depth: int = param(1000, "history depth of the subscriptions", low=1, high=1_000_000, read_only=True)
    discovery_period_s: float = param(0.5, "how often the graph is searched for new topics", unit="s",
                                      low=0.01, high=60.0, read_only=True)
    flush_period_s: float = param(1.0, "longest time between writes of the pending chunk to disk", unit="s",
                                  low=0.01, high=3600.0, read_only=True)
    compression: str = param("zstd", "chunk compression: zstd or none", choices=("zstd", "none"),
                             read_only=True)
    chunk_size_kib: int = param(1024, "uncompressed size of a chunk", unit="KiB", low=1, high=1 << 20,
                                read_only=True)
    estimator_node: str = param("/estimator_node", "estimator node whose configuration is stored in the bag "
                                "for rozyn replay; empty: none", read_only=True)

    def __post_init__(self) -> None:
        check(self)


def bag_path(root: str | Path, name: str) -> Path:
    """``<root>/<name>-<UTC time>`` (seconds; a suffix if that exists already)."""
    stem = Path(root) / f"{name}-{datetime.now(UTC).strftime('%Y%m%dT%H%M%SZ')}"
    path, k = stem, 1
    while path.exists():
        path, k = stem.with_name(f"{stem.name}-{k}"), k + 1
    return path


def qos_record(profile: QoSProfile) -> Qos:
    """An offered profile (from graph discovery) as rosbag2 stores it."""
    return Qos(
        history=profile.history.name.lower(),
        depth=profile.depth,
        reliability=profile.reliability.name.lower(),
        durability=profile.durability.name.lower(),
        deadline_ns=profile.deadline.nanoseconds,
        lifespan_ns=profile.lifespan.nanoseconds,
        liveliness=profile.liveliness.name.lower(),
        liveliness_lease_duration_ns=profile.liveliness_lease_duration.nanoseconds,
        avoid_ros_namespace_conventions=profile.avoid_ros_namespace_conventions,
    )


def adapted_qos(offered: Sequence[QoSProfile], depth: int) -> QoSProfile:
    """A subscription that matches every publisher (rosbag2's rule)."""
    reliable = all(q.reliability == ReliabilityPolicy.RELIABLE for q in offered)
    latched = all(q.durability == DurabilityPolicy.TRANSIENT_LOCAL for q in offered)
    return QoSProfile(
        history=HistoryPolicy.KEEP_LAST,
        depth=depth,
        reliability=ReliabilityPolicy.RELIABLE if reliable else ReliabilityPolicy.BEST_EFFORT,
        durability=DurabilityPolicy.TRANSIENT_LOCAL if latched else DurabilityPolicy.VOLATILE,
    )


def message_class(msgtype: str) -> Any:
    """The Python class of ``pkg/msg/Type``, or None if it is not installed."""
    pkg, _, name = msgtype.rpartition("/")
    try:
        return getattr(importlib.import_module(pkg.replace("/", ".")), name)
    except (ImportError, AttributeError, ValueError):
        return None


def estimator_config(values: dict[str, Any], node_name: str, namespace: str) -> EstimatorConfig:
    """The estimator node's effective configuration from its parameter values.

    Topics are resolved in the node's namespace, and the online config's channel names
    are the topics, as the node sets them.
    """
    config = EstimatorConfig.from_parameters(values)  # the node's own interpretation
    topics = {
        k: expand_topic_name(values[k], node_name, namespace) if values[k] else ""
        for k in (*TOPIC_PARAMETERS, "speed_topic") if k in values
    }
    return config.replace(**topics, node_name=f"{namespace.rstrip('/')}/{node_name}")


class BagRecorder(Node):
    """The recorder node. Call :meth:`close` (or let ``main`` do it) to finish the bag.

    Raises:
        ConfigError: invalid parameters. BagError: the bag cannot be created.
    """

    NAME = NODE_NAME

    def __init__(self, **kwargs: Any) -> None:
        super().__init__(self.NAME, **kwargs)
        names = ros_common.declare_config(self, RecorderOptions())
        p: RecorderOptions = build(RecorderOptions(), ros_common.values_of(self, names))
        self._p = p
        self.path = Path(p.output) if p.output else bag_path(p.bag_root, p.name)
        self._wanted = {self._resolve(t) for t in p.topics}
        self._recorded: dict[str, str] = {}  # topic -> type
        self._topic_ids: dict[str, int] = {}
        self._received: list[int] = []  # messages received, per topic id
        self._refused: set[str] = set()
        self._last_log_ns = 0
        self.estimator_config: EstimatorConfig | None = None
        self._config_clients: tuple[Any, Any] | None = None
        self._config_pending = False
        self.closed = False
        self.finished = False
        steady = Clock(clock_type=ClockType.STEADY_TIME)
        self.create_timer(p.discovery_period_s, self.discover, clock=steady)
        self.writer = QueuedBagWriter(  # last: its thread runs until close()
            BagWriter(self.path, compression=p.compression, chunk_size=p.chunk_size_kib * 1024),
            flush_period_s=p.flush_period_s,
        )
        self.get_logger().info(f"recording to {self.path}")
        self.discover()

    def _resolve(self, topic: str) -> str:
        return expand_topic_name(topic, self.get_name(), self.get_namespace())

    # -------------------------------------------------------------- discovery
    def discover(self) -> None:
        """Subscribe to the wanted topics that have publishers; fetch the estimator's config."""
        if self.closed:
            return
        if self.writer.error is not None:
            self.get_logger().error(f"writing {self.path} failed: {self.writer.error}; stopping")
            self.finished = True
            return
        for topic, types in self.get_topic_names_and_types():
            if topic in self._recorded or topic in self._refused:
                continue
            if topic not in self._wanted and not (self._p.all_topics and not _hidden(topic)):
                continue
            publishers = self.get_publishers_info_by_topic(topic)
            if publishers:
                self._subscribe(topic, types, publishers)
        self._fetch_config()

    def _subscribe(self, topic: str, types: list[str], publishers: list[Any]) -> None:
        msgtype = types[0]
        if len(types) > 1:
            self.get_logger().warning(f"{topic} has several types ({', '.join(types)}): recording {msgtype}")
        cls = message_class(msgtype)
        if cls is None:
            self.get_logger().warning(f"cannot record {topic}: type {msgtype} is not installed")
            self._refused.add(topic)
            return
        offered = [p.qos_profile for p in publishers if p.topic_type == msgtype]
        type_hash = str(publishers[0].topic_type_hash)
        tid = self.writer.add_topic(
            topic,
            msgtype,
            [qos_record(q) for q in offered],
            type_hash=None if type_hash == "INVALID" else type_hash,
        )
        self._recorded[topic] = msgtype
        self._topic_ids[topic] = tid
        self._received += [0] * (tid + 1 - len(self._received))
        self.create_subscription(
            cls,
            topic,
            functools.partial(self._on_message, tid),
            adapted_qos(offered, self._p.qos_depth),
            raw=True,
        )
        self.get_logger().info(f"recording {topic} ({msgtype})")

    def _on_message(self, topic_id: int, data: bytes) -> None:
        self._received[topic_id] += 1
        t = max(self.get_clock().now().nanoseconds, self._last_log_ns + 1)  # bag order = arrival order
        self._last_log_ns = t
        self.writer.write(topic_id, t, data)

    # ------------------------------------------------------- estimator config
    def _fetch_config(self) -> None:
        """Ask the estimator node for its parameters, once it is there (non-blocking)."""
        target = self._p.estimator_node
        if not target or self.estimator_config is not None or self._config_pending:
            return
        fqn = target if target.startswith("/") else f"/{target}"
        namespace, _, name = fqn.rpartition("/")
        if (name, namespace or "/") not in self.get_node_names_and_namespaces():
            return
        if self._config_clients is None:
            self._config_clients = (
                self.create_client(ListParameters, f"{fqn}/list_parameters"),
                self.create_client(GetParameters, f"{fqn}/get_parameters"),
            )
        lister, getter = self._config_clients
        if not (lister.service_is_ready() and getter.service_is_ready()):
            return
        self._config_pending = True

        def on_values(names: list[str], future: Any) -> None:
            self._config_pending = False
            try:
                values = future.result().values
                params = {n: parameter_value_to_python(v) for n, v in zip(names, values, strict=True)}
                self.set_estimator_config(estimator_config(params, name, namespace or "/"))
            except Exception as exc:  # a node of that name that is not our estimator, a failed call
                self.get_logger().error(f"cannot record the configuration of {fqn}: {exc}")
                self.estimator_config = EstimatorConfig()  # do not ask again

        def on_names(future: Any) -> None:
            try:
                names = list(future.result().result.names)
            except Exception as exc:
                self._config_pending = False  # ask again at the next discovery
                self.get_logger().warning(f"listing the parameters of {fqn} failed: {exc}")
                return
            request = GetParameters.Request(names=names)
            getter.call_async(request).add_done_callback(lambda f: on_values(names, f))

        lister.call_async(ListParameters.Request()).add_done_callback(on_names)

    def set_estimator_config(self, config: EstimatorConfig) -> None:
        """Store the estimator's configuration in the bag and record its input topics."""
        self.estimator_config = config
        self.writer.set_custom_data(CUSTOM_DATA_KEY, config.to_json())
        self._wanted |= {self._resolve(t) for t in (*(t for _, t in config.sensors), config.speed_topic) if t}
        self.get_logger().info(f"stored the configuration of {config.node_name} in the bag")

    # ------------------------------------------------------------------ close
    @property
    def recorded_topics(self) -> dict[str, str]:
        return dict(self._recorded)

    def received(self, topic: str) -> int:
        """Messages received on a (resolved) topic so far; 0 if it is not recorded."""
        tid = self._topic_ids.get(topic)
        return 0 if tid is None else self._received[tid]

    def close(self) -> None:
        """Write everything received, finish the bag (idempotent)."""
        if self.closed:
            return
        self.closed = True
        self.writer.close()
        counts = self.writer.writer.counts
        total = sum(counts.values())
        self.get_logger().info(f"wrote {self.path}: {total} messages on {len(counts)} topics")
        if self._p.estimator_node and self.estimator_config is None:
            self.get_logger().warning(
                f"{self._p.estimator_node} was not seen: the bag holds no estimator configuration"
            )
        if self.writer.error is not None:
            raise BagError(f"writing {self.path} failed: {self.writer.error}")

    def finish(self, executor: Any) -> int:
        """After the spin loop: write what the middleware already received, close the bag,
        print its path; the exit status (1 if writing failed)."""
        drain(executor, self.writer)
        try:
            self.close()
        except BagError as exc:
            print(f"[{self.NAME}] {exc}", file=sys.stderr)
            return 1
        print(self.path, flush=True)
        return 0

    def destroy_node(self) -> None:
        try:
            self.close()
        finally:
            super().destroy_node()


def _hidden(topic: str) -> bool:
    return any(part.startswith("_") for part in topic.split("/"))


def drain(executor: Any, writer: QueuedBagWriter, quiet_s: float = 0.1, limit_s: float = 2.0) -> None:
    """Spin until no message has arrived for ``quiet_s`` (at most ``limit_s``): what the
    middleware had already received when a stop was asked for is written too."""
    end = time.monotonic() + limit_s
    while time.monotonic() < end:
        before = writer.enqueued
        executor.spin_once(timeout_sec=quiet_s)
        if writer.enqueued == before:
            return


def main(args: Sequence[str] | None = None) -> int:
    """Run until SIGINT/SIGTERM, then drain, close the bag and print its path (exit 0)."""
    return ros_common.spin_node(BagRecorder, args)


if __name__ == "__main__":
    sys.exit(main())
