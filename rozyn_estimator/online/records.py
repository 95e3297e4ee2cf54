"""What the online estimator hands out: due jobs, updates, diagnostic statuses (ROS-free)."""

from __future__ import annotations

from dataclasses import dataclass, field
from enum import IntEnum

import numpy as np

from rozyn_estimator.method import PARAM_NAMES, Estimate

NS = 1_000_000_000


class Level(IntEnum):
    """Diagnostic levels, as ``diagnostic_msgs/DiagnosticStatus`` numbers them."""

    OK = 0
    WARN = 1
    ERROR = 2
    STALE = 3


OK, WARN, ERROR, STALE = Level.OK, Level.WARN, Level.ERROR, Level.STALE
LEVEL_NAMES = tuple(level.name for level in Level)


@dataclass(frozen=True)
class Job:
    """A due update: the window's samples, snapshot when it fell due."""

    due_ns: int
    front: tuple[np.ndarray, np.ndarray]  # (stamps_ns, values)
    rear: tuple[np.ndarray, np.ndarray]
    speed: tuple[np.ndarray, np.ndarray]  # (stamps_ns, speed_mps), may be empty
    epoch: int = 0  # the window's generation: a reset since makes the job stale


@dataclass(frozen=True)
class Update:
    """The outcome of one scheduled update."""

    stamp_ns: int  # time of the window's last paired sample (or the due time)
    level: Level
    message: str
    estimate: Estimate | None = None  # None when the pipeline was not run
    window_fill: float = 0.0
    fs_hz: float = 0.0
    speed_mps: float | None = None

    @property
    def published(self) -> bool:
        """True when there is an estimate to publish."""
        return self.estimate is not None and self.estimate.ok

    @property
    def params(self) -> np.ndarray | None:
        """(3,) the estimate to publish (``PARAM_NAMES`` order), None when there is none."""
        return self.estimate.params if self.estimate is not None and self.estimate.ok else None

    @property
    def covariance(self) -> np.ndarray | None:
        """(3, 3) its covariance, None when there is none."""
        return self.estimate.covariance if self.estimate is not None and self.estimate.ok else None


@dataclass(frozen=True)
class Health:
    """Diagnostic status: level, a message the user can act on, key/values."""

    level: Level
    message: str
    values: dict[str, str] = field(default_factory=dict)


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
    out["glitches_front"], out["glitches_rear"] = (str(n) for n in est.glitches)  # gated in the window
    stages = [("", est)] if est.rozyn is None else [("", est), ("rozyn_", est.rozyn)]
    for prefix, stage in stages:
        if stage.ok and stage.params is not None:
            std = stage.std if stage.std is not None else np.full(3, np.nan)
            for name, value, s in zip(PARAM_NAMES, stage.params, std, strict=True):
                out[f"{prefix}{name}"] = f"{value:.6g}"
                out[f"{prefix}{name}_std"] = f"{s:.4g}"
    budget = est.budget
    if budget is not None:  # the published std's statistical and systematic parts, largest contributors
        stat, sys = np.sqrt(np.diag(budget.statistical)), np.sqrt(np.diag(budget.systematic))
        for i, name in enumerate(PARAM_NAMES):
            out[f"{name}_std_statistical"] = f"{stat[i]:.4g}"
            out[f"{name}_std_systematic"] = f"{sys[i]:.4g}"
            out[f"{name}_budget"] = budget.text(i)
        for c in budget.calibration:
            out[f"calibrated {c.name}"] = c.text()
    ref = est.refinement
    if ref is not None and ref.model_fit is not None:
        out["model_fit_p"] = f"{ref.model_fit.p_value:.3g}"
        out["model_fit"] = ref.model_fit.verdict
    if ref is not None and ref.ok:
        out["road_waviness"] = f"{ref.waviness:.3f}"
        out["noise_std_front_mps2"] = f"{ref.noise_std_mps2[0]:.4g}"
        out["noise_std_rear_mps2"] = f"{ref.noise_std_mps2[1]:.4g}"
        out["refine_iterations"] = str(ref.iterations)
    for i, mode in enumerate(est.modes):
        out[f"mode{i + 1}_freq_hz"] = f"{mode.freq_hz:.4f}"
        out[f"mode{i + 1}_damping"] = f"{mode.damping_ratio:.4f}"
    return out
