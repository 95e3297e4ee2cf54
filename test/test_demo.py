"""``rozyn demo`` on a slow machine: its flow control loses nothing, and its outputs.

The demo runs in this process with every update made slow on purpose: it holds the
interpreter's lock (as the pipeline's Python does on a loaded machine) for longer than an
update period takes at 20x. Without the demo's flow control, updates fall due faster than
they are computed and the node skips the older waiting ones (6 of 8 in a run of 60 s with
1.5 s updates); with it, the simulator waits, every update is computed and printed, and
every sample is taken in.

Each test process uses ROS domains of its own (ros_helpers.domain) and localhost-only discovery.
"""

from __future__ import annotations

import csv
import os
import re
import time
from pathlib import Path

import pytest

os.environ["ROS_AUTOMATIC_DISCOVERY_RANGE"] = "LOCALHOST"

from bag_helpers import check_bag
from ros_helpers import domain
from rosbags.highlevel import AnyReader

from rozyn_estimator.online import OnlineEstimator
from rozyn_estimator.ros.estimator_node import EstimatorNode
from rozyn_estimator.tools import cli

pytestmark = pytest.mark.ros
DOMAIN = domain("demo")
UPDATE_S = 1.0  # each update; at 20x an update falls due every 0.25 s of wall time


def test_a_slow_estimator_slows_the_demo_down_and_loses_nothing(tmp_path, monkeypatch, capfd):
    monkeypatch.setenv("ROS_DOMAIN_ID", str(DOMAIN))
    nodes: list[EstimatorNode] = []
    waiting: list[int] = []  # due updates not yet done, seen by each update as it starts
    init, compute = EstimatorNode.__init__, OnlineEstimator.compute

    def keep(self, *args, **kwargs):
        init(self, *args, **kwargs)
        nodes.append(self)

    def slow_update(self, job):
        waiting.append(nodes[0].pending_updates)
        end = time.monotonic() + UPDATE_S
        while time.monotonic() < end:  # pure Python: holds the interpreter's lock
            pass
        return compute(self, job)

    monkeypatch.setattr(EstimatorNode, "__init__", keep)
    monkeypatch.setattr(OnlineEstimator, "compute", slow_update)
    bag, out = tmp_path / "bag", tmp_path / "out"
    code = cli.main(["demo", "--duration-s", "40", "--window-s", "20", "--bag", str(bag), "--out", str(out)])
    printed = capfd.readouterr().out
    assert code == 0, printed
    held = re.search(r"the simulator waited [\d.]+ s .*\(at most (\d+) updates waiting\)", printed)
    assert held and int(held.group(1)) <= 2, printed
    assert len(waiting) == 7 and max(waiting) <= 2, waiting  # due at 5, 10, ... 35 s; none skipped
    assert len(re.findall(r"^t = ", printed, re.M)) == 4  # every estimate printed: 20, 25, 30, 35 s
    est = nodes[0]
    assert est.received == [4000, 4000] and est.online.samples(0) == est.online.samples(1) == 4000
    assert est.online.dropped == {} and est.online.resets == 0 and est.updates_skipped == 0
    assert check_bag(bag)["/accel/front"] == check_bag(bag)["/accel/rear"] == 4000  # every sample
    with AnyReader([bag]) as reader:
        statuses = [s for c, _, raw in reader.messages() if c.topic == "/diagnostics"
                    for s in reader.deserialize(raw, c.msgtype).status if s.name == "/estimator_node"]
    assert statuses and all({kv.key: kv.value for kv in s.values}["missing_front"] == "0" for s in statuses)
    # the outputs: every update in updates.csv (as rozyn replay writes it) and the plot
    rows = list(csv.DictReader((out / "updates.csv").open()))
    assert [float(r["stamp_s"]) for r in rows][-1] >= 34.99 and len(rows) == 7
    assert sum(r["published"] == "1" for r in rows) == 4  # the window 80 % full from 20 s on
    assert f"plot: {out / 'estimates.png'}" in printed and Path(out / "estimates.png").stat().st_size > 10_000


def test_the_demo_gives_both_nodes_one_imu_as_a_vehicle_file():
    """``--sensors imu``: a sensors block is no flat parameter, so both nodes get it as a file;
    the *_error options (which change flat values) are refused with it."""
    import argparse

    from rozyn_estimator.errors import ConfigError
    from rozyn_estimator.online import EstimatorConfig
    from rozyn_estimator.tools.demo.command import add_arguments, node_values
    from sim_node.node import sim_config

    parser = argparse.ArgumentParser()
    add_arguments(parser)
    estimator, sim = node_values(parser.parse_args(["--sensors", "imu"]))
    assert estimator["vehicle_file"] == sim["vehicle_file"]
    config = EstimatorConfig.from_parameters(estimator)
    assert config.sensors == (("imu.accel_z", "/imu/data"), ("imu.gyro_y", "/imu/data"))
    assert config.vehicle.sensor_x_m == pytest.approx((1.5, 1.5))  # 0.3 m behind the CoG
    assert sim_config(sim).channels == ("imu.accel_z", "imu.gyro_y")
    with pytest.raises(ConfigError, match="sensors block"):
        node_values(parser.parse_args(["--sensors", "imu", "--stiffness-error", "0.1"]))
