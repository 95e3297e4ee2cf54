"""The sensors' self-calibration: the rear sensor's gain relative to the front one and its
delay behind it, fitted with the window when their tolerances allow, each with its
tolerance as a Gaussian prior (:class:`~rozyn_estimator.method.likelihood.objective.Prior`).

When the data pin a value down better than its tolerance the posterior follows the data;
when they do not, the prior keeps the value near nominal and carries its tolerance into
the covariance. Either way the estimate's uncertainty includes it (issue "Honest on a
real vehicle"). :class:`Calibration` reports each: estimate, posterior std, tolerance.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from rozyn_estimator.method.likelihood.covariance import inverse_information, kept
from rozyn_estimator.method.likelihood.model import CORNERS, HalfCarSpectrum
from rozyn_estimator.method.likelihood.objective import WhittleObjective


@dataclass(frozen=True)
class Calibration:
    """A value the data calibrated (a nuisance of the refinement with its tolerance as prior).

    ``name``: a tolerance key (``suspension_damping_front_nspm`` …, ``sensor_time_offset_s``)
    or ``sensor_gain_ratio`` (the rear gain over the front one). ``estimate``, ``std`` and
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


# θ's calibrated parameters -> the tolerance key they stand for
CALIBRATED = {
    **{f"ln_{q}_{c}": f"{key}_{c}_{unit}" for q, key, unit in (
        ("stiffness", "suspension_stiffness", "npm"), ("damping", "suspension_damping", "nspm"),
        ("tyre_stiffness", "tyre_stiffness", "npm"), ("tyre_damping", "tyre_damping", "nspm"),
        ("unsprung_mass", "unsprung_mass", "kg")) for c in CORNERS},
    "ln_rear_gain": "sensor_gain_ratio", "time_offset_ms": "sensor_time_offset_s",
}
POSITION_KEYS = {"sensor_front_x_m": "sensor_front_offset_m", "sensor_rear_x_m": "sensor_rear_offset_m"}


def calibration(objective: WhittleObjective, model: HalfCarSpectrum, start: np.ndarray, stepped: np.ndarray,
                stds: dict[str, float]) -> tuple[Calibration, ...]:
    """The calibrated values: their estimates at ``stepped``, their posterior std from the
    information at ``start``."""
    if not stds:
        return ()
    info = objective.fisher(start)
    keep = kept(objective, model, start, info)
    inv = inverse_information(info[np.ix_(keep, keep)])
    out = []
    for name, std in stds.items():
        if name == "sensor_rear_x_m" and model.pitch_gyro:  # a gyro's position: nothing to calibrate
            continue
        k = int(np.sum(keep[: model.index[name]]))
        value, sd = float(stepped[model.index[name]]), math.sqrt(inv[k, k])
        key = CALIBRATED.get(name) or POSITION_KEYS[name]
        if name == "time_offset_ms":  # reported in s
            out.append(Calibration(key, value * 1e-3, sd * 1e-3, std * 1e-3))
        elif name.startswith("ln_"):  # a log scale: reported as a share
            out.append(Calibration(key, math.expm1(value), sd, std))
        else:  # a position [m]
            out.append(Calibration(key, value, sd, std))
    return tuple(out)
