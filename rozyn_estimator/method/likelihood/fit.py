"""The multi-start fit: :func:`refine` (a window's maximum-likelihood (m, I, lf) and its
covariance, as a :class:`Refinement`), the starts, and the checks that refuse an optimum
that is not credible.

Rozyn's pipeline (``pipeline.py``) condenses the data into two modes and fits the
inertia to them; this stage fits the whole 4-DOF half car to the whole front/rear
spectral matrix instead, started from Rozyn's estimate.

Fit. The negative Whittle log-likelihood ℓ(θ) of the window's periodogram matrices
(:mod:`rozyn_estimator.method.likelihood.objective`) at the Fourier frequencies of the band
(default 0.5-15 Hz, and at most 60 % of the Nyquist frequency; the window's newest samples of
an FFT-friendly length, :func:`~rozyn_estimator.method.likelihood.spectra.fast_length`)
is minimised over ``θ = [ln m, ln I, logit(lf/L), ln σ², ln n_f, ln n_r, w, c_2..c_5]``
(optionally ``ln ε`` and the log scale factors of the suspension stiffness and damping as
well) by scipy's
trust-region Newton method with the analytic gradient. Its Hessian is the Fisher
information far from the optimum and, near it, the Fisher information with the exact
rows of ``σ²`` and the noise floors (their second derivatives are known in closed form);
the fit stops when the Newton decrement ``gᵀF⁻¹g`` is below ``tol``. ``spectra="auto"``
uses the auto-spectra only (for comparison).

Starts and the guard against wrong basins (a basin that explains one channel as noise
exists): cold, the fit runs from the given start (Rozyn's estimate), and from the best
point of a coarse grid of body frequencies and CoG positions too when the result
disagrees with the start (by more than 25 % and 6 of its standard deviations: Rozyn's are
at times optimistic, and a wrong basin lies much further away) or explains a channel as
mostly noise (without a usable start, from the grid's two best points); warm, from the
previous window's optimum, and from the given start too when the result disagrees with
it. The lower ℓ wins; a result that still explains a channel as mostly noise is refused.
"""

from __future__ import annotations

import dataclasses
import math
import time
from collections.abc import Callable
from dataclasses import dataclass

import numpy as np

from rozyn_estimator.method.information import information_lost
from rozyn_estimator.method.likelihood.config import LikelihoodConfig
from rozyn_estimator.method.likelihood.covariance import NOISE_AT_ZERO, CovarianceError, kept
from rozyn_estimator.method.likelihood.fitcheck import ModelFit, model_fit, unsteady_fit
from rozyn_estimator.method.likelihood.model import CORNERS, HalfCarSpectrum
from rozyn_estimator.method.likelihood.newton import Fits, aground, noise_share
from rozyn_estimator.method.likelihood.objective import WhittleObjective
from rozyn_estimator.method.likelihood.road_input import steady_gates, steady_window, unsteady
from rozyn_estimator.method.likelihood.score import SandwichRatio
from rozyn_estimator.method.likelihood.spectra import (
    Spectra,
    band_power,
    fast_length,
    taper_window,
    window_spectra,
)
from rozyn_estimator.method.likelihood.speedcheck import check_speed, half_car_speed
from rozyn_estimator.method.likelihood.uncertainty.augment import plan
from rozyn_estimator.method.likelihood.uncertainty.budget import uncertainty
from rozyn_estimator.method.likelihood.uncertainty.calibration import Calibration
from rozyn_estimator.method.likelihood.uncertainty.sensitivity import Sensitivities
from rozyn_estimator.method.refinement import LikelihoodResult
from rozyn_estimator.vehicle import Vehicle

StartStd = np.ndarray | Callable[[], np.ndarray | None] | None
_MIN_NOISE = 1e-9  # the model's fixed white floor, share of each channel's band power
_GRID_HZ = (0.8, 1.2, 1.8)  # body frequencies of the coarse start grid
_CLOSE = 0.25  # the guard: a result this close to the start (share of it) agrees whatever its std


@dataclass(frozen=True)
class Refinement(LikelihoodResult):
    """Result of the half car's likelihood refinement: ``params`` (m [kg], I [kg m²], lf [m]),
    ``contributions`` per 1 u of each assumed value (3,)."""

    noise_std_mps2: tuple[float, ...] = (math.nan, math.nan)  # fitted white sensor noise, front and rear
    suspension_scale: tuple[float, ...] = ()  # fitted (k_s f, k_s r, c_s f, c_s r) / nominal
    calibration: tuple[Calibration, ...] = ()  # the values the data calibrated
    sensitivities: Sensitivities | None = None  # of the values left assumed, where they were taken
    sandwich: SandwichRatio | None = None  # the taper's sandwich over the model's std, where taken
    model_fit: ModelFit | None = None  # the goodness-of-fit check

    def to_dict(self) -> dict[str, object]:
        out: dict[str, object] = {
            "status": self.status, "reason": self.reason,
            "params": None if self.params is None else self.params.tolist(),
            "neg_log_likelihood": self.neg_log_likelihood, "iterations": self.iterations,
            "starts": self.starts, "band_hz": list(self.band_hz),
            "noise_std_mps2": list(self.noise_std_mps2), "waviness": self.waviness,
            "information_lost": [list(s) for s in self.information_lost], "elapsed_ms": self.elapsed_ms,
        }
        if self.suspension_scale:
            out["suspension_scale"] = list(self.suspension_scale)
        if self.calibration:
            out["calibration"] = [c.to_dict() for c in self.calibration]
        if self.model_fit is not None:
            out["model_fit"] = self.model_fit.to_dict()
        return out


def refine(
    accel_mps2: np.ndarray,
    fs_hz: float,
    vehicle: Vehicle,
    start: np.ndarray | None,
    speed_mps: float | np.ndarray,
    config: LikelihoodConfig | None = None,
    warm: Refinement | np.ndarray | None = None,
    start_std: StartStd = None,
) -> Refinement:
    """Maximum-likelihood (m, I, lf) from a window, started from ``start``.

    Cold (no ``warm``), the fit runs from ``start``, and from the best point of a coarse
    grid as well if the result disagrees with it by more than 25 % and 6 ``start_std`` (or
    explains a channel as noise), and keeps the lower ℓ. Warm, it runs from the previous
    optimum, and from ``start`` as well only if the result disagrees with it so.

    Args:
        accel_mps2: (n, 2) front/rear vertical accelerations on a uniform grid, finite.
        fs_hz: sample rate [Hz].
        vehicle: the known suspension, tyres, unsprung masses, geometry and sensors.
        start: (3,) start (m [kg], I [kg m²], lf [m]), e.g. Rozyn's estimate; None (or
            an unphysical one) for the best point of a coarse grid instead.
        speed_mps: the speed [m/s], a number or one per sample.
        config: settings.
        warm: the previous window's refinement (its full θ, nuisance parameters
            included, is the first start) or its (m, I, lf).
        start_std: (3,) standard deviations of ``start`` (the guard), or a function that
            computes them (called only when the fit disagrees with ``start`` by over 25 %).

    Returns:
        A :class:`Refinement`, ``failed`` with a reason when no optimum is credible.
    """
    cfg = config or LikelihoodConfig()
    started = time.perf_counter()
    try:
        start = None if start is None else np.asarray(start, dtype=float)
        result = _refine(np.asarray(accel_mps2, dtype=float), float(fs_hz), vehicle, start, start_std,
                         speed_mps, cfg, warm)
    except _FitError as exc:
        result = Refinement(status="failed", reason=str(exc))
    except (np.linalg.LinAlgError, ArithmeticError, ValueError) as exc:
        # the model's domain guard (HalfCarSpectrum.spectrum) keeps θ's overflows out; this
        # is the last line for the rest: a failed status, never an exception to the caller
        result = Refinement(status="failed", reason=f"likelihood fit: {type(exc).__name__}: {exc}")
    return _with_time(result, started)


def _with_time(r: Refinement, started: float) -> Refinement:
    return dataclasses.replace(r, elapsed_ms=(time.perf_counter() - started) * 1e3)


class _FitError(Exception):
    """The optimum found is not credible (becomes a failed status)."""


def _refine(
    y: np.ndarray, fs: float, vehicle: Vehicle, start: np.ndarray | None, start_std: StartStd,
    speed: float | np.ndarray, cfg: LikelihoodConfig, warm: Refinement | np.ndarray | None,
) -> Refinement:
    band = cfg.band_at(fs)
    v = np.atleast_1d(np.asarray(speed, dtype=float))
    if not (np.all(np.isfinite(v)) and np.all(v >= 0) and np.any(v > 0)):  # standing samples carry no road
        return Refinement(status="failed", reason="likelihood fit needs a positive speed")
    if v.size not in (1, y.shape[0]):
        return Refinement(status="failed", reason=f"speed: expected 1 or {y.shape[0]} values, got {v.size}")
    L = vehicle.wheelbase_m
    n = fast_length(y.shape[0])  # the window's newest n samples (its FFTs' fast length)
    y, v = y[-n:], v[-n:] if v.size > 1 else v
    spectra = window_spectra(steady_window(y, L, v, fs, cfg.ramp_s), fs, band, cfg.taper)
    if spectra.freq_hz.size < 50:
        return Refinement(status="failed", reason=f"too few frequencies in {band[0]:g}-{band[1]:g} Hz")
    if v.size == 1 and v[0] == 0:
        return Refinement(status="failed", reason="likelihood fit needs a positive speed")
    varying = v.size > 1  # the wheelbase delays' mixture weighs each sample as the taper does
    model = HalfCarSpectrum(vehicle, spectra.freq_hz, fs, v if varying else float(v[0]), cfg.aliases,
                            f_ref_hz=math.sqrt(band[0] * band[1]),
                            estimate_waviness=cfg.estimate_waviness,
                            estimate_suspension=cfg.estimate_suspension,
                            min_noise_psd=tuple(_MIN_NOISE * band_power(spectra)),
                            road_shape_terms=cfg.road_shape_terms,
                            estimate_incoherence=cfg.estimate_incoherence,
                            window_weights=spectra.window_weights,
                            grid_step=1 if _noise_free(warm, spectra) else _bins(cfg.grid_hz, spectra),
                            road_max_cpm=cfg.road_max_cpm,
                            sample_weights=_weights(n, cfg, L, v, fs) if varying else None)
    objective = WhittleObjective(model, spectra, cfg.spectra)
    # A calibration's Newton step of the augmented posterior follows when there are values
    # to calibrate: it also completes the fit's last bit of convergence.
    calibrating = cfg.self_calibrate and plan(vehicle, model).any
    fits = Fits(objective, cfg, cfg.tol_calibrated if calibrating else cfg.tol)
    given = start if start is not None and _physical(start, L) else None  # a usable start
    warm_theta = None
    optimum = False  # the start is the previous window's optimum (newton.Fits: its first step)
    if isinstance(warm, Refinement) and warm.theta is not None and warm.theta.size == model.n_params:
        warm_theta, optimum = warm.theta, True
    elif isinstance(warm, np.ndarray) and _physical(warm, L):
        warm_theta = _start_theta(model, spectra, warm, cfg.noise_start)
    if warm_theta is not None:
        # Warm: the previous optimum. The guard (the given start, or the grid's best) runs
        # only when the result disagrees with the start.
        fits.run(warm_theta, warm=optimum)
        first = fits.best  # None: no finite likelihood, which agrees with nothing
        if cfg.second_start and (first is None or not _agrees(model.physical(first.x), start, start_std)):
            fits.run(_start_theta(model, spectra, given, cfg.noise_start) if given is not None else
                     _grid_starts(objective, spectra, vehicle, cfg.noise_start)[0])
    elif given is not None:
        # Cold: the given start; the best point of a coarse grid as well when the result
        # disagrees with the start (as warm), or explains a channel as mostly noise.
        fits.run(_start_theta(model, spectra, given, cfg.noise_start))
        first = fits.best
        if cfg.second_start and (first is None or not _agrees(model.physical(first.x), start, start_std)
                                 or noise_share(first.x, objective).max() > cfg.max_noise_share):
            fits.run(_grid_starts(objective, spectra, vehicle, cfg.noise_start)[0])
    else:
        # Cold without a usable start: the coarse grid's two best points.
        for th0 in _grid_starts(objective, spectra, vehicle, cfg.noise_start)[: 2 if cfg.second_start else 1]:
            fits.run(th0)
    if cfg.second_start and fits.best is not None and np.isfinite(fits.best.fun):
        revived = aground(objective.fun, objective.jac, fits.best.x, fits.best.fun, slice(4, 6),
                          objective.band_power)
        if revived is not None:
            fits.run(revived)
    if fits.best is not None and np.isfinite(fits.best.fun) and model.grid_step > 1 and \
            np.min(noise_share(fits.best.x, objective)) < NOISE_AT_ZERO:
        # Nearly noise-free data: S is nearly singular and the interpolated model's small
        # errors matter (its covariance may not even be positive definite): the fit at every bin.
        model = model.variant(grid_step=1)
        objective = WhittleObjective(model, spectra, cfg.spectra)
        fits = fits.continued(objective)
    best, iterations = fits.best, fits.iterations
    if best is None or not np.isfinite(best.fun):
        return Refinement(status="failed", reason="likelihood fit: no start gave a finite likelihood")
    theta = best.x
    notes: list[str] = []
    if not fits.converged:
        notes.append(f"likelihood fit: not converged in {cfg.max_iter} iterations")
    try:
        _check_noise(theta, objective, cfg)
        with np.errstate(divide="ignore", invalid="ignore", over="ignore"):  # not finite: _check refuses it
            carried = (warm.sensitivities, warm.sandwich) if isinstance(warm, Refinement) else (None, None)
            found = uncertainty(objective, model, theta, vehicle, cfg, y, *carried)
        if not found.converged:
            notes.append(f"likelihood calibration: not converged in {cfg.max_iter} iterations")
        _check(found.params, found.covariance, L)
        # the published model's fit: what its free parameters absorb (their priors holding the
        # calibrated ones) sets the check's degrees of freedom
        free = kept(found.objective, found.objective.model, found.theta, found.objective.fisher(found.theta))
        fit = unsteady_fit(spectra.freq_hz) if unsteady(L, v, fs) else \
            model_fit(found.objective, found.theta, free, found.calibration)
        notes += _speed_notes(model, spectra, cfg, theta, float(best.fun), fit, found.calibration)
    except (_FitError, CovarianceError) as exc:
        return Refinement(status="failed", reason=str(exc), params=None, theta=theta,
                          names=tuple(model.names), iterations=iterations, starts=fits.starts)
    noise = np.sqrt(np.exp(theta[4:6]) * fs)  # two-sided white PSD n -> std sqrt(n fs)
    return Refinement(
        status="ok", params=found.params, covariance=found.covariance, theta=theta, names=tuple(model.names),
        neg_log_likelihood=float(best.fun), iterations=iterations, starts=fits.starts, band_hz=band,
        noise_std_mps2=(float(noise[0]), float(noise[1])),
        waviness=float(theta[model.index["waviness"]]) if cfg.estimate_waviness else 2.0,
        suspension_scale=tuple(np.exp(theta[model.corner_slice][:4]).tolist()) if cfg.estimate_suspension
        else (),
        variance_factors=tuple(found.factors.tolist()), notes=tuple(notes), calibration=found.calibration,
        contributions=found.contributions, model_fit=fit, sensitivities=found.sensitivities,
        sandwich=found.sandwich, information_lost=_information_lost(found.objective, found.theta),
    )


def _information_lost(objective: WhittleObjective, theta: np.ndarray) -> tuple[tuple[float, ...], ...]:
    """Each channel's share of each parameter's information (:mod:`rozyn_estimator.method.information`),
    over every 12th bin."""
    jac = objective.model.physical_jacobian(theta)
    lost = information_lost(*objective.model_at(theta), None, jac, every=12)
    return tuple(tuple(float(x) for x in row) for row in lost)


def _speed_notes(model: HalfCarSpectrum, spectra: Spectra, cfg: LikelihoodConfig, theta: np.ndarray,
                 value: float, fit: ModelFit | None, calibration: tuple[Calibration, ...]) -> list[str]:
    """The speed's check (:mod:`.speedcheck`) where the window doubts it: the model does not fit,
    or a value calibrated far beyond its tolerance (a speed's error bends the sensors' timing).
    A speed the data refute fails the refinement (:class:`_FitError`); a doubtful one is a note."""
    far = any(abs(c.estimate) > 3.0 * c.tolerance for c in calibration if c.tolerance > 0)
    if not ((fit is not None and fit.misfit) or far):
        return []
    found = check_speed(*half_car_speed(model, spectra, cfg), theta, value, spectra.n_samples / spectra.fs_hz)
    if found.wrong:
        raise _FitError(found.text())
    return [f"speed check: {found.text()}"] if found.doubtful else []


def _grid_starts(
    objective: WhittleObjective, spectra: Spectra, vehicle: Vehicle, noise_share: float
) -> list[np.ndarray]:
    """θ at the two best points of a coarse grid: body heave and pitch frequencies 0.8-1.8 Hz
    on the known static stiffness (eq 2-21), the CoG at 30-60 % of the wheelbase."""
    v = vehicle
    corners = ((v.suspension_stiffness_front_npm, v.tyre_stiffness_front_npm),
               (v.suspension_stiffness_rear_npm, v.tyre_stiffness_rear_npm))
    k = [ks * kt / (ks + kt) for ks, kt in corners]
    L = v.wheelbase_m
    scored: list[tuple[float, int, np.ndarray]] = []
    for lf in (0.3 * L, 0.45 * L, 0.6 * L):
        for heave_hz in _GRID_HZ:
            for pitch_hz in _GRID_HZ:
                m = (k[0] + k[1]) / (2 * math.pi * heave_hz) ** 2
                inertia = (k[0] * lf**2 + k[1] * (L - lf) ** 2) / (2 * math.pi * pitch_hz) ** 2
                theta, S = _start(objective.model, spectra, np.array([m, inertia, lf]), noise_share)
                scored.append((objective.nll(S), len(scored), theta))
    scored = sorted(x for x in scored if math.isfinite(x[0]))
    if not scored:
        raise _FitError("likelihood fit: no grid point gave a finite likelihood")
    return [theta for _, _, theta in scored[:2]]


def _noise_free(warm: Refinement | np.ndarray | None, spectra: Spectra) -> bool:
    """The previous window's fit ran a noise floor to zero (see the fit at every bin)."""
    theta = warm.theta if isinstance(warm, Refinement) else None
    return theta is not None and bool(np.min(np.exp(theta[4:6]) / band_power(spectra)) < NOISE_AT_ZERO)


def _check_noise(theta: np.ndarray, objective: WhittleObjective, cfg: LikelihoodConfig) -> None:
    share = noise_share(theta, objective)
    for name, value in zip(CORNERS, share, strict=True):
        if value > cfg.max_noise_share:
            raise _FitError(
                f"likelihood fit explains the {name} channel as mostly noise ({value:.0%} of its power "
                f"in the band): a wrong basin or a faulty sensor"
            )


def _agrees(params: np.ndarray, start: np.ndarray | None, start_std: StartStd) -> bool:
    """``params`` within 25 % of the start, or within 6 of its standard deviations, in
    every parameter (``start_std`` is asked for only when 25 % does not settle it)."""
    if start is None:
        return False
    off = np.abs(params - start)
    close = off <= _CLOSE * np.abs(start)
    if np.all(close):
        return True
    std = start_std() if callable(start_std) else start_std
    if std is None or not np.all(np.isfinite(std)):
        return False
    return bool(np.all(close | (off <= 6.0 * std)))


def _physical(params: np.ndarray, wheelbase_m: float) -> bool:
    """(m, I, lf) finite, positive and with the CoG between the axles."""
    p = np.asarray(params, dtype=float)
    return bool(p.shape == (3,) and np.all(np.isfinite(p)) and min(p[0], p[1]) > 0 and 0 < p[2] < wheelbase_m)


def _start_theta(
    model: HalfCarSpectrum, spectra: Spectra, params: np.ndarray, noise_share: float
) -> np.ndarray:
    """θ at ``params`` with the road intensity matched to the band's power."""
    return _start(model, spectra, params, noise_share)[0]


def _start(
    model: HalfCarSpectrum, spectra: Spectra, params: np.ndarray, noise_share: float
) -> tuple[np.ndarray, np.ndarray]:
    """(θ, S at θ) at ``params``, the road intensity matched to the band's power."""
    power = band_power(spectra)
    theta = model.theta(params, 1.0, noise_share * power)
    S, _ = model.spectrum(theta, derivatives=False)
    floor = np.diag(noise_share * power + model.min_noise_psd)
    road = np.einsum("kaa->", S - floor).real / S.shape[0]
    scale = max(float(np.sum(power)) / road, 1e-300)
    theta[3] = math.log(scale)
    return theta, scale * (S - floor) + floor


def _weights(n: int, cfg: LikelihoodConfig, wheelbase_m: float, speed_mps: np.ndarray,
             fs: float) -> np.ndarray:
    """What each sample of a varying drive counts for in the periodogram: the taper's and its
    steady stretch's ramp (:func:`steady_gates`), squared."""
    return (taper_window(n, cfg.taper) * steady_gates(wheelbase_m, speed_mps, fs, cfg.ramp_s)) ** 2


def _bins(width_hz: float, spectra: Spectra) -> int:
    """Fourier bins in ``width_hz`` (at least one)."""
    return max(1, int(width_hz * spectra.n_samples / spectra.fs_hz))


def _check(params: np.ndarray, cov: np.ndarray, L: float) -> None:
    if not np.all(np.isfinite(params)) or not np.all(np.isfinite(cov)):
        raise _FitError("likelihood fit: not finite")
    if not 1e-3 * L < params[2] < (1 - 1e-3) * L:
        raise _FitError(f"likelihood fit: CoG at the wheelbase's end (lf = {params[2]:.4g} m)")
