"""Batches of samples for :meth:`OnlineEstimator.add_batch
<rozyn_estimator.online.estimator.OnlineEstimator.add_batch>`: whether a batch can be taken in
at once, and which of its samples made a job due (ROS-free, pure functions over arrays)."""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np

from rozyn_estimator.online.channel import Channel
from rozyn_estimator.online.records import Job


@dataclass(frozen=True)
class SpeedSamples:
    """Speed samples of a batch: stamps [ns], speeds [m/s] and arrival positions."""

    stamps_ns: np.ndarray
    values: Sequence[float]
    order: np.ndarray


def clean_batch(held: Sequence[Channel], channels: np.ndarray, stamps: np.ndarray, values: np.ndarray,
                gap_ns: float) -> bool:
    """No sample of the batch would be dropped or reset the window (the one-by-one rules).

    Args:
        held: the estimator's channels (their last stamps).
        channels, stamps, values: the batch (channel indices, stamps [ns], values).
        gap_ns: a longer step resets the window.
    """
    if not np.all(np.isfinite(values)):
        return False
    for c, ch in enumerate(held):
        s = stamps[channels == c]
        if s.size == 0:
            continue
        steps = np.diff(s) if ch.last_ns is None else np.diff(s, prepend=ch.last_ns)
        if steps.size and (steps.min() <= 0 or steps.max() > gap_ns):
            return False
    return True


def trigger_of(due_ns: int, before: Sequence[int | None], channels: np.ndarray, stamps: np.ndarray) -> int:
    """The index of the sample of a clean batch that made an update due: the last channel to
    reach ``due_ns``.

    Args:
        due_ns: the update's due time.
        before: each channel's last stamp before the batch (None: none).
        channels, stamps: the batch.
    """
    reached = []
    for c, last in enumerate(before):
        if last is not None and last >= due_ns:
            continue  # this channel was there before the batch
        idx = np.flatnonzero(channels == c)
        reached.append(int(idx[np.searchsorted(stamps[idx], due_ns)]))
    return max(reached)


def as_received(job: Job, before: list[int | None], channels: np.ndarray, stamps: np.ndarray,
                order: np.ndarray, speed: SpeedSamples | None) -> tuple[Job, int]:
    """A job of a clean batch as the node would have snapshot it: (the job without the speeds that
    arrived after the sample that made it due, that sample's position)."""
    trigger = trigger_of(job.due_ns, before, channels, stamps)
    if speed is not None:
        late = (speed.order > order[trigger]) & (speed.stamps_ns <= job.due_ns)
        if np.any(late):
            t, v = job.speed
            keep = ~np.isin(t, speed.stamps_ns[late])
            job = Job(job.due_ns, job.samples, (t[keep], v[keep]), job.epoch, job.speed_source)
    return job, trigger
