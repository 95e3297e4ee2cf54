"""A full car's sensors block (an IMU's accel_z, gyro_x and gyro_y, or any channels that see
heave, pitch and roll) for Rozyn's stage (its gyros' signs are checked before either stage:
:func:`rozyn_estimator.method.imu.gyro_sign_problem`).

Rozyn's stage identifies the body's modes from vertical accelerations at known points. The
block's channels give the body's three accelerations ``(z₀'', φ'', θ'')`` by least squares on
their rows (:func:`~rozyn_estimator.body_model.channel_rows`; a gyro's rate
differenced, as the half car's: :mod:`rozyn_estimator.method.imu`), and from them the four
corners'. The stage only starts the likelihood fit, which models each channel exactly.
"""

from __future__ import annotations

import numpy as np

from rozyn_estimator.body_model import channel_rows
from rozyn_estimator.vehicle_full import FullVehicle

STAGE_CORNERS = (0, 1, 2, 3)


def stage_vehicle(vehicle: FullVehicle) -> FullVehicle:
    """The full car Rozyn's stage fits: a sensors block's equivalent accelerometers at the corners."""
    if vehicle.sensors is None:
        return vehicle
    return vehicle.replace(sensors=None, sensor_x_m=vehicle.corner_x_m, sensor_y_m=vehicle.corner_y_m)


def stage_input(y: np.ndarray, fs_hz: float, vehicle: FullVehicle,
                index: tuple[int, ...]) -> tuple[np.ndarray, FullVehicle, tuple[int, ...]]:
    """(the window as Rozyn's stage reads it, the vehicle and the columns' corners it reads it
    with): as given for corner accelerometers; for a sensors block the four corners'
    accelerations from the body's (see the module's docstring)."""
    if vehicle.sensors is None:
        return y, vehicle, index
    rows, rate = channel_rows(vehicle, index)
    data = np.array(y, dtype=float)
    data[:, rate] = np.gradient(data[:, rate], 1.0 / fs_hz, axis=0)  # a rate's derivative
    body = np.linalg.lstsq(rows, data.T, rcond=None)[0]  # (3, n): z₀'', φ'', θ''
    corners = np.column_stack([np.ones(4), -np.array(vehicle.corner_x_m), np.array(vehicle.corner_y_m)])
    return (corners @ body).T, stage_vehicle(vehicle), STAGE_CORNERS


__all__ = ["STAGE_CORNERS", "stage_input", "stage_vehicle"]
