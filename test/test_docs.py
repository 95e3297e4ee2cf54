"""The README documents every topic and parameter the nodes have, and its commands exist."""

from __future__ import annotations

import os
import re
from pathlib import Path

import pytest

os.environ.setdefault("ROS_AUTOMATIC_DISCOVERY_RANGE", "LOCALHOST")

import rclpy
from rclpy.context import Context
from ros_helpers import domain

from rozyn_estimator.ros.estimator_node import EstimatorNode
from sim_node.node import SimNode

ROOT = Path(__file__).resolve().parents[1]
README = (ROOT / "README.md").read_text()
BUILT_IN = {"use_sim_time", "start_type_description_service"}


@pytest.mark.ros
@pytest.mark.parametrize("node_class", [EstimatorNode, SimNode])
def test_every_parameter_is_documented(node_class):
    ctx = Context()
    rclpy.init(context=ctx, domain_id=domain("docs"))
    try:
        node = node_class(context=ctx)
        declared = {name for name in node.get_parameters_by_prefix("") if name not in BUILT_IN}
        described = {name: node.describe_parameter(name).description for name in declared}
        node.destroy_node()
    finally:
        rclpy.shutdown(context=ctx)
    # every parameter has a row in a README parameter table, and a real description
    undocumented = sorted(n for n in declared if not n.startswith("vehicle.") and f"| `{n}` |" not in README)
    assert not undocumented, f"README lacks {undocumented}"
    vague = sorted(n for n, text in described.items() if not text or text.startswith("see "))
    assert not vague, f"parameters without a description: {vague}"


def test_topics_and_commands_are_documented():
    for topic in ("accel/front", "accel/rear", "inertia", "inertia/covariance", "/diagnostics",
                  "sim/ground_truth", "sim/speed", "/clock"):
        assert f"`{topic}`" in README, topic
    first_block = README.split("```bash\n", 1)[1].split("```", 1)[0].splitlines()
    commands = [line.split("#")[0].strip() for line in first_block]
    assert commands == ["scripts/demo", "scripts/test"]  # the two commands, first
    assert "scripts/test" in (ROOT / ".ci" / "run").read_text()  # CI runs the README's command
    for script in re.findall(r"^(scripts/[\w.]+)", README, flags=re.M):
        assert (ROOT / script).exists(), script
