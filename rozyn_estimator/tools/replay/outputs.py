"""What ``rozyn replay`` produces: the result in memory, ``updates.csv`` and the estimates bag.

:class:`ReplayResult` is what a replay did (its updates, counts, timings, and what the
bag says the truth and the node's estimates were); :class:`ReplayOutputs` writes, as
the updates come,

- ``updates.csv``: one row per scheduled update (:data:`CSV_COLUMNS`: stamp, status,
  estimates, std, covariance, modes, window fill, speed, pipeline time, the std's
  statistical and systematic parts with the largest contributors, the model-fit check,
  glitches gated), numbers at full precision; the full car's (:func:`csv_columns` of its
  layout) has its five parameters, their 5x5 covariance and its three body modes;
- ``estimates/``: a rosbag2 MCAP bag with ``/inertia``, ``/inertia/covariance`` and
  ``/diagnostics`` as the node would have published them (serialised by rclpy, no
  DDS), logged at the bag time of the message that made each update due.
"""

from __future__ import annotations

import csv
from collections.abc import Callable, Sequence
from dataclasses import dataclass, field
from datetime import UTC, datetime
from pathlib import Path
from typing import Any

import numpy as np

from rozyn_estimator.bag import BagReader, BagWriter
from rozyn_estimator.errors import BagError
from rozyn_estimator.method import Estimate
from rozyn_estimator.online import (
    CUSTOM_DATA_KEY,
    HALF_LAYOUT,
    LEVEL_NAMES,
    NS,
    EstimatorConfig,
    Health,
    Layout,
    OnlineEstimator,
    Update,
    update_values,
)

TRUTH_TOPIC = "/sim/ground_truth"
PUBLISHED_TOPIC = "/inertia"
SHORT = {"mass_kg": "m", "roll_inertia_kgm2": "ixx", "pitch_inertia_kgm2": "iyy",
         "cog_from_front_axle_m": "lf", "cog_lateral_m": "yc"}  # the covariance columns' names: cov_m_iyy …


def inertia_values(inertia: Any, front_axle_x_m: float, full: bool) -> tuple[float, ...]:
    """The parameters (a layout's order) of an ``InertiaStamped``'s inertia, as the nodes publish
    them: (m, I_yy, l_f), or the full car's (m, I_xx, I_yy, l_f, y_c)."""
    lf = front_axle_x_m - inertia.com.x
    if full:
        return inertia.m, inertia.ixx, inertia.iyy, lf, inertia.com.y
    return inertia.m, inertia.iyy, lf


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
    truth: tuple[float, ...] | None = None  # from sim/ground_truth (m, I, lf; the full car's five): the last
    truth_steps: dict[int, tuple[float, ...]] = field(default_factory=dict)  # stamp -> truth (load changes)
    recorded: dict[int, tuple[float, ...]] = field(default_factory=dict)  # stamp -> node's estimate
    out_dir: Path | None = None
    out_counts: dict[str, int] = field(default_factory=dict)
    damage: list[str] = field(default_factory=list)
    dropped: dict[str, int] = field(default_factory=dict)
    resets: int = 0
    span_ns: tuple[int, int] | None = None  # the accelerometer messages' first and last stamp
    plot: Path | None = None  # estimates.png, when drawn

    @property
    def duration_s(self) -> float:
        """Message time from the first to the last accelerometer stamp."""
        return (self.span_ns[1] - self.span_ns[0]) / NS if self.span_ns else 0.0

    @property
    def messages_per_s(self) -> float:
        """Accelerometer messages read, decoded and fed per second (updates excluded)."""
        return self.accel_messages / self.feed_s if self.feed_s > 0 else 0.0

    @property
    def published(self) -> list[ReplayedUpdate]:
        """The updates that published an estimate."""
        return [u for u in self.updates if u.update.published]


def utc() -> str:
    """Now, for output directory names: ``20261122T101500Z``."""
    return datetime.now(UTC).strftime("%Y%m%dT%H%M%SZ")


def published_estimate(update: Update) -> Estimate | None:
    """The estimate an update published, None when it published none.

    Args:
        update: one update of the online estimator.

    Returns:
        Its estimate when :attr:`Update.published <rozyn_estimator.online.Update.published>`.
    """
    return update.estimate if update.published else None


class ReplayOutputs:
    """``updates.csv`` and the output bag of one replay.

    Args:
        out_dir: where to write (created; must not hold anything yet).
        config: the estimator's configuration (stored in the output bag).
        reader: the replayed bag (its path is stored in the output bag).
        write_bag: also write the ``estimates`` bag (needs rclpy), not the CSV only.

    Raises:
        BagError: ``out_dir`` is not empty, or the bag is asked for and rclpy is missing.
    """

    def __init__(self, out_dir: Path, config: EstimatorConfig, reader: BagReader, write_bag: bool,
                 layout: Layout = HALF_LAYOUT) -> None:
        if out_dir.exists() and any(out_dir.iterdir()):
            raise BagError(f"{out_dir} exists and is not empty; choose another --out")
        messages: Callable[[Update, Health, EstimatorConfig], Sequence[tuple[str, bytes]]] | None = None
        output_topics: Sequence[tuple[str, str, Any]] = ()
        if write_bag:
            try:  # rclpy's serialisation (no DDS)
                from rozyn_estimator.ros.serialized import OUTPUT_TOPICS, update_messages
            except ImportError as exc:
                raise BagError(f"the output bag needs rclpy ({exc}); --no-bag writes the CSV only") from None
            messages, output_topics = update_messages, OUTPUT_TOPICS
        out_dir.mkdir(parents=True, exist_ok=True)
        self.out_dir = out_dir
        self.config = config
        self.layout = layout
        self.counts: dict[str, int] = {}
        self._csv_file = (out_dir / "updates.csv").open("w", newline="")
        self._csv = csv.writer(self._csv_file)
        self._csv.writerow(csv_columns(layout))
        self._messages = messages
        self._bag: BagWriter | None = None
        self._ids: dict[str, int] = {}
        if messages is not None:
            self._bag = BagWriter(out_dir / "estimates")
            self._bag.set_custom_data(CUSTOM_DATA_KEY, config.to_json())
            self._bag.set_custom_data("rozyn_estimator.replayed_from", str(reader.path.resolve()))
            self._ids = {t: self._bag.add_topic(t, msgtype, [qos]) for t, msgtype, qos in output_topics}

    def write(self, replayed: ReplayedUpdate, online: OnlineEstimator) -> None:
        """One update: its CSV row, and its messages in the bag at its trigger's bag time.

        Args:
            replayed: the update and the bag time of the message that made it due.
            online: the estimator (its diagnostics report goes to ``/diagnostics``).
        """
        self._csv.writerow(csv_row(replayed, self.layout))
        if self._bag is None or self._messages is None:
            return
        for topic, data in self._messages(replayed.update, online.report(), self.config):
            self._bag.write(self._ids[topic], replayed.log_ns, data)

    def close(self) -> None:
        """Close the CSV and finish the bag (:attr:`counts` then holds its message counts)."""
        self._csv_file.close()
        if self._bag is not None:
            self._bag.close()
            self.counts = self._bag.counts


def csv_columns(layout: Layout = HALF_LAYOUT) -> tuple[str, ...]:
    """The columns of ``updates.csv`` for a vehicle model (:data:`CSV_COLUMNS`: the half car's)."""
    names = layout.params
    short = [SHORT[n] for n in names]
    return (
        "stamp_s",
        "stamp_ns",
        "bag_time_ns",
        "status",
        "published",
        "message",
        *names,
        *(f"{n}_std" for n in names),
        *(f"cov_{a}_{b}" for a in short for b in short),
        "stage",
        *(f"mode{k}_{q}" for k in range(1, layout.modes + 1) for q in ("freq_hz", "damping")),
        "window_fill",
        "sample_rate_hz",
        "speed_mps",
        "pipeline_ms",
        # the published std's parts and largest contributors, the model-fit check
        # and the glitches gated: as /diagnostics says them (online.records.update_values)
        *budget_columns(layout),
        "model_fit_p",
        "model_fit",
        *(f"glitches_{c}" for c in layout.channels),
        # on a drive: held at a stop, the windows fused, the load changes found; what each
        # channel carries (method.information)
        "held",
        "fused_windows",
        "load_changes",
        *(f"information_lost_without_{c}" for c in layout.channels),
    )


def budget_columns(layout: Layout = HALF_LAYOUT) -> tuple[str, ...]:
    """The columns of the budget's parts and contributors."""
    return tuple(f"{name}_{part}" for name in layout.params for part in ("std_statistical", "std_systematic",
                                                                          "budget"))


CSV_COLUMNS = csv_columns()
BUDGET_COLUMNS = budget_columns()


def csv_row(replayed: ReplayedUpdate, layout: Layout = HALF_LAYOUT) -> list[Any]:
    """One CSV row (floats at full precision; empty where there is no number).

    Args:
        replayed: the update and the bag time of its trigger.
        layout: its vehicle model's.

    Returns:
        The cells in :func:`csv_columns` order.
    """
    u = replayed.update
    est = u.estimate
    published = published_estimate(u)
    k = len(layout.params)
    values = published.params if published is not None else None
    cov = published.covariance if published is not None else None
    params: list[Any] = list(values) if values is not None else [""] * k
    std: list[Any] = list(np.sqrt(np.diag(cov))) if cov is not None else [""] * k
    modes: list[Any] = []
    for i in range(layout.modes):
        mode = est.modes[i] if est is not None and len(est.modes) > i else None
        modes += [mode.freq_hz, mode.damping_ratio] if mode else ["", ""]
    described = update_values(u, layout)
    budget = [described.get(c, "") if published is not None else "" for c in budget_columns(layout)]
    tail = ["model_fit_p", "model_fit", *(f"glitches_{c}" for c in layout.channels), "held", "fused_windows",
            "load_changes", *(f"information_lost_without_{c}" for c in layout.channels)]
    return [
        f"{u.stamp_ns / NS:.9f}",
        u.stamp_ns,
        replayed.log_ns,
        LEVEL_NAMES[u.level],
        int(u.published),
        u.message,
        *(_num(x) for x in params),
        *(_num(x) for x in std),
        *(_num(x) for x in (cov.ravel() if cov is not None else [""] * k * k)),
        described.get("stage", ""),
        *(_num(x) for x in modes),
        _num(u.window_fill),
        _num(u.fs_hz),
        _num(u.speed_mps if u.speed_mps is not None else ""),
        _num(est.elapsed_ms if est is not None else ""),
        *budget,
        *(described.get(c, "") for c in tail),
    ]


def _num(x: Any) -> Any:
    return repr(float(x)) if isinstance(x, float | np.floating | int) and not isinstance(x, bool) else x
