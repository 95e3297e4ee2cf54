"""Every runtime import is declared: in package.xml (for rosdep) and in requirements.txt (for pip).

The imports are read from the installed modules (``rozyn_estimator``, ``sim_node``) and
the launch files, every import counted (also one inside a function). :data:`DECLARED`
says, for each third-party import, its rosdep key and its pip distribution; a new import
fails here until it is declared in both places, and a declaration nothing imports fails
too. A rosdep key must be a ROS package, a key of ros/rosdistro, or defined in the
package's ``rosdep.yaml``.
"""

from __future__ import annotations

import ast
import re
import sys
import xml.etree.ElementTree as ET
from pathlib import Path

import yaml

ROOT = Path(__file__).resolve().parents[1]
OURS = {"rozyn_estimator", "sim_node"}
ROS_WHEELS = "ros-jazzy-rclpy"  # rclpy and its interfaces (builtin, rcl, rosgraph)
MESSAGE_WHEELS = "ros-jazzy-common-interfaces"
# import -> (rosdep key, pip distribution; None: not on PyPI, a ROS install provides it)
DECLARED = {
    "rclpy": ("rclpy", ROS_WHEELS),
    "builtin_interfaces": ("builtin_interfaces", ROS_WHEELS),
    "rcl_interfaces": ("rcl_interfaces", ROS_WHEELS),
    "rosgraph_msgs": ("rosgraph_msgs", ROS_WHEELS),
    "std_msgs": ("std_msgs", MESSAGE_WHEELS),
    "sensor_msgs": ("sensor_msgs", MESSAGE_WHEELS),
    "geometry_msgs": ("geometry_msgs", MESSAGE_WHEELS),
    "nav_msgs": ("nav_msgs", MESSAGE_WHEELS),
    "diagnostic_msgs": ("diagnostic_msgs", MESSAGE_WHEELS),
    "launch": ("launch", None),
    "launch_ros": ("launch_ros", None),
    "numpy": ("python3-numpy", "numpy"),
    "scipy": ("python3-scipy", "scipy"),
    "yaml": ("python3-yaml", "pyyaml"),
    "tqdm": ("python3-tqdm", "tqdm"),
    "matplotlib": ("python3-matplotlib", "matplotlib"),
    "psutil": ("python3-psutil", "psutil"),
    "threadpoolctl": ("python3-threadpoolctl", "threadpoolctl"),
    "distributed": ("python3-dask-distributed-pip", "dask"),
    "rosbags": ("python3-rosbags-pip", "rosbags"),
    "mcap": ("python3-mcap-pip", "mcap"),
    "zstandard": ("python3-zstandard", "zstandard"),
    "lz4": ("python3-lz4", "lz4"),
}
# Declared without an import of their own: `ros2 launch` runs the launch files.
RUNTIME_ONLY = {"ros2launch"}
# Keys of ros/rosdistro's rosdep/python.yaml used here (checked there, 2026-08).
ROSDISTRO_KEYS = {
    "python3-numpy", "python3-scipy", "python3-yaml", "python3-tqdm", "python3-matplotlib", "python3-psutil",
    "python3-rosbags-pip", "python3-pytest", "python3-hypothesis", "mcap-ros2-support",
}
ROS_PACKAGES = {key for key, _ in DECLARED.values() if not key.startswith("python3-")} | RUNTIME_ONLY


def _imports(path: Path) -> set[str]:
    out = set()
    for node in ast.walk(ast.parse(path.read_text())):
        if isinstance(node, ast.Import):
            out |= {a.name.split(".")[0] for a in node.names}
        elif isinstance(node, ast.ImportFrom) and node.level == 0 and node.module:
            out.add(node.module.split(".")[0])
    return out


def runtime_imports() -> set[str]:
    files = [p for pkg in OURS for p in (ROOT / pkg).rglob("*.py")] + list((ROOT / "launch").glob("*.py"))
    found = set().union(*(_imports(p) for p in files))
    return found - OURS - set(sys.stdlib_module_names)


def _package_xml(tag: str) -> set[str]:
    return {e.text.strip() for e in ET.parse(ROOT / "package.xml").getroot().iter(tag) if e.text}


def _requirements() -> set[str]:
    names = set()
    for line in (ROOT / "requirements.txt").read_text().splitlines():
        line = line.split("#")[0].strip()
        if line:
            names.add(re.split(r"[\[<>=!~; ]", line, maxsplit=1)[0].lower())
    return names


def test_every_runtime_import_is_declared_and_nothing_else():
    imports = runtime_imports()
    assert imports - set(DECLARED) == set(), "declare these imports (package.xml, requirements.txt, DECLARED)"
    assert set(DECLARED) - imports == set(), "nothing imports these any more"


def test_package_xml_declares_exactly_the_runtime_imports():
    wanted = {DECLARED[name][0] for name in runtime_imports()} | RUNTIME_ONLY
    assert _package_xml("exec_depend") == wanted


def test_requirements_txt_declares_exactly_the_runtime_imports():
    wanted = {pip for name in runtime_imports() if (pip := DECLARED[name][1]) is not None}
    assert _requirements() == wanted


def test_every_rosdep_key_resolves():
    """A ROS package, a rosdistro key, or one of the package's own rosdep.yaml (with an
    entry for debian and ubuntu, the platforms of Jazzy)."""
    own = yaml.safe_load((ROOT / "rosdep.yaml").read_text())
    for key, rules in own.items():
        assert {"debian", "ubuntu"} <= set(rules), key
        assert key not in ROSDISTRO_KEYS, f"{key} is in rosdistro: drop it from rosdep.yaml"
    keys = _package_xml("exec_depend") | _package_xml("test_depend")
    unresolved = keys - ROS_PACKAGES - ROSDISTRO_KEYS - set(own)
    assert unresolved == set()
    assert set(own) <= keys, "rosdep.yaml defines keys package.xml does not use"
