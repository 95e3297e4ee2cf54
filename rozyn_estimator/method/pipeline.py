"""One estimator update: accelerations of one window in, inertial parameters out.

Pure functions over arrays (DESIGN.md, "The pipeline"):

1. demean (removes gravity), correlation functions (section 2-1);
2. state transition matrix and its modes (2-2, 2-3);
3. the two body modes (frequency and damping bands, modal amplitude);
4. measured A0 (eq 2-20) and a least-squares fit of m_s, I_yy, l_f (2-4);
5. a covariance from the delete-one-block jackknife;
6. (``refine="likelihood"``, the default) a frequency-domain maximum-likelihood fit of
   the whole half car started from that estimate (``likelihood.py``), with the Fisher
   covariance. Rozyn's estimate stays on the result (``Estimate.rozyn``); if the
   refinement fails, Rozyn's estimate is published with a warning.

A failure at any step is a ``failed`` status with a reason, never an exception and
never a number.
"""

from __future__ import annotations

import dataclasses
import functools
import time
from dataclasses import dataclass, field
from typing import Any

import numpy as np

from rozyn_estimator.method.budget import Budget, Calibration, rozyn_contributions
from rozyn_estimator.method.config import PARAM_NAMES, PipelineConfig
from rozyn_estimator.method.drive import constant_speed_only, varying_drive, window_speed
from rozyn_estimator.method.fit import characteristic_matrix, corner_shapes
from rozyn_estimator.method.full.refine import refine
from rozyn_estimator.method.full.result import Refinement
from rozyn_estimator.method.glitches import InputError, checked_window
from rozyn_estimator.method.identification import IdentificationError, Mode
from rozyn_estimator.method.imu import gyro_sign_problem, stage_input, stage_vehicle
from rozyn_estimator.method.load_transfer import carries_load_transfer, fit_without_load_transfer
from rozyn_estimator.method.modal_stage import rozyn_fit
from rozyn_estimator.vehicle import Vehicle


@dataclass(frozen=True)
class Estimate:
    """Result of one update. ``params``/``covariance`` are None unless status is ok.

    ``stage`` names the stage whose numbers ``params``/``covariance`` are: ``rozyn``
    (Rozyn's pipeline) or ``likelihood`` (the refinement). When a refinement was
    configured, ``rozyn`` holds Rozyn's own estimate (its start) and ``refinement`` the
    fit's details (nuisance parameters, ℓ, iterations); ``modes`` and ``a0`` are always
    Rozyn's. ``notes`` are what a user should look at (the online code raises them as
    diagnostics warnings): e.g. a failed refinement (Rozyn's estimate is then published),
    or a failed Rozyn stage that the refinement stood in for.
    """

    status: str  # "ok" | "failed"
    reason: str = ""
    params: np.ndarray | None = None  # (3,) in PARAM_NAMES order
    covariance: np.ndarray | None = None  # (3, 3), same order
    modes: tuple[Mode, ...] = ()
    a0: np.ndarray | None = None  # measured characteristic matrix (eq 2-20)
    n_samples: int = 0
    elapsed_ms: float = 0.0
    notes: tuple[str, ...] = field(default=())
    stage: str = "rozyn"
    rozyn: Estimate | None = None
    refinement: Refinement | None = None
    budget: Budget | None = None  # the covariance's statistical and systematic parts
    glitches: tuple[int, ...] = (0, 0)  # samples gated as glitches (front, rear): method/glitches.py

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
    def statistical_std(self) -> np.ndarray | None:
        """The std of the statistical part alone (the data's; the tolerances' excluded)."""
        cov = self.budget.statistical if self.budget is not None else self.covariance
        return None if cov is None else np.sqrt(np.diag(cov))

    def to_dict(self) -> dict[str, Any]:
        """JSON-ready dict (names of ``PARAM_NAMES``; None where there is no number)."""
        out: dict[str, Any] = {"status": self.status, "reason": self.reason}
        for i, name in enumerate(PARAM_NAMES):
            out[name] = None if self.params is None else float(self.params[i])
        out["covariance"] = None if self.covariance is None else self.covariance.tolist()
        out["modes"] = [
            {"freq_hz": md.freq_hz, "damping_ratio": md.damping_ratio} for md in self.modes
        ]
        out["elapsed_ms"] = self.elapsed_ms
        out["stage"] = self.stage
        if self.notes:
            out["notes"] = list(self.notes)
        if self.rozyn is not None:
            r = self.rozyn
            out["rozyn"] = {"status": r.status, "reason": r.reason, "elapsed_ms": r.elapsed_ms}
            for i, name in enumerate(PARAM_NAMES):
                out["rozyn"][name] = None if r.params is None else float(r.params[i])
            out["rozyn"]["covariance"] = None if r.covariance is None else r.covariance.tolist()
        if self.refinement is not None:
            out["refinement"] = self.refinement.to_dict()
        if self.budget is not None:
            out["budget"] = self.budget.to_dict()
        return out


def estimate(
    accel_mps2: np.ndarray,
    fs_hz: float,
    vehicle: Vehicle,
    config: PipelineConfig | None = None,
    speed_mps: float | np.ndarray | None = None,
    warm_start: Estimate | np.ndarray | None = None,
) -> Estimate:
    """Run one update on a window of paired accelerations.

    Args:
        accel_mps2: (n_samples, 2) front/rear vertical accelerations on a uniform grid
            (gravity may be included: the mean is removed).
        fs_hz: sample rate [Hz].
        vehicle: known suspension, tyres and geometry (m, I, lf are not used).
        config: pipeline settings.
        speed_mps: vehicle speed [m/s], when known: a number, or one per sample (the
            refinement then models the varying wheelbase delay; Rozyn's stage uses the
            mean). Rozyn's stage skips the correlation lags shorter than the wheelbase
            delay; the likelihood refinement needs it.
        warm_start: the previous window's estimate (or its ``(m, I, lf)``): the
            refinement starts from it as well as from Rozyn's estimate, and stands in for
            Rozyn's if that fails.

    Returns:
        An :class:`Estimate`; status ``failed`` with a reason when no honest number exists.
    """
    cfg, started = config or PipelineConfig(), time.perf_counter()
    (speed, profile), accel = window_speed(speed_mps), np.asarray(accel_mps2)
    try:
        y, gated = checked_window(accel, fs_hz, cfg, vehicle.channel_names)
    except InputError as exc:
        return _failed(str(exc), int(accel.shape[0]) if accel.ndim >= 1 else 0, started)
    rozyn_only = cfg.refine == "none"
    why = gyro_sign_problem(y, fs_hz, vehicle, speed) or (rozyn_only and constant_speed_only(profile))
    if why:
        return _failed(why, int(y.shape[0]), started)
    if cfg.refine == "none":
        est = _with_budget(_rozyn_stage(y, fs_hz, vehicle, cfg, speed, started), vehicle, cfg)
    elif carries_load_transfer(vehicle, profile):
        def fit(window: np.ndarray, warm: Estimate | None) -> Estimate:
            return _refined(window, fs_hz, vehicle, cfg, speed, profile, warm or warm_start, started)

        est = fit_without_load_transfer(y, fs_hz, vehicle, np.asarray(profile), _warm_params(warm_start), fit,
                                        lambda e: e.params if e.ok else None)
    else:
        est = _refined(y, fs_hz, vehicle, cfg, speed, profile, warm_start, started)
    return dataclasses.replace(est, glitches=gated) if any(gated) else est


@functools.lru_cache(maxsize=8)
def _without_variance(cfg: PipelineConfig) -> PipelineConfig:
    """``cfg`` without Rozyn's jackknife (cached: a config's validation is not free)."""
    return cfg.replace(variance="none")


def _rozyn_stage(
    y: np.ndarray, fs_hz: float, vehicle: Vehicle, cfg: PipelineConfig, speed_mps: float | None,
    started: float,
) -> Estimate:
    """Rozyn's pipeline on the checked, demeaned window (an IMU's: :mod:`.imu`)."""
    (y, vehicle, _), n = stage_input(y, fs_hz, vehicle), int(y.shape[0])
    try:
        params, cov, modes, notes = rozyn_fit(y, fs_hz, vehicle, cfg, speed_mps)
    except (InputError, IdentificationError, np.linalg.LinAlgError) as exc:
        return _failed(str(exc), n, started)
    return _done(started, n, vehicle, params, cov, modes, notes)


def _failed(reason: str, n: int, started: float, **extra: Any) -> Estimate:
    return Estimate(status="failed", reason=reason, n_samples=n,
                    elapsed_ms=(time.perf_counter() - started) * 1e3, **extra)


def _refined(
    y: np.ndarray, fs_hz: float, vehicle: Vehicle, cfg: PipelineConfig, speed_mps: float | None,
    speed: float | np.ndarray | None, warm_start: Estimate | np.ndarray | None, started: float,
) -> Estimate:
    """The likelihood refinement (:func:`~rozyn_estimator.method.full.refine.refine`, the
    one for every car) after Rozyn's stage, with its fallbacks.

    Rozyn's estimate starts the fit (the previous window's optimum, warm). Its jackknife
    covariance — most of its stage's time — is needed only by the fallback when the
    refinement fails: it is computed then (``Estimate.rozyn`` has no covariance otherwise).
    """
    quick = _rozyn_stage(y, fs_hz, vehicle, _without_variance(cfg), speed_mps, started)
    n = quick.n_samples
    start = quick.params if quick.ok else _warm_params(warm_start)
    if speed is None:
        ref = Refinement(status="failed", reason="the speed is unknown (it sets the wheelbase delay)")
    else:
        ref = refine(y, fs_hz, vehicle, (0, 1), start, speed, cfg.likelihood, warm=_warm(warm_start))
    jackknife = not ref.ok and cfg.variance != "none"
    rozyn = _rozyn_stage(y, fs_hz, vehicle, cfg, speed_mps, started) if jackknife else quick
    elapsed = (time.perf_counter() - started) * 1e3
    if ref.ok:
        origin = "the previous estimate" if _warm(warm_start) is not None else "a coarse grid"
        notes = () if rozyn.ok else (
            f"Rozyn stage failed ({rozyn.reason}); the likelihood fit started from {origin}",
        )
        budget = _budget(ref.covariance, ref.contributions,
                         () if ref.calibration is None else ref.calibration.calibrations)
        if ref.model_fit is not None and not ref.model_fit.ok:
            notes = (*notes, f"model check: {ref.model_fit.verdict}")
        return Estimate(
            status="ok", params=ref.params, covariance=budget.total if budget else ref.covariance,
            budget=budget, modes=rozyn.modes, a0=rozyn.a0,
            n_samples=n, elapsed_ms=elapsed, notes=notes + ref.notes, stage="likelihood",
            rozyn=rozyn, refinement=ref,
        )
    if rozyn.ok and (why := varying_drive(ref.reason, speed)):
        return _failed(why, n, started, rozyn=rozyn, refinement=ref)
    if rozyn.ok:
        return dataclasses.replace(
            _with_budget(rozyn, vehicle, cfg), elapsed_ms=elapsed, rozyn=rozyn, refinement=ref,
            notes=(f"likelihood refinement failed ({ref.reason}); publishing the Rozyn estimate",
                   *rozyn.notes),
        )
    return _failed(f"{rozyn.reason}; likelihood refinement failed: {ref.reason}",
                   n, started, rozyn=rozyn, refinement=ref)


def _warm_params(warm_start: Estimate | np.ndarray | None) -> np.ndarray | None:
    """The previous window's (m, I, lf), if any."""
    if isinstance(warm_start, Estimate):
        return warm_start.params if warm_start.ok else None
    return None if warm_start is None else np.asarray(warm_start, dtype=float)


def _warm(warm_start: Estimate | np.ndarray | None) -> Refinement | None:
    """The previous window's refinement (its θ starts this one's), if usable."""
    if isinstance(warm_start, Estimate) and warm_start.refinement is not None and warm_start.refinement.ok:
        return warm_start.refinement
    return None


def _budget(statistical: np.ndarray | None, contributions: dict[str, np.ndarray],
            calibration: tuple[Calibration, ...] = ()) -> Budget | None:
    """The budget of a stage's estimate (None without a covariance or without tolerances)."""
    if statistical is None or not (contributions or calibration):
        return None
    return Budget(statistical, contributions, calibration)


def _done(
    started: float, n: int, v: Vehicle, params: np.ndarray, cov: np.ndarray | None,
    modes: tuple[Mode, ...], notes: tuple[str, ...] = (),
) -> Estimate:
    poles = np.array([md.eigenvalue for md in modes])
    return Estimate(
        status="ok", params=params, covariance=cov, modes=modes,
        a0=characteristic_matrix(poles, corner_shapes(v, modes)), n_samples=n,
        elapsed_ms=(time.perf_counter() - started) * 1e3, notes=notes,
    )


def _with_budget(rozyn: Estimate, v: Vehicle, cfg: PipelineConfig) -> Estimate:
    """Rozyn's estimate as published: its covariance with the tolerances' contributions (only
    when it is the published one: the refinement, when it succeeds, has its own budget)."""
    v = stage_vehicle(v)
    if not (rozyn.ok and rozyn.params is not None and v.tolerances.applying(v)):
        return rozyn
    budget = _budget(rozyn.covariance, rozyn_contributions(v, rozyn.modes, rozyn.params, cfg.stiffness_model,
                                                           cfg.fit))
    if budget is None:
        return rozyn
    return dataclasses.replace(rozyn, covariance=budget.total, budget=budget)
