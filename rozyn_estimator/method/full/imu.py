"""A full car's sensors block (an IMU's accel_z, gyro_x and gyro_y, or any channels that see
heave, pitch and roll) for Rozyn's stage, and its gyros' signs checked before either stage.

Rozyn's stage identifies the body's modes from vertical accelerations at known points. The
block's channels give the body's three accelerations ``(z₀'', φ'', θ'')`` by least squares on
their rows (:func:`~rozyn_estimator.body_model.channel_rows`; a gyro's rate
differenced, as the half car's: :mod:`rozyn_estimator.method.imu`), and from them the four
corners'. The stage only starts the likelihood fit, which models each channel exactly.
"""

from __future__ import annotations

import numpy as np

from rozyn_estimator.body_model import channel_rows
from rozyn_estimator.method.full.spectrum import FullCarSpectrum
from rozyn_estimator.method.imu import SIGN_SCORE, sign_scores
from rozyn_estimator.vehicle_full import FullVehicle

STAGE_CORNERS = (0, 1, 2, 3)
_AXES = {"gyro_x": ("roll", "angular_velocity.x positive when the left side rises"),
         "gyro_y": ("pitch", "angular_velocity.y positive when the nose dips")}


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


def gyro_sign_problem(y: np.ndarray, fs_hz: float, vehicle: FullVehicle,
                      speed_mps: float | None) -> str | None:
    """Why a block's gyro cannot be used (None: every one can): it reads its rate with the sign
    opposite to REP 103's. As the half car's check (:func:`rozyn_estimator.method.imu.gyro_sign_problem`):
    each gyro's cross-spectra with the accelerometers over the body modes (0.5-4 Hz), against the
    model's at the vehicle file's values; a flipped axis correlates about -1."""
    kinds = vehicle.channel_kinds
    gyros = [i for i, kind in enumerate(kinds) if kind != "accel_z"]
    accels = [i for i, kind in enumerate(kinds) if kind == "accel_z"]
    if vehicle.sensors is None or not gyros or not speed_mps:
        return None

    def model_cross(freq_hz: np.ndarray) -> np.ndarray:
        model = FullCarSpectrum(vehicle, range(len(kinds)), freq_hz, fs_hz, float(speed_mps), aliases=0)
        nominal = np.array([vehicle.sprung_mass_kg, vehicle.roll_inertia_kgm2, vehicle.pitch_inertia_kgm2,
                            vehicle.cog_from_front_axle_m, vehicle.cog_lateral_m])
        S, _ = model.spectrum(model.theta(nominal, 1.0, np.full(len(kinds), 1e-12)), derivatives=False)
        return S[:, accels][:, :, gyros]

    score = sign_scores(y, fs_hz, accels, gyros, model_cross)
    if score is None:
        return None
    flipped = [(vehicle.channel_names[g], kinds[g], s)
               for g, s in zip(gyros, score, strict=True) if s <= SIGN_SCORE]
    if not flipped:
        return None
    label, kind, s = flipped[0]
    motion, convention = _AXES[kind]
    return (f"{label} reads the {motion} rate with the sign opposite to REP 103's ({convention}; its "
            f"cross-spectrum with the accelerometer correlates {s:+.2f} with the model's): check the IMU's "
            "frame (x forward, y left, z up)")


__all__ = ["STAGE_CORNERS", "gyro_sign_problem", "stage_input", "stage_vehicle"]
