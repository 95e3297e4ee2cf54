"""An IMU's accelerometer and pitch gyro as the two vertical accelerations Rozyn's stage reads.

Rozyn's stage (the thesis' method) identifies the body's modes from two vertical
accelerations. An IMU gives one vertical acceleration ``a(x)`` at its position and the pitch
rate ``gyro_y = -φ'`` (REP 103: positive nose down). A rigid body's point at ``x'`` then
accelerates ``a(x') = a(x) + (x - x') φ''``, so the stage reads the equivalent accelerations at
the axles, the pitch acceleration from the gyro's central difference (its gain
``sin(ωΔ)/(ωΔ)`` is within 0.3 % of a derivative's up to 2 Hz at 100 Hz: the stage only starts
the likelihood fit, which models the gyro exactly). The differenced gyro's noise rises with
frequency; the stage's band (the body modes) is where it is smallest.
"""

from __future__ import annotations

import numpy as np

from rozyn_estimator.vehicle import Vehicle


def stage_vehicle(vehicle: Vehicle) -> Vehicle:
    """The vehicle Rozyn's stage fits: an IMU's equivalent accelerometers at the axles."""
    if not vehicle.pitch_gyro:
        return vehicle
    return vehicle.replace(sensors=None, sensor_front_offset_m=0.0, sensor_rear_offset_m=0.0)


def stage_input(y: np.ndarray, fs_hz: float, vehicle: Vehicle) -> tuple[np.ndarray, Vehicle]:
    """(n, 2) the window as Rozyn's stage reads it, and the vehicle it reads it with: as given
    for two accelerometers; for an IMU (accel_z, gyro_y) the accelerations at the two axles."""
    if not vehicle.pitch_gyro:
        return y, vehicle
    x = vehicle.sensor_x_m[0]
    pitch_accel = -np.gradient(y[:, 1], 1.0 / fs_hz)  # φ'' = -d(gyro_y)/dt
    axles = np.array([0.0, vehicle.wheelbase_m])
    return y[:, :1] + (x - axles) * pitch_accel[:, None], stage_vehicle(vehicle)


__all__ = ["stage_input", "stage_vehicle"]
