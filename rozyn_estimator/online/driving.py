"""Windows of driving: standing time neither fills a window nor pushes driving out of it.

A speed sample below the standing threshold (``OnlineConfig.driving_speed_mps``) marks the time
until the next sample as standing; the road it carries is none (its power grows with the
speed), so a window reaches back until it holds ``window_s`` of driving (:func:`driving_start`)
and its fill is its driving time (:func:`driving_time_s`). Time before a window's first speed
sample, or without a speed topic, counts as driving (a constant speed's window is as ever).
"""

from __future__ import annotations

import numpy as np

NS = 1_000_000_000


def _intervals(speed: tuple[np.ndarray, np.ndarray], lo_ns: int, hi_ns: int,
               threshold_mps: float) -> tuple[np.ndarray, np.ndarray]:
    """(the starts of [lo, hi]'s pieces, whether each is driving), the speed held from each
    sample to the next; before the first sample: driving."""
    t, v = speed
    inside = (t > lo_ns) & (t < hi_ns)
    starts = np.concatenate(([lo_ns], t[inside])).astype(np.int64)
    before = v[t <= lo_ns]
    first = bool(before[-1] >= threshold_mps) if before.size else True
    return starts, np.concatenate(([first], v[inside] >= threshold_mps))


def driving_time_s(speed: tuple[np.ndarray, np.ndarray], lo_ns: int, hi_ns: int,
                   threshold_mps: float) -> float:
    """Seconds of driving in [lo, hi]."""
    if hi_ns <= lo_ns:
        return 0.0
    starts, driving = _intervals(speed, lo_ns, hi_ns, threshold_mps)
    return float(np.sum(np.diff(np.append(starts, hi_ns))[driving])) / NS


def driving_start(speed: tuple[np.ndarray, np.ndarray], due_ns: int, window_ns: int, reach_ns: int,
                  threshold_mps: float) -> int:
    """Where the window that ends at ``due_ns`` starts so that it holds ``window_ns`` of driving;
    at most ``reach_ns`` back (then it holds less, and its fill says so)."""
    lo = due_ns - reach_ns
    starts, driving = _intervals(speed, lo, due_ns, threshold_mps)
    length = np.diff(np.append(starts, due_ns))
    held = np.cumsum((length * driving)[::-1])  # driving time from the end back to each start
    k = int(np.searchsorted(held, window_ns))
    if k >= held.size:
        return lo
    i = starts.size - 1 - k  # the piece where the window's driving is complete
    return int(starts[i] + length[i] - (window_ns - (held[k] - length[i])))


def standing(speed: tuple[np.ndarray, np.ndarray], threshold_mps: float) -> float | None:
    """The last speed sample's speed [m/s] if it is below the threshold (the vehicle stands),
    else None."""
    t, v = speed
    return float(v[-1]) if t.size and v[-1] < threshold_mps else None
