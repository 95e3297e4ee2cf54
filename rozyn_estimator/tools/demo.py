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
"""

from __future__ import annotations

import argparse
import os
import shutil
import signal
import sys
import threading
import time
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

from rozyn_estimator.errors import BagError

NS = 1_000_000_000
# Subscription queues of the estimator and the recorder: at 20 x real time the sim sends
# 2000 Imu messages a second per sensor, and a loaded machine must not make either drop
# one (the recording then holds exactly what the estimator used).
QUEUE_DEPTH = 10_000


@dataclass
class _Seen:
    truth: Any = None
    inertia: dict[int, Any] = field(default_factory=dict)
    covariance: dict[int, Any] = field(default_factory=dict)
    printed: set[int] = field(default_factory=set)
    lines: list[str] = field(default_factory=list)
    last_status: str = ""


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
    p.add_argument("--noise-std-mps2", type=float, default=0.0, help="white sensor noise (default: 0)")
    p.add_argument("--seed", type=int, default=1, help="road seed (default: 1)")
    p.add_argument(
        "--real-time-factor", type=float, default=20.0, help="sim seconds per wall second (default: 20)"
    )
    p.add_argument("--window-s", type=float, default=120.0, help="estimator window (default: 120)")
    p.add_argument(
        "--bag-dir",
        default="bags",
        metavar="DIR",
        help="record the run to DIR/demo-<UTC time>/ (default: bags)",
    )
    p.add_argument("--bag", metavar="DIR", help="record the run to exactly DIR (not --bag-dir/demo-<UTC>)")
    p.add_argument("--no-record", action="store_true", help="do not record the run")


def _row(label: str, value: float, std: float, truth: float, digits: int) -> str:
    err = (value / truth - 1.0) * 100.0
    return f"{label} = {value:.{digits}f} ± {std:.{digits}f} ({err:+.2f} %)"


def node_values(args: argparse.Namespace) -> tuple[dict[str, Any], dict[str, Any]]:
    """The estimator's and the simulator's parameter values for the demo's options, checked
    by the nodes' own rules (ConfigError names a bad one) before anything starts."""
    from rozyn_estimator.online import EstimatorConfig
    from rozyn_estimator.parameters import build
    from sim_node.node import NODE_DEFAULTS, SimNodeOptions

    estimator = {"speed_topic": "sim/speed", "window_s": args.window_s, "qos_depth": QUEUE_DEPTH}
    sim = {"time_mode": "sim", "real_time_factor": args.real_time_factor, "duration_s": args.duration_s,
           "wait_for_subscribers": True, "road.kind": args.road, "road.amplitudes": args.amplitudes,
           "speed_kmh": args.speed_kmh, "seed": args.seed, "noise_std_mps2": args.noise_std_mps2}
    EstimatorConfig.from_parameters(estimator)
    build(SimNodeOptions(), sim)
    build(NODE_DEFAULTS, sim)
    return estimator, sim


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

    from rozyn_estimator.ros import messages as ros_io
    from rozyn_estimator.ros.estimator_node import EstimatorNode
    from rozyn_estimator.ros.recorder_node import BagRecorder, bag_path, drain
    from sim_node.node import SimNode

    ctx = Context()
    rclpy.init(context=ctx, domain_id=domain, signal_handler_options=SignalHandlerOptions.NO)
    stop = threading.Event()
    previous = _catch_signals(stop)
    executor = EventsExecutor(context=ctx)
    seen = _Seen()
    probe = rclpy.create_node("demo_probe", context=ctx)
    latched = QoSProfile(
        depth=1, reliability=ReliabilityPolicy.RELIABLE, durability=DurabilityPolicy.TRANSIENT_LOCAL
    )
    probe.create_subscription(
        InertiaStamped, "sim/ground_truth", lambda m: setattr(seen, "truth", m), latched
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
    recorder = None
    if not args.no_record:
        recorder = BagRecorder(
            context=ctx,
            parameter_overrides=[
                Parameter("use_sim_time", value=True),
                Parameter("output", value=args.bag or str(bag_path(args.bag_dir, "demo"))),
                Parameter("estimator_node", value=est.get_fully_qualified_name()),
                Parameter("qos_depth", value=QUEUE_DEPTH),
            ],
        )
    sim = SimNode(
        context=ctx,
        parameter_overrides=[Parameter(k, value=v) for k, v in sim_values.items()],
    )
    nodes = [n for n in (probe, est, recorder) if n is not None]
    for node in nodes:
        executor.add_node(node)
    print(
        f"rozyn demo: {args.road} road ({args.amplitudes} amplitudes), {args.speed_kmh:g} km/h, "
        f"{args.duration_s:g} s of sim time at {args.real_time_factor:g}x, window {args.window_s:g} s "
        f"(ROS_DOMAIN_ID {domain})",
        flush=True,
    )
    started = time.monotonic()
    try:
        if recorder is not None:
            _wait_for_recorder(executor, recorder, sim, stop)
        executor.add_node(sim)
        nodes.append(sim)
        while not sim.finished and not stop.is_set():
            executor.spin_once(timeout_sec=0.05)
            _print_new(seen)
        end = time.monotonic() + 120.0  # updates still computing: let them finish
        while (
            time.monotonic() < end
            and not stop.is_set()
            and (est.pending_updates or set(seen.inertia) - seen.printed)
        ):
            executor.spin_once(timeout_sec=0.05)
            _print_new(seen)
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
    code = _summary(seen, args, wall)
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


def _wait_for_recorder(
    executor: Any, recorder: Any, sim: Any, stop: threading.Event, timeout_s: float = 20.0
) -> None:
    """Spin (the sim not yet) until the recorder is subscribed to the sim's topics and
    matched with its publishers, and holds the estimator's configuration: the bag then
    holds every message the estimator gets."""
    inputs = ("/accel/front", "/accel/rear", "/sim/speed")
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


def _print_new(seen: _Seen) -> None:
    if seen.truth is None:
        return
    t = seen.truth.inertia
    truth = (t.m, t.iyy, -t.com.x)
    for stamp in sorted(set(seen.inertia) & set(seen.covariance) - seen.printed):
        msg, cov = seen.inertia[stamp], seen.covariance[stamp]
        std = [max(cov.data[i * 4], 0.0) ** 0.5 for i in range(3)]
        line = "  ".join(
            [
                f"t = {stamp / NS:6.1f} s",
                _row("m", msg.inertia.m, std[0], truth[0], 1) + " kg",
                _row("Iyy", msg.inertia.iyy, std[1], truth[1], 1) + " kg m²",
                _row("lf", -msg.inertia.com.x, std[2], truth[2], 4) + " m",
            ]
        )
        seen.printed.add(stamp)
        seen.lines.append(line)
        print(line, flush=True)


def _summary(seen: _Seen, args: argparse.Namespace, wall_s: float) -> int:
    print()
    if seen.truth is not None:
        t = seen.truth.inertia
        print(f"truth: m = {t.m:g} kg, Iyy = {t.iyy:g} kg m², lf = {-t.com.x:g} m")
    if not seen.printed:
        print(f"no estimate was published ({seen.last_status or 'no diagnostics'})")
        return 1
    last = seen.lines[-1]
    print(f"{len(seen.printed)} estimates in {wall_s:.1f} s wall time; last: {last}")
    return 0


HELP = "the main job: sim and estimator nodes on sim time, estimate vs truth"
DESCRIPTION = __doc__
