"""The full car's corner values as the data may calibrate them: each toleranced axle's springs,
dampers, tyres and unsprung masses and each anti-roll bar, as a share of the vehicle file's
value (as the tolerances state them and both budgets move them:
:func:`~rozyn_estimator.method.vehicle_fit.uncertainty.moves.vehicle_moves`, an axle's share on both its
corners).

:class:`CornerCalibrating` adds those shares to a :class:`~.spectrum.VehicleSpectrum`'s θ
(after its own, the sensors' calibrated values among them) for the augmented posterior of
:mod:`.calibrate`: S at the vehicle the shares move, and its derivatives by them from the
model's analytic corner derivatives (one batched pass). The values are linear in the shares,
so their directions do not change as the shares do.
"""

from __future__ import annotations

from collections.abc import Sequence

import numpy as np

from rozyn_estimator.body_model import AnyVehicle
from rozyn_estimator.method.vehicle_fit.spectrum import VehicleSpectrum
from rozyn_estimator.method.vehicle_fit.uncertainty.moves import values_of, vehicle_moves

PREFIXES = ("suspension_stiffness", "suspension_damping", "tyre_stiffness", "tyre_damping", "unsprung_mass",
            "anti_roll_stiffness")
_LOWEST = -0.9  # a share below this would leave a value at a tenth of the file's: not a calibration
NAME_PREFIX = "corner:"  # θ's name of a share: the prefix and its tolerance key


def corner_keys(vehicle: AnyVehicle) -> tuple[str, ...]:
    """The tolerance keys of the corner values that have a tolerance (a bar only if fitted)."""
    return tuple(key for key, tol in vehicle.tolerances.to_dict().items()
                 if tol > 0 and key.startswith(PREFIXES) and vehicle_moves(vehicle, key, ()))


def _scaled(vehicle: AnyVehicle, key: str, share: float) -> AnyVehicle:
    """``vehicle`` with one key's values times ``1 + share`` (as the budgets move them)."""
    moves = vehicle_moves(vehicle, key, ())
    if not moves:
        raise ValueError(f"{key} is not a corner value of this vehicle")
    return moves[0][2](share)


def directions(vehicle: AnyVehicle, keys: Sequence[str]) -> np.ndarray:
    """(len(keys), values) the change of the corner values (:func:`.moves.values_of`) per unit
    share of each key."""
    base = values_of(vehicle)
    return np.array([values_of(_scaled(vehicle, key, 1.0)) - base for key in keys])


def moved(vehicle: AnyVehicle, keys: Sequence[str], shares: np.ndarray) -> AnyVehicle:
    """``vehicle`` with each key's values times ``1 + share``.

    Raises:
        ValueError: a share below ``_LOWEST`` (or not finite).
    """
    shares = np.asarray(shares, dtype=float)
    if not np.all(np.isfinite(shares)) or np.any(shares < _LOWEST):
        raise ValueError(f"a corner value's share outside its range: {shares}")
    out = vehicle
    for key, share in zip(keys, shares.tolist(), strict=True):
        if share:
            out = _scaled(out, key, share)
    return out


class CornerCalibrating:
    """A :class:`VehicleSpectrum` (``model``, which may calibrate sensors) whose θ also holds
    the shares of ``keys`` (last): as the model's own θ to the Whittle objective.

    Args:
        model: the model; its vehicle the one the shares start from.
        vehicle: the vehicle file's (the shares are departures from its values).
        keys: the calibrated corner values' tolerance keys (:func:`corner_keys`).
    """

    def __init__(self, model: VehicleSpectrum, vehicle: AnyVehicle, keys: Sequence[str]) -> None:
        self.model, self.file_vehicle, self.keys = model, vehicle, tuple(keys)
        self.directions = directions(vehicle, self.keys)
        self.n_model = model.n_params
        self.names = [*model.names, *(NAME_PREFIX + key for key in self.keys)]
        self.n_params = len(self.names)
        self.index = {name: i for i, name in enumerate(self.names)}
        self.calibration_slice = slice(model.calibration_slice.start, self.n_params)
        self.sensors, self.k, self.noise_slice = model.sensors, model.k, model.noise_slice

    def split(self, theta: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """(the model's θ, the shares)."""
        return theta[: self.n_model], theta[self.n_model:]

    def vehicle_at(self, theta: np.ndarray) -> AnyVehicle:
        """The vehicle θ's shares make of the file's."""
        return moved(self.file_vehicle, self.keys, self.split(theta)[1])

    def node_spectrum(self, theta: np.ndarray,
                      derivatives: bool = True) -> tuple[np.ndarray, np.ndarray | None]:
        """S at the nodes and dS/dθ (the model's rows, then the shares'); NaN where the shares
        leave their range (the likelihood reads that as impossible)."""
        own, _ = self.split(theta)
        try:
            vehicle = self.vehicle_at(theta)
        except ValueError:
            shape = (self.model.n_freq, self.k, self.k)
            return np.full(shape, np.nan, dtype=complex), \
                np.full((self.n_params, *shape), np.nan, dtype=complex) if derivatives else None
        with self.model.assuming(vehicle):
            S, dS = self.model.node_spectrum(own, derivatives)
            if dS is None:
                return S, None
            return S, np.concatenate([dS, self.model.corner_derivatives(own, self.directions)])

    def calibration_derivatives(self, theta: np.ndarray) -> np.ndarray:
        """dS (G, nodes, k, k) by the calibrated sensors' values, then the shares, at θ."""
        own, _ = self.split(theta)
        with self.model.assuming(self.vehicle_at(theta)):
            return np.concatenate([self.model.calibration_derivatives(own),
                                   self.model.corner_derivatives(own, self.directions)])

    def physical_jacobian(self, theta: np.ndarray) -> np.ndarray:
        """(n_body, n_params): the shares do not enter the body's parameters."""
        jac = np.zeros((self.model.n_body, self.n_params))
        jac[:, : self.n_model] = self.model.physical_jacobian(self.split(theta)[0])
        return jac

    def to_targets(self, m: np.ndarray, rows: np.ndarray | None = None) -> np.ndarray:
        return self.model.to_targets(m, rows)

    def to_nodes(self, m: np.ndarray) -> np.ndarray:
        return self.model.to_nodes(m)
