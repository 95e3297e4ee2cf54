"""Window and schedule settings of the online estimator (seconds, Hz)."""

from __future__ import annotations

import dataclasses
import math
from dataclasses import dataclass
from typing import Any, ClassVar

from rozyn_estimator.method.likelihood.road_input import DRIVING_MPS
from rozyn_estimator.parameters import check, param

MIN_SPEED_MPS = 0.1  # a known speed below walking pace is a typo (1e-308), not a drive
MAX_SPEED_MPS = 150.0  # 540 km/h: above any road vehicle's; a speed topic reading more is corrupt


def speed_problem(speed_mps: float) -> str | None:
    """Why a speed sample [m/s] cannot be used (None: it can): not finite, or outside
    0..:data:`MAX_SPEED_MPS` (a corrupt speed topic read 1e9 m/s)."""
    if not math.isfinite(speed_mps):
        return "not a number"
    return None if 0.0 <= speed_mps <= MAX_SPEED_MPS else f"outside 0-{MAX_SPEED_MPS:g} m/s"


@dataclass(frozen=True)
class OnlineConfig:
    """Window and schedule settings; the estimator node's top-level parameters of the same names."""

    PARAM_PREFIX: ClassVar[str] = ""

    window_s: float = param(120.0, "sliding window of paired samples", unit="s", low=1.0, high=3600.0)
    update_period_s: float = param(5.0, "message time between updates; at most window_s", unit="s",
                                   low=0.1, high=3600.0)
    min_window_fill: float = param(0.8, "share of window_s that must hold paired data before estimating",
                                   low=0.05, high=1.0)
    pair_tolerance_s: float = param(0.002, "front and rear stamps this close are the same instant", unit="s",
                                    low=0.0, high=1.0)
    rate_hz: float = param(0.0, "rate of the paired grid; 0: the slower sensor's, at most max_rate_hz",
                           unit="Hz", low=0.0, high=100_000.0)
    max_rate_hz: float = param(100.0, "faster sensors are low-passed and decimated to this rate", unit="Hz",
                               low=1.0, high=100_000.0)
    max_gap_s: float = param(0.5, "a longer silence on a sensor resets the window", unit="s",
                             low=0.001, high=3600.0)
    jump_back_s: float = param(1.0, "a stamp this much older than the last resets the window (bag loop)",
                               unit="s", low=0.001, high=3600.0)
    silence_s: float = param(2.0, "a sensor silent this long is reported as waiting", unit="s",
                             low=0.01, high=3600.0)
    max_speed_variation: float = param(10.0, "windows whose (max - min)/driving speed exceeds this are not "
                                       "used (10: none refused; a varying drive is modelled)", low=0.001,
                                       high=10.0)
    driving_speed_mps: float = param(DRIVING_MPS, "below this speed the vehicle stands: standing time does "
                                     "not fill the window, and at a stop the last estimate is held",
                                     unit="m/s", low=0.0, high=MAX_SPEED_MPS)
    speed_mps: float = param(0.0, "vehicle speed when no speed samples arrive; 0: unknown", unit="m/s",
                             low=0.0, high=MAX_SPEED_MPS)
    speed_silence_s: float = param(2.0, "once a speed topic has spoken, a window in which it is silent this "
                                   "long is not used (its speed is unknown there)", unit="s",
                                   low=0.01, high=3600.0)

    def __post_init__(self) -> None:
        check(self, (
            ("update_period_s", lambda c: c.update_period_s <= c.window_s, "must be <= window_s"),
            ("speed_mps", lambda c: c.speed_mps == 0.0 or c.speed_mps >= MIN_SPEED_MPS,
             f"must be 0 (unknown) or at least {MIN_SPEED_MPS:g} m/s"),
        ))

    def replace(self, **changes: Any) -> OnlineConfig:
        return dataclasses.replace(self, **changes)
