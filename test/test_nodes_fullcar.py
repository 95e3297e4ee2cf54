"""The full car through the ROS nodes, launch-free: the simulator's four corner accelerometers,
the estimator on three or four of them, the recorder, signals, and ``rozyn demo --model full``
recorded and replayed bit for bit.

Each test process uses ROS domains of its own (ros_helpers.domain) and localhost-only discovery.
"""

from __future__ import annotations

import csv
import math
import os
import re
import signal
import subprocess
import sys
import time
from pathlib import Path

import numpy as np
import pytest
import yaml

os.environ["ROS_AUTOMATIC_DISCOVERY_RANGE"] = "LOCALHOST"

from diagnostic_msgs.msg import DiagnosticArray
from geometry_msgs.msg import InertiaStamped
from rclpy.parameter import Parameter
from rclpy.qos import DurabilityPolicy, QoSProfile, ReliabilityPolicy
from ros_helpers import domain, ros_fixture, ros_session
from sensor_msgs.msg import Imu

DOMAIN = domain("fullcar")  # and DOMAIN + 1
from bag_helpers import check_bag  # noqa: E402
from rosbags.highlevel import AnyReader  # noqa: E402
from std_msgs.msg import Float64MultiArray  # noqa: E402

from rozyn_estimator.bag import open_bag  # noqa: E402
from rozyn_estimator.errors import ConfigError  # noqa: E402
from rozyn_estimator.method import PipelineConfig  # noqa: E402
from rozyn_estimator.method.config import FULL_PARAM_NAMES  # noqa: E402
from rozyn_estimator.method.pipeline import estimate  # noqa: E402
from rozyn_estimator.online import CUSTOM_DATA_KEY, EstimatorConfig  # noqa: E402
from rozyn_estimator.ros import messages as ros_io  # noqa: E402
from rozyn_estimator.ros.estimator_node import EstimatorNode  # noqa: E402
from rozyn_estimator.ros.recorder_node import BagRecorder  # noqa: E402
from rozyn_estimator.tools import cli  # noqa: E402
from rozyn_estimator.vehicle_full import CORNERS, FullVehicle, load_full_vehicle  # noqa: E402
from sim_node.node import SimNode  # noqa: E402
from sim_node.simulation import Simulation  # noqa: E402

pytestmark = pytest.mark.ros
ROOT = Path(__file__).resolve().parents[1]
BIN = Path(sys.executable).parent
NS = 1_000_000_000
FULL_FILE = str(ROOT / "config" / "vehicle_full.yaml")
FAST = [Parameter("pipeline.refine", value="none")]  # Rozyn's stage: what is checked here is the plumbing

ros = ros_fixture(DOMAIN)


def _collect(probe):
    got = {"inertia": [], "covariance": [], "diagnostics": [], "truth": []}
    probe.create_subscription(InertiaStamped, "inertia", got["inertia"].append, 10)
    probe.create_subscription(Float64MultiArray, "inertia/covariance", got["covariance"].append, 10)
    probe.create_subscription(DiagnosticArray, "/diagnostics", got["diagnostics"].append, 50)
    latched = QoSProfile(depth=1, reliability=ReliabilityPolicy.RELIABLE,
                         durability=DurabilityPolicy.TRANSIENT_LOCAL)
    probe.create_subscription(InertiaStamped, "sim/ground_truth", got["truth"].append, latched)
    sensors = QoSProfile(depth=10_000, reliability=ReliabilityPolicy.BEST_EFFORT)
    for corner in CORNERS:  # the sim publishes all four, whichever the estimator reads
        got[corner] = []
        probe.create_subscription(Imu, f"accel/{corner}", got[corner].append, sensors)
    return got


@pytest.mark.parametrize("unused", ["", "rear_right"], ids=["four corners", "three corners"])
def test_sim_and_estimator_of_the_full_car(ros, unused):
    """Sim time at 10x, 50 s of Gaussian ISO A: the full car's inertia and its 5x5 covariance, as
    estimate gives them on the same run's window of the corners the estimator reads."""
    got = _collect(ros.probe)
    sim = ros.add(SimNode(context=ros.context, parameter_overrides=[
        Parameter("vehicle.model", value="full"), Parameter("time_mode", value="sim"),
        Parameter("real_time_factor", value=10.0), Parameter("duration_s", value=50.0),
        Parameter("road.amplitudes", value="gaussian"), Parameter("wait_for_subscribers", value=True)]))
    est = ros.add(EstimatorNode(context=ros.context, parameter_overrides=[
        Parameter("use_sim_time", value=True), Parameter("speed_topic", value="sim/speed"),
        Parameter("vehicle_file", value=FULL_FILE), Parameter("window_s", value=30.0),
        Parameter("qos_depth", value=10_000), *FAST,
        *([Parameter(f"{unused}_topic", value="")] if unused else [])]))
    corners = tuple(c for c in CORNERS if c != unused)
    assert est.online.layout.channels == corners
    accel = {s.topic_name for s in est.subscriptions} - {"/sim/speed", "/clock"}
    assert accel == {f"/accel/{c}" for c in corners}
    assert {p.topic_name for p in sim.publishers} >= {f"/accel/{c}" for c in CORNERS}
    assert ros.spin_until(lambda: sim.finished, 60.0)
    assert ros.spin_until(lambda: got["covariance"] and ros_io.covariance_stamp_ns(got["covariance"][-1])
                          >= 45 * NS, 20.0)
    assert est.received == [5000] * len(corners)
    assert [len(got[c]) for c in CORNERS] == [5000] * 4
    assert got["rear_right"][-1].header.frame_id == "accel_rear_right_link"
    truth = got["truth"][-1].inertia
    assert (truth.m, truth.ixx, truth.iyy, truth.com.x, truth.com.y) == (1000.0, 400.0, 2000.0, -1.2, 0.0)
    last = next(m for m in got["inertia"] if m.header.stamp.sec == 45)
    i = last.inertia
    # what estimate makes of the same 30 s of the same run's corners
    run = Simulation(sim.config).run(50.0)
    columns = [CORNERS.index(c) for c in corners]
    window = run.accel_mps2[(run.t_s > 15.0 + 1e-9) & (run.t_s <= 45.0 + 1e-9)][:, columns]
    expected = estimate(window, 100.0, FullVehicle(), PipelineConfig(refine="none"), speed_mps=100 / 3.6,
                             sensors=corners)
    np.testing.assert_allclose([i.m, i.ixx, i.iyy, -i.com.x, i.com.y], expected.params, rtol=1e-6)
    assert i.ixy == 0.0 and all(math.isnan(x) for x in (i.com.z, i.izz, i.ixz, i.iyz))
    cov = next(c for c in got["covariance"] if ros_io.covariance_stamp_ns(c) == 45 * NS)
    dims = [(d.label, d.size, d.stride) for d in cov.layout.dim]
    assert dims == [(",".join(FULL_PARAM_NAMES), 5, 25), ("stamp=45.000000000", 5, 5)]
    c = np.array(cov.data).reshape(5, 5)
    assert np.allclose(c, c.T) and np.all(np.linalg.eigvalsh(c) > 0)
    np.testing.assert_allclose(c, expected.covariance, rtol=1e-5)
    statuses = [s for a in got["diagnostics"] for s in a.status if s.name == "/estimator_node"]
    values = {kv.key: kv.value for kv in statuses[-1].values}
    assert {f"samples_{c}" for c in corners} <= set(values) and f"samples_{unused}" not in values
    assert values["dropped_total"] == "0" and values["window_resets"] == "0", values
    assert float(values["roll_inertia_kgm2_std"]) == pytest.approx(math.sqrt(c[1, 1]), rel=1e-3)
    assert {s.hardware_id for s in statuses} == {"full_car"}  # the model's, hardware_id not set
    sim_status = [s for a in got["diagnostics"] for s in a.status if s.name == "/sim_node"]
    assert sim_status and sim_status[-1].hardware_id == "full_car_sim"


@pytest.mark.parametrize(("overrides", "hardware_id"), [
    ([Parameter("vehicle.model", value="full")], "full_car"),
    ([Parameter("vehicle_file", value=FULL_FILE), Parameter("hardware_id", value="rig_7")], "rig_7"),
    ([], "half_car"),
], ids=["full car", "set explicitly", "half car"])
def test_the_estimators_hardware_id_follows_the_model_unless_set(ros, overrides, hardware_id):
    """Before any update: the periodic /diagnostics status of the estimator names its hardware."""
    got: list[DiagnosticArray] = []
    ros.probe.create_subscription(DiagnosticArray, "/diagnostics", got.append, 50)
    ros.add(EstimatorNode(context=ros.context, parameter_overrides=[
        *overrides, Parameter("diagnostics_period_s", value=0.1)]))

    def statuses() -> list:
        return [s for a in got for s in a.status if s.name == "/estimator_node"]

    assert ros.spin_until(lambda: len(statuses()) >= 2, 10.0)
    assert {s.hardware_id for s in statuses()} == {hardware_id}


def test_invalid_full_car_parameters_are_refused_at_startup(ros, capsys):
    for overrides, words in (
        ([Parameter("vehicle.model", value="full"), Parameter("front_left_topic", value=""),
          Parameter("rear_right_topic", value="")], "at least three of front_left_topic"),
        ([Parameter("vehicle.model", value="full"), Parameter("vehicle_file", value=str(ROOT / "config" /
                                                                                       "vehicle.yaml"))],
         "vehicle.model is full but vehicle_file"),
        ([Parameter("vehicle.model", value="quarter")], "vehicle.model: must be one of half, full"),
    ):
        with pytest.raises(ConfigError, match=words):
            EstimatorNode(context=ros.context, parameter_overrides=overrides)
    with pytest.raises(ConfigError, match="corner_gain_errors are the full car's"):
        SimNode(context=ros.context, parameter_overrides=[
            Parameter("departures.corner_gain_errors", value=[0.01, 0.0, 0.0, 0.0])])
    departed = SimNode(context=ros.context, parameter_overrides=[
        Parameter("vehicle_file", value=FULL_FILE), Parameter("departures.damper_ratio", value=2.0),
        Parameter("departures.corner_gain_errors", value=[0.01, 0.0, -0.02, 0.0])])
    try:  # the full car takes the departures, per corner
        assert departed.config.departures.corner_gains == (1.01, 1.0, 0.98, 1.0)
        departed.sim.next_block(10)
        assert departed.sim.plant.iterations > 1  # the nonlinear dampers' fixed point, at every corner
    finally:
        departed.destroy_node()
    done = subprocess.run([str(BIN / "estimator_node"), "--ros-args", "-p", "vehicle.model:=full",
                           "-p", f"vehicle_file:={ROOT / 'config' / 'vehicle.yaml'}"],
                          env=dict(os.environ, ROS_DOMAIN_ID=str(DOMAIN + 1)), capture_output=True, text=True,
                          timeout=60)
    assert done.returncode == 2 and "Traceback" not in done.stderr
    last = done.stderr.strip().splitlines()[-1]
    assert last.startswith("[estimator_node] invalid parameter: vehicle.model is full but vehicle_file"), last


def test_the_full_car_configuration_travels_in_the_bag(tmp_path, ros):
    est = ros.add(EstimatorNode(context=ros.context, parameter_overrides=[
        Parameter("vehicle.model", value="full"), Parameter("vehicle.roll_inertia_kgm2", value=450.0),
        Parameter("front_right_topic", value="imu/fr"), Parameter("rear_left_topic", value="")]))
    rec = ros.add(BagRecorder(context=ros.context, parameter_overrides=[
        Parameter("output", value=str(tmp_path / "b")), Parameter("discovery_period_s", value=0.05)]))
    assert ros.spin_until(lambda: rec.estimator_config is not None, 15.0)
    config = rec.estimator_config
    assert config.full_vehicle == FullVehicle(roll_inertia_kgm2=450.0) == est.online.vehicle
    assert config.sensors == (("front_left", "/accel/front_left"), ("front_right", "/imu/fr"),
                              ("rear_right", "/accel/rear_right"))
    assert "/imu/fr" in rec._wanted  # the estimator's inputs are recorded, wherever they are
    rec.close()
    info = yaml.safe_load((tmp_path / "b" / "metadata.yaml").read_text())["rosbag2_bagfile_information"]
    assert EstimatorConfig.from_json(info["custom_data"][CUSTOM_DATA_KEY]) == config


def test_signals_stop_the_full_car_nodes_cleanly_with_a_valid_bag(tmp_path):
    """sim_node, estimator_node and bag_recorder of the full car as processes; after the first
    estimate SIGINT (sim, estimator) and SIGTERM (recorder): status 0, the bag closed."""
    env = dict(os.environ, ROS_DOMAIN_ID=str(DOMAIN + 1), PYTHONUNBUFFERED="1")

    def start(exe: str, *params: str) -> subprocess.Popen[str]:
        args = [str(BIN / exe), "--ros-args", *(x for p in params for x in ("-p", p))]
        return subprocess.Popen(args, env=env, stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True,
                                start_new_session=True)

    procs = {
        "bag_recorder": start("bag_recorder", "use_sim_time:=true", f"output:={tmp_path / 'bag'}",
                              "qos_depth:=10000"),
        "estimator_node": start("estimator_node", f"vehicle_file:={FULL_FILE}", "use_sim_time:=true",
                                "window_s:=20.0", "speed_topic:=sim/speed", "pipeline.refine:=none",
                                "qos_depth:=10000"),
        "sim_node": start("sim_node", f"vehicle_file:={FULL_FILE}", "time_mode:=sim", "real_time_factor:=5.0",
                          "wait_for_subscribers:=true", "subscribers_per_topic:=2",
                          "road.amplitudes:=gaussian"),
    }
    got: list = []
    try:
        with ros_session(DOMAIN + 1) as probe:
            probe.probe.create_subscription(InertiaStamped, "inertia", got.append, 10)
            deadline = time.monotonic() + 90
            while time.monotonic() < deadline and len(got) < 2:
                probe.spin_until(lambda: len(got) >= 2, 0.5)
                assert all(p.poll() is None for p in procs.values()), "a node died"
    finally:
        for name, proc in procs.items():
            os.killpg(proc.pid, signal.SIGTERM if name == "bag_recorder" else signal.SIGINT)
        outputs = {name: proc.communicate(timeout=30) for name, proc in procs.items()}
    assert got and not math.isnan(got[0].inertia.ixx)
    for name, proc in procs.items():
        out, err = outputs[name]
        assert proc.returncode == 0, (name, err[-2000:])
        assert "Traceback" not in out + err, name
    counts = check_bag(tmp_path / "bag")
    assert counts.get("/inertia", 0) >= 1, counts
    # The sim waits for two subscribers per topic (the estimator's, the recorder's; as the
    # launch file's record:=true does); from the recorder's first sample on nothing is lost.
    stamps: dict[str, list[int]] = {f"/accel/{c}": [] for c in CORNERS}
    with AnyReader([tmp_path / "bag"]) as reader:
        for conn, t, _ in reader.messages([c for c in reader.connections if c.topic in stamps]):
            stamps[conn.topic].append(t)
    for topic, times in stamps.items():
        span_s = (max(times) - min(times)) * 1e-9 if times else 0.0
        assert span_s > 4.0 and len(times) >= 0.99 * span_s * 100.0, (topic, len(times), span_s, counts)
    with open_bag(tmp_path / "bag") as reader:
        config = EstimatorConfig.from_json(reader.custom_data[CUSTOM_DATA_KEY])
    assert config.full_vehicle == load_full_vehicle(FULL_FILE)


def test_the_full_car_demo_records_and_its_replay_reproduces_the_estimates(tmp_path):
    """``rozyn demo --model full`` as the user runs it (the refinement as configured by
    default), then ``rozyn replay`` on its bag: the same estimates and covariances, bit for bit."""
    env = dict(os.environ, ROS_DOMAIN_ID=str(DOMAIN + 1), PYTHONUNBUFFERED="1")
    done = subprocess.run(
        [str(BIN / "rozyn"), "demo", "--model", "full", "--duration-s", "31", "--window-s", "20",
         "--bag-dir", str(tmp_path), "--out", str(tmp_path / "demo-out")],
        env=env, capture_output=True, text=True, timeout=400,
    )
    assert done.returncode == 0, done.stderr[-2000:]
    assert re.search(r"^truth: m = 1000 kg, Ixx = 400 kg m², Iyy = 2000 kg m², lf = 1.2 m, yc = 0 m$",
                     done.stdout, re.M), done.stdout
    assert len(re.findall(r"^t = .*  Ixx = .*  yc = ", done.stdout, re.M)) == 3  # 20, 25, 30 s
    bag = Path(re.search(r"recorded the run to (\S+) ", done.stdout).group(1))
    printed = re.search(r"replay it offline with:\n  (.+)\n", done.stdout).group(1).split()
    counts = check_bag(bag)
    assert all(counts[f"/accel/{c}"] == 3100 for c in CORNERS) and "/accel/front" not in counts, counts
    out = tmp_path / "replay"
    replayed = subprocess.run([*printed, "--out", str(out)], capture_output=True, text=True, timeout=400)
    assert replayed.returncode == 0, replayed.stderr[-2000:]
    assert "(full car)" in replayed.stdout and "max relative difference 0.0e+00" in replayed.stdout
    def published(path: Path) -> dict[int, dict[str, str]]:
        return {int(r["stamp_ns"]): r for r in csv.DictReader(path.open()) if r["published"] == "1"}

    rows, demo_rows = published(out / "updates.csv"), published(tmp_path / "demo-out" / "updates.csv")
    with AnyReader([bag]) as reader:
        msgs = [(c.topic, reader.deserialize(raw, c.msgtype)) for c, _, raw in reader.messages()
                if c.topic in ("/inertia", "/inertia/covariance")]
    inertia = {ros_io.stamp_ns(m.header.stamp): m.inertia for t, m in msgs if t == "/inertia"}
    covariance = {ros_io.covariance_stamp_ns(m): m.data for t, m in msgs if t == "/inertia/covariance"}
    assert len(inertia) == 3 and set(inertia) == set(rows) == set(covariance) == set(demo_rows)
    for stamp, row in rows.items():
        i = inertia[stamp]
        node = [i.m, i.ixx, i.iyy, -i.com.x, i.com.y]
        assert [float(row[k]) for k in FULL_PARAM_NAMES] == node
        assert [float(v) for k, v in row.items() if k.startswith("cov_")] == list(covariance[stamp])
        assert {k: v for k, v in row.items() if k not in ("bag_time_ns", "pipeline_ms")} == \
            {k: v for k, v in demo_rows[stamp].items() if k not in ("bag_time_ns", "pipeline_ms")}
    assert check_bag(out / "estimates")["/inertia"] == 3
    assert (out / "estimates.png").stat().st_size > 10_000


def test_demo_refuses_a_vehicle_file_of_the_other_model(capsys):
    assert cli.main(["demo", "--model", "full", "--vehicle", str(ROOT / "config" / "vehicle.yaml"),
                     "--no-record"]) == 1
    err = capsys.readouterr().err.strip()
    assert "is a half car's vehicle file; --model full needs one that says model: full" in err
    assert len(err.splitlines()) == 1
    assert cli.main(["demo", "--model", "full", "--stiffness-error", "0.1", "--no-record"]) == 1
    assert "the full car takes none" in capsys.readouterr().err
