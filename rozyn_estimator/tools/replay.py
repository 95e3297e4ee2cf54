"""``rozyn replay BAG``: a bag through the online estimator, offline, no DDS.

Reads a rosbag2 bag (MCAP or SQLite3) or a ROS 1 bag, feeds the accelerometer messages
through :class:`~rozyn_estimator.online.estimator.OnlineEstimator` (the node's own online code,
driven by the message stamps) in the order the bag received them, and writes

- ``updates.csv``: one row per scheduled update (stamp, status, estimates, std,
  covariance, modes, window fill, speed, pipeline time), numbers at full precision;
- ``estimates/``: a rosbag2 MCAP bag with ``/inertia``, ``/inertia/covariance`` and
  ``/diagnostics`` as the node would have published them, logged at the bag time of
  the message that made each update due.

The estimator is configured from the bag: the recorder stores the estimator node's
configuration in it, so a recorded run replays to the estimates the node published.
Options override it; a bag without one (``ros2 bag record``) uses the node's defaults.

This module feeds (the command protocol of ``rozyn``: :data:`HELP`, :data:`DESCRIPTION`,
:func:`add_arguments`, :func:`run`; :func:`replay`, :func:`resolve_config` and the field
readers); :mod:`rozyn_estimator.tools.replay_outputs` holds the result and writes the
outputs; :mod:`rozyn_estimator.tools.replay_report` prints the closing report.
"""

from __future__ import annotations

import argparse
import sys
import time
from collections.abc import Sequence
from datetime import UTC, datetime
from pathlib import Path
from typing import Any

import numpy as np

from rozyn_estimator.bag import BagReader, FieldReader, RawBatch, TopicInfo, absolute_topic, open_bag
from rozyn_estimator.errors import BagError, ConfigError
from rozyn_estimator.online import (
    CUSTOM_DATA_KEY,
    NS,
    SPEED_TOPIC_TYPES,
    EstimatorConfig,
    OnlineEstimator,
    SpeedSamples,
)
from rozyn_estimator.tools.replay_outputs import (
    PUBLISHED_TOPIC,
    TRUTH_TOPIC,
    ReplayedUpdate,
    ReplayOutputs,
    ReplayResult,
)
from rozyn_estimator.tools.replay_report import format_summary

HELP = "replay a bag through the online estimator offline: CSV of updates + output bag"
DESCRIPTION = (
    "Feed the accelerometer messages of a bag (rosbag2 MCAP or SQLite3, or ROS 1) through the "
    "estimator node's own online code, in the order the bag received them, and write updates.csv "
    "(every update: stamp, status, estimates, std, covariance, modes) and a rosbag2 MCAP bag with "
    "/inertia, /inertia/covariance and /diagnostics in bag time. The estimator is configured as "
    "recorded in the bag (bag_recorder and rozyn demo store it), else with the node's defaults; "
    "options override. No DDS needed."
)


# ---------------------------------------------------------------------- CLI
def add_arguments(p: argparse.ArgumentParser) -> None:
    """The options of ``rozyn replay``.

    Args:
        p: the sub-command's parser.
    """
    p.add_argument("bag", help="rosbag2 directory, or an .mcap, .db3 or ROS 1 .bag file")
    src = p.add_argument_group("input (default: the configuration recorded in the bag, else the node's)")
    src.add_argument("--front-topic", metavar="T", help="front accelerometer topic")
    src.add_argument("--rear-topic", metavar="T", help="rear accelerometer topic")
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
    est.add_argument("--vehicle", metavar="FILE.yaml", help="vehicle parameters")
    est.add_argument("--method", help="pipeline preset of rozyn trial --method (e.g. rozyn, likelihood)")
    est.add_argument(
        "--ignore-bag-config",
        action="store_true",
        help="start from the node's defaults, not the configuration recorded in the bag",
    )
    out = p.add_argument_group("output")
    out.add_argument(
        "--out", metavar="DIR", help="output directory (default: out/replay/<bag name>-<UTC time>)"
    )
    out.add_argument("--no-bag", action="store_true", help="write the CSV only")
    out.add_argument(
        "--salvage",
        action="store_true",
        help="read a truncated or damaged MCAP recording record by record, keeping what is intact",
    )
    out.add_argument("--quiet", action="store_true", help="no progress bar, no table")


def run(args: argparse.Namespace) -> int:
    """``rozyn replay``: replay the bag, write the outputs, print the report.

    Args:
        args: the parsed options of :func:`add_arguments`.

    Returns:
        0 (the exit status).

    Raises:
        BagError: the bag cannot be read, the output directory is not empty, or no
            update fell due.
        ConfigError: an option or the recorded configuration is invalid.
    """
    bag = Path(args.bag)
    out_dir = Path(args.out) if args.out else Path("out", "replay", f"{bag.name}-{_utc()}")
    with open_bag(bag, salvage=args.salvage) as reader:
        config, source = resolve_config(reader, args)
        result = replay_reader(
            reader,
            config,
            out_dir=out_dir,
            write_bag=not args.no_bag,
            progress=not args.quiet and sys.stderr.isatty(),
        )
    result.config_source = source
    if not args.quiet:
        print(format_summary(result))
    if not result.updates:
        raise BagError(
            f"no update fell due in {bag}: {result.accel_messages} accelerometer messages, an update every "
            f"{config.online.update_period_s:g} s of message time once both sensors have data"
        )
    return 0


def resolve_config(reader: BagReader, args: argparse.Namespace) -> tuple[EstimatorConfig, str]:
    """The bag's recorded configuration (or the defaults) with the options applied.

    Args:
        reader: the open bag.
        args: options as :func:`add_arguments` names them (missing ones are unset).

    Returns:
        The configuration and where it came from, in words.

    Raises:
        ConfigError: an invalid option or recorded setting, or an unknown ``--method``.
    """
    config, source = EstimatorConfig(), "the node's defaults (the bag records no estimator configuration)"
    if getattr(args, "ignore_bag_config", False):
        source = "the node's defaults (--ignore-bag-config)"
    elif CUSTOM_DATA_KEY in reader.custom_data:
        ignored: list[str] = []
        config = EstimatorConfig.from_json(reader.custom_data[CUSTOM_DATA_KEY], ignored)
        source = f"recorded in the bag ({config.node_name})"
        if ignored:
            names = ", ".join(n.removeprefix("estimator configuration.") for n in ignored)
            source += f"; settings of another version ignored: {names}"
    changes: dict[str, Any] = {}
    for name in ("front_topic", "rear_topic", "field", "speed_topic", "speed_topic_type"):
        if getattr(args, name, None) is not None:
            changes[name] = getattr(args, name)
    online = {
        n: getattr(args, n)
        for n in ("window_s", "update_period_s", "min_window_fill", "speed_mps")
        if getattr(args, n, None) is not None
    }
    if online:
        changes["online"] = config.online.replace(**online)
    if getattr(args, "vehicle", None):
        from rozyn_estimator.vehicle import load_vehicle

        changes["vehicle"] = load_vehicle(args.vehicle)
    if getattr(args, "method", None):
        from rozyn_estimator.method import METHODS

        if args.method not in METHODS:
            raise ConfigError(f"--method: must be one of {', '.join(METHODS)}, got {args.method!r}")
        changes["pipeline"] = METHODS[args.method]
    if changes:
        source += "; overridden: " + ", ".join(sorted({*changes, *online} - {"online"}))
    return config.replace(**changes), source


# ------------------------------------------------------------------- replay
def replay(bag: str | Path, config: EstimatorConfig | None = None, **kwargs: Any) -> ReplayResult:
    """Replay a bag (with its recorded configuration unless ``config`` is given).

    Args:
        bag: the bag's path.
        config: the estimator's configuration (default: as recorded in the bag).
        **kwargs: those of :func:`replay_reader`, plus ``salvage`` (of :func:`open_bag
            <rozyn_estimator.bag.reader.open_bag>`).

    Returns:
        What the replay did.

    Raises:
        BagError: as :func:`replay_reader`, or the bag cannot be opened.
        ConfigError: as :func:`replay_reader`.
    """
    salvage = kwargs.pop("salvage", False)
    with open_bag(bag, salvage=salvage) as reader:
        source = "given"
        if config is None:
            config, source = resolve_config(reader, argparse.Namespace())
        result = replay_reader(reader, config, **kwargs)
    result.config_source = source
    return result


def replay_reader(
    reader: BagReader,
    config: EstimatorConfig,
    *,
    out_dir: str | Path | None = None,
    write_bag: bool = True,
    progress: bool = False,
    batch_size: int = 65536,
) -> ReplayResult:
    """Feed an open bag through a fresh online estimator; write the outputs to ``out_dir``.

    Args:
        reader: the open bag.
        config: the estimator's configuration (topics, field, online settings …).
        out_dir: where to write ``updates.csv`` and ``estimates/`` (None: nothing written).
        write_bag: write ``estimates/`` too, not the CSV only.
        progress: show a progress bar on stderr.
        batch_size: messages read at a time (the result does not depend on it).

    Returns:
        What the replay did (updates, counts, timings, the bag's truth and recorded
        estimates).

    Raises:
        BagError: a topic is missing or empty, or the bag is damaged.
        ConfigError: a field is missing or not numeric, or a speed topic of another type.
    """
    topics = [absolute_topic(config.front_topic), absolute_topic(config.rear_topic)]
    infos = [reader.topic(t) for t in topics]
    for info in infos:
        if info.count == 0:
            raise BagError(f"{reader.path}: topic {info.name} holds no messages")
    accel = [_field_reader(reader, info, [config.field]) for info in infos]
    speed = None
    if config.speed_topic:
        info = reader.topic(config.speed_topic)
        msgtype, fields = SPEED_TOPIC_TYPES[config.speed_topic_type]
        if info.msgtype != msgtype:
            raise ConfigError(
                f"speed topic {info.name} is {info.msgtype}; speed_topic_type {config.speed_topic_type} "
                f"expects {msgtype} (--speed-topic-type {_type_choice(info.msgtype)})"
            )
        topics.append(info.name)
        speed = _field_reader(reader, info, fields)
    extra = {
        name: len(topics) + i
        for i, name in enumerate(t for t in (TRUTH_TOPIC, PUBLISHED_TOPIC) if t in reader.topics)
    }
    topics += list(extra)

    result = ReplayResult(reader.path, config, "given", damage=reader.damage)
    online = OnlineEstimator(
        config.vehicle, config.online, config.pipeline, (config.front_topic, config.rear_topic)
    )
    outputs = ReplayOutputs(Path(out_dir), config, reader, write_bag) if out_dir is not None else None
    total = sum(reader.topics[t].count for t in topics)
    bar = _progress(total, progress)
    try:
        started = time.perf_counter()
        for batch in reader.batches(topics, batch_size):
            bar.update(len(batch))
            a_idx, chan, stamps, values = _accelerations(batch, accel)
            s_idx, s_stamps, s_values = _speeds(batch, speed)
            for name, i in extra.items():
                for j in np.flatnonzero(batch.topic == i).tolist():
                    msgtype = reader.topics[name].msgtype
                    _note_extra(result, reader, name, batch.messages.message(j), msgtype, config)
            jobs = online.add_batch(chan, stamps, values, a_idx, SpeedSamples(s_stamps, s_values, s_idx))
            result.accel_messages += a_idx.size
            result.speed_messages += s_idx.size
            t_feed = time.perf_counter()
            result.feed_s += t_feed - started
            for job, trigger in jobs:
                update = online.compute(job)
                replayed = ReplayedUpdate(update, int(batch.log_ns[a_idx[trigger]]))
                result.updates.append(replayed)
                if outputs is not None:
                    outputs.write(replayed, online)
            started = time.perf_counter()
            result.update_s += started - t_feed
    finally:
        bar.close()
        if outputs is not None:
            outputs.close()
            result.out_dir, result.out_counts = outputs.out_dir, outputs.counts
    result.dropped = dict(online.dropped)
    result.resets = online.resets
    return result


def _accelerations(
    batch: RawBatch, readers: list[FieldReader]
) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """Positions in the batch, channels (0 front, 1 rear), stamps [ns] and values of topics 0 and 1.

    The stamp is the header's, or the bag time for a type without a header.
    """
    idx = np.flatnonzero(batch.topic < 2)
    chan = batch.topic[idx].astype(np.int64)
    stamps = np.empty(idx.size, np.int64)
    values = np.empty(idx.size)
    for c, reader in enumerate(readers):
        sel = chan == c
        s, v = reader.read(batch.messages.take(idx[sel]))
        stamps[sel] = batch.log_ns[idx[sel]] if s is None else s
        values[sel] = v[:, 0]
    return idx, chan, stamps, values


def _speeds(batch: RawBatch, reader: FieldReader | None) -> tuple[np.ndarray, np.ndarray, list[float]]:
    """Positions, stamps [ns] and speeds [m/s] of topic 2, the norm computed as the node does."""
    if reader is None:
        return np.zeros(0, np.int64), np.zeros(0, np.int64), []
    idx = np.flatnonzero(batch.topic == 2)
    stamps, xy = reader.read(batch.messages.take(idx))
    speeds = [float((x**2 + y**2) ** 0.5) for x, y in xy.tolist()]  # bit for bit the node's float
    return idx, batch.log_ns[idx] if stamps is None else stamps, speeds


def _field_reader(reader: BagReader, info: TopicInfo, fields: Sequence[str]) -> FieldReader:
    try:
        return FieldReader(reader.typestore, info.msgtype, fields, reader.deserialize, cdr=reader.cdr)
    except ConfigError as exc:
        raise ConfigError(f"topic {info.name}: {exc}") from None


def _type_choice(msgtype: str) -> str:
    return next((k for k, (t, _) in SPEED_TOPIC_TYPES.items() if t == msgtype), "twist|odometry")


def _note_extra(
    result: ReplayResult, reader: BagReader, topic: str, data: bytes, msgtype: str, config: EstimatorConfig
) -> None:
    """Keep the sim's ground truth and the estimates the node published, for comparison."""
    if msgtype != "geometry_msgs/msg/InertiaStamped":
        return
    msg = reader.deserialize(data, msgtype)
    values = (msg.inertia.m, msg.inertia.iyy, config.front_axle_x_m - msg.inertia.com.x)
    if topic == TRUTH_TOPIC:
        result.truth = values
    else:
        result.recorded[msg.header.stamp.sec * NS + msg.header.stamp.nanosec] = values


def _progress(total: int, enabled: bool) -> Any:
    from tqdm import tqdm

    return tqdm(total=total, unit="msg", unit_scale=True, disable=not enabled, file=sys.stderr, leave=False)


def _utc() -> str:
    return datetime.now(UTC).strftime("%Y%m%dT%H%M%SZ")
