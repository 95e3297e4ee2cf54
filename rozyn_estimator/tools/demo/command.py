"""``rozyn demo``: the simulator and the estimator as ROS 2 nodes, on sim time.

Both nodes run in this process on one executor, talking over DDS like any other nodes
(localhost only, a domain of their own unless ROS_DOMAIN_ID is set). The simulator runs
faster than real time and publishes /clock; a probe prints one line per published
estimate against the ground truth it receives on ``sim/ground_truth``.

The run is recorded (unless ``--no-record``) by a ``bag_recorder`` node on the same
executor, on sim time, to ``<bag-dir>/demo-<UTC time>/``: the sim's topics, the
estimator's outputs and the estimator's configuration, so ``rozyn replay`` on that bag
reproduces the estimates printed here. The sim starts only once the estimator and the
recorder are subscribed to it. SIGINT or SIGTERM stops the run cleanly: the bag is
closed with everything received.

Flow control (:class:`Pacer`): the sim runs at ``--real-time-factor`` at most, and
holds whenever the estimator or the recorder has not yet taken in what it published, or
an update is due while the last one still computes. A slow or loaded machine slows the
demo down (the summary says by how much) instead of losing samples.

The updates are written to ``<out>/updates.csv`` as ``rozyn replay`` writes them, and
drawn in ``<out>/estimates.png`` (:mod:`rozyn_estimator.tools.demo.output`).

``--model full`` (or ``--vehicle`` a full car's file) runs the full car: the simulator's
four corner accelerometers, the estimator on them, roll inertia and lateral CoG besides.
Both nodes get the vehicle as ``vehicle.*`` parameters (the simulator the file's, the
estimator the file's with the ``--*-error`` options applied: the half car's only).
"""

from __future__ import annotations

import argparse
import functools
import os
import shutil
import signal
import sys
import tempfile
import threading
import time
from collections.abc import Callable, Sequence
from pathlib import Path
from typing import Any

from rozyn_estimator.bag import absolute_topic
from rozyn_estimator.errors import BagError, ConfigError
from rozyn_estimator.tools.demo.output import Seen, print_new, summary, write_outputs
from rozyn_estimator.tools.options import (
    add_departure_options,
    add_drive_options,
    add_sensors_option,
    add_vehicle_error_options,
    departure_values,
    drive_label,
    load_change_values,
    vehicle_error_values,
    with_sensor_preset,
)
from sim_node.sensors import MEMS_NOISE_MPS2

NS = 1_000_000_000
# Subscription queues of the estimator and the recorder: at 20 x real time the sim sends
# 2000 Imu messages a second per sensor, and a loaded machine must not make either drop
# one (the recording then holds exactly what the estimator used).
QUEUE_DEPTH = 10_000


class Pacer:
    """The simulator's gate (:attr:`sim_node.node.SimNode.gate`): the next block only once
    every consumer has taken in all but ``ahead`` samples of each sensor, and at most one
    update is waiting (so the printed estimates stay live).

    A consumer that has taken in nothing more for ``stall_s`` while behind no longer
    holds the sim: what it misses was lost on the way, not late (its diagnostics count
    it as missing).

    Args:
        sim: the simulator node (``published``: samples per sensor so far).
        estimator: the estimator node (``received``, ``pending_updates``).
        intakes: further counts of samples taken in (e.g. the recorder's, per sensor).
    """

    def __init__(self, sim: Any, estimator: Any, intakes: Sequence[Callable[[], int]] = (),
                 ahead: int = 50, stall_s: float = 2.0) -> None:
        self._sim, self._est = sim, estimator
        self._intakes = [lambda: min(estimator.received), *intakes]
        self._ahead, self._stall_s = ahead, stall_s
        self._taken, self._progress_at = -1, time.monotonic()
        self._held_since: float | None = None
        self.held_s = 0.0  # wall time the sim was held
        self.max_pending = 0  # most updates waiting at once

    def __call__(self) -> bool:
        now = time.monotonic()
        taken = min(count() for count in self._intakes)
        if taken != self._taken:
            self._taken, self._progress_at = taken, now
        behind = self._sim.published - taken > self._ahead and now - self._progress_at < self._stall_s
        pending = self._est.pending_updates
        self.max_pending = max(self.max_pending, pending)
        go = not behind and pending <= 1
        if go and self._held_since is not None:
            self.held_s += now - self._held_since
            self._held_since = None
        elif not go and self._held_since is None:
            self._held_since = now
        return go


def add_arguments(p: argparse.ArgumentParser) -> None:
    p.add_argument("--duration-s", type=float, default=240.0, help="simulated time (default: 240)")
    p.add_argument("--road", choices=("iso", "laplace"), default="iso", help="road model (default: iso)")
    p.add_argument(
        "--amplitudes",
        choices=("fixed", "gaussian"),
        default="gaussian",
        help="road amplitudes (default: gaussian, a true random road)",
    )
    p.add_argument("--speed-kmh", type=float, default=100.0, help="vehicle speed (default: 100)")
    add_drive_options(p)
    p.add_argument("--noise-std-mps2", type=float, default=MEMS_NOISE_MPS2,
                   help=f"white sensor noise [m/s²] (default: {MEMS_NOISE_MPS2:g}, a consumer MEMS "
                        "accelerometer's; 0: exact sensors)")
    p.add_argument("--seed", type=int, default=1, help="road seed (default: 1)")
    p.add_argument(
        "--real-time-factor", type=float, default=20.0, help="sim seconds per wall second (default: 20)"
    )
    p.add_argument("--window-s", type=float, default=120.0, help="estimator window (default: 120)")
    p.add_argument("--model", choices=("half", "full"),
                   help="half car (front and rear accelerometers) or full car (four corners); default: "
                   "the --vehicle file's, else half")
    p.add_argument("--vehicle", metavar="FILE.yaml",
                   help="vehicle file of the simulator and the estimator (default: the model's defaults, "
                   "config/vehicle.yaml's or config/vehicle_full.yaml's values)")
    add_sensors_option(p)
    p.add_argument(
        "--bag-dir",
        default="bags",
        metavar="DIR",
        help="record the run to DIR/demo-<UTC time>/ (default: bags)",
    )
    p.add_argument("--bag", metavar="DIR", help="record the run to exactly DIR (not --bag-dir/demo-<UTC>)")
    p.add_argument("--no-record", action="store_true", help="do not record the run")
    p.add_argument(
        "--out", metavar="DIR",
        help="write updates.csv and estimates.png to DIR (default: out/demo/<the bag's name>)",
    )
    p.add_argument(
        "--plot", action=argparse.BooleanOptionalAction, default=None,
        help="draw estimates.png (default: when matplotlib is installed)",
    )
    add_departure_options(p)
    add_vehicle_error_options(p)


def node_values(args: argparse.Namespace) -> tuple[dict[str, Any], dict[str, Any]]:
    """The estimator's and the simulator's parameter values for the demo's options, checked
    by the nodes' own rules (ConfigError names a bad one) before anything starts."""
    from rozyn_estimator.online import EstimatorConfig
    from rozyn_estimator.parameters import build
    from rozyn_estimator.tools.cars import HALF_ERRORS
    from sim_node.node import SimNodeOptions, sim_config

    told, vehicle = _vehicle_values(args)  # the estimator is told the vehicle with the *_error options
    errors = {key: error for key, error in vehicle_error_values(args).items() if error != 0.0}
    if errors and "vehicle.model" in vehicle:
        raise ConfigError("the --*-error options change the half car's values; the full car takes none")
    for key, error in errors.items():
        told |= {f"vehicle.{name}": told[f"vehicle.{name}"] * (1.0 + error) for name in HALF_ERRORS[key]}
    estimator = {"speed_topic": "sim/speed", "window_s": args.window_s, "qos_depth": QUEUE_DEPTH, **told}
    sim = {"time_mode": "sim", "real_time_factor": args.real_time_factor, "duration_s": args.duration_s,
           "wait_for_subscribers": True, "road.kind": args.road, "road.amplitudes": args.amplitudes,
           "speed_kmh": args.speed_kmh, "seed": args.seed, "noise_std_mps2": args.noise_std_mps2,
           "drive_cycle_file": args.drive_cycle, **load_change_values(args), **vehicle}
    sim |= {f"departures.{name}": value for name, value in departure_values(args).items()}
    EstimatorConfig.from_parameters(estimator)
    build(SimNodeOptions(), sim)
    sim_config(sim)
    return estimator, sim


def _vehicle_values(args: argparse.Namespace) -> tuple[dict[str, Any], dict[str, Any]]:
    """The vehicle as both nodes' ``vehicle.*`` parameters (twice: the estimator's to change),
    from ``--vehicle`` and ``--model``; ConfigError when they disagree."""
    from rozyn_estimator.parameters import flatten
    from rozyn_estimator.vehicle import Vehicle, dump_vehicle
    from rozyn_estimator.vehicle_full import FullVehicle, dump_full_vehicle, load_any_vehicle

    vehicle: Vehicle | FullVehicle = FullVehicle() if args.model == "full" else Vehicle()
    if args.vehicle:
        vehicle = load_any_vehicle(args.vehicle)
        model = "full" if isinstance(vehicle, FullVehicle) else "half"
        if args.model not in (None, model):
            needs = "says model: full" if args.model == "full" else "has no model: full"
            raise ConfigError(f"--vehicle {args.vehicle} is a {model} car's vehicle file; --model "
                              f"{args.model} needs one that {needs}")
    vehicle = with_sensor_preset(vehicle, args.sensors)
    if vehicle.sensors is not None:  # a block is no flat parameter: a file
        if any(error != 0.0 for error in vehicle_error_values(args).values()):
            raise ConfigError("the --*-error options change vehicle.* values; a vehicle with a sensors block "
                              "is given to the nodes as its file, as it is")
        path = Path(tempfile.mkdtemp(prefix="rozyn-demo-")) / "vehicle.yaml"
        path.write_text(dump_vehicle(vehicle) if isinstance(vehicle, Vehicle) else dump_full_vehicle(vehicle))
        return {"vehicle_file": str(path)}, {"vehicle_file": str(path)}
    values = {f.name: f.value for f in flatten(vehicle)}
    if isinstance(vehicle, FullVehicle):
        values["vehicle.model"] = "full"
    return dict(values), values


def run(args: argparse.Namespace) -> int:
    if args.bag and not args.no_record and Path(args.bag).exists():
        raise BagError(f"{args.bag} exists already; a bag is never overwritten")
    estimator_values, sim_values = node_values(args)
    os.environ.setdefault("ROS_AUTOMATIC_DISCOVERY_RANGE", "LOCALHOST")
    domain = int(os.environ.get("ROS_DOMAIN_ID", 0)) or 150 + os.getpid() % 80
    import rclpy
    from diagnostic_msgs.msg import DiagnosticArray
    from geometry_msgs.msg import InertiaStamped
    from rclpy.context import Context
    from rclpy.experimental import EventsExecutor
    from rclpy.parameter import Parameter
    from rclpy.qos import DurabilityPolicy, QoSProfile, ReliabilityPolicy
    from rclpy.signals import SignalHandlerOptions
    from std_msgs.msg import Float64MultiArray

    from rozyn_estimator.online import EstimatorConfig
    from rozyn_estimator.ros import messages as ros_io
    from rozyn_estimator.ros.estimator_node import EstimatorNode
    from rozyn_estimator.ros.recorder_node import BagRecorder, bag_path, drain
    from sim_node.node import SimNode

    ctx = Context()
    rclpy.init(context=ctx, domain_id=domain, signal_handler_options=SignalHandlerOptions.NO)
    stop = threading.Event()
    previous = _catch_signals(stop)
    executor = EventsExecutor(context=ctx)
    seen = Seen(EstimatorConfig.from_parameters(estimator_values).layout)
    probe = rclpy.create_node("demo_probe", context=ctx)
    latched = QoSProfile(
        depth=1, reliability=ReliabilityPolicy.RELIABLE, durability=DurabilityPolicy.TRANSIENT_LOCAL
    )
    probe.create_subscription(
        InertiaStamped, "sim/ground_truth", seen.take_truth, latched
    )
    def on_inertia(msg: Any) -> None:
        seen.inertia[ros_io.stamp_ns(msg.header.stamp)] = msg

    probe.create_subscription(InertiaStamped, "inertia", on_inertia, 10)
    probe.create_subscription(
        Float64MultiArray,
        "inertia/covariance",
        lambda m: seen.covariance.__setitem__(ros_io.covariance_stamp_ns(m), m),
        10,
    )

    def on_diag(msg: Any) -> None:
        for s in msg.status:
            if s.name.endswith("estimator_node"):
                seen.last_status = s.message

    probe.create_subscription(DiagnosticArray, "/diagnostics", on_diag, 10)
    est = EstimatorNode(
        context=ctx,
        parameter_overrides=[Parameter("use_sim_time", value=True),
                             *(Parameter(k, value=v) for k, v in estimator_values.items())],
    )
    updates: list[Any] = []
    est.on_update = updates.append
    bag = Path(args.bag) if args.bag else bag_path(args.bag_dir, "demo")
    recorder = None
    if not args.no_record:
        recorder = BagRecorder(
            context=ctx,
            parameter_overrides=[
                Parameter("use_sim_time", value=True),
                Parameter("output", value=str(bag)),
                Parameter("estimator_node", value=est.get_fully_qualified_name()),
                Parameter("qos_depth", value=QUEUE_DEPTH),
            ],
        )
    sim = SimNode(
        context=ctx,
        parameter_overrides=[Parameter(k, value=v) for k, v in sim_values.items()],
    )
    accel = list(dict.fromkeys(absolute_topic(topic) for _, topic in est.config.sensors))  # an IMU's once
    intakes = [] if recorder is None else [functools.partial(recorder.received, t) for t in accel]
    pacer = Pacer(sim, est, intakes)
    sim.gate = pacer
    nodes = [n for n in (probe, est, recorder) if n is not None]
    for node in nodes:
        executor.add_node(node)
    print(
        f"rozyn demo: {'the full car, ' if seen.layout.full else ''}{args.road} road ({args.amplitudes} "
        f"amplitudes), {drive_label(args)}, "
        f"{args.duration_s:g} s of sim time at {args.real_time_factor:g}x, window {args.window_s:g} s "
        f"(ROS_DOMAIN_ID {domain}){_sensors_label(sim.config)}",
        flush=True,
    )
    started = time.monotonic()
    try:
        if recorder is not None:
            _wait_for_recorder(executor, recorder, sim, stop, accel)
        executor.add_node(sim)
        nodes.append(sim)
        while not sim.finished and not stop.is_set():
            executor.spin_once(timeout_sec=0.05)
            print_new(seen)
        end = time.monotonic() + 120.0  # updates still computing or on their way: let them come
        while (
            time.monotonic() < end
            and not stop.is_set()
            and (est.pending_updates or len(set(seen.inertia) & set(seen.covariance)) < est.updates_published)
        ):
            executor.spin_once(timeout_sec=0.05)
            print_new(seen)
        if stop.is_set():
            print("interrupted", file=sys.stderr)
    except KeyboardInterrupt:
        print("interrupted", file=sys.stderr)
    finally:
        wall = time.monotonic() - started
        if recorder is not None:
            drain(executor, recorder.writer)
            recorder.close()
        for node in nodes:
            node.destroy_node()
        executor.shutdown()
        rclpy.try_shutdown(context=ctx)
        _restore_signals(previous)
    code = summary(seen, args, wall, pacer.held_s, pacer.max_pending)
    write_outputs(Path(args.out) if args.out else Path("out", "demo", bag.name), updates, seen, args)
    if recorder is not None:
        total = sum(recorder.writer.writer.counts.values())
        print(
            f"\nrecorded the run to {recorder.path} ({total} messages); replay it offline with:\n"
            f"  {_rozyn_command()} replay {recorder.path}"
        )
    return code


def _rozyn_command() -> str:
    """How to call ``rozyn`` from here: plain when it is on PATH, else its path (.venv/bin)."""
    here = Path(sys.executable).parent / "rozyn"
    found = shutil.which("rozyn")
    if found and Path(found).resolve() == here.resolve():
        return "rozyn"
    return os.path.relpath(here) if here.exists() else "rozyn"


def _sensors_label(config: Any) -> str:
    """``; sensors: imu (/imu/data, x 1.50 m): accel_z, gyro_y`` for a sensors block, else nothing."""
    block = config.plant_vehicle.sensors
    return f"; sensors: {block.describe()}" if block is not None else ""


def _wait_for_recorder(
    executor: Any, recorder: Any, sim: Any, stop: threading.Event, accel: Sequence[str],
    timeout_s: float = 20.0,
) -> None:
    """Spin (the sim not yet) until the recorder is subscribed to the sim's topics (``accel``:
    the accelerometers') and matched with its publishers, and holds the estimator's
    configuration: the bag then holds every message the estimator gets."""
    inputs = (*accel, "/sim/speed")
    wanted = {*inputs, "/sim/ground_truth", "/clock"}
    publishers = {p.topic_name: p for p in sim.publishers}

    def ready() -> bool:
        return (
            wanted <= set(recorder.recorded_topics)
            and recorder.estimator_config is not None
            and all(publishers[t].get_subscription_count() >= 2 for t in inputs)
        )

    end = time.monotonic() + timeout_s
    while not ready() and not stop.is_set() and time.monotonic() < end:
        recorder.discover()
        executor.spin_once(timeout_sec=0.02)
    if not ready():
        print(
            "warning: the recorder is not subscribed to every topic: the bag may miss the start",
            file=sys.stderr,
        )


def _catch_signals(stop: threading.Event) -> dict[int, Any]:
    """SIGINT/SIGTERM set ``stop``: the loops end and everything is closed cleanly."""
    if threading.current_thread() is not threading.main_thread():
        return {}
    return {sig: signal.signal(sig, lambda *_: stop.set()) for sig in (signal.SIGINT, signal.SIGTERM)}


def _restore_signals(previous: dict[int, Any]) -> None:
    for sig, handler in previous.items():
        signal.signal(sig, handler)


HELP = "the main job: sim and estimator nodes on sim time, estimate vs truth"
DESCRIPTION = __doc__
