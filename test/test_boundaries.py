"""DESIGN.md boundaries, per sub-package: who may import whom, and no import cycle.

The rules (README, "Layout"): the method, the online logic and bag storage are ROS-free;
the ROS nodes and their glue use the method, the online logic and storage; only the
tools may use the simulator; the simulator uses the shared modules and the ROS glue
only. Every import counts, also one inside a function.
"""

from __future__ import annotations

import ast
import graphlib
import re
import subprocess
import sys
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[1]
PKG = "rozyn_estimator"
SHARED = {f"{PKG}", f"{PKG}.errors", f"{PKG}.vehicle", f"{PKG}.vehicle_full", f"{PKG}.parameters",
          f"{PKG}.tolerances", f"{PKG}.gravity", f"{PKG}.body_model", f"{PKG}.corners", f"{PKG}.sensors",
          f"{PKG}.yaml_file"}
ROS_PACKAGES = {"rclpy", "builtin_interfaces", "diagnostic_msgs", "geometry_msgs", "sensor_msgs", "std_msgs",
                "nav_msgs", "rcl_interfaces", "rosgraph_msgs"}
# sub-package -> the project modules it may import (besides its own) and third-party ROS
RULES: dict[str, tuple[set[str], bool]] = {
    "shared": (SHARED, False),
    f"{PKG}.method": (SHARED, False),
    f"{PKG}.online": (SHARED | {f"{PKG}.method"}, False),
    f"{PKG}.bag": (SHARED, False),
    f"{PKG}.ros": (SHARED | {f"{PKG}.method", f"{PKG}.online", f"{PKG}.bag"}, True),
    f"{PKG}.tools": ({PKG, "sim_node"}, True),
    "sim_node": (SHARED | {f"{PKG}.ros.glue"}, True),
}
ROS_FREE_SIM = {"sim_node.vehicle_plant", "sim_node.road", "sim_node.simulation", "sim_node.departures",
                "sim_node.sensors", "sim_node.fixed_point", "sim_node.modal",
                "sim_node.plant", "sim_node.tracks", "sim_node.load_transfer", "sim_node.drive_cycle"}


def _modules() -> dict[str, Path]:
    out = {}
    for pkg in (PKG, "sim_node"):
        for path in (ROOT / pkg).rglob("*.py"):
            parts = path.relative_to(ROOT).with_suffix("").parts
            name = ".".join(parts[:-1] if parts[-1] == "__init__" else parts)
            out[name] = path
    return out


MODULES = _modules()


def _imports(name: str) -> set[str]:
    """Every module ``name`` imports (a ``from a import b`` of a module b counts as a.b)."""
    path = MODULES[name]
    is_pkg = path.name == "__init__.py"
    out = set()
    for node in ast.walk(ast.parse(path.read_text())):
        if isinstance(node, ast.Import):
            out |= {a.name for a in node.names}
        elif isinstance(node, ast.ImportFrom):
            base = node.module or ""
            if node.level:
                anchor = name.split(".")[: len(name.split(".")) - node.level + (1 if is_pkg else 0)]
                base = ".".join(anchor + ([base] if base else []))
            for alias in node.names:
                full = f"{base}.{alias.name}"
                out.add(full if full in MODULES else base)
    return out


def _group(name: str) -> str:
    if name in SHARED:
        return "shared"
    if name.startswith("sim_node"):
        return "sim_node"
    return ".".join(name.split(".")[:2])


def _allowed(target: str, allowed: set[str]) -> bool:
    return any(target == a or target.startswith(a + ".") for a in allowed)


@pytest.mark.parametrize("name", sorted(MODULES))
def test_module_imports_follow_the_layout(name):
    group = _group(name)
    assert group in RULES, f"{name} is in no sub-package of the layout"
    allowed, ros = RULES[group]
    own = {group} if group != "shared" else set()
    for target in _imports(name):
        top = target.split(".")[0]
        if top in (PKG, "sim_node"):
            assert _allowed(target, allowed | own), f"{name} imports {target}"
        elif top in ROS_PACKAGES:
            assert ros and name not in ROS_FREE_SIM, f"{name} imports {target}: it must stay ROS-free"


def test_method_uses_numpy_and_scipy_only():
    third_party = set()
    for name in MODULES:
        if _group(name) == f"{PKG}.method":
            third_party |= {t.split(".")[0] for t in _imports(name)}
    assert third_party - set(sys.stdlib_module_names) - {PKG} <= {"numpy", "scipy"}


def _ancestors(name: str) -> list[str]:
    parts = name.split(".")
    return [".".join(parts[:k]) for k in range(1, len(parts))]


def test_no_import_cycle():
    """Modules inside a package import their siblings, not the package (whose __init__
    only re-exports them): then no import is circular, at load time or later. Importing a
    module first runs the ``__init__`` of each of its packages that is not yet running (not
    one of the importer's own), so those count as imports too."""
    graph: dict[str, set[str]] = {}
    for name in MODULES:
        edges = set()
        for target in _imports(name):
            edges |= {t for t in (target, *_ancestors(target)) if t in MODULES}
        graph[name] = edges - {name, *_ancestors(name)}
    try:
        graphlib.TopologicalSorter(graph).prepare()
    except graphlib.CycleError as exc:
        pytest.fail(f"import cycle: {' -> '.join(exc.args[1])}")


# Finer rules inside the tools: replaying a recorded bag needs no simulator.
NOT_IMPORTED = {f"{PKG}.tools.replay": ("sim_node",)}


@pytest.mark.parametrize("name", sorted(n for n in MODULES if any(n.startswith(p) for p in NOT_IMPORTED)))
def test_tools_keep_their_finer_rules(name):
    forbidden = next(v for p, v in NOT_IMPORTED.items() if name.startswith(p))
    assert not {t for t in _imports(name) if t.split(".")[0] in forbidden}, name


@pytest.mark.parametrize("name", sorted(n for n in MODULES if n.startswith(f"{PKG}.method")
                                         or n == f"{PKG}.body_model"))
def test_the_method_never_asks_which_car(name):
    """One vehicle model: the method reads any car through the members both vehicle files have
    (``corners``, ``ROLLS``, ``body_values`` …), never by naming the full car's class."""
    text = MODULES[name].read_text()
    assert "FullVehicle" not in text or name == f"{PKG}.body_model", name  # its AnyVehicle names both
    assert not re.search(r"isinstance\([^)]*Vehicle\)", text), name


def test_no_folder_holds_more_than_15_modules():
    """Group modules by concern in sub-packages instead (tools/trial/, method/vehicle_fit/uncertainty/ …)."""
    folders = {p.parent for pkg in (PKG, "sim_node") for p in (ROOT / pkg).rglob("*.py")}
    crowded = {str(f.relative_to(ROOT)): n for f in folders if (n := len(list(f.glob("*.py")))) > 15}
    assert crowded == {}


def test_no_module_is_too_long():
    long = {n: len(p.read_text().splitlines()) for n, p in MODULES.items()}
    assert {n: k for n, k in long.items() if k > 420} == {}


def test_importing_the_core_loads_no_dds():
    code = (
        "import sys, rozyn_estimator.method.pipeline, rozyn_estimator.online.estimator, "
        "rozyn_estimator.bag.reader, rozyn_estimator.tools.trial;"
        "assert 'rclpy' not in sys.modules, 'rclpy imported'"
    )
    subprocess.run([sys.executable, "-c", code], check=True, cwd=ROOT)
