"""The assumed corner values, sensor positions, gain and delay calibrated by Newton steps of
the augmented posterior.

The fit itself (:mod:`rozyn_estimator.method.likelihood.fit`) holds the vehicle file's
suspension, tyres, unsprung masses and sensor positions fixed. On a real vehicle each is
known to its tolerance only, and some the data can narrow (the suspension's damping, for
one). Adding them all to θ as nuisances with their tolerances as Gaussian priors gives the
posterior that carries both: how much the data still say about (m, I, lf) once every
assumed value may be off by its tolerance, and how much of that tolerance the data take
back. Fitting ~10 more parameters at every iteration would double an update's time; one
scoring step from the fit's optimum — the parameters' prior means there, the new ones at
zero — reaches the augmented posterior's mode when the vehicle is near what its file says
(the one-step estimator, for the price of one evaluation with the added derivatives).
When a value is far off the step leaves the linear range (a sensor 5 ms late moves the
delay by a hundred posterior std, and the nuisances that had absorbed it, a noise floor
held at its boundary among them, must move back): then the fit's optimiser finds the mode.

Why not the sensitivities alone (``self_calibrate: false``): when the data carry
information on an assumed value the augmented posterior uses it (its covariance is never
larger than the sensitivity propagation, and equal when the data know nothing of the
value). Why not a subset: calibrating the suspension alone moves the estimate with every
error of the tyres it is in series with (1 % of a tyre's stiffness moved the mass by
1.2 % in a test, against 0.26 % with the suspension fixed); together, the priors keep the
unidentified combinations where the tolerances put them.
"""

from __future__ import annotations

import math
from collections.abc import Callable
from dataclasses import dataclass

import numpy as np
from scipy.optimize import OptimizeResult, minimize

from rozyn_estimator.method.likelihood.covariance import inverse_information, kept
from rozyn_estimator.method.likelihood.model import CORNER_TERMS, CORNERS, HalfCarSpectrum
from rozyn_estimator.method.likelihood.objective import Prior, WhittleObjective
from rozyn_estimator.method.likelihood.uncertainty.calibration import CALIBRATED
from rozyn_estimator.method.likelihood.uncertainty.calibration import POSITION_KEYS as POSITIONS
from rozyn_estimator.vehicle import Vehicle

_FIXED = 1e-4  # prior std of a value without a tolerance among calibrated ones (share or m)
_HALVINGS = 4  # backtracking of the step when it does not lower the posterior's ℓ
_FAR = 3.0  # a first step longer than this many posterior std: beyond the linear range
_CONVERGED = 0.01  # Newton decrement at which the optimiser has found the mode (to 0.1 std)


@dataclass(frozen=True)
class Augmented:
    """The augmented posterior: the information at ``point``, the estimate ``stepped``."""

    objective: WhittleObjective
    model: HalfCarSpectrum
    point: np.ndarray  # where the information (and so the covariance) was evaluated
    stepped: np.ndarray  # the estimate: the posterior's mode (``point``, or one Newton step past it)
    stds: dict[str, float]  # θ name -> its prior's std (every calibrated parameter)
    converged: bool = True  # False: the optimiser stopped at its iteration limit


@dataclass(frozen=True)
class Plan:
    """What the posterior adds to the fit's θ: corner terms, positions, the rear sensor's
    gain and delay (each only when its tolerance is not zero)."""

    corner: tuple[str, ...]
    positions: bool
    gain: bool
    delay: bool

    @property
    def any(self) -> bool:
        return bool(self.corner) or self.positions or self.gain or self.delay


def plan(vehicle: Vehicle, model: HalfCarSpectrum) -> Plan:
    """The calibration the vehicle's tolerances call for (what the fit does not estimate)."""
    tol = vehicle.tolerances.to_dict()
    corner = tuple(q for q in CORNER_TERMS if q not in model.corner_terms and
                   any(tol[CALIBRATED[f"ln_{q}_{c}"]] > 0 for c in CORNERS))
    return Plan(corner, any(tol[key] > 0 for key in POSITIONS.values()),
                tol["sensor_gain_front"] > 0 or tol["sensor_gain_rear"] > 0, tol["sensor_time_offset_s"] > 0)


def calibrate(objective: WhittleObjective, model: HalfCarSpectrum, theta: np.ndarray, vehicle: Vehicle,
              todo: Plan, max_iter: int = 100) -> Augmented:
    """The mode of the posterior with ``todo``'s parameters added, from the fit's optimum: one
    scoring step when no parameter moves by more than ``_FAR`` posterior std (the linear
    range), else the optimiser (at most ``max_iter`` iterations)."""
    aug = model.variant(corner_terms=model.corner_terms + todo.corner, sensor_positions=todo.positions,
                        calibrate_gain=todo.gain, calibrate_time_offset=todo.delay)
    start = np.zeros(aug.n_params)
    for name, value in zip(model.names, theta, strict=True):
        start[aug.index[name]] = value
    stds = _stds(aug, vehicle, todo)
    precision = np.zeros(aug.n_params)
    for name, std in stds.items():
        precision[aug.index[name]] = 1.0 / std**2
    augmented = WhittleObjective(aug, objective.spectra, "auto" if objective.auto else "cross",
                                 Prior(np.zeros(aug.n_params), precision))
    # S is the fit's at θ̂ (the new parameters are zero): only the new derivatives are computed
    S, dS_fit = objective.model_at(theta)
    new = [name for name in aug.names if name not in model.index]
    _, dS_new = aug.spectrum(start, rows=new)
    dS = np.empty((aug.n_params, *S.shape), dtype=complex)
    dS[[aug.index[name] for name in model.names]] = dS_fit
    dS[[aug.index[name] for name in new]] = dS_new
    augmented.seed(start, S, dS)
    value, grad = augmented.evaluate(start)
    step, posterior_std = _newton_step(augmented, aug, start, grad)
    if np.all(np.abs(step) <= _FAR * posterior_std):  # near its file: one step reaches the mode
        return Augmented(augmented, aug, start, start + step, stds)
    # Far off (a sensor 5 ms late): the nuisances that absorbed the departure move back, a
    # noise floor from its boundary among them; the fit's trust-region optimiser finds the mode.
    def stop_at_the_mode(intermediate_result: OptimizeResult) -> None:
        if augmented.decrement(intermediate_result.x) < _CONVERGED:
            raise StopIteration

    found = minimize(augmented.fun, backtracked(lambda th: _posterior(augmented, th), start, step, value),
                     jac=augmented.jac,
                     hess=augmented.hess, method="trust-exact", callback=stop_at_the_mode,
                     options={"gtol": 1e-12, "maxiter": max_iter})
    converged = bool(found.success) or augmented.decrement(found.x) < _CONVERGED
    return Augmented(augmented, aug, found.x, found.x, stds, converged=converged)


def _newton_step(
    objective: WhittleObjective, model: HalfCarSpectrum, theta: np.ndarray, grad: np.ndarray
) -> tuple[np.ndarray, np.ndarray]:
    """(the scoring step at θ, the posterior std of each parameter; inf where held: a noise
    floor at its boundary)."""
    info = objective.fisher(theta)
    keep = kept(objective, model, theta, info)
    inv = inverse_information(info[np.ix_(keep, keep)])
    step, std = np.zeros_like(theta), np.full(theta.shape, np.inf)
    step[keep], std[keep] = -inv @ grad[keep], np.sqrt(np.diag(inv))
    return step, std


def backtracked(
    posterior: Callable[[np.ndarray], float], point: np.ndarray, step: np.ndarray, value: float
) -> np.ndarray:
    """``point + step``, halved until the ``posterior``'s ℓ does not exceed ``value`` (at most a
    few times); ``point`` when none does."""
    for _ in range(_HALVINGS):
        if posterior(point + step) <= value:
            return point + step
        step = 0.5 * step
    return point


def _stds(aug: HalfCarSpectrum, vehicle: Vehicle, todo: Plan) -> dict[str, float]:
    """Every prior of the posterior (θ's units): the corner values' (log scale: their relative
    tolerance), the positions' (metres), the log of the rear gain over the front one (the
    two relative tolerances combined) and the rear's delay behind the front [ms]."""
    tol = vehicle.tolerances.to_dict()
    out: dict[str, float] = {}
    for q in todo.corner:
        out |= {f"ln_{q}_{c}": max(tol[CALIBRATED[f"ln_{q}_{c}"]], _FIXED) for c in CORNERS}
    if todo.positions:
        out |= {name: max(tol[key], _FIXED) for name, key in POSITIONS.items()}
    if todo.gain:
        out["ln_rear_gain"] = math.hypot(tol["sensor_gain_front"], tol["sensor_gain_rear"])
    if todo.delay:
        out["time_offset_ms"] = tol["sensor_time_offset_s"] * 1e3
    return {name: out[name] for name in aug.names if name in out}


def _posterior(objective: WhittleObjective, theta: np.ndarray) -> float:
    """ℓ plus the prior's penalty at θ (no derivatives)."""
    S, _ = objective.model.spectrum(theta, derivatives=False)
    assert objective.prior is not None
    return objective.nll(S) + objective.prior.penalty(theta)[0]
