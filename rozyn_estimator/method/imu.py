"""A sensors block (an IMU's accelerometer and gyros, or any channels that see the body's
motions) as the vertical accelerations at the corners Rozyn's stage reads, either car; and the
gyros' sign check before either stage (:func:`gyro_sign_problem`).

Rozyn's stage (the thesis' method) identifies the body's modes from vertical accelerations at
known points. A block's channels give the body's accelerations ``(z₀'', φ''[, θ''])`` by least
squares on their rows (:func:`~rozyn_estimator.body_model.channel_rows`; one IMU's accel_z
and gyro_y give the half car's two exactly), a gyro's rate differenced: ``gyro_y = -φ'`` (REP
103: positive nose down), so ``φ'' = -d(gyro_y)/dt``. A rigid body's corner at ``(x_c, y_c)``
then accelerates ``z₀'' - x_c φ'' + y_c θ''``. The central difference's gain ``sin(ωΔ)/(ωΔ)``
is within 0.3 % of a derivative's up to 2 Hz at 100 Hz: the stage only starts the likelihood
fit, which models each channel exactly. The differenced gyro's noise rises with frequency;
the stage's band (the body modes) is where it is smallest.
"""

from __future__ import annotations

from collections.abc import Callable

import numpy as np
from scipy import signal

from rozyn_estimator.body_model import AnyVehicle, channel_rows
from rozyn_estimator.method.vehicle_fit.spectrum import VehicleSpectrum


def _converted(v: AnyVehicle) -> bool:
    """The stage reads the block through the corners: it holds a gyro, or other than one channel
    per corner, or (the full car) any block (the stage's plane reads accelerometers at the corners'
    places)."""
    kinds = v.channel_kinds
    return v.sensors is not None and (v.ROLLS or len(kinds) != v.CORNER_COUNT or
                                      any(kind != "accel_z" for kind in kinds))


def stage_vehicle(vehicle: AnyVehicle) -> AnyVehicle:
    """The vehicle Rozyn's stage fits: a sensors block's equivalent accelerometers at the corners."""
    if not _converted(vehicle):
        return vehicle
    return vehicle.with_corner_sensors()


def stage_input(y: np.ndarray, fs_hz: float, vehicle: AnyVehicle,
                index: tuple[int, ...] | None = None) -> tuple[np.ndarray, AnyVehicle, tuple[int, ...]]:
    """(the window as Rozyn's stage reads it, the vehicle and the columns' sensors it reads it
    with): as given for accelerometers (``index`` the columns' sensors, None: all); for a
    sensors block the corners' accelerations from the body's (module docstring)."""
    index = tuple(range(y.shape[1])) if index is None else tuple(index)
    if not _converted(vehicle):
        return y, vehicle, index
    rows, rate = channel_rows(vehicle, index)
    data = np.array(y, dtype=float)
    data[:, rate] = np.gradient(data[:, rate], 1.0 / fs_hz, axis=0)  # a rate's derivative
    body = np.linalg.lstsq(rows, data.T, rcond=None)[0]  # (b, n): z₀'', φ''[, θ'']
    c = vehicle.corners
    cols = [np.ones(c.count), -c.x_m, c.y_m][: rows.shape[1]]
    return (np.column_stack(cols) @ body).T, stage_vehicle(vehicle), tuple(range(c.count))


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
        theta = model.theta(vehicle.body_values, 1.0, np.full(len(kinds), 1e-12))
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
