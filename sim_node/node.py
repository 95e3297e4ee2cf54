"""``sim_node``: the half-car (or full-car) simulator as a ROS 2 node (thin glue around ``Simulation``).

Publishes front/rear ``sensor_msgs/Imu`` with identical stamps for a pair (the full car,
when its vehicle is one: four, ``accel/front_left`` … ``accel/rear_right``), the ground
truth (``sim/ground_truth``, transient local), the speed (``sim/speed``), ``/diagnostics``
and, in sim-time mode, ``/clock`` at ``real_time_factor`` times real time (0: as fast as
it can). Blocks of samples are generated on a steady-clock timer, so memory stays
bounded however long it runs.

Flow control: code that runs the node in its own process (``rozyn demo``) may set
:attr:`SimNode.gate`, a callable asked before each block; while it says no, the sim
holds (sim time stands still), so a consumer that falls behind loses nothing.
"""

from __future__ import annotations

import dataclasses
import math
import sys
import time
from collections.abc import Callable, Sequence
from dataclasses import dataclass
from typing import Any

from builtin_interfaces.msg import Time
from diagnostic_msgs.msg import DiagnosticArray, DiagnosticStatus, KeyValue
from geometry_msgs.msg import InertiaStamped, TwistStamped
from rclpy.clock import Clock, ClockType
from rclpy.node import Node
from rclpy.qos import DurabilityPolicy, HistoryPolicy, QoSProfile, ReliabilityPolicy
from rosgraph_msgs.msg import Clock as ClockMsg
from sensor_msgs.msg import Imu

from rozyn_estimator.parameters import build, check, param
from rozyn_estimator.ros import glue as ros_common
from rozyn_estimator.sensors import CHANNEL_FIELDS
from rozyn_estimator.vehicle_full import FullVehicle, any_vehicle_from_parameters
from sim_node.sensors import MEMS_GYRO_BIAS_RADPS, MEMS_GYRO_NOISE_RADPS, MEMS_NOISE_MPS2
from sim_node.simulation import SimConfig, Simulation

NS = 1_000_000_000
TIME_MODES = ("realtime", "sim")


@dataclass(frozen=True)
class SimNodeOptions:
    """sim_node's own parameters (how the run is published, not what is simulated)."""

    time_mode: str = param("realtime", "realtime: stamps from the clock; sim: publish /clock",
                           choices=TIME_MODES, read_only=True)
    real_time_factor: float = param(1.0, "sim mode: sim seconds per wall second; 0: as fast as possible",
                                    low=0.0, high=10_000.0, read_only=True)
    block_s: float = param(0.05, "simulated time produced per tick", unit="s", low=0.001, high=10.0,
                           read_only=True)
    front_topic: str = param("accel/front", "front accelerometer topic", read_only=True)
    rear_topic: str = param("accel/rear", "rear accelerometer topic", read_only=True)
    front_frame_id: str = param("accel_front_link", "frame_id of the front Imu", read_only=True)
    rear_frame_id: str = param("accel_rear_link", "frame_id of the rear Imu", read_only=True)
    front_left_topic: str = param("accel/front_left", "full car: front left accelerometer topic",
                                  read_only=True)
    front_right_topic: str = param("accel/front_right", "full car: front right accelerometer topic",
                                   read_only=True)
    rear_left_topic: str = param("accel/rear_left", "full car: rear left accelerometer topic",
                                 read_only=True)
    rear_right_topic: str = param("accel/rear_right", "full car: rear right accelerometer topic",
                                  read_only=True)
    front_left_frame_id: str = param("accel_front_left_link", "full car: frame_id of the front left Imu",
                                     read_only=True)
    front_right_frame_id: str = param("accel_front_right_link", "full car: frame_id of the front right Imu",
                                      read_only=True)
    rear_left_frame_id: str = param("accel_rear_left_link", "full car: frame_id of the rear left Imu",
                                    read_only=True)
    rear_right_frame_id: str = param("accel_rear_right_link", "full car: frame_id of the rear right Imu",
                                     read_only=True)
    truth_frame_id: str = param("base_link", "frame_id of the ground truth", read_only=True)
    front_axle_x_m: float = param(0.0, "x of the front axle in truth_frame_id", unit="m", low=-100.0,
                                  high=100.0, read_only=True)
    qos_depth: int = param(100, "publisher queue depth (best effort: sensor-data QoS)", low=1,
                           high=100_000, read_only=True)
    exit_when_done: bool = param(True, "shut down when duration_s has been simulated", read_only=True)
    wait_for_subscribers: bool = param(False, "start only once every accelerometer topic has a subscriber "
                                       "(so a run on sim time loses nothing to discovery)", read_only=True)
    subscribers_per_topic: int = param(1, "with wait_for_subscribers: the subscribers each accelerometer "
                                       "topic needs first (2: the estimator and a recorder, so the bag "
                                       "holds every sample the estimator saw)", low=1, high=100,
                                       read_only=True)
    subscriber_grace_s: float = param(1.0, "with wait_for_subscribers: the wall time held after the last "
                                      "subscriber appears (a publisher sees a subscriber before the "
                                      "subscriber has matched it, and best-effort samples sent in between "
                                      "are lost)", unit="s", low=0.0, high=60.0, read_only=True)

    def __post_init__(self) -> None:
        check(self)


# the node's defaults: SimConfig's, with seed 1 and a MEMS accelerometer's noise (SimConfig's own
# default is exact sensors, for the studies of the method)
NODE_DEFAULTS = SimConfig(seed=1, noise_std_mps2=MEMS_NOISE_MPS2, gyro_noise_std_radps=MEMS_GYRO_NOISE_RADPS,
                          gyro_bias_radps=MEMS_GYRO_BIAS_RADPS)


def _time(ns: int) -> Time:
    return Time(sec=int(ns // NS), nanosec=int(ns % NS))


def sim_config(values: dict[str, Any]) -> SimConfig:
    """The simulated run of the node's parameter values: the half car of ``vehicle.*`` or
    ``vehicle_file``, or the full car (``model: full``) when ``vehicle.model`` is ``full`` or
    the file says so. Raises ConfigError naming the first invalid parameter."""
    others = {k: v for k, v in values.items() if not k.startswith("vehicle.")}
    vehicle = any_vehicle_from_parameters(values)
    if isinstance(vehicle, FullVehicle):  # the model first: the departures' rules depend on it
        model_full = dataclasses.replace(NODE_DEFAULTS, model="full", full_vehicle=vehicle)
        full: SimConfig = build(model_full, others)
        return full
    config: SimConfig = build(NODE_DEFAULTS, others)
    return dataclasses.replace(config, vehicle=vehicle)


class SimNode(Node):
    """The simulator node; raises ConfigError on invalid parameters at start-up."""

    NAME = "sim_node"

    def __init__(self, **kwargs: Any) -> None:
        super().__init__(self.NAME, **kwargs)
        names = ros_common.declare_config(self, SimNodeOptions())
        names += ros_common.declare_config(self, NODE_DEFAULTS, skip="vehicle.")
        names += ros_common.declare_vehicle(self)
        values = ros_common.values_of(self, names)
        self.options: SimNodeOptions = build(SimNodeOptions(), values)
        self.config = sim_config(values)
        self.sim = Simulation(self.config)
        o = self.options
        self._sim_mode = o.time_mode == "sim"
        self._rtf = o.real_time_factor
        self._block_n = max(1, round(o.block_s * self.config.rate_hz))
        self._epoch_ns = 0 if self._sim_mode else self.get_clock().now().nanoseconds
        self._wall_start = time.monotonic()
        self.finished = False
        self.published = 0  # samples per sensor
        self._subscribed_at: float | None = None  # wall time every accel topic had its subscribers
        self.gate: Callable[[], bool] | None = None  # produce the next block only when it says yes

        sensor_qos = QoSProfile(depth=o.qos_depth, reliability=ReliabilityPolicy.BEST_EFFORT)
        latched = QoSProfile(depth=1, reliability=ReliabilityPolicy.RELIABLE,
                             durability=DurabilityPolicy.TRANSIENT_LOCAL)
        self._outlets = self._sensor_outlets(sensor_qos)
        self._pub = [pub for pub, _, _ in self._outlets]
        self._pub_speed = self.create_publisher(TwistStamped, "sim/speed", 10)
        self._pub_diag = self.create_publisher(DiagnosticArray, "/diagnostics", 10)
        self._pub_truth = self.create_publisher(InertiaStamped, "sim/ground_truth", latched)
        self._pub_clock = None
        if self._sim_mode:
            clock_qos = QoSProfile(depth=1, history=HistoryPolicy.KEEP_LAST,
                                   reliability=ReliabilityPolicy.BEST_EFFORT)
            self._pub_clock = self.create_publisher(ClockMsg, "/clock", clock_qos)
        self._publish_truth()
        steady = Clock(clock_type=ClockType.STEADY_TIME)
        block_s = self._block_n / self.config.rate_hz
        period = block_s / self._rtf if self._sim_mode and self._rtf > 0 else block_s
        if self._sim_mode and self._rtf == 0:
            period = 1e-4  # as fast as the executor turns
        self._timer = self.create_timer(period, self._tick, clock=steady)
        self.create_timer(1.0, self._publish_diagnostics, clock=steady)
        r = self.config.road
        road = f"the {self.config.model} car on {r.kind} class {r.road_class} ({r.amplitudes})"
        pace = (f"sim time at {self._rtf:g}x" if self._rtf else "sim time, as fast as possible") \
            if self._sim_mode else "real time"
        c = self.config
        speed = f"following the drive cycle {c.drive_cycle_file}" if c.drive_cycle_file else \
            f"at {c.speed_kmh:g} km/h"
        self.get_logger().info(f"simulating {road} {speed}, {c.rate_hz:g} Hz, {pace}")

    def _sensor_outlets(self, qos: QoSProfile) -> list[tuple[Any, Imu, list[tuple[int, str, str]]]]:
        """(publisher, message, [(block column, sub-message, field)]) per sensor: one accelerometer
        per channel (front, rear; the full car's corners), or each sensor of the vehicle's
        sensors block with all its channels in one message (an IMU's accel_z and gyro_y)."""
        o, cfg = self.options, self.config
        block = cfg.plant_vehicle.sensors
        if block is None:
            return [(self.create_publisher(Imu, getattr(o, f"{c}_topic"), qos),
                     self._imu_template(getattr(o, f"{c}_frame_id"), gyro=False),
                     [(k, "linear_acceleration", "z")]) for k, c in enumerate(cfg.channels)]
        labels = cfg.channels
        outlets: list[tuple[Any, Imu, list[tuple[int, str, str]]]] = []
        for sensor in block.sensors:
            columns = []
            for kind in sensor.channels:
                if f"{sensor.name}.{kind}" in labels:
                    part, axis = CHANNEL_FIELDS[kind].split(".")
                    columns.append((labels.index(f"{sensor.name}.{kind}"), part, axis))
            gyro = any(kind != "accel_z" for kind in sensor.channels)
            outlets.append((self.create_publisher(Imu, sensor.topic, qos),
                            self._imu_template(f"{sensor.name}_link", gyro), columns))
        return outlets

    def _imu_template(self, frame_id: str, gyro: bool) -> Imu:
        msg = Imu()
        msg.header.frame_id = frame_id
        msg.orientation_covariance[0] = -1.0  # not provided
        if gyro:  # REP 145: the rates' noise; without a gyro, marked not provided
            rate = self.config.gyro_noise_std_radps**2
            msg.angular_velocity_covariance = [rate, 0.0, 0.0, 0.0, rate, 0.0, 0.0, 0.0, rate]
        else:
            msg.angular_velocity_covariance[0] = -1.0
        var = self.config.noise_std_mps2**2
        msg.linear_acceleration_covariance = [var, 0.0, 0.0, 0.0, var, 0.0, 0.0, 0.0, var]
        return msg

    def _publish_truth(self, at_s: float = 0.0) -> None:
        """The plant's values from ``at_s`` on, as the estimator publishes its estimates (the full
        car's roll inertia in ``ixx``, its lateral CoG in ``com.y``)."""
        v = self._truth = self.sim.truth
        msg = InertiaStamped()
        msg.header.stamp = _time(self._epoch_ns + round(at_s * NS))
        msg.header.frame_id = self.options.truth_frame_id
        msg.inertia.m = v.sprung_mass_kg
        msg.inertia.iyy = v.pitch_inertia_kgm2
        msg.inertia.com.x = self.options.front_axle_x_m - v.cog_from_front_axle_m
        msg.inertia.com.z = math.nan
        msg.inertia.ixx = msg.inertia.izz = msg.inertia.ixz = math.nan
        if isinstance(v, FullVehicle):
            msg.inertia.ixx, msg.inertia.com.y = v.roll_inertia_kgm2, v.cog_lateral_m
            msg.inertia.iyz = math.nan
        self._pub_truth.publish(msg)

    def _due_samples(self) -> int:
        """Samples to produce in this tick."""
        if self._sim_mode:
            n = self._block_n
        else:  # keep up with the clock: everything whose time has come
            elapsed = (self.get_clock().now().nanoseconds - self._epoch_ns) / NS
            n = max(0, math.floor(elapsed * self.config.rate_hz) + 1 - self.published)
        if self.config.duration_s > 0:
            n = min(n, round(self.config.duration_s * self.config.rate_hz) - self.published)
        return n

    def _waiting(self) -> bool:
        """Hold the start until every accel topic has its subscribers, if asked to."""
        if not self.options.wait_for_subscribers or self.published:
            return False
        wanted = self.options.subscribers_per_topic
        missing = [pub.topic_name for pub in self._pub if pub.get_subscription_count() < wanted]
        if missing:
            self.get_logger().info(f"waiting for {wanted} subscriber(s) on {', '.join(missing)}", once=True)
            self._subscribed_at = None
            return True
        if self._subscribed_at is None:
            self._subscribed_at = time.monotonic()
        if time.monotonic() - self._subscribed_at < self.options.subscriber_grace_s:
            return True  # the subscribers' side of discovery may lag the publishers'
        if not self._sim_mode:
            self._epoch_ns = self.get_clock().now().nanoseconds
        return False

    def _tick(self) -> None:
        if self._waiting() or (self.gate is not None and not self.gate()):
            return
        n = self._due_samples()
        if n <= 0:
            if self.config.duration_s > 0 and not self.finished:
                self._finish()
            return
        block = self.sim.next_block(n)
        if self.sim.truth is not self._truth:  # the load changed in this block
            before, at_s = self._truth.sprung_mass_kg, self.config.load_change_at_s
            self._publish_truth(at_s)
            self.get_logger().info(f"load changed at the stop at t = {at_s:g} s: m {before:g} -> "
                                   f"{self._truth.sprung_mass_kg:g} kg")
        stamps = [self._epoch_ns + round(t * NS) for t in block.t_s]
        if self._pub_clock is not None:
            self._pub_clock.publish(ClockMsg(clock=_time(stamps[-1])))
        for stamp, row in zip(stamps, block.accel_mps2.tolist(), strict=True):
            t = _time(stamp)
            for pub, msg, columns in self._outlets:
                msg.header.stamp = t
                for k, part, axis in columns:
                    setattr(getattr(msg, part), axis, row[k])
                pub.publish(msg)
        self.published += n
        speed = TwistStamped()
        speed.header.stamp = _time(stamps[-1])
        speed.header.frame_id = self.options.truth_frame_id
        speed.twist.linear.x = float(block.speed_mps[-1])
        self._pub_speed.publish(speed)

    def _finish(self) -> None:
        self.finished = True
        self._timer.cancel()
        self._publish_diagnostics()
        self.get_logger().info(f"done: {self.published} samples ({self.published / self.config.rate_hz:g} s)")
        if not self.options.exit_when_done:
            self.finished = False  # keep spinning (latched truth, diagnostics)

    def _publish_diagnostics(self) -> None:
        sim_s = self.published / self.config.rate_hz
        wall_s = time.monotonic() - self._wall_start
        status = DiagnosticStatus(
            level=DiagnosticStatus.OK, name=self.get_fully_qualified_name(),
            hardware_id=f"{self.config.model}_car_sim",
            message=("finished" if self.finished else "simulating") + f" at t = {sim_s:.1f} s",
            values=[
                KeyValue(key="road", value=f"{self.config.road.kind} {self.config.road.road_class}"),
                KeyValue(key="speed_kmh", value=f"{self.config.speed_kmh:g}"),
                KeyValue(key="sim_time_s", value=f"{sim_s:.2f}"),
                KeyValue(key="real_time_factor", value=f"{sim_s / wall_s:.2f}" if wall_s > 0 else "0"),
                KeyValue(key="samples_published", value=str(self.published)),
            ],
        )
        msg = DiagnosticArray(status=[status])
        msg.header.stamp = _time(self._epoch_ns + round(sim_s * NS)) if self._sim_mode else \
            self.get_clock().now().to_msg()
        self._pub_diag.publish(msg)


def main(args: Sequence[str] | None = None) -> int:
    return ros_common.spin_node(SimNode, args)


if __name__ == "__main__":
    sys.exit(main())
