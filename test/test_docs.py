"""The README documents every topic and parameter the nodes have, and its commands exist."""

from __future__ import annotations

import os
import re
from pathlib import Path

import pytest

os.environ.setdefault("ROS_AUTOMATIC_DISCOVERY_RANGE", "LOCALHOST")

import rclpy
from rclpy.context import Context
from rclpy.parameter import Parameter
from ros_helpers import domain

from rozyn_estimator.ros.estimator_node import EstimatorNode
from rozyn_estimator.ros.recorder_node import BagRecorder
from rozyn_estimator.tools import param_tables
from sim_node.node import SimNode

ROOT = Path(__file__).resolve().parents[1]
README = (ROOT / "README.md").read_text()
BUILT_IN = {"use_sim_time", "start_type_description_service"}


def test_readme_parameter_tables_are_generated_from_the_descriptions():
    assert param_tables.render(README) == README, "run: python -m rozyn_estimator.tools.param_tables --write"


@pytest.mark.ros
@pytest.mark.parametrize(("node_class", "table"), [(EstimatorNode, "estimator_node"), (SimNode, "sim_node"),
                                                   (BagRecorder, "bag_recorder")])
def test_nodes_declare_what_the_tables_describe(node_class, table, tmp_path):
    ctx = Context()
    rclpy.init(context=ctx, domain_id=domain("docs"))
    try:
        kwargs = {"parameter_overrides": [Parameter("output", value=str(tmp_path / "bag"))]} \
            if node_class is BagRecorder else {}
        node = node_class(context=ctx, **kwargs)
        declared = {name: node.describe_parameter(name) for name in node.get_parameters_by_prefix("")
                    if name not in BUILT_IN}
        node.destroy_node()
    finally:
        rclpy.shutdown(context=ctx)
    described = param_tables.node_parameters()
    expected = {p.name: p for p in described[table]}
    if table != "bag_recorder":
        expected |= {p.name: p for p in described["vehicle"]}
    assert set(declared) == set(expected)
    for name, d in declared.items():
        spec = expected[name].spec
        assert d.description == spec.description + (f" [{spec.unit}]" if spec.unit else ""), name
        assert d.read_only == spec.read_only, name
        assert spec.description and not spec.description.startswith("see "), name


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
