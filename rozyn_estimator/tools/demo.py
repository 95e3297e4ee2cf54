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
drawn in ``<out>/estimates.png`` (:mod:`rozyn_estimator.tools.replay_plot`).
"""

from __future__ import annotations

import argparse
import functools
import os
import shutil
import signal
import sys
import threading
import time
from collections.abc import Callable, Sequence
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

from rozyn_estimator.errors import BagError
from rozyn_estimator.tools.options import (
    add_departure_options,
    add_vehicle_error_options,
    departure_values,
    vehicle_error_values,
)

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


def _row(label: str, value: float, std: float, truth: float, digits: int) -> str:
    err = (value / truth - 1.0) * 100.0
    return f"{label} = {value:.{digits}f} ± {std:.{digits}f} ({err:+.2f} %)"


def node_values(args: argparse.Namespace) -> tuple[dict[str, Any], dict[str, Any]]:
    """The estimator's and the simulator's parameter values for the demo's options, checked
    by the nodes' own rules (ConfigError names a bad one) before anything starts."""
    from rozyn_estimator.online import EstimatorConfig
    from rozyn_estimator.parameters import build
    from rozyn_estimator.tools.trial import VEHICLE_ERRORS
    from rozyn_estimator.vehicle import Vehicle
    from sim_node.node import NODE_DEFAULTS, SimNodeOptions

    estimator = {"speed_topic": "sim/speed", "window_s": args.window_s, "qos_depth": QUEUE_DEPTH}
    told = Vehicle()  # the simulated vehicle; the estimator is told it with the *_error options applied
    for key, error in vehicle_error_values(args).items():
        estimator |= {f"vehicle.{name}": getattr(told, name) * (1.0 + error)
                      for name in VEHICLE_ERRORS[key] if error != 0.0}
    sim = {"time_mode": "sim", "real_time_factor": args.real_time_factor, "duration_s": args.duration_s,
           "wait_for_subscribers": True, "road.kind": args.road, "road.amplitudes": args.amplitudes,
           "speed_kmh": args.speed_kmh, "seed": args.seed, "noise_std_mps2": args.noise_std_mps2}
    sim |= {f"departures.{name}": value for name, value in departure_values(args).items()}
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
    pacer = Pacer(sim, est, [] if recorder is None else
                  [functools.partial(recorder.received, t) for t in ("/accel/front", "/accel/rear")])
    sim.gate = pacer
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
        end = time.monotonic() + 120.0  # updates still computing or on their way: let them come
        while (
            time.monotonic() < end
            and not stop.is_set()
            and (est.pending_updates or len(set(seen.inertia) & set(seen.covariance)) < est.updates_published)
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
    code = _summary(seen, args, wall, pacer)
    _write_outputs(Path(args.out) if args.out else Path("out", "demo", bag.name), updates, seen, args)
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


def _summary(seen: _Seen, args: argparse.Namespace, wall_s: float, pacer: Pacer) -> int:
    print()
    if seen.truth is not None:
        t = seen.truth.inertia
        print(f"truth: m = {t.m:g} kg, Iyy = {t.iyy:g} kg m², lf = {-t.com.x:g} m")
    print(f"the simulator waited {pacer.held_s:.1f} s for the estimator and the recorder "
          f"(at most {pacer.max_pending} updates waiting)")
    if not seen.printed:
        print(f"no estimate was published ({seen.last_status or 'no diagnostics'})")
        return 1
    last = seen.lines[-1]
    print(f"{len(seen.printed)} estimates in {wall_s:.1f} s wall time "
          f"({args.duration_s / wall_s:.1f}x real time); last: {last}")
    return 0


def _write_outputs(out_dir: Path, updates: Sequence[Any], seen: _Seen, args: argparse.Namespace) -> None:
    """``updates.csv`` as ``rozyn replay`` writes it, and ``estimates.png``; prints their paths."""
    import csv

    from rozyn_estimator.tools.replay_outputs import CSV_COLUMNS, ReplayedUpdate, csv_row
    from rozyn_estimator.tools.replay_plot import PLOT_NAME, matplotlib_available, plot_estimates

    out_dir.mkdir(parents=True, exist_ok=True)
    with (out_dir / "updates.csv").open("w", newline="") as f:
        writer = csv.writer(f)
        writer.writerow(CSV_COLUMNS)
        for update in sorted(updates, key=lambda u: u.stamp_ns):
            writer.writerow(csv_row(ReplayedUpdate(update, update.stamp_ns)))
    print(f"\nwrote {out_dir / 'updates.csv'}")
    if args.plot is False or not updates or (args.plot is None and not matplotlib_available()):
        return
    t = seen.truth.inertia if seen.truth is not None else None
    png = plot_estimates(
        out_dir / "updates.csv", out_dir / PLOT_NAME, truth=None if t is None else (t.m, t.iyy, -t.com.x),
        title=f"rozyn demo: {args.road} road ({args.amplitudes}), {args.speed_kmh:g} km/h",
    )
    print(f"plot: {png}")


HELP = "the main job: sim and estimator nodes on sim time, estimate vs truth"
DESCRIPTION = __doc__
