"""The online estimator: sliding window, channel pairing, gaps, and the update schedule.

ROS-free, and the one code path for online and offline use: the estimator node feeds it
from its subscription callbacks, ``rozyn replay`` from bag messages. Everything is driven
by the message stamps, never by the wall clock, so replaying a recorded run reproduces
the updates the node made.

Feeding: :meth:`OnlineEstimator.add` per sample (tiny work: checks and a list append)
returns the updates that sample made due; :meth:`OnlineEstimator.add_batch` takes many
samples in arrival order (vectorised when they are clean, one by one otherwise: the same
result) and returns each due update with the position of the message that made it due.
The channels: the half car's front and rear accelerometers, or the full car's three or
four corners (:class:`~rozyn_estimator.online.records.Layout`). Updates fall due every
``update_period_s`` of message time once *all* channels have reached the due time; a due
:class:`Job` is a snapshot of the window (cheap, in the feeding thread) and
:meth:`OnlineEstimator.compute` runs the pipeline on it (any thread, in due order).
:meth:`OnlineEstimator.report` gives one diagnostics message.

Bad input is dropped and counted, never raised: non-finite values or speeds, duplicate stamps,
stamps older than the channel's last (out of order: not also counted missing). A gap longer
than ``max_gap_s`` or a stamp more than ``jump_back_s`` older than the last (bag loop, sim
restart) resets the window, and the next report says so. A channel holds at most about three
windows of samples (trimmed once it holds a window more), also while the other sensor is
silent. :meth:`OnlineEstimator.compute` never raises: an unexpected failure is an ERROR
update, reported until a good one follows. The windows' estimates are fused while the load
stays, and a load change at a stop restarts them (:mod:`~rozyn_estimator.online.fusion`).

The state is shared between the feeding thread, the worker that computes and the diagnostics
timer: every public method takes the instance's lock (the pipeline runs outside it).

Example:
    >>> import numpy as np
    >>> from rozyn_estimator.vehicle import Vehicle
    >>> est = OnlineEstimator(Vehicle(), OnlineConfig(window_s=20, update_period_s=10))
    >>> t = np.arange(3000) * 10_000_000  # 30 s at 100 Hz [ns]
    >>> jobs = est.add_batch(np.r_[np.zeros(3000), np.ones(3000)], np.r_[t, t], np.zeros(6000))
    >>> [(job.due_ns, trigger) for job, trigger in jobs]
    [(10000000000, 4000), (20000000000, 5000)]
"""

from __future__ import annotations

import math
import threading
from collections import Counter, deque
from collections.abc import Sequence

import numpy as np

from rozyn_estimator.errors import ConfigError
from rozyn_estimator.method import Estimate, PipelineConfig
from rozyn_estimator.online.batch import SpeedSamples, as_received, clean_batch
from rozyn_estimator.online.channel import Channel
from rozyn_estimator.online.config import OnlineConfig, speed_problem
from rozyn_estimator.online.driving import driving_start
from rozyn_estimator.online.estimator_config import EstimatorConfig
from rozyn_estimator.online.fusion import Fusion, fuse_update, trimmed
from rozyn_estimator.online.records import ERROR, NS, OK, WARN, Health, Job, Layout, Level, Update, layout_of
from rozyn_estimator.online.status import health_values, status
from rozyn_estimator.online.update import compute_update
from rozyn_estimator.vehicle import Vehicle
from rozyn_estimator.vehicle_full import FullVehicle

_NONE: tuple[Job, ...] = ()
_MAX_EVENTS = 20


class OnlineEstimator:
    """Window, pairing, gap/reset logic and the update schedule for one vehicle.

    Args:
        vehicle: the known vehicle parameters: a half car, or a full car (its updates run
            :func:`~rozyn_estimator.method.estimate`).
        config: window and schedule settings.
        pipeline: settings of each update.
        names: what to call each sensor in messages (e.g. their topics; default: ``channels``).
        channels: the full car's corners with an accelerometer, three or four of ``front_left``,
            ``front_right``, ``rear_left``, ``rear_right`` (default: all four; the half car's
            are ``front`` and ``rear``); channel ``k`` of :meth:`add` is ``channels[k]``.

    Raises:
        ConfigError: channels the vehicle cannot have, or names not one per channel.
    """

    def __init__(
        self,
        vehicle: Vehicle | FullVehicle,
        config: OnlineConfig | None = None,
        pipeline: PipelineConfig | None = None,
        names: Sequence[str] | None = None,
        channels: Sequence[str] | None = None,
    ) -> None:
        self._layout = layout_of(vehicle, channels)
        self.names = tuple(self._layout.channels if names is None else names)
        if len(self.names) != len(self._layout.channels):
            raise ConfigError(f"one name per channel ({', '.join(self._layout.channels)}), got {self.names}")
        self._lock = threading.RLock()
        self._vehicle = vehicle
        self._config = config or OnlineConfig()
        self._pipeline = pipeline or PipelineConfig()
        self._channels = tuple(Channel() for _ in self._layout.channels)
        self._speed = Channel()
        self._speed_source = False  # any speed sample arrived (valid or not): a speed topic is in use
        self._next_due_ns: int | None = None
        self._dropped: Counter[str] = Counter()  # reason -> count, since start
        self._resets = 0
        self._epoch = 0  # the window's generation, one more at each reset
        self._events: deque[tuple[Level, str]] = deque(maxlen=_MAX_EVENTS)  # not yet reported
        self._last_update: Update | None = None
        self._fusion = Fusion()  # the windows fused since the last load change
        self._reported_losses = 0  # drops and missing samples at the last report
        self._warm: Estimate | None = None  # the last published estimate

    @classmethod
    def from_config(cls, config: EstimatorConfig) -> OnlineEstimator:
        """The estimator a node of that configuration runs (its vehicle, sensors and topics)."""
        labels, topics = zip(*config.sensors, strict=True)
        return cls(config.model_vehicle, config.online, config.pipeline, topics, labels)

    # ------------------------------------------------------------- settings
    @property
    def vehicle(self) -> Vehicle | FullVehicle:
        return self._vehicle

    @property
    def layout(self) -> Layout:
        """The channels and the parameters of the vehicle's updates."""
        return self._layout

    @property
    def config(self) -> OnlineConfig:
        return self._config

    @property
    def pipeline(self) -> PipelineConfig:
        return self._pipeline

    def reconfigure(self, vehicle: Vehicle | FullVehicle, config: OnlineConfig,
                    pipeline: PipelineConfig) -> None:
        """New settings from the next update on (the window and schedule go on).

        Raises:
            ConfigError: a vehicle of the other model (half or full car).
        """
        if self._layout.full != vehicle.ROLLS:
            raise ConfigError("the vehicle model (half or full car) cannot change while running")
        with self._lock:
            self._vehicle, self._config, self._pipeline = vehicle, config, pipeline
            self._fusion.reset()  # another vehicle file: the windows so far measured under the old one

    # ------------------------------------------------------------- counters
    @property
    def dropped(self) -> dict[str, int]:
        """Samples dropped since the start, per reason (``front: duplicate stamp`` …)."""
        with self._lock:
            return dict(self._dropped)

    @property
    def resets(self) -> int:
        return self._resets

    @property
    def events(self) -> tuple[tuple[Level, str], ...]:
        """Events not yet reported (window resets), oldest first."""
        with self._lock:
            return tuple(self._events)

    @property
    def last_update(self) -> Update | None:
        return self._last_update

    def samples(self, channel: int) -> int:
        """Samples taken in on a channel (an index into ``layout.channels``) since the start."""
        return self._channels[channel].count

    # -------------------------------------------------------------- feeding
    def add(self, channel: int, stamp_ns: int, value: float) -> Sequence[Job]:
        """One accelerometer sample (channel: an index into ``layout.channels``; the half car's 0
        front, 1 rear) [ns, m/s^2]; the jobs it made due."""
        with self._lock:
            self._add(channel, stamp_ns, value)
            return self._take_due()

    def add_speed(self, stamp_ns: int, speed_mps: float) -> None:
        """A vehicle speed sample [m/s] (used when the pipeline needs the speed)."""
        with self._lock:
            self._add_speed(stamp_ns, speed_mps)

    def drop(self, channel: int, reason: str, count: int = 1) -> None:
        """Count messages that could not be used (channel: an index into ``layout.channels``; one
        more: speed)."""
        with self._lock:
            self._dropped[f"{(*self._layout.channels, 'speed')[channel]}: {reason}"] += count
            if channel < len(self._channels):
                self._channels[channel].reject(reason, count)

    def add_batch(
        self,
        channels: np.ndarray,
        stamps_ns: np.ndarray,
        values: np.ndarray,
        order: np.ndarray | None = None,
        speed: SpeedSamples | None = None,
    ) -> list[tuple[Job, int]]:
        """Many samples in arrival order, as :meth:`add` (and :meth:`add_speed`) one by one.

        Arrival order means the channels interleaved as their samples arrive: a channel's
        samples fed more than two windows ahead of the other's are trimmed before the other
        catches up (so a silent sensor cannot make memory grow), as they would be one by one.

        Args:
            channels, stamps_ns, values: accelerometer samples (channel indices as :meth:`add`'s).
            order: their arrival positions (default: as given); ``speed.order`` places
                the speed samples among them.
            speed: speed samples that arrived among them.

        Returns:
            Each job made due, with the index (into the accelerometer arrays) of the
            sample that made it due. A speed sample that arrived after that sample is
            not in the job, as it would not have been in the node.
        """
        channels = np.asarray(channels)
        stamps_ns = np.asarray(stamps_ns, dtype=np.int64)
        values = np.asarray(values, dtype=float)
        order = np.arange(channels.size) if order is None else np.asarray(order)
        with self._lock:
            if not clean_batch(self._channels, channels, stamps_ns, values, self._config.max_gap_s * NS):
                return self._one_by_one(channels, stamps_ns, values, order, speed)
            before = [ch.last_ns for ch in self._channels]
            for c, ch in enumerate(self._channels):
                sel = channels == c
                if np.any(sel):
                    s = stamps_ns[sel]
                    if ch.last_ns is None:
                        ch.note_steps(np.diff(s), s[1:])
                    else:
                        ch.note_steps(np.diff(s, prepend=ch.last_ns), s)
                    ch.extend(s, values[sel])
            if speed is not None:
                for t, v in zip(speed.stamps_ns.tolist(), speed.values, strict=True):
                    self._add_speed(t, v)
            return [as_received(job, before, channels, stamps_ns, order, speed)
                    for job in self._take_due()]

    def reset(self, reason: str) -> None:
        """Forget the window (and the schedule) after a time jump, gap or restart."""
        with self._lock:
            for ch in (*self._channels, self._speed):
                ch.clear()
            self._next_due_ns = None
            self._warm = None
            self._fusion.reset()
            self._resets += 1
            self._epoch += 1
            self._events.append((WARN, f"window reset: {reason}"))

    def _add(self, channel: int, stamp_ns: int, value: float) -> None:
        ch = self._channels[channel]
        last = ch.last_ns
        gap = self._config.max_gap_s * NS
        if not math.isfinite(value):
            self._reject(channel, "non-finite value")
            if last is not None and 0 < stamp_ns - last <= gap:
                ch.note_steps([stamp_ns - last], [stamp_ns])  # its stamp arrived: not a missing sample
                ch.last_ns = stamp_ns
            return
        if last is not None:
            if stamp_ns == last:
                self._reject(channel, "duplicate stamp")
                return
            if stamp_ns < last:
                if last - stamp_ns > self._config.jump_back_s * NS:
                    self.reset(f"time jumped back {(last - stamp_ns) / NS:.3f} s on {self.names[channel]}")
                else:
                    ch.arrived_late(stamp_ns)  # dropped, so no longer counted missing too
                    self._reject(channel, "out-of-order stamp")
                    return
            elif stamp_ns - last > gap:
                self.reset(f"gap of {(stamp_ns - last) / NS:.3f} s on {self.names[channel]}")
            else:
                ch.note_steps([stamp_ns - last], [stamp_ns])
        ch.append(stamp_ns, value)

    def _reject(self, channel: int, reason: str) -> None:
        self._dropped[f"{self._layout.channels[channel]}: {reason}"] += 1
        self._channels[channel].reject(reason)

    def _add_speed(self, stamp_ns: int, speed_mps: float) -> None:
        self._speed_source = True
        ch, late = self._speed, self._speed.last_ns is not None and stamp_ns <= self._speed.last_ns
        if problem := speed_problem(speed_mps) or ("out-of-order speed stamp" if late else None):
            self._dropped[f"speed: {problem}"] += 1
        else:
            ch.append(stamp_ns, speed_mps)

    def _one_by_one(self, channels: np.ndarray, stamps: np.ndarray, values: np.ndarray, order: np.ndarray,
                    speed: SpeedSamples | None) -> list[tuple[Job, int]]:
        """A batch that is not clean, message by message in arrival order, as the node does."""
        arrivals = [(int(p), 0, i) for i, p in enumerate(order.tolist())]
        if speed is not None:
            arrivals += [(int(p), 1, i) for i, p in enumerate(speed.order.tolist())]
        out: list[tuple[Job, int]] = []
        for _, kind, i in sorted(arrivals):
            if kind == 1 and speed is not None:
                self._add_speed(int(speed.stamps_ns[i]), speed.values[i])
            else:
                self._add(int(channels[i]), int(stamps[i]), float(values[i]))
                out += [(job, i) for job in self._take_due()]
        return out

    # ------------------------------------------------------------- schedule
    def _take_due(self) -> Sequence[Job]:
        """Snapshot every update that has fallen due, oldest first; then forget what no
        update can need."""
        jobs = self._due()
        self._trim(bool(jobs))
        return jobs

    def _trim(self, updated: bool) -> None:
        """Forget the samples older than the next update's reach (two windows, :mod:`.driving`),
        and in any case those more than two windows and an update period behind the channel's
        newest: a silent sensor holds up the schedule, not the memory. After an update each
        channel is trimmed; otherwise once it holds a window more than that (cheap per sample).
        """
        window = round(self._config.window_s * NS)
        horizon = 2 * window + round(self._config.update_period_s * NS)
        slack = 0 if updated else window
        for ch in (*self._channels, self._speed):
            oldest = ch.oldest_ns()
            if oldest is None or ch.last_ns is None:
                continue
            keep = ch.last_ns - horizon
            if self._next_due_ns is not None:
                keep = max(keep, self._next_due_ns - 2 * window)  # a window reaches back over stops
            if oldest < keep - slack:
                ch.trim(keep)

    def _due(self) -> Sequence[Job]:
        lasts = [ch.last_ns for ch in self._channels]
        if None in lasts:
            return _NONE
        period = round(self._config.update_period_s * NS)
        if self._next_due_ns is None:
            self._next_due_ns = max(ch.first_ns() for ch in self._channels) + period
        reached = min(t for t in lasts if t is not None)
        if reached < self._next_due_ns:
            return _NONE
        window, cfg, jobs = round(self._config.window_s * NS), self._config, []
        while reached >= self._next_due_ns:
            due = self._next_due_ns  # the window reaches back over standing time, at most 2 windows
            lo = driving_start(self._speed.window(due - 2 * window, due), due, window, 2 * window,
                               cfg.driving_speed_mps)
            samples = tuple(ch.window(lo, due) for ch in self._channels)
            jobs.append(Job(due, samples, self._speed.window(lo, due), self._epoch, self._speed_source))
            self._next_due_ns = due + period
        return jobs

    def compute(self, job: Job) -> Update:
        """Run the pipeline on a due window (call in due order; any thread).

        Never raises: an unexpected exception (a bug) becomes an ERROR update that names
        it, and like every update it stands in :meth:`health` until the next one.
        """
        with self._lock:
            current = job.epoch == self._epoch
            settings = (self._config, self._vehicle, self._pipeline, self._warm if current else None)
            cfg = self._config
            cut = self._fusion.test_cut(job, cfg.min_window_fill * cfg.window_s, cfg.driving_speed_mps)
            since = self._fusion.restart_cut(job) if cut is None else None
        start = cut if cut is not None else since  # after a stop: its test; after a change: the new load
        job = trimmed(job, start) if current and start is not None else job
        try:
            update = compute_update(job, self.names, *settings, self._layout)
        except Exception as exc:  # the one guard: node and replay both compute here
            text = f"{type(exc).__name__}: {exc}"
            text = text if len(text) <= 200 else text[:197] + "..."
            update = Update(job.due_ns, ERROR, f"update failed (internal error, please report): {text}")
        with self._lock:
            if current and job.epoch == self._epoch:  # no reset meanwhile
                if update.published and not update.held:
                    self._warm = update.estimate  # the next window's refinement starts here (its own)
                update, change = fuse_update(self._fusion, update, job, self._config.driving_speed_mps,
                                             self._vehicle.wheelbase_m, probe=cut is not None,
                                             since_change=since is not None)
                if change:
                    self._events.append((OK, change))
                self._last_update = update
        return update

    # --------------------------------------------------------------- health
    def health(self, silent_s: Sequence[float] | None = None) -> Health:
        """The current status for diagnostics, without changing anything.

        Args:
            silent_s: seconds since each sensor's last message arrived (the node's clock);
                a sensor silent for longer than ``silence_s`` is reported. Without it (a
                replay), a sensor whose stamps lag the other's by ``silence_s`` is.
        """
        with self._lock:
            return self._health(silent_s)

    def report(self, silent_s: Sequence[float] | None = None) -> Health:
        """:meth:`health` for one diagnostics message: the events and losses it reports
        (window resets, dropped and missing samples) are not reported again."""
        with self._lock:
            health = self._health(silent_s)
            self._events.clear()
            self._reported_losses = self._losses()
            return health

    def _losses(self) -> int:
        return sum(self._dropped.values()) + sum(ch.missing for ch in self._channels)

    def _health(self, silent_s: Sequence[float] | None) -> Health:
        lost = self._losses() - self._reported_losses
        level, message = status(self.names, self._channels, self._config.silence_s, silent_s,
                                tuple(self._events), self._last_update, lost)
        return Health(level, message, health_values(self._channels, self._layout, self._resets, self._dropped,
                                                    self._last_update))
