"""The uncertainty budget of an estimate, as GUM (JCGM 100) has it: a statistical part (the
data's, type A) and a systematic part (the assumed values', type B) — and which assumed
values contribute most.

Every assumed value ``β_j`` with a tolerance ``u_j`` (a standard uncertainty, see
:mod:`rozyn_estimator.tolerances`) moves the estimate by ``c_j = (d(m, I, lf)/dβ_j) u_j``
when it is one standard uncertainty off; the systematic covariance is ``Σ_j c_j c_jᵀ``
(the values independent) and the published covariance the sum of both parts. The
sensitivities are exact derivatives of each stage: of the refinement's optimum
(:mod:`rozyn_estimator.method.full.uncertainty.refine_budget`) and of Rozyn's linear fit
(:func:`rozyn_contributions`, central differences of the fit on the measured modes).
Values the data calibrate themselves (:class:`Calibration`: the sensors' gains, positions and
timing, the corners' values, with their tolerances as priors) contribute what their posterior
leaves (:mod:`rozyn_estimator.method.full.uncertainty.calibrate`).
"""

from __future__ import annotations

import dataclasses
import math
from collections.abc import Sequence
from dataclasses import dataclass, field
from typing import ClassVar

import numpy as np

from rozyn_estimator.method.config import PARAM_NAMES
from rozyn_estimator.method.fit import fit_inertia
from rozyn_estimator.method.identification import IdentificationError, Mode
from rozyn_estimator.tolerances import RELATIVE_FIELDS
from rozyn_estimator.vehicle import Vehicle


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
    "drive_model": "varying drive's model",
}
_REL_STEP = 1e-5
_ABS_STEP = 1e-6


def group_of(key: str) -> str:
    return next((label for prefix, label in GROUPS.items() if key.startswith(prefix)), key)


@dataclass(frozen=True)
class Budget:
    """The statistical covariance and the systematic contributions of one estimate."""

    NAMES: ClassVar[tuple[str, ...]] = PARAM_NAMES  # the estimated parameters, in order

    statistical: np.ndarray  # (k, k), k = len(NAMES)
    contributions: dict[str, np.ndarray] = field(default_factory=dict)  # key -> (k,) shift per 1 u
    calibration: tuple[Calibration, ...] = ()
    # of the contributions, the data-calibrated values' part that varies from window to window
    # (each window calibrates them afresh; the rest is common to every window)
    varying: dict[str, np.ndarray] = field(default_factory=dict)

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
            "contributors": {name: dict(self.by_group(i)) for i, name in enumerate(self.NAMES)},
            "calibration": [c.to_dict() for c in self.calibration],
        }


def _short(x: float, digits: int) -> str:
    return f"{x:.{digits}g}" if x >= 1e-3 or x == 0 else f"{x:.1e}"


def rozyn_contributions(
    vehicle: Vehicle, modes: Sequence[Mode], params: np.ndarray, model: str, kind: str,
    tolerances: dict[str, float],
) -> dict[str, np.ndarray]:
    """Contributions ``c_j`` of each toleranced value to Rozyn's linear fit (thesis 2-4): the
    fit repeated on the same measured modes with the value moved a small step.

    The sensors act on the modes: a gain on a channel scales its component of every mode
    shape; the rear sensor's delay ``τ`` turns its component of a mode with pole ``s`` by
    ``e^(-sτ)``. The common scale of both gains changes no shape and nothing in the fit.
    """
    out = {}
    for key, u in tolerances.items():
        h = _REL_STEP * abs(getattr(vehicle, key)) if key in RELATIVE_FIELDS else _ABS_STEP
        try:
            moved = _refit(vehicle, modes, model, kind, key, h)
        except IdentificationError:  # at the edge of the physical range: the stage's own result stands
            continue
        out[key] = (moved - params) / h * u  # forward difference: the fit is smooth, h tiny
    return out


def _refit(
    vehicle: Vehicle, modes: Sequence[Mode], model: str, kind: str, key: str, delta: float
) -> np.ndarray:
    if key.startswith("sensor_gain") or key == "sensor_time_offset_s":
        return fit_inertia(vehicle, [_sensed(m, key, delta) for m in modes], model, kind)
    moved = dataclasses.replace(vehicle, **{key: getattr(vehicle, key) + delta})
    return fit_inertia(moved, modes, model, kind)


def _sensed(mode: Mode, key: str, delta: float) -> Mode:
    """The mode as a sensor with ``key`` moved by ``delta`` would have measured it (the
    estimator then undoes what it assumes: here, the perturbation's inverse)."""
    front, rear = mode.shape
    if key == "sensor_gain_front":
        front = front / (1.0 + delta)
    elif key == "sensor_gain_rear":
        rear = rear / (1.0 + delta)
    else:
        rear = rear * complex(np.exp(mode.eigenvalue * delta))
    return Mode(mode.eigenvalue, (front, rear), mode.amplitude)
