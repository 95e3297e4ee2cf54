"""Node integration tests, launch-free: in one process and across processes.

Each test process uses ROS domains of its own (ros_helpers.domain) and localhost-only discovery.
"""

from __future__ import annotations

import math
import os
import signal
import subprocess
import sys
import time
from pathlib import Path

import numpy as np
import pytest

os.environ["ROS_AUTOMATIC_DISCOVERY_RANGE"] = "LOCALHOST"

import rclpy
from diagnostic_msgs.msg import DiagnosticArray
from geometry_msgs.msg import InertiaStamped
from rclpy.context import Context
from rclpy.experimental import EventsExecutor
from rclpy.parameter import Parameter
from rclpy.qos import QoSProfile, ReliabilityPolicy, qos_profile_sensor_data
from ros_helpers import domain, ros_fixture

DOMAIN = domain("nodes")  # and the next few: this module's private ROS domains
from sensor_msgs.msg import Imu  # noqa: E402
from std_msgs.msg import Float64MultiArray  # noqa: E402

from rozyn_estimator.errors import ConfigError  # noqa: E402
from rozyn_estimator.ros import messages as ros_io  # noqa: E402
from rozyn_estimator.ros.estimator_node import EstimatorNode  # noqa: E402
from rozyn_estimator.vehicle import Vehicle  # noqa: E402
from sim_node.node import SimNode  # noqa: E402
from sim_node.simulation import SimConfig, Simulation  # noqa: E402

pytestmark = pytest.mark.ros
ROOT = Path(__file__).resolve().parents[1]
BIN = Path(sys.executable).parent
NS = 1_000_000_000


ros = ros_fixture(DOMAIN)


def collect(probe):
    got = {"inertia": [], "covariance": [], "diagnostics": []}
    probe.create_subscription(InertiaStamped, "inertia", got["inertia"].append, 10)
    probe.create_subscription(Float64MultiArray, "inertia/covariance", got["covariance"].append, 10)
    probe.create_subscription(DiagnosticArray, "/diagnostics", got["diagnostics"].append, 50)
    return got


def estimator_status(got):
    return [s for a in got["diagnostics"] for s in a.status if s.name.endswith("estimator_node")]


def test_sim_and_estimator_in_one_process(ros):
    """ISO A, fixed amplitudes, 100 km/h, sim time at 20x: after 150 s within 5 %."""
    got = collect(ros.probe)
    sim = ros.add(SimNode(context=ros.context, parameter_overrides=[
        Parameter("time_mode", value="sim"), Parameter("real_time_factor", value=20.0),
        Parameter("duration_s", value=150.0), Parameter("wait_for_subscribers", value=True)]))
    ros.add(EstimatorNode(context=ros.context, parameter_overrides=[
        Parameter("use_sim_time", value=True), Parameter("speed_topic", value="sim/speed")]))
    assert ros.spin_until(lambda: sim.finished, 50.0)
    def covariance_of_145():
        return got["covariance"] and ros_io.covariance_stamp_ns(got["covariance"][-1]) >= 145 * NS

    ros.spin_until(covariance_of_145, 10.0)
    last = got["inertia"][-1]
    assert last.header.stamp.sec == 145 and last.header.frame_id == "base_link"
    estimate = np.array([last.inertia.m, last.inertia.iyy, -last.inertia.com.x])
    assert np.all(np.abs(estimate / [1000.0, 2000.0, 1.2] - 1) < 0.05), estimate
    assert math.isnan(last.inertia.ixx) and last.inertia.ixy == 0.0
    cov = got["covariance"][-1]
    assert ros_io.covariance_stamp_ns(cov) == ros_io.stamp_ns(last.header.stamp)
    assert cov.layout.dim[0].label == "mass_kg,pitch_inertia_kgm2,cog_from_front_axle_m"
    c = np.array(cov.data).reshape(3, 3)
    assert np.allclose(c, c.T) and np.all(np.diag(c) > 0)
    def last_status():
        found = [s for s in estimator_status(got)
                 if any(kv.key == "update_stamp" and kv.value == "145.000000000" for kv in s.values)]
        return found[-1] if found else None

    assert ros.spin_until(last_status, 5.0)
    status = last_status()
    values = {kv.key: kv.value for kv in status.values}
    assert status.level in (b"\x00", b"\x01") and values["dropped_total"] == "0", (status.message, values)
    assert float(values["mass_kg"]) == pytest.approx(last.inertia.m, rel=1e-5)
    assert {"mode1_freq_hz", "mode2_damping", "window_fill_pct", "pipeline_ms", "speed_mps"} <= set(values)


def test_one_imu_through_both_nodes(ros, tmp_path):
    """A vehicle file whose sensors block is one IMU: the sim publishes complete Imu messages on
    its topic, the estimator reads both channels of it and estimates."""
    path = tmp_path / "imu_car.yaml"
    path.write_text("vehicle:\n  sensors:\n    names: [imu]\n    imu: {topic: /imu/data, x_m: 1.5, "
                    "channels: [accel_z, gyro_y]}\n")
    got = collect(ros.probe)
    imu: list[Imu] = []
    ros.probe.create_subscription(Imu, "/imu/data", imu.append, qos_profile_sensor_data)
    sim = ros.add(SimNode(context=ros.context, parameter_overrides=[
        Parameter("time_mode", value="sim"), Parameter("real_time_factor", value=20.0),
        Parameter("duration_s", value=130.0), Parameter("wait_for_subscribers", value=True),
        Parameter("vehicle_file", value=str(path))]))
    ros.add(EstimatorNode(context=ros.context, parameter_overrides=[
        Parameter("use_sim_time", value=True), Parameter("speed_topic", value="sim/speed"),
        Parameter("vehicle_file", value=str(path))]))
    assert ros.spin_until(lambda: sim.finished, 50.0)
    ros.spin_until(lambda: got["inertia"] and got["inertia"][-1].header.stamp.sec >= 125, 10.0)
    last = got["inertia"][-1]
    estimate = np.array([last.inertia.m, last.inertia.iyy, -last.inertia.com.x])
    assert np.all(np.abs(estimate / [1000.0, 2000.0, 1.2] - 1) < 0.05), estimate
    msg = imu[-1]
    assert msg.header.frame_id == "imu_link" and msg.orientation_covariance[0] == -1.0
    assert msg.angular_velocity_covariance[4] > 0 and msg.linear_acceleration.z > 9.0
    assert 0.0 < abs(msg.angular_velocity.y) < 1.0 and msg.angular_velocity.x == 0.0
    names = {kv.key for s in estimator_status(got) for kv in s.values}
    assert {"samples_imu.accel_z", "samples_imu.gyro_y", "noise_std_imu.gyro_y_radps"} <= names, sorted(names)


def test_the_sim_waits_for_as_many_subscribers_as_asked(ros):
    """With a recorder beside the estimator (``subscribers_per_topic`` 2) the sim holds its
    start until every accelerometer topic has both: one subscriber is not enough; then for
    ``subscriber_grace_s`` more, while the subscribers' side of discovery catches up."""
    sim = ros.add(SimNode(context=ros.context, parameter_overrides=[
        Parameter("time_mode", value="sim"), Parameter("wait_for_subscribers", value=True),
        Parameter("subscribers_per_topic", value=2), Parameter("subscriber_grace_s", value=2.0)]))
    topics, qos = ("accel/front", "accel/rear"), qos_profile_sensor_data  # the sim's best effort
    for topic in topics:
        ros.probe.create_subscription(Imu, topic, lambda _: None, qos)
    assert ros.spin_until(lambda: all(p.get_subscription_count() == 1 for p in sim._pub), 10.0)
    ros.spin_until(lambda: sim.published > 0, 1.0)
    assert sim.published == 0
    got: list = []
    ros.probe.create_subscription(Imu, topics[0], got.append, qos)
    ros.spin_until(lambda: sim.published > 0, 1.0)
    assert sim.published == 0  # the rear has one subscriber still
    ros.probe.create_subscription(Imu, topics[1], lambda _: None, qos)
    assert ros.spin_until(lambda: all(p.get_subscription_count() == 2 for p in sim._pub), 10.0)
    ros.spin_until(lambda: sim.published > 0, 0.5)
    assert sim.published == 0  # within the grace
    assert ros.spin_until(lambda: got, 10.0)


def test_console_scripts_across_processes():
    """Both executables as subprocesses; a probe here receives estimates; SIGINT stops both."""
    env = dict(os.environ, ROS_DOMAIN_ID=str(DOMAIN + 1), PYTHONUNBUFFERED="1")
    sim = subprocess.Popen(
        [str(BIN / "sim_node"), "--ros-args", "--params-file", str(ROOT / "config" / "sim.yaml"),
         "-p", "real_time_factor:=25.0"],
        env=env, stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True, start_new_session=True)
    est = subprocess.Popen(
        [str(BIN / "estimator_node"), "--ros-args", "--params-file", str(ROOT / "config" / "estimator.yaml"),
         "--params-file", str(ROOT / "config" / "vehicle.yaml"), "-p", "use_sim_time:=true",
         "-p", "window_s:=40.0", "-p", "speed_mps:=27.78"],
        env=env, stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True, start_new_session=True)
    ctx = Context()
    rclpy.init(context=ctx, domain_id=DOMAIN + 1)
    probe = rclpy.create_node("probe", context=ctx)
    got = []
    probe.create_subscription(InertiaStamped, "inertia", got.append, 10)
    executor = EventsExecutor(context=ctx)
    executor.add_node(probe)
    try:
        deadline = time.monotonic() + 60
        while time.monotonic() < deadline and len(got) < 2:
            executor.spin_once(timeout_sec=0.1)
            assert sim.poll() is None and est.poll() is None, "a node died"
    finally:
        for proc in (sim, est):
            os.killpg(proc.pid, signal.SIGINT)
        outputs = [proc.communicate(timeout=20) for proc in (sim, est)]
        probe.destroy_node()
        executor.shutdown()
        rclpy.shutdown(context=ctx)
    assert len(got) >= 2
    assert 800 < got[-1].inertia.m < 1200
    for proc, (out, err) in zip((sim, est), outputs, strict=True):
        assert proc.returncode == 0, err
        assert "Traceback" not in err + out


def test_the_spin_loop_keeps_one_blas_thread(monkeypatch):
    """The executables' spin loop makes the node with one BLAS thread (the console scripts do not
    run ``main``: a second BLAS thread made the node's updates 1.5-3x slower on 2 busy cores)."""
    from threadpoolctl import threadpool_info, threadpool_limits

    from rozyn_estimator.ros import glue

    monkeypatch.setenv("ROS_DOMAIN_ID", str(DOMAIN + 2))
    seen: list[int] = []

    def factory() -> EstimatorNode:
        seen.extend(lib["num_threads"] for lib in threadpool_info() if lib["user_api"] == "blas")
        node = EstimatorNode()
        node.finished = True  # the loop ends at once
        return node

    factory.NAME = "estimator_node"  # type: ignore[attr-defined]
    with threadpool_limits(2, user_api="blas"):
        assert glue.spin_node(factory, []) == 0
    assert seen and set(seen) == {1}


def _imu(stamp_ns: int, value: float) -> Imu:
    msg = Imu()
    msg.header.stamp = ros_io.to_time(stamp_ns)
    msg.linear_acceleration.z = value
    return msg


def test_bad_input_streams(ros):
    """Faulty streams at the estimator: drops counted, resets reported, waiting for a
    silent sensor reported, and no estimate ever published from garbage."""
    got = collect(ros.probe)
    est = ros.add(EstimatorNode(context=ros.context, parameter_overrides=[
        Parameter("window_s", value=20.0), Parameter("update_period_s", value=2.0),
        Parameter("diagnostics_period_s", value=0.1), Parameter("silence_s", value=1.0)]))
    qos = QoSProfile(depth=1000, reliability=ReliabilityPolicy.RELIABLE)
    front = ros.probe.create_publisher(Imu, "accel/front", qos)
    rear = ros.probe.create_publisher(Imu, "accel/rear", qos)
    ros.spin_until(lambda: front.get_subscription_count() and rear.get_subscription_count(), 10.0)

    sent = [0]

    def processed():  # samples the estimator has taken in (kept or dropped)
        return est.online.samples(0) + est.online.samples(1) + sum(est.online.dropped.values())

    def send(samples):
        for i, (channel, stamp, value) in enumerate(samples):
            (front, rear)[channel].publish(_imu(stamp, value))
            sent[0] += 1
            if i % 20 == 19:  # pace: let the estimator keep up with its queue
                ros.spin_until(lambda: processed() >= sent[0] - 20, 2.0)
        ros.spin_until(lambda: processed() >= sent[0], 5.0)

    t0 = 5000 * NS
    step = 10_000_000
    # 1. garbage: NaN on the front, a constant on the rear -> no estimate, ever
    send([(c, t0 + k * step, math.nan if c == 0 else 9.81) for k in range(3000) for c in (0, 1)])
    assert est.online.dropped["front: non-finite value"] == 3000
    # 2. good data with faults: duplicates, out of order, a gap, time jumping back
    accel = Simulation(SimConfig(duration_s=30.0)).run(30.0).accel_mps2
    t1 = t0 + 40 * NS
    stream = []
    for k, (a, b) in enumerate(accel.tolist()):
        t = t1 + k * step + (3 * NS if k >= 1500 else 0)  # a 3 s gap at 15 s
        stream += [(0, t, a), (1, t, b)]
        if k == 100:
            stream += [(0, t, a), (1, t - 5 * step, b)]  # duplicate, out of order
    stream += [(0, t0 + 10 * NS, 9.8), (1, t0 + 10 * NS, 9.8)]  # back in time: reset
    send(stream)
    online = est.online
    assert online.dropped["front: duplicate stamp"] == 1
    assert online.dropped["rear: out-of-order stamp"] == 1
    assert online.resets >= 2
    # 3. the rear falls silent: waiting for it
    send([(0, t0 + 10 * NS + k * step, 9.8) for k in range(1, 300)])
    ros.spin_until(lambda: any("waiting for accel/rear" in s.message for s in estimator_status(got)), 5.0)
    messages = [s.message for s in estimator_status(got)]
    assert any("waiting for accel/rear" in m for m in messages)
    assert any("window reset: gap of 3.010 s on accel/" in m for m in messages)  # reached /diagnostics
    assert any("window reset: time jumped back" in m for m in messages)
    levels = {s.level for s in estimator_status(got)}
    assert b"\x01" in levels
    # nothing bogus: no inertia from the garbage, and any estimate is a physical number
    for msg in got["inertia"]:
        assert msg.header.stamp.sec >= t1 // NS
        assert math.isfinite(msg.inertia.m) and msg.inertia.m > 0


def test_invalid_parameters_are_refused_at_startup(ros):
    with pytest.raises(ConfigError, match="update_period_s"):
        EstimatorNode(context=ros.context, parameter_overrides=[Parameter("update_period_s", value=500.0)])
    with pytest.raises(ConfigError, match="freq_band_hz"):
        EstimatorNode(context=ros.context, parameter_overrides=[
            Parameter("pipeline.freq_band_hz", value=[3.0, 1.0])])
    with pytest.raises(ConfigError, match=r"road\.kind"):
        SimNode(context=ros.context, parameter_overrides=[Parameter("road.kind", value="gravel")])
    with pytest.raises(ConfigError, match="cog_from_front_axle_m"):
        SimNode(context=ros.context, parameter_overrides=[
            Parameter("vehicle.cog_from_front_axle_m", value=5.0)])


@pytest.mark.parametrize(
    ("exe", "arg", "words"),
    [("estimator_node", "window_s:=-5.0", "window_s"), ("estimator_node", "window_s:=abc", "window_s"),
     ("estimator_node", "field:=linear_acceleration.w", "no field"),
     ("estimator_node", "field:=header.frame_id", "not a number"),
     ("estimator_node", "update_period_s:=500.0", "update_period_s"),
     ("estimator_node", "qos_depth:=abc", "qos_depth"), ("estimator_node", "front_topic:=5", "front_topic"),
     ("sim_node", "road.kind:=gravel", "road.kind"), ("sim_node", "seed:=abc", "seed"),
     ("sim_node", "wait_for_subscribers:=7", "wait_for_subscribers"),
     ("bag_recorder", "qos_depth:=abc", "qos_depth"), ("bag_recorder", "topics:=5", "topics"),
     ("bag_recorder", "compression:=lzma", "compression"),
     ("bag_recorder", "flush_period_s:=0.0", "flush_period_s")],
)
def test_invalid_parameters_exit_with_a_message(exe, arg, words, tmp_path):
    """A wrong value or a wrong type, any node: one line naming it, status 2, nothing created."""
    env = dict(os.environ, ROS_DOMAIN_ID=str(DOMAIN + 2))
    output = ["-p", f"output:={tmp_path / 'bag'}"] if exe == "bag_recorder" else []
    done = subprocess.run([str(BIN / exe), "--ros-args", "-p", arg, *output], env=env, capture_output=True,
                          text=True, timeout=30)
    assert done.returncode == 2
    assert words in done.stderr and "Traceback" not in done.stderr
    assert done.stderr.strip().count("\n") == 0 and done.stderr.startswith(f"[{exe}] invalid parameter: ")
    assert not (tmp_path / "bag").exists()


def test_runtime_parameter_changes_are_validated(ros):
    est = ros.add(EstimatorNode(context=ros.context))
    result = est.set_parameters([Parameter("window_s", value=2.0)])[0]
    assert not result.successful and "update_period_s" in result.reason
    assert est.get_parameter("window_s").value == 120.0
    result = est.set_parameters([Parameter("pipeline.damping_band", value=[0.5, 0.1])])[0]
    assert not result.successful and "damping_band" in result.reason
    result = est.set_parameters([Parameter("window_s", value=60)])[0]  # an integer is fine
    assert result.successful and est.online.config.window_s == 60.0
    result = est.set_parameters([Parameter("vehicle.wheelbase_m", value=0.5)])[0]
    assert not result.successful and "cog_from_front_axle_m" in result.reason
    assert est.online.vehicle == Vehicle()


def test_parameter_files_configure_both_nodes():
    files = ["--params-file", str(ROOT / "config" / "estimator.yaml"),
             "--params-file", str(ROOT / "config" / "sim.yaml"),
             "--params-file", str(ROOT / "config" / "vehicle.yaml")]
    ctx = Context()
    rclpy.init(args=["--ros-args", *files], context=ctx, domain_id=DOMAIN + 3)
    try:
        est = EstimatorNode(context=ctx)
        sim = SimNode(context=ctx)
        assert est.online.config.window_s == 120.0 and est.online.pipeline.gamma == 4
        assert est.online.vehicle == Vehicle() == sim.config.vehicle
        assert sim.get_parameter("time_mode").value == "sim"
        assert sim.get_parameter("wait_for_subscribers").value is True
        est.destroy_node()
        sim.destroy_node()
    finally:
        rclpy.shutdown(context=ctx)


def test_a_parameter_file_with_a_sensors_block_configures_both_nodes(tmp_path):
    """config/vehicle_imu.yaml as a parameter file: its nested sensors block arrives as flat
    ``vehicle.sensors.*`` parameters, and both nodes read one IMU (an IMU and two accelerometers:
    config/vehicle_imu_axles.yaml); so they do a full car's
    (config/vehicle_full_imu.yaml); a set that cannot see the body is refused."""
    ctx = Context()
    files = ["--params-file", str(ROOT / "config" / "vehicle_imu.yaml")]
    rclpy.init(args=["--ros-args", *files], context=ctx, domain_id=DOMAIN + 4)
    try:
        est = EstimatorNode(context=ctx)
        sim = SimNode(context=ctx)
        assert est.config.sensors == (("imu.accel_z", "/imu/data"), ("imu.gyro_y", "/imu/data"))
        assert est.config.fields == ("linear_acceleration.z", "angular_velocity.y")
        assert sim.config.channels == ("imu.accel_z", "imu.gyro_y")
        assert est.online.vehicle == sim.config.vehicle and est.online.vehicle.sensor_x_m == (1.5, 1.5)
        est.destroy_node()
        sim.destroy_node()
    finally:
        rclpy.shutdown(context=ctx)
    ctx = Context()
    files = ["--params-file", str(ROOT / "config" / "vehicle_imu_axles.yaml")]  # three sensors, four channels
    rclpy.init(args=["--ros-args", *files], context=ctx, domain_id=DOMAIN + 4)
    try:
        est, sim = EstimatorNode(context=ctx), SimNode(context=ctx)
        assert est.config.sensors == (("front.accel_z", "/accel/front"), ("imu.accel_z", "/imu/data"),
                                      ("rear.accel_z", "/accel/rear"), ("imu.gyro_y", "/imu/data"))
        assert sim.config.channels == tuple(label for label, _ in est.config.sensors)
        assert est.online.vehicle == sim.config.vehicle
        assert est.online.vehicle.sensor_x_m == (0.0, 1.5, 2.8, 1.5)
        est.destroy_node()
        sim.destroy_node()
    finally:
        rclpy.shutdown(context=ctx)
    ctx = Context()
    files = ["--params-file", str(ROOT / "config" / "vehicle_full_imu.yaml")]
    rclpy.init(args=["--ros-args", *files], context=ctx, domain_id=DOMAIN + 4)
    try:
        est, sim = EstimatorNode(context=ctx), SimNode(context=ctx)
        labels = ("imu.accel_z", "imu.gyro_x", "imu.gyro_y")
        assert est.config.sensors == tuple((label, "/imu/data") for label in labels)
        assert est.config.fields == ("linear_acceleration.z", "angular_velocity.x", "angular_velocity.y")
        assert sim.config.channels == labels and est.config.model == "full"
        assert est.online.vehicle == sim.config.plant_vehicle and est.online.vehicle.sensor_y_m[0] == 0.2
        est.destroy_node()
        sim.destroy_node()
    finally:
        rclpy.shutdown(context=ctx)
    bad = tmp_path / "bad.yaml"
    bad.write_text("/**:\n  ros__parameters:\n    vehicle:\n      sensors:\n        names: [imu]\n"
                   "        imu: {topic: /imu/data, x_m: 1, channels: [accel_z]}\n")
    ctx = Context()
    rclpy.init(args=["--ros-args", "--params-file", str(bad)], context=ctx, domain_id=DOMAIN + 4)
    try:
        with pytest.raises(ConfigError, match="sees heave but not pitch"):
            EstimatorNode(context=ctx)
        with pytest.raises(ConfigError, match="see heave but neither pitch nor roll"):
            EstimatorNode(context=ctx, parameter_overrides=[Parameter("vehicle.model", value="full")])
    finally:
        rclpy.shutdown(context=ctx)
