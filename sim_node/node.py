"""``sim_node``: the half-car simulator as a ROS 2 node (thin glue around ``Simulation``).

Publishes front/rear ``sensor_msgs/Imu`` with identical stamps for a pair, the ground
truth (``sim/ground_truth``, transient local), the speed (``sim/speed``), ``/diagnostics``
and, in sim-time mode, ``/clock`` at ``real_time_factor`` times real time (0: as fast as
it can). Blocks of samples are generated on a steady-clock timer, so memory stays
bounded however long it runs.
"""

from __future__ import annotations

import math
import sys
import time
from collections.abc import Sequence
from typing import Any

from builtin_interfaces.msg import Time
from diagnostic_msgs.msg import DiagnosticArray, DiagnosticStatus, KeyValue
from geometry_msgs.msg import InertiaStamped, TwistStamped
from rclpy.clock import Clock, ClockType
from rclpy.node import Node
from rclpy.qos import DurabilityPolicy, HistoryPolicy, QoSProfile, ReliabilityPolicy
from rosgraph_msgs.msg import Clock as ClockMsg
from sensor_msgs.msg import Imu

from rozyn_estimator import parameters as params
from rozyn_estimator.ros import glue as ros_common
from sim_node.road import AMPLITUDE_MODES, RoadSpec
from sim_node.simulation import SimConfig, Simulation

NS = 1_000_000_000
TIME_MODES = ("realtime", "sim")

# name: (default, description, range or None, read-only)
_PARAMS: dict[str, tuple[Any, str, tuple[float, float] | None, bool]] = {
    "road.kind": ("iso", "road model: iso (ISO 8608) or laplace (Bogsjo)", None, True),
    "road.class": ("A", "ISO 8608 class A..H", None, True),
    "road.amplitudes": ("fixed", "fixed (the thesis' generator) or gaussian", None, True),
    "road.laplace_nu": (1.0, "Laplace road: variance of the section gamma variable", (0.0, 100.0), True),
    "road.section_length_m": (100.0, "Laplace road section length [m]", (1.0, 100000.0), True),
    "road.waviness": (2.0, "ISO 8608 waviness w", (0.5, 5.0), True),
    "speed_kmh": (100.0, "vehicle speed [km/h]", (1.0, 400.0), True),
    "rate_hz": (100.0, "accelerometer rate [Hz]", (1.0, 100000.0), True),
    "seed": (1, "random seed of the road and the noise", (0, 2**31 - 1), True),
    "noise_std_mps2": (0.0, "white sensor noise per channel [m/s^2]", (0.0, 100.0), True),
    "duration_s": (0.0, "simulated time to run [s]; 0: forever", (0.0, 1e9), True),
    "time_mode": ("realtime", "realtime: stamps from the clock; sim: publish /clock", None, True),
    "real_time_factor": (1.0, "sim mode: sim seconds per wall second; 0: as fast as possible",
                         (0.0, 10000.0), True),
    "block_s": (0.05, "simulated time produced per tick [s]", (0.001, 10.0), True),
    "front_topic": ("accel/front", "front accelerometer topic", None, True),
    "rear_topic": ("accel/rear", "rear accelerometer topic", None, True),
    "front_frame_id": ("accel_front_link", "frame_id of the front Imu", None, True),
    "rear_frame_id": ("accel_rear_link", "frame_id of the rear Imu", None, True),
    "truth_frame_id": ("base_link", "frame_id of the ground truth", None, True),
    "front_axle_x_m": (0.0, "x of the front axle in truth_frame_id [m]", (-100.0, 100.0), True),
    "qos_depth": (100, "publisher queue depth (best effort: sensor-data QoS)", (1, 100000), True),
    "exit_when_done": (True, "shut down when duration_s has been simulated", None, True),
    "wait_for_subscribers": (False, "start only once both accelerometer topics have a subscriber "
                             "(so a run on sim time loses nothing to discovery)", None, True),
}


def _config(values: dict[str, Any]) -> SimConfig:
    """The simulation from parameter values; ConfigError names the bad parameter."""
    params.check_choice("road.kind", values["road.kind"], ("iso", "laplace"))
    params.check_choice("road.amplitudes", values["road.amplitudes"], AMPLITUDE_MODES)
    params.check_choice("time_mode", values["time_mode"], TIME_MODES)
    for name, (default, *_rest) in _PARAMS.items():
        if isinstance(default, float):
            values[name] = params.number(name, values[name])
    road = RoadSpec(
        kind=values["road.kind"], road_class=values["road.class"], amplitudes=values["road.amplitudes"],
        laplace_nu=values["road.laplace_nu"], section_length_m=values["road.section_length_m"],
        waviness=values["road.waviness"],
    )
    return SimConfig(
        vehicle=params.vehicle_from_parameters(values), road=road, seed=values["seed"],
        speed_kmh=values["speed_kmh"], rate_hz=values["rate_hz"], noise_std_mps2=values["noise_std_mps2"],
        duration_s=values["duration_s"],
    )


def _time(ns: int) -> Time:
    return Time(sec=int(ns // NS), nanosec=int(ns % NS))


class SimNode(Node):
    """The simulator node; raises ConfigError on invalid parameters at start-up."""

    NAME = "sim_node"

    def __init__(self, **kwargs: Any) -> None:
        super().__init__(self.NAME, **kwargs)
        names = list(_PARAMS)
        for name, (default, text, bounds, read_only) in _PARAMS.items():
            ros_common.declare(self, name, default, text, bounds, read_only)
        names += ros_common.declare_vehicle(self)
        p = ros_common.values_of(self, names)
        self.config = _config(p)
        self.sim = Simulation(self.config)
        self._p = p
        self._sim_mode = p["time_mode"] == "sim"
        self._rtf = p["real_time_factor"]
        self._block_n = max(1, round(p["block_s"] * self.config.rate_hz))
        self._epoch_ns = 0 if self._sim_mode else self.get_clock().now().nanoseconds
        self._wall_start = time.monotonic()
        self.finished = False
        self.published = 0

        sensor_qos = QoSProfile(depth=p["qos_depth"], reliability=ReliabilityPolicy.BEST_EFFORT)
        latched = QoSProfile(depth=1, reliability=ReliabilityPolicy.RELIABLE,
                             durability=DurabilityPolicy.TRANSIENT_LOCAL)
        self._pub = (self.create_publisher(Imu, p["front_topic"], sensor_qos),
                     self.create_publisher(Imu, p["rear_topic"], sensor_qos))
        self._msgs = (self._imu_template(p["front_frame_id"]), self._imu_template(p["rear_frame_id"]))
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
        road = f"{p['road.kind']} class {p['road.class']} ({p['road.amplitudes']})"
        pace = (f"sim time at {self._rtf:g}x" if self._rtf else "sim time, as fast as possible") \
            if self._sim_mode else "real time"
        self.get_logger().info(f"simulating {road} at {p['speed_kmh']:g} km/h, {p['rate_hz']:g} Hz, {pace}")

    def _imu_template(self, frame_id: str) -> Imu:
        msg = Imu()
        msg.header.frame_id = frame_id
        msg.orientation_covariance[0] = -1.0  # not provided
        msg.angular_velocity_covariance[0] = -1.0
        var = self.config.noise_std_mps2**2
        msg.linear_acceleration_covariance = [var, 0.0, 0.0, 0.0, var, 0.0, 0.0, 0.0, var]
        return msg

    def _publish_truth(self) -> None:
        v = self.config.vehicle
        msg = InertiaStamped()
        msg.header.stamp = _time(self._epoch_ns)
        msg.header.frame_id = self._p["truth_frame_id"]
        msg.inertia.m = v.sprung_mass_kg
        msg.inertia.iyy = v.pitch_inertia_kgm2
        msg.inertia.com.x = self._p["front_axle_x_m"] - v.cog_from_front_axle_m
        msg.inertia.com.z = math.nan
        msg.inertia.ixx = msg.inertia.izz = msg.inertia.ixz = math.nan
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
        """Hold the start until both accel topics are subscribed, if asked to."""
        if not self._p["wait_for_subscribers"] or self.published:
            return False
        missing = [pub.topic_name for pub in self._pub if pub.get_subscription_count() == 0]
        if missing:
            self.get_logger().info(f"waiting for a subscriber on {', '.join(missing)}", once=True)
            return True
        if not self._sim_mode:
            self._epoch_ns = self.get_clock().now().nanoseconds
        return False

    def _tick(self) -> None:
        if self._waiting():
            return
        n = self._due_samples()
        if n <= 0:
            if self.config.duration_s > 0 and not self.finished:
                self._finish()
            return
        block = self.sim.next_block(n)
        stamps = [self._epoch_ns + round(t * NS) for t in block.t_s]
        if self._pub_clock is not None:
            self._pub_clock.publish(ClockMsg(clock=_time(stamps[-1])))
        front, rear = self._msgs
        for stamp, (a_f, a_r) in zip(stamps, block.accel_mps2.tolist(), strict=True):
            t = _time(stamp)
            front.header.stamp = t
            front.linear_acceleration.z = a_f
            rear.header.stamp = t
            rear.linear_acceleration.z = a_r
            self._pub[0].publish(front)
            self._pub[1].publish(rear)
        self.published += n
        speed = TwistStamped()
        speed.header.stamp = _time(stamps[-1])
        speed.header.frame_id = self._p["truth_frame_id"]
        speed.twist.linear.x = float(block.speed_mps[-1])
        self._pub_speed.publish(speed)

    def _finish(self) -> None:
        self.finished = True
        self._timer.cancel()
        self._publish_diagnostics()
        self.get_logger().info(f"done: {self.published} samples ({self.published / self.config.rate_hz:g} s)")
        if not self._p["exit_when_done"]:
            self.finished = False  # keep spinning (latched truth, diagnostics)

    def _publish_diagnostics(self) -> None:
        sim_s = self.published / self.config.rate_hz
        wall_s = time.monotonic() - self._wall_start
        status = DiagnosticStatus(
            level=DiagnosticStatus.OK, name=self.get_fully_qualified_name(), hardware_id="half_car_sim",
            message=("finished" if self.finished else "simulating") + f" at t = {sim_s:.1f} s",
            values=[
                KeyValue(key="road", value=f"{self._p['road.kind']} {self._p['road.class']}"),
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
