"""DESIGN.md boundaries: a ROS-free core, and the plant and observer kept apart."""

from __future__ import annotations

import ast
import subprocess
import sys
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
# Tools that need both the plant and the estimator (allowed to import sim_node).
TOOLS = {"trial.py", "bench.py", "cli.py", "study.py", "study_plots.py", "compare.py", "ros_demo.py",
         "node_bench.py"}
ROS_MODULES = {"node.py", "recorder.py", "ros_io.py", "ros_common.py", "ros_demo.py", "ros_bag.py",
               "node_bench.py"}


def _imports(path: Path) -> set[str]:
    names = set()
    for node in ast.walk(ast.parse(path.read_text())):
        if isinstance(node, ast.Import):
            names |= {a.name.split(".")[0] for a in node.names}
        elif isinstance(node, ast.ImportFrom) and node.module:
            names.add(node.module.split(".")[0])
    return names


def test_estimator_never_imports_the_plant():
    for path in (ROOT / "rozyn_estimator").glob("*.py"):
        if path.name not in TOOLS:
            assert "sim_node" not in _imports(path), path.name


def test_plant_never_imports_the_estimator_algorithm():
    shared = {"rozyn_estimator"}
    for path in (ROOT / "sim_node").glob("*.py"):
        tree = ast.parse(path.read_text())
        allowed = {"rozyn_estimator.vehicle", "rozyn_estimator.errors", "rozyn_estimator.ros_common",
                   "rozyn_estimator.params"}
        for node in ast.walk(tree):
            if isinstance(node, ast.ImportFrom) and node.module and node.module.split(".")[0] in shared:
                # "from rozyn_estimator import x" imports the module rozyn_estimator.x
                names = [node.module] if node.module != "rozyn_estimator" else \
                    [f"{node.module}.{alias.name}" for alias in node.names]
                for name in names:
                    assert name in allowed, (path, name)


def test_core_is_ros_free():
    for pkg in ("rozyn_estimator", "sim_node"):
        for path in (ROOT / pkg).glob("*.py"):
            if path.name not in ROS_MODULES:
                assert "rclpy" not in _imports(path), path.name


def test_importing_the_core_loads_no_dds():
    code = (
        "import sys, rozyn_estimator, rozyn_estimator.pipeline, rozyn_estimator.trial;"
        "assert 'rclpy' not in sys.modules, 'rclpy imported'"
    )
    subprocess.run([sys.executable, "-c", code], check=True, cwd=ROOT)
