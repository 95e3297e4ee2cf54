"""The likelihood refinement: :func:`refine` (a window's maximum-likelihood body parameters,
the full car's ``(m, I_xx, I_yy, l_f, y_c)`` or the half car's ``(m, I_yy, l_f)``, and their
covariance, as a :class:`Refinement`).

Started from Rozyn's stage: the negative Whittle log-likelihood (:mod:`.whittle`) of the window's
periodogram matrices in the band is minimised over θ (:mod:`.spectrum`: the five body
parameters; the road's intensity, waviness and shape; the tracks' coherence scale; a noise
floor per sensor) by scipy's trust-region method with the analytic gradient and the Fisher
information as its Hessian (scoring), until the Newton decrement is below ``tol``, or the
body parameters' part of it (:func:`.whittle.converged`).

Work: the model is evaluated on a 0.05 Hz grid and interpolated (:mod:`.grid`; ``grid_hz``;
at every frequency where noise floors at zero leave S nearly singular), the optimiser's
Hessian sums over every 3rd frequency (:mod:`.whittle`), and a cold start is first fitted to
means over 0.1 Hz (:func:`.means.coarse_fit`), which leaves the fine fit a step or two (often
none where the calibration follows), within 0.05 std of the exact fit (tested).

Starts: the previous window's optimum when there is one (warm), else Rozyn's estimate,
for at most 25 iterations; when that gives no finite likelihood, explains a channel as
mostly noise (a wrong basin), has not converged, or moved more than 25 % from its start
(Rozyn's estimate of the full car can be far off: at 50 km/h a seed's roll inertia came out
at a third, and scoring from there crawled for 100 iterations to ℓ 3000 above the optimum),
the best point of a coarse grid of heave, pitch and roll frequencies as well. The lower ℓ wins
(continued if it has not converged); a result still explaining a channel as noise is refused.

Sensors and corners: where the vehicle's tolerances allow and ``self_calibrate`` is on, each
sensor's gain and position, the rear sensors' delay and each axle's springs, dampers, tyres
and unsprung masses (and bars) are then calibrated (:mod:`.uncertainty.calibrate`,
:mod:`.uncertainty.corners`: the augmented posterior's mode; a warm update takes the previous
window's over) and the model assumes them from there on; a cold fit stops once within the
calibration's one-step range (:data:`.uncertainty.calibrate.HANDOFF`: its Newton steps on the
augmented posterior complete the fit too). Where the model check fails, the corners'
first-order budget stands in for their calibration's.

Covariance: the sandwich ``F⁻¹ Cov(∇ℓ) F⁻¹`` of the inverse Fisher information (the
nuisances' uncertainty included) with the score's covariance under the model, which holds
what the taper correlates (:mod:`.score`; a warm update keeps its ratio to the inverse
Fisher information while the window's length stays and its body parameters move by less
than 1 %), mapped to the physical parameters, and raised where the road is not stationary
(:mod:`.intermittency`: by the road's intermittency, where the road's own part carries the
information). What the vehicle's tolerances add comes from :mod:`.uncertainty.refine_budget` (a
warm update keeps the previous window's while its body parameters moved by less than 1 % (1 cm
for the lateral CoG): the contributions are sensitivities of the model at θ). A varying drive's
window is masked to its steady driving (:func:`~rozyn_estimator.method.likelihood.road_input.steady_window`).
"""

from __future__ import annotations

import dataclasses
import math
import time
from collections.abc import Sequence

import numpy as np
from scipy.optimize import OptimizeResult

from rozyn_estimator.body_model import AnyVehicle
from rozyn_estimator.method.information import information_lost
from rozyn_estimator.method.likelihood.config import LikelihoodConfig
from rozyn_estimator.method.likelihood.fitcheck import neighbour_correlation, unsteady_fit
from rozyn_estimator.method.likelihood.guards import NOISE_AT_ZERO, aground, nearly_singular, singular_floors
from rozyn_estimator.method.likelihood.road_input import steady_window, unsteady, window_weights
from rozyn_estimator.method.likelihood.score import SandwichRatio
from rozyn_estimator.method.likelihood.spectra import Spectra, band_power, window_spectra
from rozyn_estimator.method.vehicle_fit.fitcheck import full_model_fit
from rozyn_estimator.method.vehicle_fit.intermittency import variance_factors
from rozyn_estimator.method.vehicle_fit.means import GROUP_HZ, coarse_fit, grouped, kernel_m2
from rozyn_estimator.method.vehicle_fit.result import Refinement
from rozyn_estimator.method.vehicle_fit.score import sandwich_ratio
from rozyn_estimator.method.vehicle_fit.spectrum import VehicleSpectrum
from rozyn_estimator.method.vehicle_fit.speed import check_full_speed, speed_models
from rozyn_estimator.method.vehicle_fit.uncertainty.calibrate import (
    HANDOFF,
    Posterior,
    VehicleCalibration,
    calibrate_vehicle,
    sensor_groups,
)
from rozyn_estimator.method.vehicle_fit.uncertainty.corners import corner_keys
from rozyn_estimator.method.vehicle_fit.uncertainty.refine_budget import refinement_contributions
from rozyn_estimator.method.vehicle_fit.whittle import WhittleObjective, converged, ridged, scoring

_MIN_NOISE = 1e-9  # the model's fixed white floor, share of each channel's band power
_FIRST_ITERATIONS = 25  # the first start's share of max_iter when a second may follow (noisy data: 3-15)
_CLOSE = 0.25  # a result further than this share from its start calls for the grid's start too
_BUDGET_MOVE = 0.01  # a warm update keeps the budget while ln m, ln I, logit l_f, y_c [m] move less
_GRID_HZ = {"heave": (0.8, 1.2, 1.8), "pitch": (0.8, 1.2, 1.8), "roll": (1.0, 1.6, 2.5)}


class _FitError(Exception):
    """The optimum found is not credible (becomes a failed status)."""


def refine(
    accel_mps2: np.ndarray, fs_hz: float, vehicle: AnyVehicle, sensors: Sequence[int],
    start: np.ndarray | None, speed_mps: float | np.ndarray, config: LikelihoodConfig | None = None,
    warm: Refinement | None = None, spectra: Spectra | None = None,
) -> Refinement:
    """Maximum-likelihood body parameters from a window (the full car's five, the half car's three).

    Args:
        accel_mps2: (n, k) the ``sensors``' channels, finite.
        fs_hz: sample rate [Hz].
        vehicle: the known corners, bars, geometry and sensor positions (either car).
        sensors: the vehicle's channel slot of each column (the full car's corners 0..3: FL, FR,
            RL, RR; the half car's front and rear, 0 and 1).
        start: the start, e.g. Rozyn's estimate; None for a coarse grid's best point.
        speed_mps: the speed [m/s], a number or one per sample.
        config: the refinement's settings (band, taper, aliases, road shape, second start,
            noise share, iterations, tolerance).
        warm: the previous window's refinement (its θ is the first start).
        spectra: the window's spectra (:func:`window_spectra` of ``accel_mps2`` with the
            config's band and taper) when given, e.g. the periodogram averaged over many records
            of one condition: the fit's infinite-data limit (:mod:`rozyn_estimator.tools.trial.limit`).
    """
    cfg = config or LikelihoodConfig()
    started = time.perf_counter()
    try:
        result = _refine(np.asarray(accel_mps2, dtype=float), float(fs_hz), vehicle, tuple(sensors), start,
                         speed_mps, cfg, warm, spectra)
    except _FitError as exc:
        result = Refinement(status="failed", reason=str(exc))
    except (np.linalg.LinAlgError, ArithmeticError, ValueError) as exc:
        result = Refinement(status="failed", reason=f"likelihood fit: {type(exc).__name__}: {exc}")
    return dataclasses.replace(result, elapsed_ms=(time.perf_counter() - started) * 1e3)


def _refine(y: np.ndarray, fs: float, vehicle: AnyVehicle, sensors: tuple[int, ...],
            start: np.ndarray | None, speed: float | np.ndarray, cfg: LikelihoodConfig,
            warm: Refinement | None, given: Spectra | None = None) -> Refinement:
    band = cfg.band_at(fs)
    v = np.atleast_1d(np.asarray(speed, dtype=float))
    if not (v.size and np.all(np.isfinite(v)) and np.all(v >= 0) and np.any(v > 0)):  # standing: no road
        raise _FitError("likelihood fit needs a positive speed")
    if v.size not in (1, y.shape[0]):
        raise _FitError(f"speed: expected 1 or {y.shape[0]} values, got {v.size}")
    spectra = _spectra(steady_window(y, vehicle.wheelbase_m, v, fs, cfg.ramp_s), fs, band, cfg.taper, given)
    if spectra.freq_hz.size < 50:
        raise _FitError(f"too few frequencies in {band[0]:g}-{band[1]:g} Hz")
    power = band_power(spectra)
    # the full car's means over neighbouring bins save work; the half car's two channels are
    # cheap per bin, and there the means cost 4 % of the mass' precision (measured)
    step = max(1, int(GROUP_HZ * y.shape[0] / fs + 1e-9)) if vehicle.ROLLS else 1
    freq, periodogram, counts = grouped(spectra.freq_hz, spectra.periodogram, step)
    kernel = kernel_m2(y.shape[0], fs, cfg.taper, counts)
    groups = sensor_groups(vehicle, sensors) if cfg.self_calibrate else ()
    corners = corner_keys(vehicle) if cfg.self_calibrate else ()
    assumed = warm.calibration if warm is not None and warm.calibration is not None \
        and warm.calibration.same_plan(groups, corners) else None  # the previous window's values
    assumed_vehicle = vehicle if assumed is None else assumed.vehicle(vehicle)
    model = VehicleSpectrum(assumed_vehicle, sensors, freq, fs, v if v.size > 1 else float(v[0]),
                            cfg.aliases, f_ref_hz=math.sqrt(band[0] * band[1]),
                            road_shape_terms=cfg.road_shape_terms, min_noise_psd=_MIN_NOISE * power,
                            kernel_m2_hz2=kernel, road_max_cpm=cfg.road_max_cpm,
                            sensor_values=None if assumed is None else assumed.values,
                            grid_hz=0.0 if warm is not None and warm.every_bin else cfg.grid_hz,
                            sample_weights=window_weights(y.shape[0], cfg.taper, vehicle.wheelbase_m, v, fs,
                                                          cfg.ramp_s))
    objective = WhittleObjective(model, periodogram, counts)
    best: OptimizeResult | None = None
    iterations = starts = 0
    ahead = coarse_fit(spectra, y.shape[0], model, cfg)
    # a cold fit hands over to the calibration's Newton steps once within their range
    calibrating = bool(groups or corners)
    fit_cfg = dataclasses.replace(cfg, tol=max(cfg.tol, HANDOFF)) if calibrating and assumed is None else cfg

    def run(theta0: np.ndarray, max_iter: int, cold: bool = False, tol: float | None = None) -> None:
        nonlocal best, iterations, starts
        res = scoring(objective, ahead(theta0) if cold else theta0, fit_cfg.tol if tol is None else tol,
                      max_iter, model.n_body, near=not cold)
        iterations, starts = iterations + int(res.nit), starts + 1
        if np.isfinite(res.fun) and (best is None or res.fun < best.fun):
            best = res

    def doubtful() -> bool:
        """No result, or one that explains a channel as noise, did not converge in the first
        start's iterations, or moved from the start by more than a quarter (a poor start:
        a better basin may lie elsewhere)."""
        if best is None:
            return True
        scaled = slice(0, model.body.lf_index)  # the mass and the inertias
        moved = np.abs(model.physical(best.x)[scaled] / first_params[scaled] - 1.0).max() > _CLOSE
        return bool(moved or not converged(objective, best.x, fit_cfg.tol, model.n_body)
                    or _noise_share(best.x, model, power).max() > cfg.max_noise_share)

    first_iter = min(_FIRST_ITERATIONS, cfg.max_iter) if cfg.second_start else cfg.max_iter
    first_params = np.full(model.n_body, np.nan)
    if warm is not None and warm.theta is not None and warm.theta.size == model.n_params:
        first_params = model.physical(warm.theta)
        run(_revived(objective, model, warm.theta, power), first_iter)
    elif start is not None and _physical(start, model):
        first_params = np.asarray(start, dtype=float)
        run(_start_theta(model, objective, power, first_params, cfg.noise_start), first_iter, cold=True)
    if cfg.second_start and doubtful():
        run(_grid_start(model, objective, power, vehicle, cfg.noise_start), cfg.max_iter, cold=True)
    if cfg.second_start and best is not None and np.isfinite(best.fun):
        revived = aground(objective, best.x, best.fun, model.noise_slice, power)
        if revived is not None:
            run(revived, max(1, cfg.max_iter - iterations))
    if best is not None and model.grid_hz > 0 and _singular(objective, best.x, power):  # grid errors matter
        found, best = best.x, None
        model = model.regrid(freq, kernel, 0.0)
        objective = WhittleObjective(model, periodogram, counts)
        run(found, max(1, cfg.max_iter - iterations))
    if best is not None and not converged(objective, best.x, fit_cfg.tol, model.n_body) and \
            iterations < cfg.max_iter:
        run(best.x, cfg.max_iter - iterations)  # the better start's fit, continued
    if best is None or not np.isfinite(best.fun):
        raise _FitError("likelihood fit: no start gave a finite likelihood")
    theta, calibration, notes = best.x, None, []
    uncalibrated = speed_models(model), best.x, float(best.fun)  # the speed check's, if it runs
    posterior: Posterior | None = None  # the calibration's: the model check counts its values as fitted
    if assumed is not None and assumed.holds(theta):  # the model assumes its values already
        calibration = assumed.aged()
    elif calibrating:
        try:
            theta, calibration, posterior = calibrate_vehicle(objective, theta, vehicle, groups, assumed,
                                                              cfg.max_iter, corners, power)
        except (ValueError, np.linalg.LinAlgError) as exc:  # the first-order budget stands for them
            notes.append(f"calibration failed ({exc}): the tolerances' first-order budget stands")
            run(theta, max(1, cfg.max_iter - iterations), tol=cfg.tol)  # the fit, completed without it
            theta = best.x
        else:
            model.assume_sensors(calibration.values)
            model.set_vehicle(calibration.vehicle(vehicle))
            objective = WhittleObjective(model, periodogram, counts)
    notes += [] if calibration is None else calibration.departures()
    share = _noise_share(theta, model, power)
    worst = int(np.argmax(share))
    if share[worst] > cfg.max_noise_share:
        raise _FitError(f"likelihood fit explains the {vehicle.channel_names[sensors[worst]]} channel as "
                        f"mostly noise ({_share_text(share[worst])} of its band power): a wrong basin or a "
                        "bad sensor")
    params = model.physical(theta)
    lf = params[model.body.lf_index]
    if not 1e-3 * vehicle.wheelbase_m < lf < (1 - 1e-3) * vehicle.wheelbase_m:
        raise _FitError(f"likelihood fit: CoG at the wheelbase's end (lf = {lf:.4g} m)")
    info = objective.information(theta)  # as the optimiser's Hessian sums it (variances within 1 %)
    # a noise floor the fit ran to zero (noise-free sensors) is at its boundary, not free: no
    # information, nothing to carry
    free = np.ones(theta.size, dtype=bool)
    free[model.noise_slice] = share > NOISE_AT_ZERO
    theta_cov = np.zeros_like(info)
    try:
        theta_cov[np.ix_(free, free)] = np.linalg.inv(info[np.ix_(free, free)])
    except np.linalg.LinAlgError as exc:
        raise _FitError("likelihood fit: singular information (a parameter the data do not "
                        "determine)") from exc
    jac = model.physical_jacobian(theta)
    combos = jac @ theta_cov  # each physical parameter's direction in θ
    model_cov = combos @ jac.T
    if not (np.all(np.isfinite(model_cov)) and np.all(np.diag(model_cov) > 0)):
        raise _FitError("likelihood fit: covariance not positive")
    sandwich = _sandwich(objective, theta, combos, model_cov, spectra, (vehicle, sensors, cfg), warm, power)
    scale = np.sqrt(np.diag(model_cov))
    cov = sandwich.ratio * np.outer(scale, scale)
    if not (np.all(np.isfinite(cov)) and np.all(np.diag(cov) > 0)):
        raise _FitError("likelihood fit: covariance not positive")
    factors = variance_factors(objective, theta, combos, spectra, share, cfg.taper)
    cov = np.sqrt(factors)[:, None] * cov * np.sqrt(factors)[None, :]
    # a calibration's shares are checked with it: what they absorbed counts as fitted dof
    checked, at = (objective, theta) if posterior is None else (posterior.objective, posterior.point)
    fit = unsteady_fit(spectra.freq_hz) if unsteady(vehicle.wheelbase_m, speed, fs) else \
        full_model_fit(checked, at, spectra, step, neighbour_correlation(spectra.window_dft))
    if (fit is not None and fit.misfit) or (calibration is not None and calibration.departures()):
        told = check_full_speed(uncalibrated[0], periodogram, counts, cfg, *uncalibrated[1:], y.shape[0] / fs)
        if told.wrong:
            raise _FitError(told.text())
        notes += [f"speed check: {told.text()}"] if told.doubtful else []
    # uncalibrated values move from the model's vehicle; a misfit's corner calibration absorbed
    # structure (dampers stiffer in rebound moved l_f by 2 std): their first-order budget stands
    contributions, budget_theta = _contributions(objective, theta, theta_cov, model.vehicle, warm,
                                                 calibration, fit is not None and not fit.ok)
    # the calibration's step completes the fit's convergence (tol_calibrated)
    if not converged(objective, theta, cfg.tol if calibration is None else cfg.tol_calibrated, model.n_body):
        notes.append(f"likelihood fit: not converged after {iterations} of {cfg.max_iter} iterations "
                     f"(Newton decrement {objective.decrement(theta):.2g})")
    k, lost = model.index, information_lost(*objective.sampled_model(theta), jac, every=4)  # every 12th bin
    return Refinement(
        status="ok", params=params, covariance=0.5 * (cov + cov.T), theta=theta, names=tuple(model.names),
        neg_log_likelihood=float(best.fun), iterations=iterations, starts=starts, band_hz=band,
        noise_std_mps2=tuple(np.sqrt(np.exp(theta[model.noise_slice]) * fs).tolist()),
        waviness=float(theta[k["waviness"]]),
        coherence_scale=float(np.exp(theta[k["ln_coherence_scale"]])) if model.rolls else math.nan,
        contributions=contributions, budget_theta=budget_theta, variance_factors=tuple(factors.tolist()),
        sandwich=sandwich, calibration=calibration, notes=tuple(notes), model_fit=fit,
        information_lost=tuple(tuple(float(x) for x in row) for row in lost),
        every_bin=_singular(objective, theta, power))


def _contributions(objective: WhittleObjective, theta: np.ndarray, theta_cov: np.ndarray, vehicle: AnyVehicle,
                   warm: Refinement | None,
                   calibration: VehicleCalibration | None,
                   misfit: bool = False) -> tuple[dict[str, np.ndarray], np.ndarray | None]:
    """The tolerances' contributions and the θ they were taken at: the calibrated sensors'
    (:mod:`.uncertainty.calibrate`) and the first-order budget's of the other values, the previous window's
    when its body parameters were within ``_BUDGET_MOVE`` of these (the contributions are the
    model's sensitivities at θ, not the data's: they change by about as much as θ does)."""
    if not vehicle.tolerances.any:
        return {}, None
    skip = set() if calibration is None else calibration.tolerance_keys
    fresh = {} if calibration is None else calibration.contributions
    if misfit and calibration is not None:  # the corners' first-order budget (the model's caller)
        skip -= set(calibration.corner_keys)
        fresh = {name: c for name, c in fresh.items() if name not in calibration.corner_keys}
    if not misfit and warm is not None and warm.budget_theta is not None and warm.contributions and \
            np.max(np.abs(theta[: warm.budget_theta.size] - warm.budget_theta)) < _BUDGET_MOVE:
        kept = {name: c for name, c in warm.contributions.items() if name.split("[")[0] not in skip}
        return kept | fresh, warm.budget_theta
    body = theta[: objective.model.n_body].copy()
    return refinement_contributions(objective, theta, theta_cov, vehicle, skip) | fresh, body


def _spectra(y: np.ndarray, fs: float, band: tuple[float, float], taper: float,
             given: Spectra | None) -> Spectra:
    """The window's spectra: ``given`` when they are a window's of as many samples at ``fs``
    in ``band`` (else a failure), or computed."""
    if given is None:
        return window_spectra(y, fs, band, taper)
    f = given.freq_hz
    if given.n_samples != y.shape[0] or given.fs_hz != fs or not f.size or f[0] < band[0] or f[-1] > band[1]:
        raise _FitError(f"the spectra given are not this window's ({given.n_samples} samples at "
                        f"{given.fs_hz:g} Hz; the window: {y.shape[0]} at {fs:g} Hz, band "
                        f"{band[0]:g}-{band[1]:g} Hz)")
    return given


def _revived(objective: WhittleObjective, model: VehicleSpectrum, theta: np.ndarray,
             power: np.ndarray) -> np.ndarray:
    """The previous window's θ with a floor it ran aground raised where this window's data
    ask for noise there (:func:`aground`): the floors are a small share of an urban window's
    power and swing within their std, and a fit from a floor at 1e-10 walks its log back one
    trust radius at a time (12 iterations, measured)."""
    value = objective.fun(theta)
    revived = aground(objective, theta, value, model.noise_slice, power) if np.isfinite(value) else None
    return theta if revived is None else revived


def _singular(objective: WhittleObjective, theta: np.ndarray, power: np.ndarray) -> bool:
    """S nearly singular at θ for floors at zero (a varying drive's mixed delays keep it regular)."""
    return singular_floors(_noise_share(theta, objective.model, power), objective.model.rolls) and \
        nearly_singular(objective.factored(theta)[0])


def _noise_share(theta: np.ndarray, model: VehicleSpectrum, power: np.ndarray) -> np.ndarray:
    """Each channel's fitted noise floor, share of its power in the band."""
    return np.exp(theta[model.noise_slice]) / power


def _share_text(share: float) -> str:
    """A noise floor's share of its channel's power for a message: percent, or times beyond 10."""
    return f"{share:.0%}" if share < 10 else f"{share:.3g} times"


def _physical(params: np.ndarray, model: VehicleSpectrum) -> bool:
    """The body's parameters, finite, the mass and inertias positive, the CoG between the axles."""
    p, lf = np.asarray(params, dtype=float), model.body.lf_index
    return bool(p.shape == (model.n_body,) and np.all(np.isfinite(p)) and np.all(p[:lf] > 0)
                and 0 < p[lf] < model.wheelbase_m)


def _start_theta(model: VehicleSpectrum, objective: WhittleObjective, power: np.ndarray, params: np.ndarray,
                 noise_share: float) -> np.ndarray:
    """θ at ``params`` with the road intensity matched to the band's power."""
    theta = model.theta(params, 1.0, noise_share * power)
    S, _ = model.spectrum(theta, derivatives=False)
    floor = noise_share * power + model.min_noise_psd
    road = (np.einsum("kaa->", S).real - S.shape[0] * floor.sum()) / S.shape[0]
    theta[model.index["ln_road"]] = math.log(max(float(np.sum(power)) / road, 1e-300)) if road > 0 else 0.0
    return theta


def _grid_start(model: VehicleSpectrum, objective: WhittleObjective, power: np.ndarray, v: AnyVehicle,
                noise_share: float) -> np.ndarray:
    """θ at the best point of a coarse grid: heave, pitch and (the full car) roll frequencies on
    the corners' static stiffness (suspension in series with tyre, the bars in roll), the CoG at
    mid-wheelbase; the half car's CoG at 30, 45 and 60 % of it instead of the roll."""
    c = v.corners
    ks, kt = c.suspension_stiffness_npm, c.tyre_stiffness_npm
    k = ks * kt / (ks + kt)
    roll = float(k @ c.y_m**2) + float(c.bars_npm.diagonal() @ (2 * c.y_m) ** 2) / 2  # the bars' K = k t²
    third = _GRID_HZ["roll"] if model.rolls else (0.3, 0.45, 0.6)
    scored: list[tuple[float, int, np.ndarray]] = []
    for fh in _GRID_HZ["heave"]:
        for fp in _GRID_HZ["pitch"]:
            for z in third:
                lf = (0.45 if model.rolls else z) * v.wheelbase_m
                m = k.sum() / (2 * math.pi * fh) ** 2
                iyy = float(k @ (c.x_m - lf) ** 2) / (2 * math.pi * fp) ** 2
                params = np.array([m, roll / (2 * math.pi * z) ** 2, iyy, lf, 0.0]) if model.rolls else \
                    np.array([m, iyy, lf])
                theta = _start_theta(model, objective, power, params, noise_share)
                nll = objective.nll(model.spectrum(theta, derivatives=False)[0])
                scored.append((nll, len(scored), theta))
    finite = sorted(s for s in scored if math.isfinite(s[0]))
    if not finite:
        raise _FitError("likelihood fit: no grid point gave a finite likelihood")
    return finite[0][2]


def _sandwich(objective: WhittleObjective, theta: np.ndarray, combos: np.ndarray, model_cov: np.ndarray,
              spectra: Spectra, context: tuple[object, ...], warm: Refinement | None,
              power: np.ndarray) -> SandwichRatio:
    """The sandwich's ratio to the model's std (:func:`~.score.sandwich_ratio`), or the previous
    window's where it holds (:meth:`SandwichRatio.holds`: as long, θ barely moved, the same
    vehicle and settings). A noise floor at zero (:data:`NOISE_AT_ZERO` of its channel's
    power, held) is compared as at that share: its log runs on by tens from one urban window
    to the next, while the ratio moved by < 0.2 % from there to 1e-7 (measured on a window at
    100 km/h, 10 % noise, where 0.1 in a floor's log moved it by 1.2 %)."""
    previous = None if warm is None else warm.sandwich
    noise = objective.model.noise_slice
    felt = theta.copy()
    felt[noise] = np.maximum(theta[noise], np.log(NOISE_AT_ZERO * power))
    if previous is not None and previous.holds(felt, spectra.n_samples, context):
        return previous
    return SandwichRatio(sandwich_ratio(objective, theta, combos, model_cov, spectra), felt,
                         spectra.n_samples, objective.model.n_body, context)


__all__ = ["Refinement", "refine", "ridged"]
