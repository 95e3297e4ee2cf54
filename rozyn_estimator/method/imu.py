"""An IMU's accelerometer and pitch gyro as the two vertical accelerations Rozyn's stage reads
(the full car's: :mod:`rozyn_estimator.method.full.imu`).

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

from collections.abc import Callable

import numpy as np
from scipy import signal

from rozyn_estimator.body_model import AnyVehicle
from rozyn_estimator.method.full.spectrum import VehicleSpectrum
from rozyn_estimator.vehicle import Vehicle
from rozyn_estimator.vehicle_full import FullVehicle


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


def gyro_sign_problem(y: np.ndarray, fs_hz: float, vehicle: AnyVehicle,
                      speed_mps: float | None) -> str | None:
    """Why a gyro cannot be used (None: every one can), either car: it reads its rate with the sign
    opposite to REP 103's. Each gyro's cross-spectra with the accelerometers over the body modes
    (0.5-4 Hz) are compared with the model's at the vehicle file's values: a flipped axis turns
    them half round (a correlation of about -1, where the right sign gives +1). Fitted anyway, a
    flipped pitch gyro read as a speed 0.4x the topic's and the half car's Rozyn stage as m +12 %,
    l_f +75 %."""
    kinds = vehicle.channel_kinds
    gyros = [i for i, kind in enumerate(kinds) if kind != "accel_z"]
    accels = [i for i, kind in enumerate(kinds) if kind == "accel_z"]
    if not gyros or not accels or not speed_mps:
        return None

    def model_cross(freq_hz: np.ndarray) -> np.ndarray:
        model = VehicleSpectrum(vehicle, range(len(kinds)), freq_hz, fs_hz, float(speed_mps), aliases=0)
        theta = model.theta(_nominal(vehicle), 1.0, np.full(len(kinds), 1e-12))
        S, _ = model.spectrum(theta, derivatives=False)
        return S[:, accels][:, :, gyros]

    scores = sign_scores(y, fs_hz, accels, gyros, model_cross)
    if scores is None:
        return None
    flipped = [(vehicle.channel_names[g], kinds[g], s) for g, s in zip(gyros, scores, strict=True)
               if s <= SIGN_SCORE]
    if not flipped:
        return None
    label, kind, score = flipped[0]
    motion, convention = _AXES[kind]
    return (f"{label} reads the {motion} rate with the sign opposite to REP 103's ({convention}; its "
            f"cross-spectrum with the accelerometer correlates {score:+.2f} with the model's): check the "
            "IMU's frame (x forward, y left, z up)")


def _nominal(v: AnyVehicle) -> np.ndarray:
    """The vehicle file's body parameters in the model's order (:mod:`..body_parameters`)."""
    if isinstance(v, FullVehicle):
        return np.array([v.sprung_mass_kg, v.roll_inertia_kgm2, v.pitch_inertia_kgm2, v.cog_from_front_axle_m,
                         v.cog_lateral_m])
    return np.array([v.sprung_mass_kg, v.pitch_inertia_kgm2, v.cog_from_front_axle_m])


_AXES = {"gyro_x": ("roll", "angular_velocity.x positive when the left side rises"),
         "gyro_y": ("pitch", "angular_velocity.y positive when the nose dips")}
SIGN_SCORE = -0.5  # the right sign correlates about +1 and noise about 0; a flipped axis about -1


def sign_scores(y: np.ndarray, fs_hz: float, accels: list[int], gyros: list[int],
                model_cross: Callable[[np.ndarray], np.ndarray]) -> np.ndarray | None:
    """(gyros,) how each gyro's cross-spectra with the accelerometers over the body modes
    (0.5-4 Hz) correlate with the model's, ``model_cross(freq_hz)`` (K, accels, gyros) as
    ``E[Y_a conj(Y_g)]``: about +1 for the right sign, -1 for a flipped axis; None for a window
    too short to tell (under 8 s, or under 8 frequencies in the band)."""
    if y.shape[0] < 8 * fs_hz:
        return None
    f, cross = signal.csd(y[:, accels, None], y[:, None, gyros], fs=fs_hz, axis=0,
                          nperseg=min(y.shape[0], round(16 * fs_hz)))
    band = (f >= 0.5) & (f <= 4.0)
    if np.count_nonzero(band) < 8:
        return None
    expected = np.conj(model_cross(f[band]))  # scipy's csd(x, y) is E[conj(X) Y]
    got = cross[band]
    return np.real(np.sum(np.conj(expected) * got, axis=(0, 1))) / \
        np.maximum(np.sum(np.abs(expected) * np.abs(got), axis=(0, 1)), 1e-300)


__all__ = ["SIGN_SCORE", "gyro_sign_problem", "sign_scores", "stage_input", "stage_vehicle"]
