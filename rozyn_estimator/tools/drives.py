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

import dataclasses
import time
from collections.abc import Callable, Sequence
from typing import Any, TypeVar

import numpy as np

from rozyn_estimator.errors import ConfigError
from rozyn_estimator.method import estimate
from rozyn_estimator.method.full import estimate_full
from rozyn_estimator.tools.trial import TrialResult, TrialSpec, simulate
from rozyn_estimator.tools.trial_full import FullTrialResult, FullTrialSpec, simulate_full

E = TypeVar("E")


def drive_lengths(durations_s: Sequence[float], rate_hz: float) -> list[int]:
    """The windows' sample counts, in ascending order of ``durations_s`` (positive, distinct).

    Raises:
        ConfigError: no durations, or one that is not a positive number.
    """
    values = sorted(float(d) for d in durations_s)
    if not values or not all(np.isfinite(values)) or values[0] <= 0:
        raise ConfigError(f"durations: expected positive measurement times, got {list(durations_s)}")
    return [round(d * rate_hz) for d in values]


def _windows(accel: np.ndarray, speed: np.ndarray, counts: Sequence[int],
             estimate_window: Callable[[np.ndarray, np.ndarray, E | None], E]) -> list[E]:
    """``estimate_window(first n samples, their speeds, the previous estimate)`` for each count."""
    out: list[E] = []
    for n in counts:
        previous = out[-1] if out else None
        out.append(estimate_window(accel[:n], speed[:n] if np.ndim(speed) else speed, previous))
    return out


def run_drive(spec: TrialSpec, seed: int, durations_s: Sequence[float]) -> list[TrialResult]:
    """The half car's nested drive: one result per measurement time, in ascending order
    (``spec.duration_s`` is replaced by the longest)."""
    counts = drive_lengths(durations_s, spec.rate_hz)
    started = time.perf_counter()
    drive = spec.replace(duration_s=max(durations_s))
    block = simulate(drive, seed)
    sim_ms = (time.perf_counter() - started) * 1e3
    vehicle, cfg = drive.estimator_vehicle, drive.pipeline_config()
    estimates = _windows(block.accel_mps2, block.speed_mps, counts,
                         lambda y, v, previous: estimate(y, drive.rate_hz, vehicle, cfg, speed_mps=v,
                                                         warm_start=previous))
    return [TrialResult(seed=seed, estimate=e, truth=drive.truth, sim_ms=sim_ms) for e in estimates]


def run_full_drive(spec: FullTrialSpec, seed: int, durations_s: Sequence[float]) -> list[FullTrialResult]:
    """The full car's nested drive (as :func:`run_drive`)."""
    counts = drive_lengths(durations_s, spec.sim.rate_hz)
    drive = dataclasses.replace(spec, sim=dataclasses.replace(spec.sim, duration_s=max(durations_s)))
    accel, speed, channels, sim_ms = simulate_full(drive, seed)
    cfg = drive.pipeline_config()
    estimates = _windows(accel, speed, counts,
                         lambda y, v, previous: estimate_full(y, drive.sim.rate_hz, drive.vehicle, cfg, v,
                                                              sensors=channels, warm=previous))
    return [FullTrialResult(seed, e, drive.truth, sim_ms) for e in estimates]


def run_any_drive(item: tuple[TrialSpec | FullTrialSpec, int, Sequence[float]]) -> list[Any]:
    """:func:`run_drive` or :func:`run_full_drive` of ``(spec, seed, durations_s)`` (for a process pool)."""
    spec, seed, durations_s = item
    if isinstance(spec, FullTrialSpec):
        return list(run_full_drive(spec, seed, durations_s))
    return list(run_drive(spec, seed, durations_s))
