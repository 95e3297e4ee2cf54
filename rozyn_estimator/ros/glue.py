"""ROS glue shared by the nodes: parameter descriptors, the vehicle parameters, the
spin loop with a clean, ordered shutdown.

It holds no algorithm, so the simulator node may import it (DESIGN.md boundaries).
"""

from __future__ import annotations

import contextlib
import signal
import sys
from collections.abc import Iterable, Sequence
from typing import Any

import rclpy
from rcl_interfaces.msg import FloatingPointRange, IntegerRange, ParameterDescriptor
from rclpy.exceptions import ParameterException
from rclpy.impl.implementation_singleton import rclpy_implementation as _rclpy
from rclpy.node import Node
from rclpy.signals import SignalHandlerOptions
from threadpoolctl import threadpool_limits

from rozyn_estimator import parameters
from rozyn_estimator.errors import ConfigError, RozynError
from rozyn_estimator.parameters import Param
from rozyn_estimator.ros.stop import StopRequest
from rozyn_estimator.sensors import SENSOR_PARAMETER_PREFIX, SENSORS_PARAMETER_HELP, sensor_parameter_names
from rozyn_estimator.vehicle import Vehicle
from rozyn_estimator.vehicle_full import MODEL_PARAM, FullVehicle, load_any_vehicle

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


def declare_config(node: Node, config: Any, skip: str = "") -> list[str]:
    """Declare every described parameter of a config dataclass (nested ones under their
    prefixes), with its defaults from ``config``, except those whose names start with
    ``skip`` (when given); returns their names."""
    names = []
    for flat in parameters.flatten(config):
        if skip and flat.name.startswith(skip):
            continue
        node.declare_parameter(flat.name, flat.value, descriptor(flat.name, flat.value, flat.spec))
        names.append(flat.name)
    return names


def declare_vehicle(node: Node) -> list[str]:
    """Declare ``vehicle_file`` and ``vehicle.model``, then the ``vehicle.*`` parameters of the
    model they name: the full car's when ``vehicle.model`` is ``full`` or the vehicle file says
    ``model: full``, else the half car's. Returns their names.

    Raises:
        ConfigError: the vehicle file cannot be read, or ``vehicle.model`` is not a model.
    """
    node.declare_parameter("vehicle_file", "", descriptor("vehicle_file", "", Param(VEHICLE_FILE_HELP,
                                                                                      read_only=True)))
    node.declare_parameter("vehicle.model", "half", descriptor("vehicle.model", "half", MODEL_PARAM))
    names = ["vehicle_file", "vehicle.model"]
    values = values_of(node, names)
    parameters.coerce("vehicle.model", MODEL_PARAM, "half", values["vehicle.model"])
    full = values["vehicle.model"] == "full" or (
        bool(values["vehicle_file"]) and isinstance(load_any_vehicle(values["vehicle_file"]), FullVehicle))
    return names + declare_config(node, FullVehicle() if full else Vehicle()) + declare_sensors(node)


def declare_sensors(node: Node) -> list[str]:
    """Declare ``vehicle.sensors.names`` and, for each name it holds (from a parameter file's
    nested ``vehicle: sensors:`` block), its ``topic``, ``x_m``, ``y_m`` and ``channels``
    (dynamically typed: a file's 1 is as good as 1.0; unset: None). Returns their names."""
    def declare(name: str, text: str) -> None:
        node.declare_parameter(name, None, ParameterDescriptor(description=text, dynamic_typing=True,
                                                               read_only=True))

    declare(f"{SENSOR_PARAMETER_PREFIX}names", SENSORS_PARAMETER_HELP)
    given = node.get_parameter(f"{SENSOR_PARAMETER_PREFIX}names").value
    sensors = [str(n) for n in given] if isinstance(given, list | tuple) else []
    for name in sensor_parameter_names(sensors):
        declare(name, "a sensor of vehicle.sensors.names (rozyn_estimator.sensors)")
    return [f"{SENSOR_PARAMETER_PREFIX}names", *sensor_parameter_names(sensors)]


def values_of(node: Node, names: Iterable[str]) -> dict[str, Any]:
    """Current values of declared parameters."""
    return {p.name: p.value for p in node.get_parameters(list(names))}


SPIN_TIMEOUT_S = 0.1  # how soon the loop sees a stop request


def spin_node(node_factory: Any, args: Sequence[str] | None = None, stop: StopRequest | None = None) -> int:
    """Init, create the node, spin until SIGINT/SIGTERM (or the node is ``finished``), stop
    it in order; the exit status: 0, or what the node's ``finish`` returns.

    Shutdown is deterministic: rclpy installs no signal handler, so nothing shuts the
    context down under a running callback or worker; a signal only sets ``stop`` (installed
    here unless the console script installed it before its imports). The loop then ends,
    the node's ``finish(executor)`` stops its work (the estimator stops taking new updates,
    publishes nothing more and joins its worker; the recorder drains and closes its bag),
    and only then are the node destroyed and the context shut down. A signal during
    start-up is seen before the first spin: the node is created, finished and destroyed.
    A ``stop`` passed in stays installed (its owner restores it); one made here is
    restored on return.

    An invalid parameter (or ``--ros-args``) is reported in one line naming it (exit 2).

    The process keeps one BLAS thread: a node's matrices are tiny, and a second BLAS thread
    spinning for a core that intake, the executor or a neighbouring process holds slows the
    estimator's update by half or more.
    """
    name = getattr(node_factory, "NAME", "node")
    threadpool_limits(1)  # every BLAS library loaded by now: the node's module is imported
    with contextlib.nullcontext(stop) if stop is not None else StopRequest() as request:
        try:
            rclpy.init(
                args=None if args is None else list(args), signal_handler_options=SignalHandlerOptions.NO
            )
        except _rclpy.RCLError as exc:  # malformed --ros-args
            print(f"[{name}] invalid arguments: {str(exc).split(', at ')[0]}", file=sys.stderr)
            return 2
        node = executor = None
        try:
            try:
                node = node_factory()
            except (ConfigError, ParameterException) as exc:
                print(f"[{name}] invalid parameter: {parameter_error(exc)}", file=sys.stderr)
                return 2
            except RozynError as exc:  # e.g. the recorder's bag cannot be created
                print(f"[{name}] {exc}", file=sys.stderr)
                return 2
            executor = _executor()
            executor.add_node(node)
            while not request.requested and not getattr(node, "finished", False) and rclpy.ok():
                executor.spin_once(timeout_sec=SPIN_TIMEOUT_S)
            if request.signal is not None:
                node.get_logger().info(f"{signal.Signals(request.signal).name}: stopping")
            finish = getattr(node, "finish", None)
            return int(finish(executor) or 0) if finish is not None else 0
        finally:
            if node is not None:
                node.destroy_node()
            if executor is not None:
                executor.shutdown()
            rclpy.try_shutdown()


def parameter_error(exc: Exception) -> str:
    """One line naming the parameter: ConfigError's own, or rclpy's refusal (a wrong type)."""
    reason = str(exc)
    if isinstance(exc, ParameterException):  # rclpy: "... Reason: <why>: <name>"
        reason = reason.split("Reason: ")[-1]
    return " ".join(reason.split())


def _executor() -> Any:
    """EventsExecutor (a fraction of the CPU of the default executor), else the default."""
    try:
        from rclpy.experimental import EventsExecutor

        return EventsExecutor()
    except (ImportError, RuntimeError):
        from rclpy.executors import SingleThreadedExecutor

        return SingleThreadedExecutor()
