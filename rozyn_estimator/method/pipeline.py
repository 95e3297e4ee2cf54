"""One estimator update, either car: a window of body sensors' readings in, the body's inertial
parameters out (DESIGN.md, "The pipeline"). Pure functions over arrays:

1. the window checked, demeaned (gravity removed) and its glitches gated (:mod:`.glitches`);
2. Rozyn's stage (:mod:`.modal_stage`): correlation functions (section 2-1), the state
   transition matrix's modes (2-2, 2-3), the body modes (heave, pitch and, on a car that
   rolls, roll) by their frequency and damping bands, the measured A0 (eq 2-20) and the linear
   fit of the body's parameters (2-4) — from an IMU through the corners' accelerations
   (:mod:`.imu`);
3. (``refine="likelihood"``, the default) the frequency-domain maximum-likelihood fit of the
   whole vehicle (:func:`~rozyn_estimator.method.vehicle_fit.refine.refine`) started from Rozyn's
   estimate (or the previous window's optimum), with its covariance and the tolerances'
   contributions (:class:`~rozyn_estimator.method.budget.Budget`). Rozyn's stage then skips its
   jackknife unless the refinement fails, when Rozyn's estimate is published with a note (on a
   drive at a nearly constant speed only: its method assumes one).

The half car estimates ``(m, I_yy, l_f)`` (:data:`~.config.PARAM_NAMES`), a car that rolls
``(m, I_xx, I_yy, l_f, y_c)`` (:data:`~.config.FULL_PARAM_NAMES`). A failure at any step is a
``failed`` status with a reason, never an exception and never a number.
"""

from __future__ import annotations

import dataclasses
import functools
import time
from collections.abc import Sequence
from dataclasses import dataclass
from typing import Any

import numpy as np

from rozyn_estimator.body_model import AnyVehicle
from rozyn_estimator.method.budget import Budget, Calibration, rozyn_contributions
from rozyn_estimator.method.config import FULL_PARAM_NAMES, PARAM_NAMES, PipelineConfig
from rozyn_estimator.method.drive import constant_speed_only, varying_drive, window_speed
from rozyn_estimator.method.fit import characteristic_matrix, corner_shapes
from rozyn_estimator.method.glitches import InputError, checked_window
from rozyn_estimator.method.identification import IdentificationError, Mode
from rozyn_estimator.method.imu import gyro_sign_problem, stage_input, stage_vehicle
from rozyn_estimator.method.load_transfer import carries_load_transfer, fit_without_load_transfer
from rozyn_estimator.method.modal_stage import rozyn_fit
from rozyn_estimator.method.vehicle_fit.refine import refine
from rozyn_estimator.method.vehicle_fit.result import Refinement
from rozyn_estimator.vehicle_full import CORNERS


@dataclass(frozen=True)
class Estimate:
    """Result of one update, either car. ``params``/``covariance`` are None unless status is ok.

    ``stage`` names the stage whose numbers ``params``/``covariance`` are: ``rozyn`` or
    ``likelihood`` (the refinement). When a refinement was configured, ``rozyn`` holds Rozyn's
    own estimate (its start) and ``refinement`` the fit's details; ``modes`` and ``a0`` are
    always Rozyn's. ``notes`` are what a user should look at (the online code raises them as
    diagnostics warnings): e.g. a failed refinement, or a failed Rozyn stage the refinement
    stood in for.
    """

    status: str  # "ok" | "failed"
    reason: str = ""
    params: np.ndarray | None = None  # (k,) in ``names`` order
    covariance: np.ndarray | None = None  # (k, k), same order: the budget's total where there is one
    names: tuple[str, ...] = PARAM_NAMES  # the estimated parameters: PARAM_NAMES or FULL_PARAM_NAMES
    modes: tuple[Mode, ...] = ()  # the body modes Rozyn's stage identified, by frequency
    a0: np.ndarray | None = None  # measured characteristic matrix (eq 2-20)
    sensors: tuple[str, ...] = ()  # the window's columns: the channels they were
    n_samples: int = 0
    elapsed_ms: float = 0.0
    notes: tuple[str, ...] = ()
    stage: str = "rozyn"
    rozyn: Estimate | None = None
    refinement: Refinement | None = None
    budget: Budget | None = None  # the covariance's statistical and systematic parts
    glitches: tuple[int, ...] = ()  # samples gated per channel (:mod:`.glitches`; (): not checked)

    @property
    def ok(self) -> bool:
        return self.status == "ok"

    @property
    def rozyn_stage(self) -> Estimate:
        """Rozyn's pipeline's estimate (this one when no refinement was configured)."""
        return self.rozyn if self.rozyn is not None else self

    @property
    def std(self) -> np.ndarray | None:
        return None if self.covariance is None else np.sqrt(np.diag(self.covariance))

    @property
    def statistical_covariance(self) -> np.ndarray | None:
        """The statistical part alone (the data's; the tolerances' excluded): the budget's, else
        the whole covariance."""
        return self.budget.statistical if self.budget is not None else self.covariance

    @property
    def statistical_std(self) -> np.ndarray | None:
        """The std of :attr:`statistical_covariance`."""
        cov = self.statistical_covariance
        return None if cov is None else np.sqrt(np.diag(cov))

    def to_dict(self) -> dict[str, Any]:
        """JSON-ready: the values by name (None where there is no number), the covariance with its
        labelled layout."""
        out: dict[str, Any] = {"status": self.status, "reason": self.reason, "stage": self.stage,
                               "n_samples": self.n_samples, "elapsed_ms": self.elapsed_ms,
                               "sensors": list(self.sensors), "notes": list(self.notes)}
        out.update(self._values())
        out["modes"] = [{"freq_hz": md.freq_hz, "damping_ratio": md.damping_ratio} for md in self.modes]
        if self.rozyn is not None:
            r = self.rozyn
            out["rozyn"] = {"status": r.status, "reason": r.reason, "elapsed_ms": r.elapsed_ms, **r._values()}
        if self.refinement is not None:
            out["refinement"] = self.refinement.to_dict()
        if self.budget is not None:
            out["budget"] = self.budget.to_dict()
        return out

    def _values(self) -> dict[str, Any]:
        out: dict[str, Any] = {name: None if self.params is None else float(self.params[i])
                               for i, name in enumerate(self.names)}
        out["covariance_layout"] = list(self.names)
        out["covariance"] = None if self.covariance is None else self.covariance.tolist()
        return out


def estimate(
    accel_mps2: np.ndarray,
    fs_hz: float,
    vehicle: AnyVehicle,
    config: PipelineConfig | None = None,
    speed_mps: float | np.ndarray | None = None,
    warm_start: Estimate | np.ndarray | None = None,
    sensors: Sequence[str] | None = None,
) -> Estimate:
    """Run one update on a window of body sensors' readings, either car.

    Args:
        accel_mps2: (n_samples, k) readings on a uniform grid, one column per channel: vertical
            accelerations (gravity may be included: the mean is removed) [m/s²] and, with a
            sensors block, rates [rad/s].
        fs_hz: sample rate [Hz].
        vehicle: the known suspension, tyres (anti-roll bars) and geometry, and where each
            sensor sits (its inertial values are not used).
        config: pipeline settings.
        speed_mps: vehicle speed [m/s] when known: a number, or one per sample (the refinement
            then models the varying wheelbase delay; Rozyn's stage uses the mean). Rozyn's stage
            skips the correlation lags shorter than the wheelbase delay; the refinement needs it.
        warm_start: the previous window's estimate (or its parameters): the refinement starts
            from it as well as from Rozyn's estimate, and stands in for Rozyn's if that fails.
        sensors: the channel of each column (None: the vehicle's ``channel_names``): a full car
            without a sensors block may have three of its four corners.

    Returns:
        An :class:`Estimate`; status ``failed`` with a reason when no honest number exists.
    """
    cfg, started, accel = config or PipelineConfig(), time.perf_counter(), np.asarray(accel_mps2)
    names = tuple(vehicle.channel_names if sensors is None else sensors)
    base: dict[str, Any] = {"sensors": names, "names": FULL_PARAM_NAMES if vehicle.ROLLS else PARAM_NAMES}
    try:
        index = _sensor_indices(names, vehicle)
        y, gated = checked_window(accel, fs_hz, cfg, names)
    except InputError as exc:
        return _failed(str(exc), int(accel.shape[0]) if accel.ndim >= 1 else 0, started, base)
    base["glitches"] = gated
    (speed, profile), n = window_speed(speed_mps), int(y.shape[0])
    rozyn_only = cfg.refine == "none"
    if why := gyro_sign_problem(y, fs_hz, vehicle, speed) or (rozyn_only and constant_speed_only(profile)):
        return _failed(why, n, started, base)
    if rozyn_only:
        rozyn = _rozyn_stage(y, fs_hz, vehicle, cfg, speed, index, started, base)
        return _with_budget(rozyn, vehicle, index, cfg)

    def fit(window: np.ndarray, warm: Estimate | None) -> Estimate:
        return _refined(window, fs_hz, vehicle, cfg, (speed, profile), index, warm or warm_start, started,
                        base)

    if carries_load_transfer(vehicle, profile):
        start = _warm_params(warm_start)
        return fit_without_load_transfer(y, fs_hz, vehicle, np.asarray(profile), start, fit,
                                         lambda e: e.params if e.ok else None, columns=index)
    return fit(y, None)


@functools.lru_cache(maxsize=8)
def _without_variance(cfg: PipelineConfig) -> PipelineConfig:
    """``cfg`` without Rozyn's jackknife (cached: a config's validation is not free)."""
    return cfg.replace(variance="none")


def _rozyn_stage(y: np.ndarray, fs_hz: float, vehicle: AnyVehicle, cfg: PipelineConfig,
                 speed_mps: float | None, index: tuple[int, ...], started: float,
                 base: dict[str, Any]) -> Estimate:
    """Rozyn's pipeline on the checked, demeaned window (an IMU's: :func:`.imu.stage_input`)."""
    n = int(y.shape[0])
    y, v, index = stage_input(y, fs_hz, vehicle, index)
    try:
        params, cov, modes, notes = rozyn_fit(y, fs_hz, v, cfg, speed_mps, index)
    except (InputError, IdentificationError, np.linalg.LinAlgError) as exc:
        return _failed(str(exc), n, started, base)
    return Estimate(status="ok", params=params, covariance=cov, modes=modes, a0=_a0(v, modes, index),
                    n_samples=n, elapsed_ms=(time.perf_counter() - started) * 1e3, notes=notes, **base)


def _a0(v: AnyVehicle, modes: tuple[Mode, ...], index: tuple[int, ...]) -> np.ndarray | None:
    """The measured characteristic matrix (eq 2-20) where the modes span the corners (the half
    car's two on two; a car that rolls has three modes on four corners: none)."""
    shapes = corner_shapes(v, modes, index)
    if shapes.shape[0] != shapes.shape[1]:
        return None
    return characteristic_matrix(np.array([md.eigenvalue for md in modes]), shapes)


def _failed(reason: str, n: int, started: float, base: dict[str, Any], **extra: Any) -> Estimate:
    return Estimate(status="failed", reason=reason, n_samples=n,
                    elapsed_ms=(time.perf_counter() - started) * 1e3, **base, **extra)


def _refined(
    y: np.ndarray, fs_hz: float, vehicle: AnyVehicle, cfg: PipelineConfig,
    speeds: tuple[float | None, float | np.ndarray | None], index: tuple[int, ...],
    warm_start: Estimate | np.ndarray | None, started: float, base: dict[str, Any],
) -> Estimate:
    """The likelihood refinement after Rozyn's stage, with its fallbacks.

    Rozyn's estimate starts the fit (the previous window's optimum, warm). Its jackknife
    covariance — most of its stage's time — is needed only by the fallback when the
    refinement fails: it is computed then (``Estimate.rozyn`` has no covariance otherwise).
    """
    (speed, profile), warm = speeds, _warm(warm_start)
    quick = _rozyn_stage(y, fs_hz, vehicle, _without_variance(cfg), speed, index, started, base)
    n = quick.n_samples
    start = quick.params if quick.ok else _warm_params(warm_start)
    if profile is None:
        ref = Refinement(status="failed", reason="the speed is unknown (it sets the wheelbase delay)")
    else:
        ref = refine(y, fs_hz, vehicle, index, start, profile, cfg.likelihood, warm=warm)
    jackknife = not ref.ok and cfg.variance != "none"
    rozyn = _rozyn_stage(y, fs_hz, vehicle, cfg, speed, index, started, base) if jackknife else quick
    elapsed = (time.perf_counter() - started) * 1e3
    if ref.ok:
        origin = "the previous estimate" if warm is not None else "a coarse grid"
        notes = () if rozyn.ok else (
            f"Rozyn stage failed ({rozyn.reason}); the likelihood fit started from {origin}",
        )
        if ref.model_fit is not None and not ref.model_fit.ok:
            notes = (*notes, f"model check: {ref.model_fit.verdict}")
        cal = ref.calibration
        budget = _budget(ref.covariance, ref.contributions, base["names"],
                         () if cal is None else cal.calibrations, {} if cal is None else cal.varying)
        return Estimate(
            status="ok", params=ref.params, covariance=budget.total if budget else ref.covariance,
            budget=budget, modes=rozyn.modes, a0=rozyn.a0, n_samples=n, elapsed_ms=elapsed,
            notes=notes + ref.notes, stage="likelihood", rozyn=rozyn, refinement=ref, **base,
        )
    if rozyn.ok and (why := varying_drive(ref.reason, profile)):
        return _failed(why, n, started, base, rozyn=rozyn, refinement=ref)
    if rozyn.ok:
        return dataclasses.replace(
            _with_budget(rozyn, vehicle, index, cfg), elapsed_ms=elapsed, rozyn=rozyn, refinement=ref,
            notes=(f"likelihood refinement failed ({ref.reason}); publishing the Rozyn estimate",
                   *rozyn.notes),
        )
    return _failed(f"{rozyn.reason}; likelihood refinement failed: {ref.reason}",
                   n, started, base, rozyn=rozyn, refinement=ref)


def _warm_params(warm_start: Estimate | np.ndarray | None) -> np.ndarray | None:
    """The previous window's parameters, if any."""
    if isinstance(warm_start, Estimate):
        return warm_start.params if warm_start.ok else None
    return None if warm_start is None else np.asarray(warm_start, dtype=float)


def _warm(warm_start: Estimate | np.ndarray | None) -> Refinement | None:
    """The previous window's refinement (its θ starts this one's), if usable."""
    if isinstance(warm_start, Estimate) and warm_start.refinement is not None and warm_start.refinement.ok:
        return warm_start.refinement
    return None


def _budget(statistical: np.ndarray | None, contributions: dict[str, np.ndarray], names: tuple[str, ...],
            calibration: tuple[Calibration, ...] = (),
            varying: dict[str, np.ndarray] | None = None) -> Budget | None:
    """The budget of a stage's estimate (None without a covariance or without tolerances)."""
    if statistical is None or not (contributions or calibration):
        return None
    return Budget(statistical, contributions, calibration, varying or {}, names)


def _with_budget(rozyn: Estimate, vehicle: AnyVehicle, index: tuple[int, ...],
                 cfg: PipelineConfig) -> Estimate:
    """Rozyn's estimate as published: its covariance with the tolerances' contributions (only when
    it is the published one: the refinement, when it succeeds, has its own budget), taken on the
    stage's vehicle and columns (a sensors block's: the corners')."""
    v = stage_vehicle(vehicle)
    if not (rozyn.ok and rozyn.params is not None and v.tolerances.applying(v)):
        return rozyn
    columns = index if v is vehicle else tuple(range(len(v.sensor_x_m)))
    contributions = rozyn_contributions(v, rozyn.modes, rozyn.params, cfg.stiffness_model, cfg.fit, columns)
    budget = _budget(rozyn.covariance, contributions, rozyn.names)
    return rozyn if budget is None else dataclasses.replace(rozyn, covariance=budget.total, budget=budget)


def _sensor_indices(sensors: tuple[str, ...], vehicle: AnyVehicle) -> tuple[int, ...]:
    """Each column's slot among the vehicle's sensors: all of them in order, or (a full car without
    a sensors block) three or four of its corners."""
    if sensors == vehicle.channel_names:
        return tuple(range(len(sensors)))
    got = ", ".join(sensors) or "none"
    if vehicle.ROLLS and vehicle.sensors is None:
        if any(s not in CORNERS for s in sensors) or len(set(sensors)) != len(sensors) or len(sensors) < 3:
            raise InputError(f"full car: sensors must be 3 or 4 distinct corners of {', '.join(CORNERS)}; "
                             f"got {got}")
        return tuple(CORNERS.index(s) for s in sensors)
    raise InputError(f"the vehicle's channels are {', '.join(vehicle.channel_names)}; got {got}")
