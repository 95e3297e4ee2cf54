"""Nested drives: one seeded drive as long as the longest measurement time, and the estimator
after each measurement time of it, every update warm-started from the one before — as the
online estimator updates its growing window while the vehicle drives.

``rozyn study``'s design for a refined method (each road gives the estimate after 10, 20, …
120 s of the same drive: the times' differences are not the roads', and the refinement
starts near its optimum) and ``rozyn trial --durations-s``, which repeats one of its drives.
A window is the drive's first samples, so the road is an endless one seen for that long
(not periodic over the window, as a single trial's default road is).
"""

from __future__ import annotations

import time
from collections.abc import Sequence

import numpy as np

from rozyn_estimator.errors import ConfigError
from rozyn_estimator.tools.trial.run import TrialResult, estimate_block, simulate
from rozyn_estimator.tools.trial.spec import TrialSpec


def drive_lengths(durations_s: Sequence[float], rate_hz: float) -> list[int]:
    """The windows' sample counts, in ascending order of ``durations_s`` (positive, distinct).

    Raises:
        ConfigError: no durations, or one that is not a positive number.
    """
    values = sorted(float(d) for d in durations_s)
    if not values or not all(np.isfinite(values)) or values[0] <= 0:
        raise ConfigError(f"durations: expected positive measurement times, got {list(durations_s)}")
    return [round(d * rate_hz) for d in values]


def run_drive(spec: TrialSpec, seed: int, durations_s: Sequence[float]) -> list[TrialResult]:
    """One nested drive: a result per measurement time, in ascending order (``spec.duration_s``
    is replaced by the longest)."""
    counts = drive_lengths(durations_s, spec.rate_hz)
    started = time.perf_counter()
    drive = spec.replace(duration_s=max(durations_s))
    block = simulate(drive, seed)
    sim_ms = (time.perf_counter() - started) * 1e3
    results: list[TrialResult] = []
    for n in counts:
        warm = results[-1].estimate if results else None
        results.append(TrialResult(seed, estimate_block(drive, block, warm=warm, n=n), drive.truth, sim_ms,
                                   drive.car.name))
    return results


def run_drive_args(item: tuple[TrialSpec, int, Sequence[float]]) -> list[TrialResult]:
    """:func:`run_drive` of ``(spec, seed, durations_s)`` (for a process pool)."""
    return run_drive(*item)
