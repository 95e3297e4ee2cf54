"""How long a drive must be for 1 %: the study's shortest-drive table (in ``summary.md``).

For each road, speed and parameter, the shortest measurement time of the grid from which
on — at it and at every longer time of the grid — the estimates are both precise and
unbiased enough: two standard deviations of their spread over the roads within 1 % of the
truth (for the CoG position too: 1 % of the true l_f) and the bias of their mean within
0.5 %. Requiring every longer time as well keeps a short time that met the target by the
luck of its roads from standing in for the answer (the std falls with the time). The full
car's lateral CoG, whose truth is often 0: 1 % of the half track, and a bias within 0.5 % of it.
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np

from rozyn_estimator.tools.study.settings import StudySettings, fmt_value
from rozyn_estimator.tools.study.summary import CellSummary

TARGET_PCT = 1.0  # two std of the spread within this share of the truth [%]
TARGET_SIGMAS = 2.0
MAX_BIAS_PCT = 0.5  # |mean / truth - 1| [%]


@dataclass(frozen=True)
class ShortestDrive:
    """The shortest drive for the target at one road and speed, per parameter (the model's order)."""

    road: str
    speed_kmh: float
    duration_s: tuple[float | None, ...]  # None: not within the grid's times
    longest_s: float  # the grid's longest time with results


def meets_target(summary: CellSummary) -> np.ndarray:
    """(k,) bool: 2 × spread std ≤ 1 % of the truth (the lateral CoG: of the half track) and
    |bias| ≤ 0.5 %, per parameter.

    A cell with fewer than two estimates has no spread and meets nothing.
    """
    if summary.n - summary.failures < 2:
        return np.zeros(len(summary.truth), dtype=bool)
    with np.errstate(invalid="ignore"):
        precise = TARGET_SIGMAS * summary.std <= TARGET_PCT / 100.0 * np.abs(summary.scale)
        return np.asarray(precise & (np.abs(summary.bias_pct) <= MAX_BIAS_PCT), dtype=bool)


def shortest_drives(settings: StudySettings, summaries: Sequence[CellSummary]) -> list[ShortestDrive]:
    """The shortest drive per road and speed of the grid that has results, in grid order."""
    out = []
    for road in settings.roads:
        for speed in settings.speeds_kmh:
            cells = sorted((s.cell.duration_s, meets_target(s)) for s in summaries
                           if s.cell.road == road and s.cell.speed_kmh == speed)
            if not cells:
                continue
            durations = [d for d, _ in cells]
            met = np.array([m for _, m in cells])  # (n_durations, k)
            out.append(ShortestDrive(road, speed, tuple(_from_on(durations, column) for column in met.T),
                                     durations[-1]))
    return out


def _from_on(durations: Sequence[float], met: np.ndarray) -> float | None:
    """The first duration from which on ``met`` holds; None if it fails at the longest."""
    for j, duration in enumerate(durations):
        if met[j:].all():
            return duration
    return None


def shortest_drive_markdown(settings: StudySettings, summaries: Sequence[CellSummary]) -> list[str]:
    """The lines of ``summary.md``'s shortest-drive section."""
    symbols = [p.symbol for p in settings.car.params]
    scaled = [p.symbol for p in settings.car.params if p.of_half_track]
    lines = [
        f"## Shortest drive for {TARGET_PCT:g} % ({TARGET_SIGMAS:g}σ)", "",
        f"The shortest measurement time of the grid from which on (there and at every longer time) "
        f"{TARGET_SIGMAS:g} × the spread std ≤ {TARGET_PCT:g} % of the truth and |bias| ≤ "
        f"{MAX_BIAS_PCT:g} %; \"> T\": not within the grid's times (T the longest)."
        + (f" For {', '.join(scaled)}: of the half track." if scaled else ""), "",
        "| road | speed [km/h] | " + " | ".join(symbols) + " |",
        "|---|---|" + "---|" * len(symbols),
    ]
    for drive in shortest_drives(settings, summaries):
        times = [f"> {fmt_value(drive.longest_s)} s" if d is None else f"{fmt_value(d)} s"
                 for d in drive.duration_s]
        lines.append(f"| {drive.road} | {fmt_value(drive.speed_kmh)} | " + " | ".join(times) + " |")
    return lines
