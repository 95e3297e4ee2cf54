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

from rozyn_estimator.errors import ConfigError
from rozyn_estimator.vehicle import FIELD_UNITS, Vehicle

VEHICLE_FILE_HELP = "vehicle YAML (flat or ROS params); when set it overrides the vehicle.* parameters"


def declare(
    node: Node,
    name: str,
    default: Any,
    description: str,
    bounds: tuple[float, float] | None = None,
    read_only: bool = False,
) -> None:
    """Declare a parameter with a descriptor (and a range for numbers).

    Floating-point parameters accept integers too (``window_s:=60``): they are declared
    with dynamic typing, and the typed configs check and convert the values.
    """
    is_float = isinstance(default, float) or (
        isinstance(default, list) and all(isinstance(x, float) for x in default)
    )
    d = ParameterDescriptor(
        name=name, description=description, read_only=read_only, dynamic_typing=is_float
    )
    if bounds is not None and isinstance(default, int) and not isinstance(default, bool):
        d.integer_range = [IntegerRange(from_value=int(bounds[0]), to_value=int(bounds[1]), step=0)]
    elif bounds is not None and isinstance(default, float):
        d.floating_point_range = [FloatingPointRange(from_value=bounds[0], to_value=bounds[1], step=0.0)]
    node.declare_parameter(name, default, d)


def declare_vehicle(node: Node) -> list[str]:
    """Declare ``vehicle_file`` and ``vehicle.<field>`` (Table 5-1 defaults); their names."""
    declare(node, "vehicle_file", "", VEHICLE_FILE_HELP, read_only=True)
    defaults = Vehicle()
    for name, unit in FIELD_UNITS.items():
        declare(
            node, f"vehicle.{name}", getattr(defaults, name), f"vehicle {name.replace('_', ' ')} [{unit}]"
        )
    return ["vehicle_file", *(f"vehicle.{name}" for name in FIELD_UNITS)]


def values_of(node: Node, names: Iterable[str]) -> dict[str, Any]:
    """Current values of declared parameters."""
    return {p.name: p.value for p in node.get_parameters(list(names))}


def spin_node(node_factory: Any, args: Sequence[str] | None = None) -> int:
    """Init, create the node, spin until SIGINT/SIGTERM, shut down cleanly (exit 0).

    Invalid parameters are reported in one line naming the parameter (exit 2).
    """
    name = getattr(node_factory, "NAME", "node")
    try:
        rclpy.init(args=args)
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
