"""``rozyn replay BAG [BAG …]``: bags through the online estimator, offline, no DDS.

One bag: it is fed through :class:`~rozyn_estimator.online.estimator.OnlineEstimator`
(the node's own online code, driven by the message stamps) in the order the bag received
the messages (:mod:`rozyn_estimator.tools.replay.feed`), and the output directory gets

- ``updates.csv``: one row per scheduled update (stamp, status, estimates, std,
  covariance, modes, window fill, speed, pipeline time), numbers at full precision;
- ``estimates/``: a rosbag2 MCAP bag with ``/inertia``, ``/inertia/covariance`` and
  ``/diagnostics`` as the node would have published them, logged at the bag time of
  the message that made each update due (:mod:`rozyn_estimator.tools.replay.outputs`);
- ``estimates.png``: the estimates over time (:mod:`rozyn_estimator.tools.replay.plot`),
  when matplotlib is installed (``--plot`` insists, ``--no-plot`` skips);

then a report (:mod:`rozyn_estimator.tools.replay.report`). Several bags, or a directory
of bags: each is replayed the same way in parallel, one table and ``fleet.csv``
(:mod:`rozyn_estimator.tools.replay.fleet`).

This module is the command (the protocol of ``rozyn``: :data:`HELP`, :data:`DESCRIPTION`,
:func:`add_arguments`, :func:`run`).
"""

from __future__ import annotations

import argparse
import sys
from pathlib import Path

from rozyn_estimator.errors import BagError
from rozyn_estimator.online import SPEED_TOPIC_TYPES
from rozyn_estimator.tools.replay.feed import ReplayOptions, replay_bag
from rozyn_estimator.tools.replay.outputs import utc
from rozyn_estimator.tools.replay.report import format_summary
from rozyn_estimator.vehicle_full import CORNERS

__all__ = ["DESCRIPTION", "HELP", "add_arguments", "run"]

HELP = "replay bags through the online estimator offline: CSV of updates + output bag"  # as cli.py lists it
DESCRIPTION = (
    "Feed the accelerometer messages of a bag (rosbag2 MCAP or SQLite3, or ROS 1) through the "
    "estimator node's own online code, in the order the bag received them, and write updates.csv "
    "(every update: stamp, status, estimates, std, covariance, modes), a rosbag2 MCAP bag with "
    "/inertia, /inertia/covariance and /diagnostics in bag time, and estimates.png. The estimator is "
    "configured as recorded in the bag (bag_recorder and rozyn demo store it), else with the node's "
    "defaults; options override. Several bags, or directories of bags, are replayed in parallel (all "
    "cores, or a Dask cluster with --scheduler) into one table and fleet.csv. No DDS needed."
)


def add_arguments(p: argparse.ArgumentParser) -> None:
    """The options of ``rozyn replay``.

    Args:
        p: the sub-command's parser.
    """
    p.add_argument(
        "bags", nargs="+", metavar="BAG",
        help="rosbag2 directory, .mcap, .db3 or ROS 1 .bag file; or a directory of bags (all under it)",
    )
    src = p.add_argument_group("input (default: the configuration recorded in the bag, else the node's)")
    src.add_argument("--front-topic", metavar="T", help="front accelerometer topic")
    src.add_argument("--rear-topic", metavar="T", help="rear accelerometer topic")
    for corner in CORNERS:  # the full car's
        src.add_argument(f"--{corner.replace('_', '-')}-topic", metavar="T",
                         help=f"full car: {corner.replace('_', ' ')} accelerometer topic ('' for none)")
    src.add_argument(
        "--field", metavar="F", help="numeric field of their messages, e.g. linear_acceleration.z"
    )
    src.add_argument("--speed-topic", metavar="T", help="vehicle speed topic ('' for none)")
    src.add_argument("--speed-topic-type", choices=tuple(SPEED_TOPIC_TYPES), help="type of --speed-topic")
    est = p.add_argument_group("estimator (default: as recorded, else the node's defaults)")
    est.add_argument("--window-s", type=float, help="sliding window [s]")
    est.add_argument("--update-period-s", type=float, help="message time between updates [s]")
    est.add_argument("--min-window-fill", type=float, help="share of the window needed to estimate")
    est.add_argument("--speed-mps", type=float, help="known speed without a speed topic [m/s]")
    est.add_argument("--vehicle", metavar="FILE.yaml",
                     help="vehicle parameters (a full car's file, model: full, replays the corner topics)")
    est.add_argument("--method", help="pipeline preset of rozyn trial --method (e.g. rozyn, likelihood)")
    est.add_argument(
        "--ignore-bag-config",
        action="store_true",
        help="start from the node's defaults, not the configuration recorded in the bag",
    )
    out = p.add_argument_group("output")
    out.add_argument(
        "--out", metavar="DIR",
        help="output directory (default: out/replay/<bag name>-<UTC time>, for several bags "
        "out/replay/fleet-<UTC time> with a directory per bag)",
    )
    out.add_argument("--no-bag", action="store_true", help="write the CSV only")
    out.add_argument(
        "--plot", action=argparse.BooleanOptionalAction, default=None,
        help="write estimates.png (default: when matplotlib is installed)",
    )
    out.add_argument(
        "--salvage",
        action="store_true",
        help="read a truncated or damaged MCAP recording record by record, keeping what is intact",
    )
    out.add_argument("--quiet", action="store_true", help="no progress bar, no table")
    fleet = p.add_argument_group("several bags")
    fleet.add_argument("--jobs", type=int, metavar="N", help="local worker processes (default: all cores)")
    fleet.add_argument(
        "--scheduler", metavar="tcp://HOST:PORT",
        help="run on this Dask scheduler's workers instead (they need this package, and to see --out)",
    )


def run(args: argparse.Namespace) -> int:
    """``rozyn replay``: one bag in detail, or a fleet of bags in parallel.

    Args:
        args: the parsed options of :func:`add_arguments`.

    Returns:
        The exit status: 0, or (several bags) 1 if any bag failed.

    Raises:
        BagError: (one bag) it cannot be read, the output directory is not empty, or no
            update fell due.
        ConfigError: an option or the recorded configuration is invalid.
    """
    from rozyn_estimator.tools.replay.fleet import find_bags, run_fleet

    bags = find_bags([Path(b) for b in args.bags])
    if len(args.bags) == 1 and bags == [Path(args.bags[0])]:
        return _run_one(bags[0], args)
    return run_fleet(bags, args)


def _run_one(bag: Path, args: argparse.Namespace) -> int:
    out_dir = Path(args.out) if args.out else Path("out", "replay", f"{bag.name}-{utc()}")
    result = replay_bag(bag, out_dir, ReplayOptions.from_args(args), progress=not args.quiet and
                        sys.stderr.isatty())
    if not args.quiet:
        print(format_summary(result))
    if not result.updates:
        raise BagError(
            f"no update fell due in {bag}: {result.accel_messages} accelerometer messages, an update every "
            f"{result.config.online.update_period_s:g} s of message time once both sensors have data"
        )
    return 0
