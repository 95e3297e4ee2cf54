"""What the online estimator hands out: due jobs, updates, diagnostic statuses (ROS-free).

A :class:`Layout` says what one vehicle model's updates hold: the half car's front and
rear channels and (m, I_yy, l_f), or the full car's three or four corners and
(m, I_xx, I_yy, l_f, y_c).
"""

from __future__ import annotations

import dataclasses
from collections.abc import Sequence
from dataclasses import dataclass, field
from enum import IntEnum
from typing import Any

import numpy as np

from rozyn_estimator.errors import ConfigError
from rozyn_estimator.method import PARAM_NAMES, Estimate
from rozyn_estimator.method.config import FULL_PARAM_NAMES
from rozyn_estimator.method.information import describe
from rozyn_estimator.sensors import unit_suffix
from rozyn_estimator.vehicle import Vehicle
from rozyn_estimator.vehicle_full import CORNERS, FullVehicle

NS = 1_000_000_000
HALF_CHANNELS = ("front", "rear")


@dataclass(frozen=True)
class Layout:
    """What the updates of one vehicle model hold.

    Attributes:
        params: the estimated parameters, in the order of an estimate and its covariance.
        channels: the sensors' channels, in the order of the online estimator's: ``front``,
            ``rear`` (half car; a sensors block's labels, ``imu.accel_z``, ``imu.gyro_y``) or
            three or four of :data:`CORNERS` (full car).
        modes: the body modes an update identifies.
        positive: the first ``positive`` parameters must be > 0 to publish (the full car's
            lateral CoG may have either sign).
    """

    params: tuple[str, ...]
    channels: tuple[str, ...]
    modes: int
    positive: int

    @property
    def full(self) -> bool:
        """The full car's layout."""
        return self.params == FULL_PARAM_NAMES


HALF_LAYOUT = Layout(PARAM_NAMES, HALF_CHANNELS, modes=2, positive=3)


def layout_of(vehicle: Vehicle | FullVehicle, channels: Sequence[str] | None = None) -> Layout:
    """The layout of a vehicle's updates.

    Args:
        vehicle: the half car or the full car.
        channels: the full car's corners with an accelerometer (default: all four, in
            :data:`CORNERS` order); the half car's are always front and rear.

    Raises:
        ConfigError: channels that are not front and rear for a half car, or not three or
            four distinct corners for a full car.
    """
    if not isinstance(vehicle, FullVehicle):
        names = vehicle.channel_names  # front and rear, or a sensors block's (imu.accel_z, imu.gyro_y)
        if channels is not None and tuple(channels) != names:
            raise ConfigError(f"a half car's channels are {' and '.join(names)}, got {', '.join(channels)}")
        return HALF_LAYOUT if names == HALF_CHANNELS else dataclasses.replace(HALF_LAYOUT, channels=names)
    if vehicle.sensors is not None:  # a sensors block: its channels, all of them
        labels = vehicle.channel_names
        if channels is not None and tuple(channels) != labels:
            raise ConfigError(f"this full car's channels are {', '.join(labels)}, got {', '.join(channels)}")
        return Layout(FULL_PARAM_NAMES, labels, modes=3, positive=4)
    corners = CORNERS if channels is None else tuple(channels)
    if len(corners) not in (3, 4) or len(set(corners)) != len(corners) or not set(corners) <= set(CORNERS):
        raise ConfigError(f"a full car needs three or four distinct corners of {', '.join(CORNERS)}, got "
                          f"{', '.join(corners) or 'none'}")
    return Layout(FULL_PARAM_NAMES, corners, modes=3, positive=4)


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
    samples: tuple[tuple[np.ndarray, np.ndarray], ...]  # per channel (stamps_ns, values)
    speed: tuple[np.ndarray, np.ndarray]  # (stamps_ns, speed_mps), may be empty
    epoch: int = 0  # the window's generation: a reset since makes the job stale
    speed_source: bool = False  # a speed topic has spoken (its silence in the window is then a fault)

    @property
    def front(self) -> tuple[np.ndarray, np.ndarray]:
        """The first channel's samples (the half car's front sensor)."""
        return self.samples[0]

    @property
    def rear(self) -> tuple[np.ndarray, np.ndarray]:
        """The second channel's samples (the half car's rear sensor)."""
        return self.samples[1]


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
    held: bool = False  # at a stop: the last estimate, republished
    fused_windows: int = 0  # disjoint windows the estimate fuses since the last load change (0: none)
    load_changes: int = 0  # load changes found at stops so far

    @property
    def published(self) -> bool:
        """True when there is an estimate to publish."""
        return self.estimate is not None and self.estimate.ok

    @property
    def params(self) -> np.ndarray | None:
        """(3,) the half car's estimate to publish (``PARAM_NAMES`` order), (5,) the full car's
        (``FULL_PARAM_NAMES``); None when there is none."""
        return self.estimate.params if self.estimate is not None and self.estimate.ok else None

    @property
    def covariance(self) -> np.ndarray | None:
        """(3, 3) or (5, 5) its covariance, None when there is none."""
        return self.estimate.covariance if self.estimate is not None and self.estimate.ok else None


@dataclass(frozen=True)
class Health:
    """Diagnostic status: level, a message the user can act on, key/values."""

    level: Level
    message: str
    values: dict[str, str] = field(default_factory=dict)


def update_values(update: Update, layout: Layout = HALF_LAYOUT) -> dict[str, str]:
    """Key/values describing one update (for diagnostics and replay CSV).

    Args:
        update: the update.
        layout: its vehicle model's (names the parameters and the channels).
    """
    out = {
        "update_stamp": f"{update.stamp_ns / NS:.9f}",
        "update_status": LEVEL_NAMES[update.level],
        "sample_rate_hz": f"{update.fs_hz:.3f}",
    }
    if update.speed_mps is not None:
        out["speed_mps"] = f"{update.speed_mps:.3f}"
    if update.held:
        out["held"] = "true"
    if update.fused_windows:
        out["fused_windows"] = str(update.fused_windows)
        out["load_changes"] = str(update.load_changes)
    est = update.estimate
    if est is None:
        return out
    out["pipeline_ms"] = f"{est.elapsed_ms:.2f}"
    out["stage"] = est.stage
    if est.glitches:  # gated in the window (none: the window was not checked)
        out |= {f"glitches_{c}": str(n) for c, n in zip(layout.channels, est.glitches, strict=True)}
    stages = [("", est)] if est.rozyn is None else [("", est), ("rozyn_", est.rozyn)]
    for prefix, stage in stages:
        if stage.ok and stage.params is not None:
            std = stage.std if stage.std is not None else np.full(len(layout.params), np.nan)
            for name, value, s in zip(layout.params, stage.params, std, strict=True):
                out[f"{prefix}{name}"] = f"{value:.6g}"
                out[f"{prefix}{name}_std"] = f"{s:.4g}"
    budget = est.budget
    if budget is not None:  # the published std's statistical and systematic parts, largest contributors
        stat, sys = np.sqrt(np.diag(budget.statistical)), np.sqrt(np.diag(budget.systematic))
        for i, name in enumerate(layout.params):
            out[f"{name}_std_statistical"] = f"{stat[i]:.4g}"
            out[f"{name}_std_systematic"] = f"{sys[i]:.4g}"
            out[f"{name}_budget"] = budget.text(i)
        for c in budget.calibration:
            out[f"calibrated {c.name}"] = c.text()
    out |= _refinement_values(est.refinement, layout)
    for i, mode in enumerate(est.modes):
        out[f"mode{i + 1}_freq_hz"] = f"{mode.freq_hz:.4f}"
        out[f"mode{i + 1}_damping"] = f"{mode.damping_ratio:.4f}"
    return out


def _refinement_values(ref: Any, layout: Layout) -> dict[str, str]:
    """The refinement's model-fit check, fitted waviness, sensor noise, each channel's share of
    the information (:mod:`rozyn_estimator.method.information`) and iterations (the half car's
    refinement has them all; the full car's what it has)."""
    channels = layout.channels
    out = {}
    fit = getattr(ref, "model_fit", None)
    if fit is not None:
        out["model_fit_p"] = f"{fit.p_value:.3g}"
        out["model_fit"] = fit.verdict
    if ref is not None and ref.ok:
        out["road_waviness"] = f"{ref.waviness:.3f}"
        for c, noise in zip(channels, ref.noise_std_mps2, strict=False):
            out[f"noise_std_{c}_{unit_suffix(c)}"] = f"{noise:.4g}"  # a gyro's in rad/s
        for c, lost in zip(channels, getattr(ref, "information_lost", ()), strict=False):
            out[f"information_lost_without_{c}"] = describe(lost, layout.params)
        out["refine_iterations"] = str(ref.iterations)
    return out
