"""Rozyn's pipeline on the full car: three or four corner accelerometers in, ``(m, I_xx, I_yy,
l_f, y_c)`` and their jackknife covariance out.

The half car's steps (:mod:`rozyn_estimator.method.pipeline`) on more channels: the
multi-reference correlation functions of every channel pair (section 2-1), the state
transition matrix's modes (2-2, 2-3), the three body modes (heave, pitch, roll) by the
frequency and damping bands and their amplitude, the linear fit of
:mod:`rozyn_estimator.method.full.corner_matrices`, the delete-one-block jackknife, and the tolerances'
contributions (:func:`rozyn_estimator.method.budget.rozyn_contributions`): the published covariance is the
jackknife's plus theirs.

With ``refine="likelihood"`` (the pipeline's default) the likelihood refinement of the full
car follows (:mod:`rozyn_estimator.method.full.refine`), started from Rozyn's estimate (or
the previous window's optimum), and its estimate is published: the inverse Fisher
information plus the tolerances' contributions to it. Rozyn's stage then skips its
jackknife unless the refinement fails, when Rozyn's estimate is published with a note.

A failure at any step is a ``failed`` status with a reason, never an exception and never a
number.
"""

from __future__ import annotations

import dataclasses
import time
from collections.abc import Sequence
from dataclasses import dataclass
from typing import Any

import numpy as np

from rozyn_estimator.method.budget import FullBudget, rozyn_contributions
from rozyn_estimator.method.config import FULL_PARAM_NAMES, PipelineConfig
from rozyn_estimator.method.drive import constant_speed_only, varying_drive, window_speed
from rozyn_estimator.method.full.refine import Refinement, refine
from rozyn_estimator.method.glitches import InputError, checked_window
from rozyn_estimator.method.identification import IdentificationError, Mode
from rozyn_estimator.method.imu import gyro_sign_problem, stage_input
from rozyn_estimator.method.load_transfer import carries_load_transfer, fit_without_load_transfer
from rozyn_estimator.method.modal_stage import rozyn_fit
from rozyn_estimator.vehicle_full import CORNERS, FullVehicle


@dataclass(frozen=True)
class FullEstimate:
    """One full-car update. ``params``/``covariance`` are None unless status is ok."""

    status: str  # "ok" | "failed"
    reason: str = ""
    params: np.ndarray | None = None  # (5,) in FULL_PARAM_NAMES order
    covariance: np.ndarray | None = None  # (5, 5), same order: the budget's total
    modes: tuple[Mode, ...] = ()  # heave, pitch and roll, by frequency
    sensors: tuple[str, ...] = ()  # the corners whose accelerometers the columns were
    n_samples: int = 0
    elapsed_ms: float = 0.0
    notes: tuple[str, ...] = ()
    budget: FullBudget | None = None  # the covariance's statistical and systematic parts
    stage: str = "rozyn"  # whose estimate this is: "rozyn" or "likelihood"
    rozyn: FullEstimate | None = None  # with a refinement: Rozyn's own estimate (its start)
    refinement: Refinement | None = None  # the likelihood refinement, when one ran
    glitches: tuple[int, ...] | None = None  # samples gated as glitches per channel (None: not checked)

    @property
    def ok(self) -> bool:
        return self.status == "ok"

    @property
    def std(self) -> np.ndarray | None:
        return None if self.covariance is None else np.sqrt(np.diag(self.covariance))

    def to_dict(self) -> dict[str, Any]:
        """JSON-ready: the values by name, the covariance with its labelled layout."""
        out: dict[str, Any] = {"status": self.status, "reason": self.reason, "stage": self.stage,
                               "n_samples": self.n_samples, "elapsed_ms": self.elapsed_ms,
                               "sensors": list(self.sensors), "notes": list(self.notes)}
        for i, name in enumerate(FULL_PARAM_NAMES):
            out[name] = None if self.params is None else float(self.params[i])
        out["covariance_layout"] = list(FULL_PARAM_NAMES)
        out["covariance"] = None if self.covariance is None else self.covariance.tolist()
        out["modes"] = [{"freq_hz": md.freq_hz, "damping_ratio": md.damping_ratio} for md in self.modes]
        if self.budget is not None:
            out["budget"] = self.budget.to_dict()
        if self.refinement is not None:
            out["refinement"] = self.refinement.to_dict()
        if self.rozyn is not None:
            out["rozyn"] = {name: None if self.rozyn.params is None else float(self.rozyn.params[i])
                            for i, name in enumerate(FULL_PARAM_NAMES)}
        return out


def estimate_full(
    accel_mps2: np.ndarray,
    fs_hz: float,
    vehicle: FullVehicle,
    config: PipelineConfig | None = None,
    speed_mps: float | np.ndarray | None = None,
    sensors: Sequence[str] | None = None,
    warm: FullEstimate | None = None,
) -> FullEstimate:
    """Rozyn's stage of the full car on one window.

    Args:
        accel_mps2: (n_samples, k) vertical accelerations of ``k`` = 3 or 4 body points on a
            uniform grid (gravity may be included: the mean is removed).
        fs_hz: sample rate [Hz].
        vehicle: the known suspension, tyres, anti-roll bars and geometry, and where each
            accelerometer sits (its inertial values are not used).
        config: the pipeline's settings (bands, lags, stiffness model, jackknife).
        speed_mps: the vehicle's speed [m/s] when known, a number or one per sample: the
            correlation lags shorter than the wheelbase delay are skipped (the rear wheels
            repeat the front ones' road); the refinement needs it.
        sensors: the channel of each column: the corner (``front_left`` …) of its
            accelerometer, or a sensors block's channels (all, in order; None: the vehicle's).
        warm: the previous window's estimate (the refinement's warm start; unused by
            Rozyn's stage).
    """
    cfg = config or PipelineConfig()
    sensors = vehicle.channel_names if sensors is None else sensors
    if cfg.refine == "likelihood":
        return _refined(accel_mps2, fs_hz, vehicle, cfg, speed_mps, sensors, warm)
    started = time.perf_counter()
    accel = np.asarray(accel_mps2)
    try:
        index = _sensor_indices(sensors, vehicle)
        y, gated = checked_window(accel, fs_hz, cfg, tuple(sensors))
    except InputError as exc:
        return FullEstimate(status="failed", reason=str(exc), sensors=tuple(sensors),
                            n_samples=int(accel.shape[0]) if accel.ndim else 0,
                            elapsed_ms=(time.perf_counter() - started) * 1e3)
    if why := constant_speed_only(speed_mps) or \
            gyro_sign_problem(y, fs_hz, vehicle, window_speed(speed_mps)[0]):
        return FullEstimate(status="failed", reason=why, sensors=tuple(sensors), n_samples=int(y.shape[0]),
                            elapsed_ms=(time.perf_counter() - started) * 1e3)
    return dataclasses.replace(_rozyn_stage(y, fs_hz, vehicle, cfg, speed_mps, sensors, index, started),
                               glitches=gated)


def _rozyn_stage(y: np.ndarray, fs_hz: float, vehicle: FullVehicle, cfg: PipelineConfig,
                 speed_mps: float | np.ndarray | None, sensors: Sequence[str], index: tuple[int, ...],
                 started: float) -> FullEstimate:
    """Rozyn's stage on the checked, demeaned window ``y`` (:func:`checked_window`)."""
    n = int(y.shape[0])
    y, vehicle, index = stage_input(y, fs_hz, vehicle, index)  # a sensors block's: the corners'
    try:
        params, cov, modes, notes = rozyn_fit(y, fs_hz, vehicle, cfg, window_speed(speed_mps)[0], index)
    except (InputError, IdentificationError, np.linalg.LinAlgError) as exc:
        return FullEstimate(status="failed", reason=str(exc), n_samples=n, sensors=tuple(sensors),
                            elapsed_ms=(time.perf_counter() - started) * 1e3)
    budget = None
    if cov is not None and vehicle.tolerances.any:
        contributions = rozyn_contributions(vehicle, modes, params, cfg.stiffness_model, sensors=index)
        budget = FullBudget(cov, contributions)
        cov = budget.total
    return FullEstimate(status="ok", params=params, covariance=cov, modes=modes, sensors=tuple(sensors),
                        n_samples=n, elapsed_ms=(time.perf_counter() - started) * 1e3, notes=notes,
                        budget=budget)


def _refined(
    accel_mps2: np.ndarray, fs_hz: float, vehicle: FullVehicle, cfg: PipelineConfig,
    speed_mps: float | np.ndarray | None, sensors: Sequence[str], warm: FullEstimate | None,
) -> FullEstimate:
    """Rozyn's stage (without its jackknife) as the start, the refinement, its budget; Rozyn's
    full stage with a note when the refinement fails."""
    started = time.perf_counter()
    try:
        index = _sensor_indices(sensors, vehicle)
        y, gated = checked_window(np.asarray(accel_mps2), fs_hz, cfg, tuple(sensors))
    except InputError as exc:  # bad input: neither stage can use it
        return FullEstimate(status="failed", reason=str(exc), sensors=tuple(sensors),
                            n_samples=int(np.shape(accel_mps2)[0]) if np.ndim(accel_mps2) else 0,
                            elapsed_ms=(time.perf_counter() - started) * 1e3)
    if why := gyro_sign_problem(y, fs_hz, vehicle, window_speed(speed_mps)[0]):
        return FullEstimate(status="failed", reason=why, sensors=tuple(sensors), n_samples=int(y.shape[0]),
                            elapsed_ms=(time.perf_counter() - started) * 1e3)
    warm_ref = warm.refinement if warm is not None else None

    def fit(window: np.ndarray, again: FullEstimate | None) -> FullEstimate:
        return _refine_window(window, gated, fs_hz, vehicle, cfg, speed_mps, sensors, index,
                              again.refinement if again is not None else warm_ref, started)

    if carries_load_transfer(vehicle, speed_mps):
        start = warm.params if warm is not None and warm.ok else None
        return fit_without_load_transfer(y, fs_hz, vehicle, np.asarray(speed_mps), start, fit,
                                         lambda e: e.params if e.ok else None, columns=index)
    return fit(y, None)


def _refine_window(y: np.ndarray, gated: tuple[int, ...], fs_hz: float, vehicle: FullVehicle,
                   cfg: PipelineConfig, speed_mps: float | np.ndarray | None, sensors: Sequence[str],
                   index: tuple[int, ...], warm: Refinement | None, started: float) -> FullEstimate:
    """:func:`_refined`'s stages on the checked window ``y``."""
    rozyn_cfg = dataclasses.replace(cfg, refine="none")
    quick_cfg = dataclasses.replace(rozyn_cfg, variance="none")
    quick = _rozyn_stage(y, fs_hz, vehicle, quick_cfg, speed_mps, sensors, index, time.perf_counter())
    ref = refine(y, fs_hz, vehicle, index, quick.params, 0.0 if speed_mps is None else speed_mps,
                      cfg.likelihood, warm=warm)
    if ref.ok and ref.params is not None and ref.covariance is not None:
        cal = ref.calibration
        budget = None if not vehicle.tolerances.any else \
            FullBudget(ref.covariance, ref.contributions, () if cal is None else cal.calibrations,
                       {} if cal is None else cal.varying)
        fit = ref.model_fit
        check = () if fit is None or fit.ok else (f"model check: {fit.verdict}",)
        return FullEstimate(status="ok", params=ref.params,
                            covariance=ref.covariance if budget is None else budget.total, modes=quick.modes,
                            sensors=tuple(sensors), n_samples=quick.n_samples,
                            notes=check + ref.notes + quick.notes,
                            budget=budget, stage="likelihood", rozyn=quick, refinement=ref, glitches=gated,
                            elapsed_ms=(time.perf_counter() - started) * 1e3)
    if why := varying_drive(ref.reason, speed_mps):
        return FullEstimate(status="failed", reason=why,
                            sensors=tuple(sensors), n_samples=quick.n_samples, rozyn=quick, refinement=ref,
                            glitches=gated, elapsed_ms=(time.perf_counter() - started) * 1e3)
    rozyn = _rozyn_stage(y, fs_hz, vehicle, rozyn_cfg, speed_mps, sensors, index, time.perf_counter())
    note = f"likelihood refinement failed ({ref.reason}); publishing the Rozyn estimate"
    return dataclasses.replace(rozyn, rozyn=quick, refinement=ref, notes=(note, *rozyn.notes), glitches=gated,
                               elapsed_ms=(time.perf_counter() - started) * 1e3)




def _sensor_indices(sensors: Sequence[str], vehicle: FullVehicle) -> tuple[int, ...]:
    if vehicle.sensors is not None:  # a block's channels, all of them in order
        if tuple(sensors) != vehicle.channel_names:
            names, got = ", ".join(vehicle.channel_names), ", ".join(sensors) or "none"
            raise InputError(f"full car: the sensors block's channels are {names}; got {got}")
        return tuple(range(len(sensors)))
    unknown = [s for s in sensors if s not in CORNERS]
    if unknown or len(set(sensors)) != len(sensors) or len(sensors) not in (3, 4):
        raise InputError(f"full car: sensors must be 3 or 4 distinct corners of {', '.join(CORNERS)}; "
                          f"got {', '.join(sensors) or 'none'}")
    return tuple(CORNERS.index(s) for s in sensors)
