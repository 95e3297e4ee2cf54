"""The launch files, checked without ``launch`` (CI has no ROS install): each is run against
stand-ins of the launch API that record what it builds, and what it builds is checked
against the package and the nodes.

- every ``Node`` runs an executable of this package, under the node's own name;
- its parameter files exist in ``config/`` (installed with the launch files), and every
  parameter it sets is one the node declares;
- with the arguments' defaults (and with ``model:=full``), the parameters are valid for the
  node (its own checks);
- an argument with choices offers exactly the node parameter's choices;
- every argument is used, every ``LaunchConfiguration`` is declared;
- remapped topics are topics the node uses.

Running them for real (``ros2 launch``) needs a ROS install: README, "ROS 2 nodes".
"""

from __future__ import annotations

import importlib.util
import sys
import types
from pathlib import Path
from typing import Any

import pytest
import yaml

from rozyn_estimator.online import EstimatorConfig
from rozyn_estimator.parameters import build
from rozyn_estimator.ros.estimator_node import COVARIANCE_TOPIC, INERTIA_TOPIC, NodeOptions
from rozyn_estimator.ros.recorder_node import RecorderOptions
from rozyn_estimator.tools.node_scripts import NODES
from rozyn_estimator.tools.param_tables import node_parameters
from sim_node.node import SimNodeOptions, sim_config

ROOT = Path(__file__).resolve().parents[1]
LAUNCH_FILES = sorted((ROOT / "launch").glob("*.launch.py"))
MODULES = ("launch", "launch.launch_description", "launch.actions", "launch.conditions",
           "launch.event_handlers", "launch.events", "launch.substitutions", "launch_ros",
           "launch_ros.actions", "launch_ros.parameter_descriptions", "launch_ros.substitutions")


class Recorded:
    """A launch class's stand-in: keeps the arguments it was built with."""

    def __init__(self, *args: Any, **kwargs: Any) -> None:
        self.args, self.kwargs = args, kwargs


class _StandIns(types.ModuleType):
    def __getattr__(self, name: str) -> type[Recorded]:
        cls = type(name, (Recorded,), {})
        setattr(self, name, cls)
        return cls


def _describe(path: Path, monkeypatch) -> list[Recorded]:
    """The actions of a launch file's description, built with the stand-ins."""
    for name in MODULES:
        monkeypatch.setitem(sys.modules, name, _StandIns(name))
    spec = importlib.util.spec_from_file_location(path.stem.replace(".", "_"), path)
    module = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(module)
    return list(module.generate_launch_description().args[0])


def _kind(x: Any) -> str:
    return type(x).__name__


def _walk(x: Any):
    """Every Recorded object inside x (arguments, keyword arguments, lists, dicts)."""
    if isinstance(x, Recorded):
        yield x
        for y in (*x.args, *x.kwargs.values()):
            yield from _walk(y)
    elif isinstance(x, list | tuple):
        for y in x:
            yield from _walk(y)
    elif isinstance(x, dict):
        for k, v in x.items():
            yield from _walk(k)
            yield from _walk(v)


class Evaluator:
    """Substitutions evaluated with the arguments' defaults (or ``given`` values), the package
    share = the repo."""

    def __init__(self, actions: list[Recorded], given: dict[str, str] | None = None) -> None:
        self.arguments = {a.args[0]: a for a in actions if _kind(a) == "DeclareLaunchArgument"}
        self.given = given or {}

    def __call__(self, x: Any) -> Any:
        kind = _kind(x)
        if isinstance(x, str | int | float | bool):
            return x
        if isinstance(x, list):
            return "".join(str(self(y)) for y in x)
        if kind == "FindPackageShare":
            assert x.args == ("rozyn_estimator",)
            return str(ROOT)
        if kind == "PathJoinSubstitution":
            return str(Path(*(str(self(y)) for y in x.args[0])))
        if kind == "LaunchConfiguration":
            name = x.args[0]
            default = self.arguments[name].kwargs["default_value"]
            return self.given[name] if name in self.given else self(default)
        if kind == "PythonExpression":
            return str(eval(self(x.args[0])))  # as launch evaluates it
        if kind == "ParameterValue":
            value, value_type = self(x.args[0]), x.kwargs.get("value_type")
            if value_type is bool:
                return yaml.safe_load(value)
            return value_type(value) if value_type else yaml.safe_load(value)
        raise AssertionError(f"cannot evaluate {kind}")


def _file_parameters(path: Path, node: str) -> dict[str, Any]:
    """A ROS parameter file's values for ``node`` (and ``/**``), flattened to dotted names."""
    def flat(d: dict[str, Any], prefix: str = "") -> dict[str, Any]:
        out: dict[str, Any] = {}
        for k, v in d.items():
            out |= flat(v, f"{prefix}{k}.") if isinstance(v, dict) else {f"{prefix}{k}": v}
        return out

    data = yaml.safe_load(path.read_text())
    values: dict[str, Any] = {}
    for key in ("/**", node, f"/{node}"):
        values |= flat(data.get(key, {}).get("ros__parameters", {}))
    return values


def _check_values(executable: str, values: dict[str, Any]) -> str | None:
    """The node's own checks (ConfigError names the parameter); the vehicle model it runs."""
    if executable == "estimator_node":
        build(NodeOptions(), values)
        return EstimatorConfig.from_parameters(values).model
    if executable == "sim_node":
        build(SimNodeOptions(), values)
        return sim_config(values).model
    build(RecorderOptions(), values)
    return None


def _declared(executable: str) -> dict[str, Any]:
    table = {"estimator_node": "estimator_node", "sim_node": "sim_node", "bag_recorder": "bag_recorder"}
    flats = node_parameters()[table[executable]]
    if executable != "bag_recorder":
        flats = [*flats, *node_parameters()["vehicle"]]
    return {f.name: f.spec for f in flats}


def _node_topics(executable: str) -> set[str]:
    if executable == "estimator_node":
        config = EstimatorConfig()
        return {config.front_topic, config.rear_topic, INERTIA_TOPIC, COVARIANCE_TOPIC}
    return set()


def test_launch_files_are_there_and_installed():
    assert [p.name for p in LAUNCH_FILES] == ["estimator.launch.py", "sim_estimator.launch.py"]
    assert '"launch/*.launch.py"' in (ROOT / "setup.py").read_text()  # setup.py data_files


@pytest.mark.parametrize("model", ["default", "full"])
@pytest.mark.parametrize("path", LAUNCH_FILES, ids=lambda p: p.name)
def test_launch_file_matches_the_nodes(path, model, monkeypatch):
    actions = _describe(path, monkeypatch)
    evaluate = Evaluator(actions)
    if model == "full":  # model:=full, or (the estimator alone) the full car's vehicle file
        given = {"vehicle_file": str(ROOT / "config" / "vehicle_full.yaml")}
        evaluate = Evaluator(actions, {"model": "full"} if "model" in evaluate.arguments else given)
    nodes = [a for a in actions if _kind(a) == "Node"]
    assert nodes
    used = {x.args[0] for x in _walk(actions) if _kind(x) == "LaunchConfiguration"}
    assert used == set(evaluate.arguments), "every argument used, every configuration declared"
    for node in nodes:
        kw = node.kwargs
        exe = kw["executable"]
        assert kw["package"] == "rozyn_estimator" and exe in NODES and kw["name"] == exe
        declared = _declared(exe)
        values: dict[str, Any] = {}
        for entry in kw.get("parameters", []):
            if isinstance(entry, dict):
                assert set(entry) <= set(declared) | {"use_sim_time"}, set(entry) - set(declared)
                values |= {name: evaluate(v) for name, v in entry.items()}
                for name, v in entry.items():
                    config = [x for x in _walk(v) if _kind(x) == "LaunchConfiguration"]
                    choices = config and evaluate.arguments[config[0].args[0]].kwargs.get("choices")
                    if choices and name in declared and declared[name].choices:
                        assert set(choices) == set(declared[name].choices), name
            else:
                file = Path(evaluate(entry))
                assert file.parent == ROOT / "config" and file.is_file(), file
                values |= _file_parameters(file, exe)
        assert set(values) <= set(declared) | {"use_sim_time"}, set(values) - set(declared)
        assert _check_values(exe, values) in (None, "half" if model == "default" else "full")
        remapped = {source for source, _ in kw.get("remappings", [])}
        assert remapped <= _node_topics(exe), remapped - _node_topics(exe)
