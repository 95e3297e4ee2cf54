"""The bag recorder with DDS: signals, QoS, late and latched topics, the estimator's
configuration, and the demo's recording replayed to the node's very estimates.

Each test process uses ROS domains of its own (ros_helpers.domain) and localhost-only discovery.
"""

from __future__ import annotations

import csv
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
from bag_helpers import check_bag
from mcap.reader import make_reader

os.environ["ROS_AUTOMATIC_DISCOVERY_RANGE"] = "LOCALHOST"

from rclpy.parameter import Parameter
from rclpy.qos import DurabilityPolicy, QoSProfile, ReliabilityPolicy
from ros_helpers import domain, ros_fixture

DOMAIN = domain("recorder")  # and the next few: this module's private ROS domains
from rosbags.highlevel import AnyReader  # noqa: E402
from sensor_msgs.msg import Imu  # noqa: E402

from rozyn_estimator.bag import open_bag  # noqa: E402
from rozyn_estimator.errors import BagError  # noqa: E402
from rozyn_estimator.online import CUSTOM_DATA_KEY, EstimatorConfig  # noqa: E402
from rozyn_estimator.ros import messages as ros_io  # noqa: E402
from rozyn_estimator.ros.estimator_node import EstimatorNode  # noqa: E402
from rozyn_estimator.ros.recorder_node import BagRecorder  # noqa: E402

pytestmark = pytest.mark.ros
BIN = Path(sys.executable).parent
NS = 1_000_000_000


ros = ros_fixture(DOMAIN)


def _seq_numbers(path: Path, salvage: bool = False) -> list[int]:
    """The sequence numbers (header.stamp.nanosec) of the /seq messages in a bag."""
    with open_bag(path, salvage=salvage) as reader:
        return [int(m) for b in reader.batches(["/seq"]) for m in _nanosec(reader, b)]


def _nanosec(reader, batch):
    for i in range(len(batch)):
        yield reader.deserialize(batch.messages.message(i), "sensor_msgs/msg/Imu").header.stamp.nanosec


def test_sigint_and_sigterm_close_the_bag_with_every_message_and_sigkill_loses_little(tmp_path, ros):
    """Three recorders on a reliable 1 kHz stream; signalled mid-run (mid-write, very likely)."""
    env = dict(os.environ, ROS_DOMAIN_ID=str(DOMAIN), PYTHONUNBUFFERED="1")
    signals = {"int": signal.SIGINT, "term": signal.SIGTERM, "kill": signal.SIGKILL}
    procs = {
        name: subprocess.Popen(
            [
                str(BIN / "bag_recorder"),
                "--ros-args",
                "-p",
                "topics:=[/seq]",
                "-p",
                f"output:={tmp_path / name}",
                "-p",
                "flush_period_s:=0.1",
                "-p",
                "qos_depth:=100000",
                "-p",
                "estimator_node:=''",
                "-p",
                "discovery_period_s:=0.1",
            ],
            env=env,
            stdout=subprocess.PIPE,
            stderr=subprocess.PIPE,
            text=True,
            start_new_session=True,
        )
        for name in signals
    }
    qos = QoSProfile(depth=100000, reliability=ReliabilityPolicy.RELIABLE)
    pub = ros.probe.create_publisher(Imu, "/seq", qos)
    msg = Imu()
    msg.header.frame_id = "seq"
    try:
        assert ros.spin_until(lambda: pub.get_subscription_count() == 3, 30.0), "recorders not subscribed"
        sent_at = []
        started = time.monotonic()
        signalled = None
        while time.monotonic() - started < 3.0:
            for _ in range(10):
                msg.header.stamp.nanosec = len(sent_at)
                pub.publish(msg)
                sent_at.append(time.monotonic())
            if signalled is None and time.monotonic() - started > 2.0:
                for name, sig in signals.items():
                    os.killpg(procs[name].pid, sig)
                signalled = (len(sent_at), time.monotonic())
            time.sleep(0.01)
        outputs = {name: p.communicate(timeout=30) for name, p in procs.items()}
    finally:
        for p in procs.values():
            if p.poll() is None:
                os.killpg(p.pid, signal.SIGKILL)
    n_signal, t_signal = signalled
    for name in ("int", "term"):
        out, err = outputs[name]
        assert procs[name].returncode == 0, err
        assert out.strip().splitlines()[-1] == str(tmp_path / name) and "Traceback" not in err
        assert check_bag(tmp_path / name) == {"/seq": len(_seq_numbers(tmp_path / name))}
        seq = _seq_numbers(tmp_path / name)
        assert seq == list(range(len(seq))) and len(seq) >= n_signal, (name, len(seq), n_signal)
    assert procs["kill"].returncode == -signal.SIGKILL
    with pytest.raises(BagError, match=r"no metadata\.yaml"):
        open_bag(tmp_path / "kill")
    seq = _seq_numbers(tmp_path / "kill", salvage=True)
    flushed_before = sum(1 for t in sent_at if t < t_signal - 1.0)  # flushed every 0.1 s
    assert seq == list(range(len(seq))) and len(seq) >= flushed_before > 0


def test_qos_adapts_to_publishers_latched_and_late_topics(tmp_path, ros):
    latched = QoSProfile(
        depth=1, reliability=ReliabilityPolicy.RELIABLE, durability=DurabilityPolicy.TRANSIENT_LOCAL
    )
    best_effort = QoSProfile(depth=5, reliability=ReliabilityPolicy.BEST_EFFORT)
    truth = ros.probe.create_publisher(Imu, "/latched", latched)
    truth.publish(Imu())  # before the recorder exists
    sensor = ros.probe.create_publisher(Imu, "/sensor", best_effort)
    rec = ros.add(
        BagRecorder(
            context=ros.context,
            parameter_overrides=[
                Parameter("topics", value=["/latched", "sensor", "/late"]),
                Parameter("output", value=str(tmp_path / "b")),
                Parameter("estimator_node", value=""),
                Parameter("discovery_period_s", value=0.05),
            ],
        )
    )
    assert ros.spin_until(
        lambda: {"/latched", "/sensor"} <= set(rec.recorded_topics) and sensor.get_subscription_count() == 1,
        10.0,
    )
    for k in range(50):
        sensor.publish(Imu())
        ros.spin_until(lambda k=k: rec.writer.enqueued >= k + 2, 1.0)
    late = ros.probe.create_publisher(Imu, "/late", QoSProfile(depth=10))  # appears after the start
    assert ros.spin_until(lambda: "/late" in rec.recorded_topics and late.get_subscription_count() == 1, 10.0)
    for _ in range(7):
        late.publish(Imu())
    ros.spin_until(lambda: rec.writer.enqueued >= 58, 5.0)
    rec.close()
    assert check_bag(tmp_path / "b") == {"/latched": 1, "/sensor": 50, "/late": 7}
    with AnyReader([tmp_path / "b"]) as reader:
        qos = {c.topic: c.ext.offered_qos_profiles[0] for c in reader.connections}
    assert qos["/sensor"].reliability.name == "BEST_EFFORT" and qos["/late"].reliability.name == "RELIABLE"
    assert (
        qos["/latched"].durability.name == "TRANSIENT_LOCAL" and qos["/sensor"].durability.name == "VOLATILE"
    )


def test_the_estimator_configuration_travels_in_the_bag(tmp_path, ros):
    est = ros.add(
        EstimatorNode(
            context=ros.context,
            parameter_overrides=[
                Parameter("window_s", value=42.0),
                Parameter("pipeline.gamma", value=5),
                Parameter("vehicle.sprung_mass_kg", value=1100.0),
                Parameter("speed_topic", value="sim/speed"),
                Parameter("frame_id", value="car"),
            ],
        )
    )
    rec = ros.add(
        BagRecorder(
            context=ros.context,
            parameter_overrides=[
                Parameter("output", value=str(tmp_path / "b")),
                Parameter("discovery_period_s", value=0.05),
            ],
        )
    )
    assert ros.spin_until(lambda: rec.estimator_config is not None, 15.0)
    assert "/sim/speed" in rec._wanted  # the estimator's inputs are recorded too
    rec.close()
    info = yaml.safe_load((tmp_path / "b" / "metadata.yaml").read_text())["rosbag2_bagfile_information"]
    config = EstimatorConfig.from_json(info["custom_data"][CUSTOM_DATA_KEY])
    with (tmp_path / "b" / "b_0.mcap").open("rb") as f:  # also in the MCAP at once, for a crash
        records = [m.metadata for m in make_reader(f).iter_metadata() if m.name == "custom_data"]
    assert [EstimatorConfig.from_json(r[CUSTOM_DATA_KEY]) for r in records] == [config]
    assert (config.vehicle, config.online, config.pipeline) == (
        est.online.vehicle,
        est.online.config,
        est.online.pipeline,
    )
    assert (
        config.vehicle.sprung_mass_kg == 1100.0
        and config.online.window_s == 42.0
        and config.pipeline.gamma == 5
    )
    assert (config.front_topic, config.rear_topic, config.speed_topic) == (
        "/accel/front",
        "/accel/rear",
        "/sim/speed",
    )
    assert (config.frame_id, config.node_name) == ("car", "/estimator_node")
    plain = ros.add(EstimatorNode(context=ros.context))
    assert plain.config == EstimatorConfig()  # the replay's defaults are the node's


def test_the_demo_records_and_its_replay_reproduces_the_estimates(tmp_path):
    """README's main command prints the bag path, and ``rozyn replay`` on it gives the
    node's estimates and covariances (same stamps, values to 1e-9) with the pipeline's
    current defaults. Both run as the user runs them (the same BLAS threading)."""
    env = dict(os.environ, ROS_DOMAIN_ID=str(DOMAIN + 1), PYTHONUNBUFFERED="1")
    done = subprocess.run(
        [str(BIN / "rozyn"), "demo", "--duration-s", "26", "--window-s", "20", "--bag-dir", str(tmp_path),
         "--out", str(tmp_path / "demo-out")],
        env=env,
        capture_output=True,
        text=True,
        timeout=300,
    )
    assert done.returncode == 0, done.stderr[-2000:]
    bag = Path(re.search(r"recorded the run to (\S+) ", done.stdout).group(1))
    assert bag.parent == tmp_path and bag.name.startswith("demo-")
    printed = re.search(r"replay it offline with:\n  (.+)\n", done.stdout).group(1).split()
    assert printed[-2:] == ["replay", str(bag)] and Path(printed[0]).name == "rozyn"
    counts = check_bag(bag)
    assert counts["/accel/front"] == counts["/accel/rear"] == 2600 and counts["/sim/ground_truth"] == 1

    out = tmp_path / "replay"
    replayed = subprocess.run(
        [*printed, "--out", str(out)],  # the command as printed works as it is
        capture_output=True,
        text=True,
        timeout=300,
    )
    assert replayed.returncode == 0, replayed.stderr[-2000:]
    assert "configuration: recorded in the bag (/estimator_node)" in replayed.stdout
    rows = {
        int(r["stamp_ns"]): r for r in csv.DictReader((out / "updates.csv").open()) if r["published"] == "1"
    }
    with AnyReader([bag]) as reader:
        msgs = [
            (c.topic, reader.deserialize(raw, c.msgtype))
            for c, _, raw in reader.messages()
            if c.topic in ("/inertia", "/inertia/covariance", "/diagnostics")
        ]
    # the estimator dropped nothing and never reset: its windows were the sim's whole stream
    statuses = [s for t, m in msgs if t == "/diagnostics" for s in m.status if s.name == "/estimator_node"]
    for status in statuses:
        values = {kv.key: kv.value for kv in status.values}
        assert values["dropped_total"] == "0" and values["window_resets"] == "0", values
    inertia = {
        m.header.stamp.sec * NS + m.header.stamp.nanosec: m.inertia for t, m in msgs if t == "/inertia"
    }
    covariance = {ros_io.covariance_stamp_ns(m): m.data for t, m in msgs if t == "/inertia/covariance"}
    assert len(inertia) == 2 and set(inertia) == set(rows) == set(covariance)
    for stamp, row in rows.items():
        node = [inertia[stamp].m, inertia[stamp].iyy, -inertia[stamp].com.x]
        ours = [float(row[k]) for k in ("mass_kg", "pitch_inertia_kgm2", "cog_from_front_axle_m")]
        np.testing.assert_allclose(ours, node, rtol=1e-9, atol=0, err_msg=f"the node's last status: {values}")
        ours = [float(v) for k, v in row.items() if k.startswith("cov_")]
        np.testing.assert_allclose(ours, covariance[stamp], rtol=1e-9, atol=0)
    assert check_bag(out / "estimates")["/inertia"] == 2
