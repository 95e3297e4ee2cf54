"""The full car's sensors and corner values calibrated by the data: each sensor's gain and
position, the rear sensors' delay and each axle's corner values (:mod:`.corners`), nuisances
of the augmented posterior with their tolerances as Gaussian priors (:func:`calibrate_vehicle`).

Why not the first-order budget alone (:mod:`.refine_budget`): four sensors on one rigid body
measure its three motions, and their one redundant combination shows what the assumed sensing
gets wrong. With quiet sensors a gain or position off by its tolerance is many standard
deviations of that combination, far beyond the budget's linear range: without sensor noise
the budget put the roll inertia's std at 401 kg·m² where refitting with a sensor's gain 2 %
off moved it by 0.4 (a noise floor absorbs the departure); with 0.005 m/s² of noise the fit
bent the body's parameters to explain it (24 kg·m², the budget said 11). Fitted with their
priors, the values the data pin down are corrected and the rest keep their tolerances.

From the fit's optimum (the new values at the model's assumed ones) one scoring step of the
posterior when no value moves by more than ``_FAR`` posterior std and no noise floor's log by
more than ``_FLOOR_STEP`` (the one-step estimator; a floor at zero held), else the fit's
trust-region optimiser to the mode. Corner values act on S nonlinearly: when
the first step leaves the posterior short of its mode, a second scoring step from there (the
trust region's first, without its check evaluation), or the optimiser when far short. The
model then assumes the calibrated sensors (:class:`SensorCalibration`'s ``values``); what
their remaining uncertainty adds to the estimate is the augmented inverse information's θ
block beyond the fit's own, ``A (F_ββ + P - F_βθ A)⁻¹ Aᵀ`` with ``A = F⁻¹ F_θβ``, split per
value by the symmetric square root of the middle factor (:func:`_contributions`): when the
data know nothing of the values that is the first-order budget's contributions, value by
value.
"""

from __future__ import annotations

import dataclasses
import math
from dataclasses import dataclass, field
from typing import cast

import numpy as np

from rozyn_estimator.body_model import AnyVehicle
from rozyn_estimator.method.budget import Calibration
from rozyn_estimator.method.likelihood.guards import NOISE_AT_ZERO, aground, backtracked
from rozyn_estimator.method.vehicle_fit.spectrum import VehicleSpectrum
from rozyn_estimator.method.vehicle_fit.uncertainty import corners, sensing
from rozyn_estimator.method.vehicle_fit.uncertainty.corners import CornerCalibrating
from rozyn_estimator.method.vehicle_fit.uncertainty.moves import axle_of
from rozyn_estimator.method.vehicle_fit.whittle import WhittleObjective, ridged, scoring

_FAR = 3.0  # a step longer than this many posterior std: beyond the linear range
# a cold fit's Newton decrement at which it may hand over to the calibration: every combination
# of its parameters is then within _FAR std of its optimum, the one-step estimator's range (a fine
# fit's step or two saved; the estimates within 0.07 std of the posterior's mode, as before)
HANDOFF = _FAR**2
# a floor a small share of its channel's power is nearly flat in its log, and a step there is no
# guide: the one step holds while no floor's log moves by more than this (100 km/h: at most 0.23;
# urban windows: up to 190, the floor then 10⁸⁰ times its channel's power and the update failed)
_FLOOR_STEP = 1.0
_CONVERGED = 0.01  # Newton decrement at which the optimiser has found the mode
_SECOND_STEP = 1.0  # after the first step, a decrement below this takes one more step, above it scoring
_KEEP_MOVE = 0.01  # a warm update takes the calibration over while ln m, ln I, logit l_f, y_c [m] move less
_KEEP_UPDATES = 10  # ... for at most this many windows (at 5 s apart: as many new seconds as half a window)
_DEPARTED = 3.0  # a value further than this many tolerances from the file's gets a note
_FIXED = 1e-6  # prior std of a value without a tolerance in a calibrated group (share, m)
# each group's tolerance keys (what the budget leaves to the calibration)
TOLERANCE_KEYS = {"gain": ("sensor_gain_front", "sensor_gain_rear"),
                  "x": ("sensor_front_offset_m", "sensor_rear_offset_m"),
                  "y": ("sensor_lateral_m",), "delay": ("sensor_time_offset_s",),
                  "turn": ("gyro_misalignment_rad",)}


@dataclass(frozen=True)
class VehicleCalibration:
    """The sensors and corner values as the data calibrated them (departures from the vehicle
    file's)."""

    groups: tuple[str, ...]  # the calibrated sensor groups (:data:`.sensing.GROUPS`)
    values: np.ndarray  # the sensors' departures, all groups' (:func:`.sensing.parameter_names`; 0: not fit)
    calibrations: tuple[Calibration, ...]  # each calibrated value: estimate, posterior std, tolerance
    contributions: dict[str, np.ndarray]  # what each value's remaining uncertainty adds to (n_body,)
    body: np.ndarray  # θ's body parameters (ln m, ln I_xx, ln I_yy, logit l_f, y_c [m]) it was taken at
    age: int = 0  # the later windows that took it over
    corner_keys: tuple[str, ...] = ()  # the calibrated corner values' tolerance keys (:mod:`.corners`)
    corner_shares: np.ndarray = field(default_factory=lambda: np.zeros(0))  # their departures (shares)
    # the part of the contributions that varies from window to window: each window's data
    # calibrate the values afresh (the posterior mean's spread about the truth, M - M P⁻¹ M)
    varying: dict[str, np.ndarray] = field(default_factory=dict)

    def holds(self, theta: np.ndarray) -> bool:
        """A warm update may take it over (values and contributions): the body's parameters
        moved by less than ``_KEEP_MOVE`` since, and it is younger than ``_KEEP_UPDATES``
        windows (the vehicle does not change; the later windows' data refresh it)."""
        return self.age < _KEEP_UPDATES and \
            float(np.max(np.abs(theta[: self.body.size] - self.body))) < _KEEP_MOVE

    def departures(self) -> list[str]:
        """Notes on the values the data put further from the vehicle file's than ``_DEPARTED``
        tolerances (and posterior std): the file, or the sensor, is off."""
        return [f"{'sensor' if c.name.startswith(('sensor', 'gyro')) else 'corner'} calibration: {c.name} "
                f"{c.text()}: "
                "beyond its tolerance, check the vehicle file"
                for c in self.calibrations if abs(c.estimate) > _DEPARTED * max(c.tolerance, c.std)]

    def aged(self) -> VehicleCalibration:
        """The same, taken over by one more window."""
        return dataclasses.replace(self, age=self.age + 1)

    def same_plan(self, groups: tuple[str, ...], corner_keys: tuple[str, ...]) -> bool:
        """It calibrated these sensor groups and corner values (a window may start from it)."""
        return self.groups == groups and self.corner_keys == corner_keys

    def vehicle(self, file_vehicle: AnyVehicle) -> AnyVehicle:
        """The vehicle file's with the calibrated corner values."""
        return corners.moved(file_vehicle, self.corner_keys, self.corner_shares)

    @property
    def tolerance_keys(self) -> set[str]:
        """The vehicle's tolerance keys the calibration stands for."""
        return {key for g in self.groups for key in TOLERANCE_KEYS[g]} | set(self.corner_keys)


def sensor_groups(vehicle: AnyVehicle, sensors: tuple[int, ...]) -> tuple[str, ...]:
    """The groups the vehicle's tolerances call for (the delay with channels on both clocks only:
    :attr:`~rozyn_estimator.vehicle_full.AnyVehicle.channel_late`)."""
    tol = vehicle.tolerances.to_dict()
    late = [vehicle.channel_late[c] for c in sensors]
    both_axles = any(late) and not all(late)
    gyros = any(vehicle.channel_kinds[c] != "accel_z" for c in sensors)
    return tuple(g for g in sensing.GROUPS if any(tol.get(key, 0.0) > 0 for key in TOLERANCE_KEYS[g])
                 and (g != "delay" or both_axles) and (g != "turn" or gyros))


@dataclass(frozen=True)
class Posterior:
    """The augmented posterior (the fit's θ, then the calibrated values) and its mode: what the
    model check counts as fitted (the calibrated values absorb misfit too)."""

    objective: WhittleObjective
    point: np.ndarray


def calibrate_vehicle(
    objective: WhittleObjective, theta: np.ndarray, vehicle: AnyVehicle, groups: tuple[str, ...],
    start: VehicleCalibration | None = None, max_iter: int = 100, corner_keys: tuple[str, ...] = (),
    power: np.ndarray | None = None,
) -> tuple[np.ndarray, VehicleCalibration, Posterior]:
    """(the fit's θ at the posterior's mode, the calibration, the posterior) from the fit's
    optimum ``theta`` of ``objective``, whose model assumes the values of ``start`` (None: the
    vehicle file's, ``vehicle``). Raises ValueError when the posterior is not finite there."""
    base = objective.model
    sensor_model = base.calibrating(groups)
    model = CornerCalibrating(sensor_model, vehicle, corner_keys) if corner_keys else sensor_model
    n, k = base.n_params, base.k
    names = model.names[model.calibration_slice]
    stds = _prior_stds(vehicle, base.sensors, names)
    labels = tuple(vehicle.channel_names[c] for c in base.sensors)
    gyros = [vehicle.channel_kinds[c] != "accel_z" for c in base.sensors]
    precision = np.r_[np.zeros(n), 1.0 / stds**2]
    posterior = WhittleObjective(model, objective.periodogram, objective.counts, precision)  # type: ignore[arg-type]
    every = np.zeros(len(sensing.parameter_names(sensing.GROUPS, k))) if start is None else start.values
    shares = np.zeros(len(corner_keys)) if start is None else start.corner_shares
    point = np.r_[theta, _pick(every, groups, k), shares]
    S_nodes, dS_fit = objective.evaluated(theta)  # the same S: only the new derivatives are computed
    posterior.seed(point, S_nodes, np.concatenate([dS_fit, model.calibration_derivatives(point)]))
    value, grad = posterior.evaluate(point)
    if not math.isfinite(value):
        raise ValueError("the calibration: the posterior is not finite at the fit's optimum")
    info = posterior.information(point)
    held = _floors_at_zero(point, base.noise_slice, power)
    step, std = _scoring_step(info, precision, grad, held)
    near = bool(np.all(np.abs(step) <= _FAR * std)) and \
        bool(np.all(np.abs(step[base.noise_slice]) <= _FLOOR_STEP))
    if near:  # the one-step estimator: the information at its start stands for the mode's
        point = point + step
    remaining = posterior.decrement(point) if near and corner_keys else 0.0
    if near and _CONVERGED <= remaining < _SECOND_STEP:
        # the corner values act on S nonlinearly (a tyre's damping moves by tens of %): a
        # second step with the information there (Newton's convergence leaves ~remaining²; the
        # chord method's, with the first step's derivatives, left the estimates 0.35 std off)
        _, grad = posterior.evaluate(point)
        info = posterior.information(point)
        second = point + _scoring_step(info, precision, grad, held)[0]  # as the first step's
        point = second if _shares_valid(model, second) else point
    elif not near or remaining >= _SECOND_STEP:
        # far off: the nuisances that absorbed the departure (a noise floor) must move back, or
        # the corners too nonlinear for two steps: scoring to the mode
        found = scoring(posterior, point if near else backtracked(posterior.fun, point, step, value),
                        _CONVERGED, max_iter, near=True)
        # a floor that absorbed the departure and ran to its boundary does not come back by
        # scoring (no gradient there): revived as the fit's are (a rear sensor 5 ms late left
        # the front floor at zero and the half car's l_f 1.8 std off)
        revived = None if power is None else aground(posterior, found.x, float(found.fun), base.noise_slice,
                                                     power)
        if revived is not None:
            again = scoring(posterior, revived, _CONVERGED, max_iter, near=True)
            found = again if again.fun < found.fun else found
        point = found.x
        if not found.get("success") and (remaining := posterior.decrement(point)) >= _CONVERGED:
            raise ValueError(f"its optimiser stopped short of the posterior's mode after {found.nit} "
                             f"iterations (Newton decrement {remaining:.2g})")
        info = posterior.information(point)
    contributions, posterior_std, varying = _contributions(info, model, point, precision[n:], vehicle,
                                                           base.sensors, labels)
    fitted = point[n:]
    calibrations = tuple(Calibration(*_reported(name, labels, float(x), float(sd), float(tol)))
                         for name, x, sd, tol in zip(names, fitted, posterior_std, stds, strict=True)
                         if not _held(name, gyros))
    n_sensor = fitted.size - len(corner_keys)
    calibration = VehicleCalibration(groups, _every(fitted[:n_sensor], groups, k), calibrations,
                                     contributions, point[: base.n_body].copy(),
                                     corner_keys=corner_keys,
                                     corner_shares=fitted[n_sensor:].copy(), varying=varying)
    return point[:n], calibration, Posterior(posterior, point)


def _floors_at_zero(point: np.ndarray, noise: slice, power: np.ndarray | None) -> np.ndarray:
    """(len(point),) True at the noise floors the fit ran to zero (below :data:`NOISE_AT_ZERO` of
    their channel's band power; none when ``power`` is not given)."""
    held = np.zeros(point.size, dtype=bool)
    if power is not None:
        held[noise] = np.exp(point[noise]) < NOISE_AT_ZERO * np.asarray(power)
    return held


def _scoring_step(info: np.ndarray, precision: np.ndarray, grad: np.ndarray,
                  held: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """(the posterior's scoring step, each coordinate's posterior std) with the ``held`` floors
    still: a floor at zero is at its boundary, where the information on it vanishes, and a step
    there extrapolates from nothing (urban windows' steps put floors at up to 10⁸⁰ times their
    channel's power). Their std is 0."""
    free = ~held
    inv = np.linalg.inv((ridged(info) + np.diag(precision))[np.ix_(free, free)])
    step, std = np.zeros(grad.size), np.zeros(grad.size)
    step[free] = -inv @ grad[free]
    std[free] = np.sqrt(np.abs(np.diag(inv)))
    return step, std


def _shares_valid(model: VehicleSpectrum | CornerCalibrating, point: np.ndarray) -> bool:
    """The corner shares of ``point`` make a vehicle (each value above its lowest share)."""
    try:
        cast(CornerCalibrating, model).vehicle_at(point)
    except ValueError:
        return False
    return True


def _contributions(
    info: np.ndarray, model: VehicleSpectrum | CornerCalibrating, point: np.ndarray, precision: np.ndarray,
    vehicle: AnyVehicle, sensors: tuple[int, ...], labels: tuple[str, ...],
) -> tuple[dict[str, np.ndarray], np.ndarray, dict[str, np.ndarray]]:
    """(each calibrated value's contribution (n_body,) to the estimate, the values' posterior std, the
    contributions' part that varies between windows) from the data's information ``info`` of the
    augmented ``model``: the module docstring's split of ``A M Aᵀ``, ``M`` the values' posterior
    covariance; the varying part ``A (M - M P⁻¹ M) Aᵀ``, the spread of a window's posterior mean
    about the truth (``P`` the prior's: a value the data pin down varies as ``M``, one they do
    not as nothing)."""
    n = model.calibration_slice.start
    F, shared = ridged(info[:n, :n]), info[:n, n:]
    A = np.linalg.solve(F, shared)
    M = np.linalg.inv(info[n:, n:] + np.diag(precision) - shared.T @ A)
    to_params = model.physical_jacobian(point)[:, :n] @ A
    names = [_budget_name(vehicle, name, sensors, labels) for name in model.names[model.calibration_slice]]
    per_value, varying = (to_params @ _root(C) for C in (M, M - M @ np.diag(precision) @ M))
    return ({name: per_value[:, j] for j, name in enumerate(names)}, np.sqrt(np.clip(np.diag(M), 0.0, None)),
            {name: varying[:, j] for j, name in enumerate(names)})


def _root(C: np.ndarray) -> np.ndarray:
    """The symmetric square root of a covariance (its negative eigenvalues, rounding, as 0)."""
    lam, vec = np.linalg.eigh(0.5 * (C + C.T))
    return (vec * np.sqrt(np.clip(lam, 0.0, None))) @ vec.T


def _tolerance_key(vehicle: AnyVehicle, name: str, sensors: tuple[int, ...]) -> tuple[str, int | None]:
    """(the tolerance key, the sensor's channel slot; None for the delay and a corner value) of
    a calibrated value."""
    if name.startswith(corners.NAME_PREFIX):
        return name.removeprefix(corners.NAME_PREFIX), None
    if name == "delay_ms":
        return "sensor_time_offset_s", None
    kind, index = name.rsplit("_", 1)
    corner = sensors[int(index)]
    axle = axle_of(vehicle, corner)
    return {"ln_gain": f"sensor_gain_{axle}", "sensor_dx": f"sensor_{axle}_offset_m",
            "sensor_dy": "sensor_lateral_m", "gyro_turn": "gyro_misalignment_rad"}[kind], corner


def _prior_stds(vehicle: AnyVehicle, sensors: tuple[int, ...], names: list[str]) -> np.ndarray:
    """Each calibrated value's tolerance in θ's units (a log gain: the share; m; ms)."""
    tol = vehicle.tolerances.to_dict()
    gyros = [vehicle.channel_kinds[c] != "accel_z" for c in sensors]
    out = [0.0 if _held(name, gyros) else
           tol.get(key, 0.0) / (sensing.DELAY_SCALE_S if name == "delay_ms" else 1.0)
           for name, (key, _) in ((name, _tolerance_key(vehicle, name, sensors)) for name in names)]
    return np.maximum(np.array(out), _FIXED)


def _held(name: str, gyros: list[bool]) -> bool:
    """The calibrated value does not act on its channel (held at the file's by a tight prior): a
    gyro's position, an accelerometer's turn."""
    kind, _, index = name.rpartition("_")
    return (kind in ("sensor_dx", "sensor_dy") and gyros[int(index)]) or (kind == "gyro_turn" and
                                                                          not gyros[int(index)])


def _budget_name(vehicle: AnyVehicle, name: str, sensors: tuple[int, ...], labels: tuple[str, ...]) -> str:
    """The budget's name of a calibrated value (as :mod:`.refine_budget` names its moves)."""
    key, corner = _tolerance_key(vehicle, name, sensors)
    return key if corner is None else f"{key}[{labels[int(name.rsplit('_', 1)[1])]}]"


def _reported(name: str, labels: tuple[str, ...], value: float, std: float,
              tol: float) -> tuple[str, float, float, float]:
    """(name, estimate, std, tolerance) as :class:`Calibration` reports them (SI; the name's
    unit suffix picks the display: a gain in %, a position in mm, the delay in ms; a corner
    value: its tolerance key and share)."""
    if name.startswith(corners.NAME_PREFIX):
        return name.removeprefix(corners.NAME_PREFIX), value, std, tol
    if name == "delay_ms":
        s = sensing.DELAY_SCALE_S
        return "sensor_time_offset_s", value * s, std * s, tol * s
    kind, index = name.rsplit("_", 1)
    corner = labels[int(index)]
    label = {"ln_gain": f"sensor_gain_{corner}", "sensor_dx": f"sensor_x_{corner}_m",
             "sensor_dy": f"sensor_y_{corner}_m", "gyro_turn": f"gyro_turn_{corner}_rad"}[kind]
    return label, (math.expm1(value) if kind == "ln_gain" else value), std, tol


def _positions(groups: tuple[str, ...], k: int) -> np.ndarray:
    """Where the calibrated groups' values sit among every group's (both θ's units)."""
    chosen = set(sensing.parameter_names(groups, k))
    every = sensing.parameter_names(sensing.GROUPS, k)
    return np.array([i for i, name in enumerate(every) if name in chosen], dtype=int)


def _pick(every: np.ndarray, groups: tuple[str, ...], k: int) -> np.ndarray:
    """The calibrated groups' values out of every group's."""
    return every[_positions(groups, k)]


def _every(fitted: np.ndarray, groups: tuple[str, ...], k: int) -> np.ndarray:
    """Every group's values (zeros for those not calibrated) from the calibrated groups'."""
    out = np.zeros(len(sensing.parameter_names(sensing.GROUPS, k)))
    out[_positions(groups, k)] = fitted
    return out

