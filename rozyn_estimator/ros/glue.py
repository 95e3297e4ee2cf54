"""ROS glue shared by both nodes: parameter descriptors, the vehicle parameters, the
spin loop with a clean shutdown.

It holds no algorithm, so the simulator node may import it (DESIGN.md boundaries).
"""

from __future__ import annotations

import sys
from collections.abc import Iterable, Sequence
from typing import Any

import rclpy
from rcl_interfaces.msg import FloatingPointRange, IntegerRange, ParameterDescriptor
from rclpy.exceptions import ParameterException
from rclpy.executors import ExternalShutdownException
from rclpy.impl.implementation_singleton import rclpy_implementation as _rclpy
from rclpy.node import Node

from rozyn_estimator import parameters
from rozyn_estimator.errors import ConfigError
from rozyn_estimator.parameters import Param

VEHICLE_FILE_HELP = "vehicle YAML (flat or ROS params); when set it overrides the vehicle.* parameters"


def descriptor(name: str, default: Any, spec: Param) -> ParameterDescriptor:
    """The ROS descriptor of a described parameter: description with its unit, the range
    (when closed) or the choices, read-only flag.

    Floating-point parameters accept integers too (``window_s:=60``): they are declared
    with dynamic typing, and the typed configs check and convert the values.
    """
    is_float = isinstance(default, float) or (
        isinstance(default, list) and all(isinstance(x, float) for x in default)
    )
    text = spec.description + (f" [{spec.unit}]" if spec.unit else "")
    d = ParameterDescriptor(name=name, description=text, read_only=spec.read_only, dynamic_typing=is_float)
    if spec.choices:
        d.additional_constraints = f"one of: {', '.join(spec.choices)}"
    elif spec.low is not None or spec.high is not None:
        d.additional_constraints = parameters.range_rule(spec)
    low, high = spec.low, spec.high
    if low is None or high is None or spec.open_low:
        return d  # ROS ranges are closed: the config's own check enforces the rest
    if isinstance(default, int) and not isinstance(default, bool):
        d.integer_range = [IntegerRange(from_value=int(low), to_value=int(high), step=0)]
    elif isinstance(default, float):
        d.floating_point_range = [FloatingPointRange(from_value=float(low), to_value=float(high), step=0.0)]
    return d


def declare_config(node: Node, config: Any) -> list[str]:
    """Declare every described parameter of a config dataclass (nested ones under their
    prefixes), with its defaults from ``config``; returns their names."""
    names = []
    for flat in parameters.flatten(config):
        node.declare_parameter(flat.name, flat.value, descriptor(flat.name, flat.value, flat.spec))
        names.append(flat.name)
    return names


def declare_vehicle_file(node: Node) -> str:
    """Declare ``vehicle_file`` (the ``vehicle.*`` parameters come with the node's config)."""
    node.declare_parameter("vehicle_file", "", descriptor("vehicle_file", "", Param(VEHICLE_FILE_HELP,
                                                                                      read_only=True)))
    return "vehicle_file"


def values_of(node: Node, names: Iterable[str]) -> dict[str, Any]:
    """Current values of declared parameters."""
    return {p.name: p.value for p in node.get_parameters(list(names))}


def spin_node(node_factory: Any, args: Sequence[str] | None = None) -> int:
    """Init, create the node, spin until SIGINT/SIGTERM, shut down cleanly (exit 0).

    Invalid parameters are reported in one line naming the parameter (exit 2).
    """
    name = getattr(node_factory, "NAME", "node")
    try:
        rclpy.init(args=None if args is None else list(args))
    except _rclpy.RCLError as exc:  # malformed --ros-args
        print(f"[{name}] invalid arguments: {str(exc).split(', at ')[0]}", file=sys.stderr)
        return 2
    node = None
    try:
        try:
            node = node_factory()
        except (ConfigError, ParameterException) as exc:
            reason = str(exc)
            if isinstance(exc, ParameterException):  # rclpy: "... Reason: <why>: <name>"
                reason = reason.split("Reason: ")[-1]
            print(f"[{name}] invalid parameter: {reason}", file=sys.stderr)
            return 2
        executor = _executor()
        executor.add_node(node)
        while rclpy.ok() and not getattr(node, "finished", False):
            executor.spin_once(timeout_sec=0.2)
    except (KeyboardInterrupt, ExternalShutdownException):
        pass
    finally:
        if node is not None:
            node.destroy_node()
        rclpy.try_shutdown()
    return 0


def _executor() -> Any:
    """EventsExecutor (a fraction of the CPU of the default executor), else the default."""
    try:
        from rclpy.experimental import EventsExecutor

        return EventsExecutor()
    except (ImportError, RuntimeError):
        from rclpy.executors import SingleThreadedExecutor

        return SingleThreadedExecutor()
