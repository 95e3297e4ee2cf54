"""The samples of one sensor as the online estimator holds them (ROS-free)."""

from __future__ import annotations

from collections import deque

import numpy as np

_PERIOD_STEPS = 20  # steps between stamps that set a sensor's period
_GAPS_KEPT = 64  # recent gaps counted as missing samples, for samples that arrive late


class Channel:
    """Samples of one sensor: recent appends in lists (cheap per message), the rest in arrays.

    ``count``, ``period_ns`` and ``missing`` survive :meth:`clear` (a window reset);
    ``invalid_run`` counts the samples dropped since the last one taken in (and
    ``invalid_reason`` says why the last was), so a sensor that sends only bad samples
    is told from a silent one.
    """

    def __init__(self) -> None:
        self.count = 0  # samples taken in, across resets
        self.period_ns: int | None = None  # the sensor's sample period, from its first steps
        self.missing = 0  # samples missing between stamps (lost before reaching us)
        self.invalid_run = 0  # samples dropped since the last one taken in
        self.invalid_reason = ""
        self._first_steps: list[int] = []
        self._gaps: deque[list[int]] = deque(maxlen=_GAPS_KEPT)  # [after_ns, before_ns, still missing]
        self.clear()

    def clear(self) -> None:
        """Forget the samples (a reset); the counts and the period stay."""
        self.stamps = np.zeros(0, dtype=np.int64)
        self.values = np.zeros(0)
        self.new_stamps: list[int] = []
        self.new_values: list[float] = []
        self.last_ns: int | None = None

    def append(self, stamp_ns: int, value: float) -> None:
        self.last_ns = stamp_ns
        self.new_stamps.append(stamp_ns)
        self.new_values.append(value)
        self.count += 1
        self.invalid_run = 0

    def extend(self, stamps_ns: np.ndarray, values: np.ndarray) -> None:
        """Samples known to be in order after the last (a clean batch)."""
        self.consolidate()
        self.stamps = np.concatenate([self.stamps, stamps_ns])
        self.values = np.concatenate([self.values, values])
        self.last_ns = int(stamps_ns[-1])
        self.count += int(stamps_ns.size)
        self.invalid_run = 0

    def reject(self, reason: str, count: int = 1) -> None:
        """Note samples that were dropped (they did not reach the window)."""
        self.invalid_run += count
        self.invalid_reason = reason

    def note_steps(self, steps: np.ndarray | list[int], ends_ns: np.ndarray | list[int]) -> None:
        """Learn the period from the first steps between stamps, then count missing samples.

        Args:
            steps: steps between consecutive stamps [ns].
            ends_ns: the stamp that ends each step.
        """
        steps = np.asarray(steps, dtype=np.int64)
        ends = np.asarray(ends_ns, dtype=np.int64)
        if self.period_ns is None:
            take = _PERIOD_STEPS - len(self._first_steps)
            self._first_steps += steps[:take].tolist()
            steps, ends = steps[take:], ends[take:]
            if len(self._first_steps) < _PERIOD_STEPS:
                return
            self.period_ns = max(1, int(np.median(self._first_steps)))
        late = steps > 1.5 * self.period_ns
        if np.any(late):
            lost = np.round(steps[late] / self.period_ns).astype(np.int64) - 1
            self.missing += int(np.sum(lost))
            for end, step, k in zip(ends[late][-_GAPS_KEPT:].tolist(), steps[late][-_GAPS_KEPT:].tolist(),
                                    lost[-_GAPS_KEPT:].tolist(), strict=True):
                self._gaps.append([end - step, end, k])

    def arrived_late(self, stamp_ns: int) -> None:
        """A sample older than the last arrived: if its slot was counted missing, it is not."""
        for gap in self._gaps:
            if gap[0] < stamp_ns < gap[1] and gap[2] > 0:
                gap[2] -= 1
                self.missing -= 1
                return

    def consolidate(self) -> None:
        if self.new_stamps:
            self.stamps = np.concatenate([self.stamps, np.asarray(self.new_stamps, dtype=np.int64)])
            self.values = np.concatenate([self.values, np.asarray(self.new_values, dtype=float)])
            self.new_stamps.clear()
            self.new_values.clear()

    def first_ns(self) -> int:
        self.consolidate()
        return int(self.stamps[0])

    def oldest_ns(self) -> int | None:
        """The oldest sample held (cheap: nothing is consolidated)."""
        if self.stamps.size:
            return int(self.stamps[0])
        return self.new_stamps[0] if self.new_stamps else None

    def trim(self, keep_from_ns: int) -> None:
        """Forget the samples stamped before ``keep_from_ns``."""
        self.consolidate()
        start = int(np.searchsorted(self.stamps, keep_from_ns, side="left"))
        if start:
            self.stamps = self.stamps[start:]
            self.values = self.values[start:]

    def window(self, lo_ns: int, hi_ns: int) -> tuple[np.ndarray, np.ndarray]:
        """Copies of the samples with ``lo_ns < stamp <= hi_ns``."""
        self.consolidate()
        a = int(np.searchsorted(self.stamps, lo_ns, side="right"))
        b = int(np.searchsorted(self.stamps, hi_ns, side="right"))
        return self.stamps[a:b].copy(), self.values[a:b].copy()
