"""The uncertainty budget of an estimate, as GUM (JCGM 100) has it: a statistical part (the
data's, type A) and a systematic part (the assumed values', type B) — and which assumed
values contribute most.

Every assumed value ``β_j`` with a tolerance ``u_j`` (a standard uncertainty, see
:mod:`rozyn_estimator.tolerances`) moves the estimate by ``c_j = (d(m, I, lf)/dβ_j) u_j``
when it is one standard uncertainty off; the systematic covariance is ``Σ_j c_j c_jᵀ``
(the values independent) and the published covariance the sum of both parts. The
sensitivities are exact derivatives of each stage: of the refinement's optimum
(:mod:`rozyn_estimator.method.vehicle_fit.uncertainty.refine_budget`) and of Rozyn's linear fit
(:func:`rozyn_contributions`, central differences of the fit on the measured modes).
Values the data calibrate themselves (:class:`Calibration`: the sensors' gains, positions and
timing, the corners' values, with their tolerances as priors) contribute what their posterior
leaves (:mod:`rozyn_estimator.method.vehicle_fit.uncertainty.calibrate`).
"""

from __future__ import annotations

import math
from collections.abc import Callable, Sequence
from dataclasses import dataclass, field

import numpy as np

from rozyn_estimator.body_model import AnyVehicle
from rozyn_estimator.method.config import PARAM_NAMES
from rozyn_estimator.method.fit import fit_inertia
from rozyn_estimator.method.identification import IdentificationError, Mode
from rozyn_estimator.method.vehicle_fit.uncertainty.moves import (
    ABS_STEP,
    axle_channels,
    shifted_sensor,
    vehicle_moves,
)


@dataclass(frozen=True)
class Calibration:
    """A value the data calibrated (a nuisance of the refinement with its tolerance as prior).

    ``name``: a tolerance key (``suspension_damping_front_nspm`` …, ``sensor_time_offset_s``)
    or a sensor's value (``sensor_gain_rear``, ``sensor_x_front_m``). ``estimate``, ``std`` and
    ``tolerance`` are the departure from the vehicle file's value: seconds for the time
    offset, a share of the value otherwise.
    """

    name: str
    estimate: float
    std: float  # posterior standard deviation
    tolerance: float  # the prior's standard deviation

    @property
    def identified(self) -> bool:
        """The data pin it down: its posterior std is under half its tolerance."""
        return self.std < 0.5 * self.tolerance

    def text(self) -> str:
        scale, unit = {"s": (1e3, "ms"), "m": (1e3, "mm"), "rad": (57.29577951308232, "°")}.get(
            self.name.rsplit("_", 1)[-1], (100.0, "%"))
        verdict = "identified by the data" if self.identified else "not identified: its tolerance stands"
        return (f"{self.estimate * scale:+.3g} ± {self.std * scale:.2g} {unit} "
                f"(tolerance {self.tolerance * scale:.2g} {unit}; {verdict})")

    def to_dict(self) -> dict[str, object]:
        return {"name": self.name, "estimate": self.estimate, "std": self.std, "tolerance": self.tolerance,
                "identified": self.identified}


STATISTICS = "statistics"
# contributor groups, as a user reads them ("mass std 12 kg: tyre stiffness 9, …")
GROUPS = {
    "suspension_stiffness": "suspension stiffness", "suspension_damping": "suspension damping",
    "tyre_stiffness": "tyre stiffness", "tyre_damping": "tyre damping", "unsprung_mass": "unsprung masses",
    "wheelbase": "wheelbase", "sensor_front_offset": "sensor positions",
    "sensor_rear_offset": "sensor positions", "sensor_gain": "sensor gains",
    "sensor_time_offset": "sensor timing", "cog_height": "heights", "wheel_centre_height": "heights",
    "drive_model": "varying drive's model", "load_change": "load change", "track": "tracks",
    "anti_roll": "anti-roll bars",
    "sensor_lateral": "sensor positions", "gyro_misalignment": "gyro turns",
}


def group_of(key: str) -> str:
    return next((label for prefix, label in GROUPS.items() if key.startswith(prefix)), key)


@dataclass(frozen=True)
class Budget:
    """The statistical covariance and the systematic contributions of one estimate, either car."""

    statistical: np.ndarray  # (k, k), k = len(names)
    contributions: dict[str, np.ndarray] = field(default_factory=dict)  # key -> (k,) shift per 1 u
    calibration: tuple[Calibration, ...] = ()
    # of the contributions, the data-calibrated values' part that varies from window to window
    # (each window calibrates them afresh; the rest is common to every window)
    varying: dict[str, np.ndarray] = field(default_factory=dict)
    names: tuple[str, ...] = PARAM_NAMES  # the estimated parameters, in order (the car's)

    @staticmethod
    def group(key: str) -> str:
        """The contributor group a tolerance key belongs to, as a user reads it."""
        return group_of(key)

    @property
    def systematic(self) -> np.ndarray:
        out = np.zeros(self.statistical.shape)
        for c in self.contributions.values():
            out += np.outer(c, c)
        return out

    @property
    def total(self) -> np.ndarray:
        return self.statistical + self.systematic

    @property
    def varying_covariance(self) -> np.ndarray:
        """The calibrated values' part that varies between windows (``varying``'s), (k, k)."""
        return sum((np.outer(c, c) for c in self.varying.values()), np.zeros(self.statistical.shape))

    @property
    def between_windows(self) -> np.ndarray:
        """How the estimate varies between windows of the same vehicle: the statistical part and
        the calibrated values' varying part."""
        return self.statistical + self.varying_covariance

    def by_group(self, i: int) -> list[tuple[str, float]]:
        """(contributor, std) for parameter ``i``, largest first, statistics included."""
        groups: dict[str, float] = {STATISTICS: float(self.statistical[i, i])}
        for key, c in self.contributions.items():
            groups[self.group(key)] = groups.get(self.group(key), 0.0) + float(c[i]) ** 2
        return sorted(((k, math.sqrt(max(v, 0.0))) for k, v in groups.items()), key=lambda kv: -kv[1])

    def text(self, i: int, shown: int = 3) -> str:
        """``"tyre stiffness 9, suspension damping 6, statistics 1"`` (the largest few)."""
        digits = 3 if i < 2 else 2
        return ", ".join(f"{name} {_short(std, digits)}" for name, std in self.by_group(i)[:shown])

    def to_dict(self) -> dict[str, object]:
        return {
            "statistical": self.statistical.tolist(),
            "systematic": self.systematic.tolist(),
            "contributors": {name: dict(self.by_group(i)) for i, name in enumerate(self.names)},
            "calibration": [c.to_dict() for c in self.calibration],
        }


def _short(x: float, digits: int) -> str:
    return f"{x:.{digits}g}" if x >= 1e-3 or x == 0 else f"{x:.1e}"


def rozyn_contributions(
    vehicle: AnyVehicle, modes: Sequence[Mode], params: np.ndarray, model: str, kind: str = "modal",
    sensors: Sequence[int] | None = None, tolerances: dict[str, float] | None = None,
) -> dict[str, np.ndarray]:
    """Contributions ``c_j`` of each toleranced value to Rozyn's linear fit (thesis 2-4), either
    car: the fit repeated on the same measured modes with the value moved a small step (forward
    differences: the fit is smooth, the step tiny).

    ``tolerances`` as :meth:`~rozyn_estimator.tolerances.Tolerances.applying` gives them (None:
    the vehicle's). The sensors act on the modes: a gain on a channel scales its component of
    every mode shape; the rear sensors' delay ``τ`` turns their components of a mode with pole
    ``s`` by ``e^(-sτ)``. The common scale of every gain changes no shape and nothing in the fit.
    """
    index = tuple(range(len(vehicle.sensor_x_m))) if sensors is None else tuple(sensors)
    given = vehicle.tolerances.applying(vehicle) if tolerances is None else tolerances
    out = {}
    for key, tol in given.items():
        for name, step, move in _moves(vehicle, key, index):
            try:
                moved_vehicle, sensed = move(step)
                moved = fit_inertia(moved_vehicle, [sensed(md) for md in modes], model, kind, index)
            except IdentificationError:  # at the edge of the physical range: the stage's result stands
                continue
            out[name] = (moved - params) / step * tol
    return out


Sensing = Callable[[Mode], Mode]
Move = Callable[[float], tuple[AnyVehicle, Sensing]]


def _same(md: Mode) -> Mode:
    return md


def _moves(v: AnyVehicle, key: str, sensors: tuple[int, ...]) -> list[tuple[str, float, Move]]:
    """(contribution name, step, the vehicle and the sensing with the value moved by the step)."""
    alike = vehicle_moves(v, key, sensors)
    if alike is not None:
        return [(name, step, _unsensed(move)) for name, step, move in alike]
    axle = "front" if "_front" in key else "rear"
    if key in ("sensor_front_offset_m", "sensor_rear_offset_m"):
        def shifted(h: float) -> AnyVehicle:
            out = v
            for c in axle_channels(v, axle):
                out = shifted_sensor(out, c, h)
            return out
        return [(key, ABS_STEP, _unsensed(shifted))]
    if key.startswith("sensor_gain"):
        # the estimator undoes the gain it assumes: the measured shape divided by (1 + h)
        return [(key, ABS_STEP, lambda h: (v, _sensed(sensors, axle_channels(v, axle),
                                                     lambda md: 1.0 / (1.0 + h))))]
    if key == "sensor_time_offset_s":  # the rear sensors late by h: their components turned by e^(sh)
        return [(key, ABS_STEP, lambda h: (v, _sensed(sensors, axle_channels(v, "rear"),
                                                     lambda md: complex(np.exp(md.eigenvalue * h)))))]
    return []


def _unsensed(move: Callable[[float], AnyVehicle]) -> Move:
    return lambda h: (move(h), _same)


def _sensed(sensors: tuple[int, ...], channels: tuple[int, ...],
            factor: Callable[[Mode], complex]) -> Sensing:
    """Each mode with the components of the columns on ``channels`` times ``factor``."""
    cols = [j for j, s in enumerate(sensors) if s in channels]

    def apply(md: Mode) -> Mode:
        shape = list(md.shape)
        for j in cols:
            shape[j] *= factor(md)
        return Mode(md.eigenvalue, tuple(shape), md.amplitude)
    return apply
