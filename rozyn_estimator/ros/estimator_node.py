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

from rozyn_estimator import parameters as params
from rozyn_estimator.errors import ConfigError
from rozyn_estimator.online.estimator import Job, OnlineEstimator, Update
from rozyn_estimator.online.estimator_config import EstimatorConfig
from rozyn_estimator.ros import glue as ros_common
from rozyn_estimator.ros import messages as ros_io

NODE_NAME = "estimator_node"

# Node-only parameters: name -> (default, description, range or None, read-only)
_NODE_ONLY: dict[str, tuple[Any, str, tuple[float, float] | None, bool]] = {
    "qos_depth": (
        100,
        "subscription queue depth (best effort, volatile: sensor-data QoS)",
        (1, 100000),
        True,
    ),
    "diagnostics_period_s": (1.0, "period of /diagnostics between updates [s]", (0.05, 60.0), True),
}
# Parameters of EstimatorConfig (defaults from there): name -> (description, range, read-only)
_CONFIG_HELP: dict[str, tuple[str, tuple[float, float] | None, bool]] = {
    "front_topic": ("front accelerometer topic (sensor_msgs/Imu)", None, True),
    "rear_topic": ("rear accelerometer topic (sensor_msgs/Imu)", None, True),
    "field": (
        "numeric field of the Imu message that holds the vertical acceleration "
        "(gravity included is fine: the mean is removed)",
        None,
        True,
    ),
    "speed_topic": ("optional vehicle speed topic; empty: use speed_mps", None, True),
    "speed_topic_type": (
        "type of speed_topic: twist (geometry_msgs/TwistStamped) or odometry "
        "(nav_msgs/Odometry); the speed is the norm of linear x, y",
        None,
        True,
    ),
    "frame_id": ("frame of the published centre of gravity", None, False),
    "front_axle_x_m": (
        "x of the front axle in frame_id [m] (com.x = front_axle_x_m - lf)",
        (-100.0, 100.0),
        False,
    ),
    "hardware_id": ("hardware_id of the diagnostic status", None, False),
}
# OnlineConfig fields: name -> (description, range)
_ONLINE_HELP: dict[str, tuple[str, tuple[float, float]]] = {
    "window_s": ("sliding window of paired samples [s]", (1.0, 3600.0)),
    "update_period_s": ("message time between updates [s]; at most window_s", (0.1, 3600.0)),
    "min_window_fill": ("share of window_s that must hold paired data before estimating", (0.05, 1.0)),
    "pair_tolerance_s": ("front and rear stamps this close are the same instant [s]", (0.0, 1.0)),
    "rate_hz": ("rate of the paired grid [Hz]; 0: the slower sensor's, at most max_rate_hz", (0.0, 100000.0)),
    "max_rate_hz": ("faster sensors are low-passed and decimated to this rate [Hz]", (1.0, 100000.0)),
    "max_gap_s": ("a longer silence on a sensor resets the window [s]", (0.001, 3600.0)),
    "jump_back_s": (
        "a stamp this much older than the last resets the window (bag loop) [s]",
        (0.001, 3600.0),
    ),
    "silence_s": ("a sensor silent this long is reported as waiting [s]", (0.01, 3600.0)),
    "max_speed_variation": ("windows whose (max - min)/mean speed exceeds this are not used", (0.001, 10.0)),
    "speed_mps": ("vehicle speed when no speed samples arrive [m/s]; 0: unknown", (0.0, 150.0)),
}

_PIPELINE_HELP = {
    "identifier": "modal identification method",
    "gamma": "eq 2-5 factor: pseudo-measurement blocks p = gamma 2n/m",
    "n_dof": "degrees of freedom n of eq 2-4",
    "correlation": "free-decay source: multi-reference, thesis-acf or free-decay",
    "max_lag_s": "length of the correlation function used as free decay [s]",
    "min_lag_s": "first correlation lag used [s]",
    "skip_wheelbase_delay": "skip lags shorter than wheelbase/speed when the speed is known",
    "freq_band_hz": "[min, max] natural frequency of the body modes [Hz]",
    "damping_band": "[min, max] damping ratio of the body modes",
    "stiffness_model": "corner stiffness: eq2-21, eq2-22 or condensed",
    "fit": "fit of A0: modal or stiffness-block",
    "variance": "covariance method: jackknife or none",
    "jackknife_blocks": "blocks of the jackknife",
    "min_duration_s": "shortest window the pipeline accepts [s]",
    "refine": "after Rozyn's pipeline: likelihood (the Whittle fit of the half car) or none",
    "likelihood.band_hz": "[min, max] frequency band of the fit [Hz]",
    "likelihood.max_band_nyquist": "the band ends at most at this share of the Nyquist frequency",
    "likelihood.taper": "share of the window under a cosine taper",
    "likelihood.spectra": "cross (front/rear auto- and cross-spectra) or auto (auto-spectra only)",
    "likelihood.aliases": "aliasing terms of the sampled spectrum modelled on each side",
    "likelihood.estimate_waviness": "fit the road's waviness w (ISO 8608 allows w other than 2)",
    "likelihood.road_shape_terms": "smooth departures of the road spectrum from a power law",
    "likelihood.estimate_suspension": "fit the suspension stiffness and damping (per corner) too",
    "likelihood.estimate_incoherence": "fit a share of the road part incoherent between the channels",
    "likelihood.second_start": "guard against wrong basins: a second start, the lower likelihood wins",
    "likelihood.max_noise_share": "a channel fitted as more noise than this share of its power fails",
    "likelihood.covariance": "information in the covariance sandwich: expected or observed",
    "likelihood.max_iter": "optimiser iterations per start",
    "likelihood.tol": "convergence: Newton decrement below this",
    "likelihood.noise_start": "the starts' noise floors, share of each channel's band power",
    "likelihood.block_s": "time blocks of the covariance's empirical score variance [s]",
    "likelihood.block_weight": "the time blocks' share in the score variance, 0..1 (0: the model's alone)",
}


class EstimatorNode(Node):
    """The estimator node; raises ConfigError on invalid parameters at start-up."""

    NAME = NODE_NAME

    def __init__(self, **kwargs: Any) -> None:
        super().__init__(self.NAME, **kwargs)
        self._declare_parameters()
        values = self._values()
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
        qos = QoSProfile(depth=values["qos_depth"], reliability=ReliabilityPolicy.BEST_EFFORT)
        self.create_subscription(Imu, cfg.front_topic, lambda m: self._on_imu(0, m), qos)
        self.create_subscription(Imu, cfg.rear_topic, lambda m: self._on_imu(1, m), qos)
        self._subscribe_speed(qos)
        self.pub_inertia = self.create_publisher(InertiaStamped, "inertia", 10)
        self.pub_covariance = self.create_publisher(Float64MultiArray, "inertia/covariance", 10)
        self.pub_diagnostics = self.create_publisher(DiagnosticArray, "/diagnostics", 10)
        self.create_timer(values["diagnostics_period_s"], self._publish_health)
        self.add_on_set_parameters_callback(self._on_set_parameters)
        self.get_logger().info(
            f"estimating from {cfg.front_topic} and {cfg.rear_topic} ({cfg.field}), window "
            f"{cfg.online.window_s:g} s, update every {cfg.online.update_period_s:g} s"
        )

    # ------------------------------------------------------------ parameters
    def _declare_parameters(self) -> None:
        names = []
        for name, (default, text, bounds, read_only) in _NODE_ONLY.items():
            ros_common.declare(self, name, default, text, bounds, read_only)
            names.append(name)
        defaults = EstimatorConfig()
        for name, (text, bounds, read_only) in _CONFIG_HELP.items():
            ros_common.declare(self, name, getattr(defaults, name), text, bounds, read_only)
            names.append(name)
        for name, (text, bounds) in _ONLINE_HELP.items():
            ros_common.declare(self, name, getattr(defaults.online, name), text, bounds)
            names.append(name)
        for name, default in params.flat_fields("pipeline", defaults.pipeline):
            text = _PIPELINE_HELP.get(name.removeprefix("pipeline."), "see rozyn_estimator.method.pipeline")
            ros_common.declare(self, name, default, text)
            names.append(name)
        self._param_names = names + ros_common.declare_vehicle(self)

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
        self.online.vehicle = config.vehicle
        self.online.config = config.online
        self.online.pipeline = config.pipeline
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
            self.online.dropped[f"{('front', 'rear')[channel]}: field {self.config.field} not numeric"] += 1
            return
        self._arrival[channel] = time.monotonic()
        self.online.add(channel, ros_io.stamp_ns(msg.header.stamp), value)
        for job in self.online.take_due():
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
            if update.estimate.covariance is not None:
                self.pub_covariance.publish(ros_io.covariance_msg(update))
            self.updates_published += 1
        self._publish_health()

    def _publish_health(self) -> None:
        now = self.get_clock().now().nanoseconds
        wall = time.monotonic()
        health = self.online.health(silent_s=(wall - self._arrival[0], wall - self._arrival[1]))
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
