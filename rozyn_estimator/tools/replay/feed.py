"""Feeding a bag through the online estimator, offline, no DDS: the core of ``rozyn replay``.

Reads a rosbag2 bag (MCAP or SQLite3) or a ROS 1 bag and feeds the accelerometer messages
through :class:`~rozyn_estimator.online.estimator.OnlineEstimator` (the node's own online
code, driven by the message stamps) in the order the bag received them
(:func:`replay_reader`); :mod:`rozyn_estimator.tools.replay.outputs` writes what comes
out, :mod:`rozyn_estimator.tools.replay.plot` draws it.

The estimator is configured from the bag: the recorder stores the estimator node's
configuration in it, so a recorded run replays to the estimates the node published.
Options (:class:`ReplayOptions`) override it; a bag without one (``ros2 bag record``) uses
the node's defaults. :func:`replay_bag` does all of it for one bag into one directory:
the unit of work of a fleet replay (:mod:`rozyn_estimator.tools.replay.fleet`).
"""

from __future__ import annotations

import argparse
import sys
import time
from collections.abc import Sequence
from dataclasses import dataclass, fields
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
from rozyn_estimator.tools.replay.outputs import (
    PUBLISHED_TOPIC,
    TRUTH_TOPIC,
    ReplayedUpdate,
    ReplayOutputs,
    ReplayResult,
    inertia_values,
)

TOPIC_OPTIONS = ("front_topic", "rear_topic", "front_left_topic", "front_right_topic", "rear_left_topic",
                 "rear_right_topic", "field", "speed_topic", "speed_topic_type")


@dataclass(frozen=True)
class ReplayOptions:
    """What ``rozyn replay``'s options ask of each bag (None: as recorded / automatic).

    The configuration overrides are read by :func:`resolve_config`; ``no_bag``,
    ``salvage`` and ``plot`` (None: when matplotlib is installed) by :func:`replay_bag`.
    """

    front_topic: str | None = None
    rear_topic: str | None = None
    front_left_topic: str | None = None
    front_right_topic: str | None = None
    rear_left_topic: str | None = None
    rear_right_topic: str | None = None
    field: str | None = None
    speed_topic: str | None = None
    speed_topic_type: str | None = None
    window_s: float | None = None
    update_period_s: float | None = None
    min_window_fill: float | None = None
    speed_mps: float | None = None
    vehicle: str | None = None
    method: str | None = None
    ignore_bag_config: bool = False
    no_bag: bool = False
    salvage: bool = False
    plot: bool | None = None

    @classmethod
    def from_args(cls, args: argparse.Namespace) -> ReplayOptions:
        """The options of a parsed ``rozyn replay`` command line (missing ones unset)."""
        return cls(**{f.name: getattr(args, f.name) for f in fields(cls) if hasattr(args, f.name)})


def replay_bag(bag: Path, out_dir: Path, options: ReplayOptions, progress: bool = False) -> ReplayResult:
    """One bag into ``out_dir``: ``updates.csv``, ``estimates/`` unless ``no_bag``, and
    ``estimates.png`` when plotting.

    Args:
        bag: the bag's path.
        out_dir: the output directory (created; must be empty).
        options: the configuration overrides and output flags.
        progress: show a progress bar on stderr.

    Returns:
        What the replay did (``plot`` is the figure's path, if one was drawn).

    Raises:
        BagError: the bag cannot be read, or the output directory is not empty.
        ConfigError: an option or the recorded configuration is invalid, or ``plot`` is
            asked for without matplotlib.
    """
    from rozyn_estimator.tools.replay.plot import PLOT_NAME, matplotlib_available, plot_estimates

    plot = matplotlib_available() if options.plot is None else options.plot
    if plot and not matplotlib_available():
        raise ConfigError("--plot needs matplotlib (pip install matplotlib); --no-plot skips the figure")
    with open_bag(bag, salvage=options.salvage) as reader:
        for note in reader.unverified:
            print(f"rozyn replay: warning: {note}", file=sys.stderr)
        config, source = resolve_config(reader, options)
        result = replay_reader(
            reader, config, out_dir=out_dir, write_bag=not options.no_bag, progress=progress
        )
    result.config_source = source
    if plot and result.updates:
        result.plot = plot_estimates(out_dir / "updates.csv", out_dir / PLOT_NAME, truth=_truth(result),
                                     recorded=result.recorded, title=str(bag))
    return result


def resolve_config(reader: BagReader, args: ReplayOptions) -> tuple[EstimatorConfig, str]:
    """The bag's recorded configuration (or the defaults) with the options applied.

    Args:
        reader: the open bag.
        args: the options.

    Returns:
        The configuration and where it came from, in words.

    Raises:
        ConfigError: an invalid option or recorded setting, or an unknown ``--method``.
    """
    config, source = EstimatorConfig(), "the node's defaults (the bag records no estimator configuration)"
    if args.ignore_bag_config:
        source = "the node's defaults (--ignore-bag-config)"
    elif CUSTOM_DATA_KEY in reader.custom_data:
        ignored: list[str] = []
        config = EstimatorConfig.from_json(reader.custom_data[CUSTOM_DATA_KEY], ignored)
        source = f"recorded in the bag ({config.node_name})"
        if ignored:
            names = ", ".join(n.removeprefix("estimator configuration.") for n in ignored)
            source += f"; settings of another version ignored: {names}"
    config, overridden = _apply(config, args)
    if overridden:
        source += "; overridden: " + ", ".join(overridden)
    return config, source


def check_options(options: ReplayOptions) -> None:
    """Check the options against the node's defaults (before replaying many bags).

    Raises:
        ConfigError: an invalid option, an unknown ``--method`` or a bad ``--vehicle`` file.
    """
    _apply(EstimatorConfig(), options)


def _apply(config: EstimatorConfig, args: ReplayOptions) -> tuple[EstimatorConfig, list[str]]:
    """``config`` with the options' overrides, and the names of what they changed."""
    changes: dict[str, Any] = {}
    for name in TOPIC_OPTIONS:
        if getattr(args, name) is not None:
            changes[name] = getattr(args, name)
    online = {
        n: getattr(args, n)
        for n in ("window_s", "update_period_s", "min_window_fill", "speed_mps")
        if getattr(args, n) is not None
    }
    if online:
        changes["online"] = config.online.replace(**online)
    if args.vehicle:  # a half car's file, or a full car's (model: full): the model follows the file
        from rozyn_estimator.vehicle_full import FullVehicle, load_any_vehicle

        vehicle = load_any_vehicle(args.vehicle)
        full = isinstance(vehicle, FullVehicle)
        changes["full_vehicle"] = vehicle if full else None
        if not full:
            changes["vehicle"] = vehicle
    if args.method:
        from rozyn_estimator.method import METHODS

        if args.method not in METHODS:
            raise ConfigError(f"--method: must be one of {', '.join(METHODS)}, got {args.method!r}")
        changes["pipeline"] = METHODS[args.method]
    names = {*changes, *online} - {"online", "full_vehicle"} | ({"vehicle"} if args.vehicle else set())
    return config.replace(**changes), sorted(names)


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
            config, source = resolve_config(reader, ReplayOptions())
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
    channels: dict[str, list[int]] = {}  # topic -> its channels (an IMU's topic holds several)
    for k, (_, t) in enumerate(config.sensors):
        channels.setdefault(absolute_topic(t), []).append(k)
    topics = list(channels)
    infos = [reader.topic(t) for t in topics]
    for info in infos:
        if info.count == 0:
            raise BagError(f"{reader.path}: topic {info.name} holds no messages")
    accel = [(_field_reader(reader, info, [config.fields[k] for k in chans]), tuple(chans))
             for info, chans in zip(infos, channels.values(), strict=True)]
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
    online = OnlineEstimator.from_config(config)
    outputs = ReplayOutputs(Path(out_dir), config, reader, write_bag, online.layout) \
        if out_dir is not None else None
    total = sum(reader.topics[t].count for t in topics)
    bar = _progress(total, progress)
    try:
        started = time.perf_counter()
        for batch in reader.batches(topics, batch_size):
            bar.update(len(batch))
            a_idx, chan, stamps, values, lost = _accelerations(batch, accel)
            s_idx, s_stamps, s_values, lost[-1] = _speeds(batch, speed, len(accel))
            for c in np.flatnonzero(lost).tolist():  # garbled messages: dropped and counted
                online.drop(c, "undecodable message", int(lost[c]))
            for name, i in extra.items():
                for j in np.flatnonzero(batch.topic == i).tolist():
                    msgtype = reader.topics[name].msgtype
                    _note_extra(result, reader, name, batch.messages.message(j), msgtype, config)
            jobs = online.add_batch(chan, stamps, values, a_idx, SpeedSamples(s_stamps, s_values, s_idx))
            if a_idx.size:
                first, last = int(stamps.min()), int(stamps.max())
                if result.span_ns is not None:
                    first, last = min(first, result.span_ns[0]), max(last, result.span_ns[1])
                result.span_ns = (first, last)
            result.accel_messages += np.unique(a_idx).size if len(accel) < len(config.sensors) else a_idx.size
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
    batch: RawBatch, readers: list[tuple[FieldReader, tuple[int, ...]]]
) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """Positions in the batch, channels, stamps [ns] and values of the sensor topics 0 … k - 1
    (topic k's reader reads the fields of its channels, one each); and per channel (then
    speed: 0) the messages that could not be decoded, left out. A message with several
    channels gives a sample of each at its position, in the channels' order.

    The stamp is the header's, or the bag time for a type without a header.
    """
    n_channels = sum(len(chans) for _, chans in readers)
    lost = np.zeros(n_channels + 1, np.int64)
    parts: list[tuple[np.ndarray, ...]] = []
    for t, (reader, chans) in enumerate(readers):
        idx = np.flatnonzero(batch.topic == t)
        decoded = reader.decode(batch.messages.take(idx))
        ok = decoded.ok
        stamps = (batch.log_ns[idx] if decoded.stamps is None else decoded.stamps)[ok]
        for j, c in enumerate(chans):
            parts.append((idx[ok], np.full(int(ok.sum()), c, np.int64), stamps, decoded.values[ok, j]))
            lost[c] = int(np.sum(~ok))
    idx, chan, stamps, values = (np.concatenate(p) for p in zip(*parts, strict=True))
    order = np.argsort(idx, kind="stable")  # the bag's order; a message's channels in theirs
    return idx[order], chan[order], stamps[order].astype(np.int64), values[order].astype(float), lost


def _speeds(batch: RawBatch, reader: FieldReader | None,
            topic: int) -> tuple[np.ndarray, np.ndarray, list[float], int]:
    """Positions, stamps [ns] and speeds [m/s] of the speed topic (index ``topic``), the norm
    computed as the node does; and how many could not be decoded (left out)."""
    if reader is None:
        return np.zeros(0, np.int64), np.zeros(0, np.int64), [], 0
    idx = np.flatnonzero(batch.topic == topic)
    decoded = reader.decode(batch.messages.take(idx))
    ok = decoded.ok
    speeds = [float((x**2 + y**2) ** 0.5) for x, y in decoded.values[ok].tolist()]  # bit for bit the node's
    stamps = batch.log_ns[idx] if decoded.stamps is None else decoded.stamps
    return idx[ok], stamps[ok], speeds, int(np.sum(~ok))


def _field_reader(reader: BagReader, info: TopicInfo, fields: Sequence[str]) -> FieldReader:
    try:
        return FieldReader(reader.typestore, info.msgtype, fields, reader.deserialize, cdr=reader.cdr)
    except ConfigError as exc:
        raise ConfigError(f"topic {info.name}: {exc}") from None


def _type_choice(msgtype: str) -> str:
    return next((k for k, (t, _) in SPEED_TOPIC_TYPES.items() if t == msgtype), "twist|odometry")


def _truth(result: ReplayResult) -> Any:
    """What the plot draws as the truth: its steps where it changed (a load change), else the truth."""
    return result.truth_steps if len(set(result.truth_steps.values())) > 1 else result.truth


def _note_extra(
    result: ReplayResult, reader: BagReader, topic: str, data: bytes, msgtype: str, config: EstimatorConfig
) -> None:
    """Keep the sim's ground truth and the estimates the node published, for comparison."""
    if msgtype != "geometry_msgs/msg/InertiaStamped":
        return
    try:
        msg = reader.deserialize(data, msgtype)
    except BagError:  # garbled: the comparison goes without it
        return
    values = inertia_values(msg.inertia, config.front_axle_x_m, config.full_vehicle is not None)
    if topic == TRUTH_TOPIC:
        result.truth = values
        result.truth_steps[msg.header.stamp.sec * NS + msg.header.stamp.nanosec] = values
    else:
        result.recorded[msg.header.stamp.sec * NS + msg.header.stamp.nanosec] = values


def _progress(total: int, enabled: bool) -> Any:
    from tqdm import tqdm

    return tqdm(total=total, unit="msg", unit_scale=True, disable=not enabled, file=sys.stderr, leave=False)


