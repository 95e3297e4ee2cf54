"""The online estimator: sliding window, front/rear pairing, gaps, and the update schedule.

ROS-free, and the one code path for online and offline use: the estimator node feeds it
from its subscription callbacks, ``rozyn replay`` from bag messages. Everything is driven
by the message stamps, never by the wall clock, so replaying a recorded run reproduces
the updates the node made.

Feeding: :meth:`OnlineEstimator.add` per sample (tiny work: checks and a list append),
or :meth:`OnlineEstimator.add_batch` for many samples in arrival order (vectorised; the
same result as adding them one by one). Updates fall due every ``update_period_s`` of
message time once *both* channels have reached the due time; :meth:`take_due` snapshots
their windows (cheap, in the feeding thread) and :meth:`compute` runs the pipeline on one
(in any thread, in due order). :meth:`process` does both, for synchronous callers.

Bad input is dropped and counted, never raised: non-finite values, duplicate stamps,
stamps older than the channel's last (out of order). A gap longer than ``max_gap_s`` or a
stamp more than ``jump_back_s`` older than the last (bag loop, sim restart) resets the
window.
"""

from __future__ import annotations

import dataclasses
import functools
import math
from collections import Counter, deque
from dataclasses import dataclass, field
from typing import Any

import numpy as np
from scipy import signal

from rozyn_estimator.errors import ConfigError
from rozyn_estimator.method.pipeline import PARAM_NAMES, Estimate, PipelineConfig, estimate
from rozyn_estimator.vehicle import Vehicle

OK, WARN, ERROR, STALE = 0, 1, 2, 3
_PERIOD_STEPS = 20  # steps between stamps that set a sensor's period
LEVEL_NAMES = ("OK", "WARN", "ERROR", "STALE")
NS = 1_000_000_000


@dataclass(frozen=True)
class OnlineConfig:
    """Window and schedule settings (seconds, Hz)."""

    window_s: float = 120.0
    update_period_s: float = 5.0
    min_window_fill: float = 0.8  # share of window_s that must hold paired data
    pair_tolerance_s: float = 0.002  # stamps this close are the same instant
    rate_hz: float = 0.0  # grid rate of the window; 0: the slower channel's, at most max_rate_hz
    max_rate_hz: float = 100.0  # faster sensors are low-passed and decimated to this
    max_gap_s: float = 0.5  # a longer silence on a channel resets the window
    jump_back_s: float = 1.0  # a stamp this much older than the last resets the window
    silence_s: float = 2.0  # a channel this far behind is reported as silent
    max_speed_variation: float = 0.1  # (max - min) / mean speed allowed in a window
    speed_mps: float = 0.0  # known speed when no speed samples arrive; 0: unknown

    def __post_init__(self) -> None:
        rules = {
            "window_s": (self.window_s > 0, "must be > 0 s"),
            "update_period_s": (0 < self.update_period_s <= self.window_s, "must be > 0 and <= window_s"),
            "min_window_fill": (0 < self.min_window_fill <= 1, "must lie in (0, 1]"),
            "pair_tolerance_s": (self.pair_tolerance_s >= 0, "must be >= 0 s"),
            "rate_hz": (self.rate_hz >= 0, "must be >= 0 Hz (0: from the data)"),
            "max_rate_hz": (self.max_rate_hz > 0, "must be > 0 Hz"),
            "max_gap_s": (self.max_gap_s > 0, "must be > 0 s"),
            "jump_back_s": (self.jump_back_s > 0, "must be > 0 s"),
            "silence_s": (self.silence_s > 0, "must be > 0 s"),
            "max_speed_variation": (self.max_speed_variation > 0, "must be > 0"),
            "speed_mps": (self.speed_mps >= 0, "must be >= 0 m/s (0: unknown)"),
        }
        for name, (ok, rule) in rules.items():
            value = getattr(self, name)
            if not (ok and math.isfinite(float(value))):
                raise ConfigError(f"{name}: {rule}, got {value!r}")

    def replace(self, **changes: Any) -> OnlineConfig:
        return dataclasses.replace(self, **changes)


@dataclass(frozen=True)
class Job:
    """A due update: the window's samples, snapshot when it fell due."""

    due_ns: int
    front: tuple[np.ndarray, np.ndarray]  # (stamps_ns, values)
    rear: tuple[np.ndarray, np.ndarray]
    speed: tuple[np.ndarray, np.ndarray]  # (stamps_ns, speed_mps), may be empty


@dataclass(frozen=True)
class Update:
    """The outcome of one scheduled update."""

    stamp_ns: int  # time of the window's last paired sample (or the due time)
    level: int  # OK / WARN / ERROR
    message: str
    estimate: Estimate | None = None  # None when the pipeline was not run
    window_fill: float = 0.0
    fs_hz: float = 0.0
    speed_mps: float | None = None

    @property
    def published(self) -> bool:
        """True when there is an estimate to publish."""
        return self.estimate is not None and self.estimate.ok


@dataclass(frozen=True)
class Health:
    """Diagnostic status: level, a message the user can act on, key/values."""

    level: int
    message: str
    values: dict[str, str] = field(default_factory=dict)


class _Channel:
    """Samples of one sensor: recent appends in lists, the rest in arrays."""

    def __init__(self) -> None:
        self.stamps = np.zeros(0, dtype=np.int64)
        self.values = np.zeros(0)
        self.new_stamps: list[int] = []
        self.new_values: list[float] = []
        self.last_ns: int | None = None
        self.count = 0  # samples taken in, across resets
        self.period_ns: int | None = None  # the sensor's sample period, from its first steps
        self.missing = 0  # samples missing between stamps (lost before reaching us)
        self._first_steps: list[int] = []

    def note_steps(self, steps: np.ndarray | list[int]) -> None:
        """Learn the period from the first steps between stamps, then count missing samples."""
        steps = np.asarray(steps, dtype=np.int64)
        if self.period_ns is None:
            take = _PERIOD_STEPS - len(self._first_steps)
            self._first_steps += steps[:take].tolist()
            steps = steps[take:]
            if len(self._first_steps) < _PERIOD_STEPS:
                return
            self.period_ns = int(np.median(self._first_steps))
        late = steps[steps > 1.5 * self.period_ns]
        if late.size:
            self.missing += int(np.sum(np.round(late / self.period_ns) - 1))

    def consolidate(self) -> None:
        if self.new_stamps:
            self.stamps = np.concatenate([self.stamps, np.asarray(self.new_stamps, dtype=np.int64)])
            self.values = np.concatenate([self.values, np.asarray(self.new_values, dtype=float)])
            self.new_stamps.clear()
            self.new_values.clear()

    def trim(self, keep_from_ns: int) -> None:
        self.consolidate()
        start = int(np.searchsorted(self.stamps, keep_from_ns, side="left"))
        if start:
            self.stamps = self.stamps[start:]
            self.values = self.values[start:]

    def window(self, lo_ns: int, hi_ns: int) -> tuple[np.ndarray, np.ndarray]:
        self.consolidate()
        a = int(np.searchsorted(self.stamps, lo_ns, side="right"))
        b = int(np.searchsorted(self.stamps, hi_ns, side="right"))
        return self.stamps[a:b].copy(), self.values[a:b].copy()

    def clear(self) -> None:
        """Forget the samples (a reset); the counts and the period stay."""
        kept = (self.count, self.period_ns, self.missing, self._first_steps)
        self.__init__()
        self.count, self.period_ns, self.missing, self._first_steps = kept


class OnlineEstimator:
    """Window, pairing, gap/reset logic and the update schedule for one vehicle.

    Args:
        vehicle: the known vehicle parameters.
        config: window and schedule settings.
        pipeline: settings of each update.
        names: what to call the front and rear sensor in messages (e.g. their topics).
    """

    def __init__(
        self,
        vehicle: Vehicle,
        config: OnlineConfig | None = None,
        pipeline: PipelineConfig | None = None,
        names: tuple[str, str] = ("front", "rear"),
    ) -> None:
        self.vehicle = vehicle
        self.names = names
        self.config = config or OnlineConfig()
        self.pipeline = pipeline or PipelineConfig()
        self._channels = (_Channel(), _Channel())
        self._speed = _Channel()
        self._next_due_ns: int | None = None
        self.dropped: Counter[str] = Counter()  # reason -> count, since start
        self.resets = 0
        self.events: deque[tuple[int, str]] = deque(maxlen=20)  # (level, message), newest last
        self.last_update: Update | None = None
        self._reported_losses = 0  # drops and missing samples at the last health report
        self._warm: Estimate | None = None  # the last published estimate

    # ---------------------------------------------------------------- feeding
    def add(self, channel: int, stamp_ns: int, value: float) -> None:
        """One accelerometer sample (channel 0 front, 1 rear) [ns, m/s^2]."""
        ch = self._channels[channel]
        last = ch.last_ns
        if not math.isfinite(value):
            self._drop(channel, "non-finite value")
            if last is not None and 0 < stamp_ns - last <= self.config.max_gap_s * NS:
                ch.note_steps([stamp_ns - last])  # its stamp arrived: not a missing sample
                ch.last_ns = stamp_ns
            return
        if last is not None:
            if stamp_ns == last:
                self._drop(channel, "duplicate stamp")
                return
            if stamp_ns < last:
                if last - stamp_ns > self.config.jump_back_s * NS:
                    self.reset(f"time jumped back {(last - stamp_ns) / NS:.3f} s on {self.names[channel]}")
                else:
                    self._drop(channel, "out-of-order stamp")
                    return
            elif stamp_ns - last > self.config.max_gap_s * NS:
                self.reset(f"gap of {(stamp_ns - last) / NS:.3f} s on {self.names[channel]}")
            else:
                ch.note_steps([stamp_ns - last])
        ch.last_ns = stamp_ns
        ch.new_stamps.append(stamp_ns)
        ch.new_values.append(value)
        ch.count += 1

    def add_batch(self, channels: np.ndarray, stamps_ns: np.ndarray, values: np.ndarray) -> None:
        """Many samples in arrival order; same outcome as calling :meth:`add` on each."""
        channels = np.asarray(channels)
        stamps_ns = np.asarray(stamps_ns, dtype=np.int64)
        values = np.asarray(values, dtype=float)
        per_channel = [(channels == c) for c in (0, 1)]
        if self._batch_is_clean(per_channel, stamps_ns, values):
            for c, sel in enumerate(per_channel):
                if np.any(sel):
                    ch = self._channels[c]
                    s = stamps_ns[sel]
                    ch.note_steps(np.diff(s) if ch.last_ns is None else np.diff(s, prepend=ch.last_ns))
                    ch.consolidate()
                    ch.stamps = np.concatenate([ch.stamps, stamps_ns[sel]])
                    ch.values = np.concatenate([ch.values, values[sel]])
                    ch.last_ns = int(stamps_ns[sel][-1])
                    ch.count += int(sel.sum())
            return
        for c, t, v in zip(channels.tolist(), stamps_ns.tolist(), values.tolist(), strict=True):
            self.add(c, t, v)

    def _batch_is_clean(self, per_channel: list[np.ndarray], stamps: np.ndarray, values: np.ndarray) -> bool:
        """No sample of the batch would be dropped or reset the window."""
        if not np.all(np.isfinite(values)):
            return False
        gap = self.config.max_gap_s * NS
        for c, sel in enumerate(per_channel):
            s = stamps[sel]
            if s.size == 0:
                continue
            last = self._channels[c].last_ns
            steps = np.diff(s) if last is None else np.diff(s, prepend=last)
            if steps.size and (steps.min() <= 0 or steps.max() > gap):
                return False
        return True

    def add_speed(self, stamp_ns: int, speed_mps: float) -> None:
        """A vehicle speed sample [m/s] (used when the pipeline needs the speed)."""
        if not math.isfinite(speed_mps) or speed_mps < 0:
            self._drop(2, "invalid speed")
            return
        ch = self._speed
        if ch.last_ns is not None and stamp_ns <= ch.last_ns:
            self._drop(2, "out-of-order speed stamp")
            return
        ch.last_ns = stamp_ns
        ch.new_stamps.append(stamp_ns)
        ch.new_values.append(speed_mps)

    def reset(self, reason: str) -> None:
        """Forget the window (and the schedule) after a time jump, gap or restart."""
        for ch in (*self._channels, self._speed):
            ch.clear()
        self._next_due_ns = None
        self._warm = None
        self.resets += 1
        self._event(WARN, f"window reset: {reason}")

    def _drop(self, channel: int, reason: str) -> None:
        name = ("front", "rear", "speed")[channel]
        self.dropped[f"{name}: {reason}"] += 1

    def _event(self, level: int, message: str) -> None:
        self.events.append((level, message))

    # --------------------------------------------------------------- schedule
    def take_due(self) -> list[Job]:
        """Snapshot every update that has fallen due, oldest first."""
        front, rear = self._channels
        if front.last_ns is None or rear.last_ns is None:
            return []
        period = round(self.config.update_period_s * NS)
        if self._next_due_ns is None:
            front.consolidate()
            rear.consolidate()
            start = max(int(front.stamps[0]), int(rear.stamps[0]))
            self._next_due_ns = start + period
        reached = min(front.last_ns, rear.last_ns)
        window = round(self.config.window_s * NS)
        jobs = []
        while reached >= self._next_due_ns:
            due = self._next_due_ns
            lo = due - window
            jobs.append(Job(due, front.window(lo, due), rear.window(lo, due), self._speed.window(lo, due)))
            self._next_due_ns = due + period
        if jobs:
            keep = self._next_due_ns - window
            for ch in (front, rear, self._speed):
                ch.trim(keep)
        return jobs

    def compute(self, job: Job) -> Update:
        """Run the pipeline on a due window (call in due order; any thread)."""
        update = self._compute(job)
        if update.published:
            self._warm = update.estimate  # the next window's refinement starts here
        self.last_update = update
        if update.level != OK:
            self._event(update.level, update.message)
        return update

    def process(self) -> list[Update]:
        """Take and compute every due update."""
        return [self.compute(job) for job in self.take_due()]

    def _compute(self, job: Job) -> Update:
        cfg = self.config
        names = self.names
        paired = pair_channels(job.front, job.rear, cfg)
        if isinstance(paired, str):
            return Update(job.due_ns, ERROR, paired)
        t_ns, accel, fs = paired
        fill = min(1.0, (t_ns[-1] - t_ns[0]) / NS / cfg.window_s) if t_ns.size > 1 else 0.0
        stamp = int(t_ns[-1]) if t_ns.size else job.due_ns
        if fill < cfg.min_window_fill:
            missing = [n for n, ch in zip(names, (job.front, job.rear), strict=True) if ch[0].size == 0]
            need = f"{cfg.min_window_fill * 100:.0f} % of {cfg.window_s:g} s"
            why = (
                f"waiting for {missing[0]}: no samples in the window"
                if missing
                else f"window {fill * 100:.0f} % full (need {need})"
            )
            return Update(stamp, WARN if missing else OK, why, window_fill=fill, fs_hz=fs)
        speed: float | np.ndarray | None = cfg.speed_mps or None
        if job.speed[1].size:
            s = job.speed[1]
            mean_speed = float(np.mean(s))
            if mean_speed > 0 and (s.max() - s.min()) / mean_speed > cfg.max_speed_variation:
                return Update(
                    stamp,
                    WARN,
                    f"speed varied {(s.max() - s.min()) / mean_speed * 100:.0f} % within "
                    f"the window (max {cfg.max_speed_variation * 100:.0f} %): not used",
                    window_fill=fill,
                    fs_hz=fs,
                    speed_mps=mean_speed,
                )
            # one speed per sample: the refinement models the varying wheelbase delay
            speed = np.interp(t_ns.astype(float), job.speed[0].astype(float), s)
        est = estimate(accel, fs, self.vehicle, self.pipeline, speed_mps=speed, warm_start=self._warm)
        mean_speed = None if speed is None else float(np.mean(speed))
        if not est.ok:
            return Update(stamp, WARN, f"identification failed: {est.reason}", est, fill, fs, mean_speed)
        note = "; ".join(est.notes)
        return Update(stamp, WARN if note else OK, note or "estimate published", est, fill, fs, mean_speed)

    # ---------------------------------------------------------------- health
    def health(self, silent_s: tuple[float, float] | None = None) -> Health:
        """Current status for diagnostics.

        Args:
            silent_s: seconds since each sensor's last message arrived (the node's clock);
                a sensor silent for longer than ``silence_s`` is reported. Without it (a
                replay), a sensor whose stamps lag the other's by ``silence_s`` is.
        """
        cfg = self.config
        front, rear = self._channels
        values: dict[str, str] = {}
        names = self.names
        lasts = [ch.last_ns for ch in self._channels]
        level, message = OK, "estimating"
        waiting = []
        if silent_s is not None:
            waiting = [
                (s, f"{n}: no message for {s:.1f} s")
                for n, s in zip(names, silent_s, strict=True)
                if s > cfg.silence_s
            ]
        if not waiting and None not in lasts:
            newest = max(lasts)
            waiting = [
                ((newest - t) / NS, f"{n}: {(newest - t) / NS:.1f} s behind")
                for n, t in zip(names, lasts, strict=True)
                if newest - t > cfg.silence_s * NS
            ]
        if not waiting and None in lasts:
            waiting = [
                (math.inf, f"{n}: no message yet") for n, t in zip(names, lasts, strict=True) if t is None
            ]
        if waiting:
            waiting.sort(reverse=True)
            level, message = WARN, "waiting for " + "; ".join(text for _, text in waiting)
        upd = self.last_update
        if level == OK and upd is not None and upd.level != OK:
            level, message = upd.level, upd.message
        elif level == OK and upd is not None:
            message = upd.message
        elif level == OK:
            message = "collecting the first window"
        losses = sum(self.dropped.values()) + front.missing + rear.missing
        if level == OK and losses > self._reported_losses:
            level = WARN
            message = (
                f"lost {losses - self._reported_losses} samples since the last report (see dropped/missing)"
            )
        self._reported_losses = losses
        values["window_fill_pct"] = f"{(upd.window_fill if upd else 0.0) * 100:.0f}"
        values["samples_front"] = str(front.count)
        values["samples_rear"] = str(rear.count)
        values["missing_front"] = str(front.missing)  # gaps in the stamps: lost on the way
        values["missing_rear"] = str(rear.missing)
        values["window_resets"] = str(self.resets)
        values["dropped_total"] = str(sum(self.dropped.values()))
        for reason, n in sorted(self.dropped.items()):
            values[f"dropped ({reason})"] = str(n)
        if upd is not None:
            values.update(update_values(upd))
        return Health(level, message, values)


def update_values(update: Update) -> dict[str, str]:
    """Key/values describing one update (for diagnostics and replay CSV)."""
    out = {
        "update_stamp": f"{update.stamp_ns / NS:.9f}",
        "update_status": LEVEL_NAMES[update.level],
        "sample_rate_hz": f"{update.fs_hz:.3f}",
    }
    if update.speed_mps is not None:
        out["speed_mps"] = f"{update.speed_mps:.3f}"
    est = update.estimate
    if est is None:
        return out
    out["pipeline_ms"] = f"{est.elapsed_ms:.2f}"
    out["stage"] = est.stage
    stages = [("", est)] if est.rozyn is None else [("", est), ("rozyn_", est.rozyn)]
    for prefix, stage in stages:
        if stage.ok:
            std = stage.std if stage.std is not None else np.full(3, np.nan)
            for name, value, s in zip(PARAM_NAMES, stage.params, std, strict=True):
                out[f"{prefix}{name}"] = f"{value:.6g}"
                out[f"{prefix}{name}_std"] = f"{s:.4g}"
    ref = est.refinement
    if ref is not None and ref.ok:
        out["road_waviness"] = f"{ref.waviness:.3f}"
        out["noise_std_front_mps2"] = f"{ref.noise_std_mps2[0]:.4g}"
        out["noise_std_rear_mps2"] = f"{ref.noise_std_mps2[1]:.4g}"
        out["refine_iterations"] = str(ref.iterations)
    for i, mode in enumerate(est.modes):
        out[f"mode{i + 1}_freq_hz"] = f"{mode.freq_hz:.4f}"
        out[f"mode{i + 1}_damping"] = f"{mode.damping_ratio:.4f}"
    return out


def pair_channels(
    front: tuple[np.ndarray, np.ndarray], rear: tuple[np.ndarray, np.ndarray], cfg: OnlineConfig
) -> tuple[np.ndarray, np.ndarray, float] | str:
    """Front/rear samples on one uniform grid: (stamps_ns, (n, 2) values, rate) or a reason.

    Aligned channels (the same stamps within ``pair_tolerance_s``, as from the sim) at
    most ``max_rate_hz`` fast are paired sample by sample. Otherwise both are resampled
    by linear interpolation onto a grid at ``rate_hz`` (default: the slower channel's
    rate, at most ``max_rate_hz``) over their overlap, a channel sampled faster than the
    grid first low-pass filtered below the grid's Nyquist frequency.
    """
    (tf, vf), (tr, vr) = front, rear
    if tf.size < 3 or tr.size < 3:
        return np.zeros(0, dtype=np.int64), np.zeros((0, 2)), 0.0
    dt_f, dt_r = float(np.median(np.diff(tf))), float(np.median(np.diff(tr)))
    tol = cfg.pair_tolerance_s * NS
    same_rate = abs(dt_f - dt_r) <= max(tol, 0.01 * min(dt_f, dt_r))
    slowest = NS / cfg.max_rate_hz
    if same_rate and not cfg.rate_hz and dt_f >= slowest * (1 - 1e-6):
        idx = np.clip(np.searchsorted(tr, tf), 1, tr.size - 1)
        nearest = np.where(np.abs(tr[idx - 1] - tf) <= np.abs(tr[idx] - tf), idx - 1, idx)
        match = np.abs(tr[nearest] - tf) <= tol
        if match.mean() > 0.95:
            t, a, b = tf[match], vf[match], vr[nearest[match]]
            if t.size > 2 and np.max(np.diff(t)) <= 1.5 * dt_f:
                return t, np.column_stack([a, b]), NS / dt_f
    dt = NS / cfg.rate_hz if cfg.rate_hz else max(dt_f, dt_r, slowest)
    lo, hi = max(tf[0], tr[0]), min(tf[-1], tr[-1])
    if hi - lo < 3 * dt:
        return "front and rear samples do not overlap in time"
    grid = hi - np.arange(int((hi - lo) // dt) + 1)[::-1] * dt
    grid_ns = np.round(grid).astype(np.int64)
    cols = [_resample(t, v, d, grid, dt) for t, v, d in ((tf, vf, dt_f), (tr, vr, dt_r))]
    return grid_ns, np.column_stack(cols), NS / dt


def _resample(t: np.ndarray, v: np.ndarray, dt_native: float, grid: np.ndarray, dt: float) -> np.ndarray:
    """One channel at the grid times; low-passed first if it is sampled faster than the grid."""
    if dt >= 1.5 * dt_native:
        native = np.arange(t[0], t[-1] + 0.5 * dt_native, dt_native)
        uniform = native.size == t.size and np.abs(native - t).max() < 0.01 * dt_native
        x = v if uniform else np.interp(native, t, v)  # a gap-free channel needs no interpolation
        q, first = dt / dt_native, (grid[0] - native[0]) / dt_native
        if abs(q - round(q)) < 1e-6 and abs(first - round(first)) < 0.01:
            # the grid is every q-th native sample (a 1 kHz IMU to 100 Hz): a polyphase FIR
            # computes only the samples kept, several times faster than filtering them all
            return _decimate(x, round(first), round(q), grid.size)
        sos = _lowpass(round(0.8 * dt_native / dt, 6))  # 0.8 x the grid's Nyquist
        if x.size > 3 * 2 * sos.shape[0] * 3:
            x = signal.sosfiltfilt(sos, x - x.mean()) + x.mean()
        return np.interp(grid, native, x)
    return np.interp(grid, t, v)


_FIR_HALF_OUT = 10  # the decimating FIR's half length, in output samples


def _decimate(x: np.ndarray, first: int, q: int, n: int) -> np.ndarray:
    """``n`` samples ``x[first], x[first + q], …``, low-passed (zero phase) below 0.8 x the
    output's Nyquist frequency. The filter reads samples beyond both ends where they exist
    and an odd reflection (as ``filtfilt`` pads) where they do not."""
    half = _FIR_HALF_OUT * q
    last = first + (n - 1) * q
    lo, hi = max(first - half, 0), min(last + half, x.size - 1)
    seg = x[lo: hi + 1]
    need_lo, need_hi = half - (first - lo), half - (hi - last)
    if need_lo or need_hi:
        head = 2 * seg[0] - seg[need_lo:0:-1] if need_lo else seg[:0]
        tail = 2 * seg[-1] - seg[-2:-need_hi - 2:-1] if need_hi else seg[:0]
        seg = np.concatenate([head, seg, tail])
    mean = seg.mean()
    y = signal.resample_poly(seg - mean, 1, q, window=_fir(q))
    return y[_FIR_HALF_OUT: _FIR_HALF_OUT + n] + mean


@functools.lru_cache(maxsize=8)
def _fir(q: int) -> np.ndarray:
    """Linear-phase low-pass for decimating by ``q``: passband flat to 0.6 x the output's
    Nyquist frequency (within 1 %), stop band (< 1e-3) from its Nyquist frequency."""
    return signal.firwin(2 * _FIR_HALF_OUT * q + 1, 0.8 / q, window=("kaiser", 8.0))


@functools.lru_cache(maxsize=8)
def _lowpass(cutoff: float) -> np.ndarray:
    """The anti-aliasing filter (cutoff as a share of the native Nyquist frequency); cached:
    designing it costs as much as running it on a window."""
    return signal.butter(8, cutoff, output="sos")
