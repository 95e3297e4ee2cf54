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
"""

from __future__ import annotations

import argparse
import csv
import sys
import time
from collections.abc import Sequence
from dataclasses import dataclass, field
from datetime import UTC, datetime
from pathlib import Path
from typing import Any

import numpy as np

from rozyn_estimator.bag.cdr import FieldReader
from rozyn_estimator.bag.reader import BagReader, RawBatch, open_bag
from rozyn_estimator.bag.writer import BagWriter, absolute_topic
from rozyn_estimator.errors import BagError, ConfigError
from rozyn_estimator.online import (
    CUSTOM_DATA_KEY,
    LEVEL_NAMES,
    NS,
    SPEED_TOPIC_TYPES,
    EstimatorConfig,
    OnlineEstimator,
    SpeedSamples,
    Update,
)

HELP = "replay a bag through the online estimator offline: CSV of updates + output bag"
DESCRIPTION = (
    "Feed the accelerometer messages of a bag (rosbag2 MCAP or SQLite3, or ROS 1) through the "
    "estimator node's own online code, in the order the bag received them, and write updates.csv "
    "(every update: stamp, status, estimates, std, covariance, modes) and a rosbag2 MCAP bag with "
    "/inertia, /inertia/covariance and /diagnostics in bag time. The estimator is configured as "
    "recorded in the bag (bag_recorder and rozyn demo store it), else with the node's defaults; "
    "options override. No DDS needed."
)
TRUTH_TOPIC = "/sim/ground_truth"
PUBLISHED_TOPIC = "/inertia"
PARAM_SHORT = ("m", "iyy", "lf")


@dataclass(frozen=True)
class ReplayedUpdate:
    """One update and the bag time [ns] of the message that made it due."""

    update: Update
    log_ns: int


@dataclass
class ReplayResult:
    """What a replay did; ``feed_s`` is reading, decoding and feeding, ``update_s`` the updates."""

    bag: Path
    config: EstimatorConfig
    config_source: str
    updates: list[ReplayedUpdate] = field(default_factory=list)
    accel_messages: int = 0
    speed_messages: int = 0
    feed_s: float = 0.0
    update_s: float = 0.0
    truth: tuple[float, float, float] | None = None  # from sim/ground_truth (m, I, lf)
    recorded: dict[int, tuple[float, float, float]] = field(default_factory=dict)  # stamp -> node's estimate
    out_dir: Path | None = None
    out_counts: dict[str, int] = field(default_factory=dict)
    damage: list[str] = field(default_factory=list)
    dropped: dict[str, int] = field(default_factory=dict)
    resets: int = 0

    @property
    def messages_per_s(self) -> float:
        """Accelerometer messages read, decoded and fed per second (updates excluded)."""
        return self.accel_messages / self.feed_s if self.feed_s > 0 else 0.0

    @property
    def published(self) -> list[ReplayedUpdate]:
        return [u for u in self.updates if u.update.published]


# ---------------------------------------------------------------------- CLI
def add_arguments(p: argparse.ArgumentParser) -> None:
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
    """The bag's recorded configuration (or the defaults) with the options applied."""
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

    Keyword arguments are those of :func:`replay_reader`, plus ``salvage``.
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

    Messages are read ``batch_size`` at a time (the result does not depend on it).

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
    outputs = _Outputs(Path(out_dir), config, reader, write_bag) if out_dir is not None else None
    total = sum(reader.topics[t].count for t in topics)
    bar = _progress(total, progress)
    try:
        started = time.perf_counter()
        for batch in reader.batches(topics, batch_size):
            bar.update(len(batch))
            a_idx, chan, stamps, values = _accelerations(batch, accel)
            s_idx, s_stamps, s_values = _speeds(batch, speed)
            for name, i in extra.items():
                for j in np.flatnonzero(batch.topic == i):
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


def _field_reader(reader: BagReader, info: Any, fields: Sequence[str]) -> FieldReader:
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


# ------------------------------------------------------------------- outputs
class _Outputs:
    """``updates.csv`` and the output bag of one replay."""

    def __init__(self, out_dir: Path, config: EstimatorConfig, reader: BagReader, write_bag: bool) -> None:
        if out_dir.exists() and any(out_dir.iterdir()):
            raise BagError(f"{out_dir} exists and is not empty; choose another --out")
        ros_bag = None
        if write_bag:
            try:
                from rozyn_estimator.ros import serialized as ros_bag  # rclpy's serialisation (no DDS)
            except ImportError as exc:
                raise BagError(f"the output bag needs rclpy ({exc}); --no-bag writes the CSV only") from None
        out_dir.mkdir(parents=True, exist_ok=True)
        self.out_dir = out_dir
        self.config = config
        self.counts: dict[str, int] = {}
        self._csv_file = (out_dir / "updates.csv").open("w", newline="")
        self._csv = csv.writer(self._csv_file)
        self._csv.writerow(CSV_COLUMNS)
        self._bag: BagWriter | None = None
        if ros_bag is not None:
            self._messages = ros_bag.update_messages
            self._bag = BagWriter(out_dir / "estimates")
            self._bag.set_custom_data(CUSTOM_DATA_KEY, config.to_json())
            self._bag.set_custom_data("rozyn_estimator.replayed_from", str(reader.path.resolve()))
            self._ids = {
                t: self._bag.add_topic(t, msgtype, [qos]) for t, msgtype, qos in ros_bag.OUTPUT_TOPICS
            }

    def write(self, replayed: ReplayedUpdate, online: OnlineEstimator) -> None:
        self._csv.writerow(csv_row(replayed))
        if self._bag is None:
            return
        for topic, data in self._messages(replayed.update, online.report(), self.config):
            self._bag.write(self._ids[topic], replayed.log_ns, data)

    def close(self) -> None:
        self._csv_file.close()
        if self._bag is not None:
            self._bag.close()
            self.counts = self._bag.counts


CSV_COLUMNS = (
    "stamp_s",
    "stamp_ns",
    "bag_time_ns",
    "status",
    "published",
    "message",
    "mass_kg",
    "pitch_inertia_kgm2",
    "cog_from_front_axle_m",
    "mass_kg_std",
    "pitch_inertia_kgm2_std",
    "cog_from_front_axle_m_std",
    *(f"cov_{a}_{b}" for a in PARAM_SHORT for b in PARAM_SHORT),
    "stage",
    "mode1_freq_hz",
    "mode1_damping",
    "mode2_freq_hz",
    "mode2_damping",
    "window_fill",
    "sample_rate_hz",
    "speed_mps",
    "pipeline_ms",
)


def csv_row(replayed: ReplayedUpdate) -> list[Any]:
    """One CSV row (floats at full precision; empty where there is no number)."""
    u = replayed.update
    est = u.estimate
    ok = u.published
    params = list(est.params) if ok else [""] * 3
    cov = est.covariance if ok and est.covariance is not None else None
    std = list(np.sqrt(np.diag(cov))) if cov is not None else [""] * 3
    modes = []
    for k in range(2):
        mode = est.modes[k] if est is not None and len(est.modes) > k else None
        modes += [mode.freq_hz, mode.damping_ratio] if mode else ["", ""]
    return [
        f"{u.stamp_ns / NS:.9f}",
        u.stamp_ns,
        replayed.log_ns,
        LEVEL_NAMES[u.level],
        int(ok),
        u.message,
        *(_num(x) for x in params),
        *(_num(x) for x in std),
        *(_num(x) for x in (cov.ravel() if cov is not None else [""] * 9)),
        est.stage if est is not None else "",
        *(_num(x) for x in modes),
        _num(u.window_fill),
        _num(u.fs_hz),
        _num(u.speed_mps if u.speed_mps is not None else ""),
        _num(est.elapsed_ms if est is not None else ""),
    ]


def _num(x: Any) -> Any:
    return repr(float(x)) if isinstance(x, float | np.floating | int) and not isinstance(x, bool) else x


# ------------------------------------------------------------------- report
def format_summary(result: ReplayResult) -> str:
    """The closing report: throughput, configuration, a table of the estimates, checks."""
    cfg = result.config
    lines = [
        f"replayed {result.bag}: {result.accel_messages} accelerometer messages "
        f"({absolute_topic(cfg.front_topic)}, {absolute_topic(cfg.rear_topic)}, {cfg.field})"
        + (
            f" and {result.speed_messages} speed messages ({absolute_topic(cfg.speed_topic)})"
            if cfg.speed_topic
            else ""
        ),
        f"  read, decoded and fed in {result.feed_s:.2f} s ({result.messages_per_s:,.0f} msg/s); "
        f"{len(result.updates)} updates in {result.update_s:.2f} s",
        f"  configuration: {result.config_source}",
        f"  window {cfg.online.window_s:g} s, update every {cfg.online.update_period_s:g} s, "
        f"pipeline refine={cfg.pipeline.refine}",
    ]
    for note in result.damage:
        lines.append(f"  salvaged: {note}")
    if result.resets or result.dropped:
        dropped = ", ".join(f"{k}: {v}" for k, v in sorted(result.dropped.items())) or "none"
        lines.append(f"  window resets: {result.resets}; dropped: {dropped}")
    lines += ["", _table(result)]
    published = result.published
    if published:
        p = np.array([u.update.estimate.params for u in published])
        lines.append(f"{'mean over updates':<22}" + "".join(f"{x:>24.6g}" for x in p.mean(axis=0)))
        if result.truth is not None:
            err = (p[-1] / np.array(result.truth) - 1) * 100
            lines.append(
                f"{'truth (' + TRUTH_TOPIC + ')':<22}" + "".join(f"{x:>24.6g}" for x in result.truth)
            )
            lines.append(f"{'last vs truth':<22}" + "".join(f"{e:>+23.2f}%" for e in err))
    if result.recorded:
        lines.append(_against_recorded(result))
    if result.out_dir is not None:
        counts = ", ".join(f"{t} {n}" for t, n in result.out_counts.items())
        lines += [
            "",
            f"wrote {result.out_dir / 'updates.csv'}"
            + (f" and {result.out_dir / 'estimates'} ({counts})" if counts else ""),
        ]
    return "\n".join(lines)


def _table(result: ReplayResult, max_rows: int = 24) -> str:
    head = (
        f"{'stamp [s]':>12}  {'status':<6}{'mass [kg]':>24}{'pitch inertia [kg m2]':>24}"
        f"{'CoG from front [m]':>24}"
    )
    rows = [head]
    updates = result.updates
    shown = updates if len(updates) <= max_rows else updates[-max_rows:]
    if len(shown) < len(updates):
        rows.append(f"{'…':>12}  ({len(updates) - len(shown)} earlier updates in the CSV)")
    for ru in shown:
        u = ru.update
        if u.published:
            std = u.estimate.std if u.estimate.std is not None else np.full(3, np.nan)
            cells = "".join(
                f"{f'{v:.6g} ± {s:.3g}':>24}" for v, s in zip(u.estimate.params, std, strict=True)
            )
        else:
            cells = f"  {u.message if len(u.message) <= 90 else u.message[:89] + '…'}"
        rows.append(f"{u.stamp_ns / NS:>12.3f}  {LEVEL_NAMES[u.level]:<6}{cells}")
    return "\n".join(rows)


def _against_recorded(result: ReplayResult) -> str:
    """How the replayed estimates compare with those the node published in the bag."""
    replayed = {u.update.stamp_ns: u.update.estimate.params for u in result.published}
    common = sorted(set(replayed) & set(result.recorded))
    if not common:
        return f"no stamp of the {len(result.recorded)} estimates on {PUBLISHED_TOPIC} is in the replay"
    rel = max(float(np.max(np.abs(np.array(result.recorded[s]) / replayed[s] - 1))) for s in common)
    text = (
        f"against the {len(result.recorded)} estimates recorded on {PUBLISHED_TOPIC}: {len(common)} at "
        f"the same stamps, max relative difference {rel:.1e}"
    )
    extra, missing = len(set(replayed) - set(result.recorded)), len(set(result.recorded) - set(replayed))
    if extra:
        text += f"; {extra} more in the replay (not yet published when the recording stopped?)"
    if missing:
        text += f"; {missing} recorded ones the replay does not have"
    return text


def _progress(total: int, enabled: bool) -> Any:
    from tqdm import tqdm

    return tqdm(total=total, unit="msg", unit_scale=True, disable=not enabled, file=sys.stderr, leave=False)


def _utc() -> str:
    return datetime.now(UTC).strftime("%Y%m%dT%H%M%SZ")
