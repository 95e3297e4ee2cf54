"""Accelerating and braking pitch the body: the load transfer, a known input removed from the data.

A vehicle accelerating at ``a_x`` is pushed by its tyres at the road, ``h`` (``cog_height_m``)
below its centre of gravity: a pitch moment ``m h a_x`` on the body (nose down when braking).
The speed's changes are slow, but not slow enough for the fit's band (from 0.5 Hz): in town,
a 120 s window's m and I_yy read 0.6 % low with it and the model check warned on a quarter of
the windows (docs/method.md, "Real drives"). The estimator knows ``a_x`` (the speed's
derivative) and the vehicle, so it predicts the body's response at the sensors and subtracts it
before the spectra: the window's response in the frequency domain,

    y(ω) = -ω² R (K - ω² M + iω C)⁻¹ e_pitch · m h · A(ω),

with ``M, C, K`` the vehicle's equations of motion (:mod:`rozyn_estimator.body_model`, the
simulator's too) at the parameters it predicts with, ``R`` the sensors' rows and ``A`` the
acceleration's transform (zero-padded: the body starts from rest under the window's first
acceleration and the padding holds the response's decay). It predicts with the previous
estimate (or the vehicle file's values); where the fit lands more than :data:`REPREDICT` away,
once more with the fit. A few per cent off in ``m, I, l_f`` or ``h`` leaves as many per cent of
a small effect: the tolerance of ``h`` (3 cm of about 0.55 m) moves the estimates by a few
thousandths of a per cent, which the budget does not carry.

``a_x`` is the speed's derivative low-passed at :data:`ACCEL_LOWPASS_HZ` (zero phase): a speed
topic's own noise differentiated would add noise at every frequency, and a driver's
acceleration changes more slowly. Nothing is removed where the vehicle gives no heights (the
moment's arm is unknown: the docs say to give them for drives in traffic) or the speed is
constant.
"""

from __future__ import annotations

from collections.abc import Callable
from typing import TypeVar

import numpy as np
from scipy import fft
from scipy.signal import butter, sosfiltfilt

from rozyn_estimator.body_model import AnyVehicle, pitch_index, second_order_model, sensor_rates, sensor_rows
from rozyn_estimator.errors import ConfigError

# the longitudinal acceleration's band (zero-phase 2nd-order Butterworth): well above the body's
# modes, which it would otherwise dim (at 3 Hz the pitch mode's response lost 7 %)
ACCEL_LOWPASS_HZ = 8.0
REPREDICT = 0.02  # the fit this far (relative: m and the first two of the rest) from the prediction's: again
NEGLIGIBLE = 1e-3  # a response below this share of the window's rms is not removed (nothing to gain)
E = TypeVar("E")


def carries_load_transfer(vehicle: AnyVehicle, speed_mps: float | np.ndarray | None) -> bool:
    """Whether there is a load transfer to remove: the vehicle gives its CoG's height and the
    speed is given per sample."""
    return vehicle.cog_height_m > 0.0 and isinstance(speed_mps, np.ndarray) and speed_mps.ndim == 1


def longitudinal_acceleration_mps2(speed_mps: np.ndarray, fs_hz: float) -> np.ndarray:
    """The speed's derivative [m/s²], low-passed at :data:`ACCEL_LOWPASS_HZ` (zero phase)."""
    accel = np.gradient(np.asarray(speed_mps, dtype=float), 1.0 / fs_hz)
    if accel.size < 16 or 0.5 * fs_hz <= ACCEL_LOWPASS_HZ:
        return accel
    return np.asarray(sosfiltfilt(butter(2, ACCEL_LOWPASS_HZ, fs=fs_hz, output="sos"), accel))


def load_transfer_mps2(vehicle: AnyVehicle, accel_x_mps2: np.ndarray, fs_hz: float,
                       columns: tuple[int, ...] | None = None) -> np.ndarray:
    """(n, sensors) the body's vertical acceleration at the sensors (a gyro's rate; the full car's:
    those of ``columns``, default all four) from the load transfer of the longitudinal acceleration
    ``accel_x_mps2`` (n,) (see the module's docstring)."""
    model, pitch = second_order_model(vehicle), pitch_index(vehicle)
    rows, rates = sensor_rows(vehicle), sensor_rates(vehicle)  # a gyro reads the rate: iω, not -ω²
    if columns is not None:
        rows, rates = rows[list(columns)], rates[list(columns)]
    a = np.asarray(accel_x_mps2, dtype=float)
    n = a.size
    nfft = fft.next_fast_len(2 * n, real=True)
    w = 2.0 * np.pi * fft.rfftfreq(nfft, 1.0 / fs_hz)
    dynamic = (model.stiffness[None] - (w * w)[:, None, None] * model.mass[None]
               + 1j * w[:, None, None] * model.damping[None])
    force = np.zeros(model.dof)
    force[pitch] = vehicle.sprung_mass_kg * vehicle.cog_height_m
    q = np.linalg.solve(dynamic, np.broadcast_to(force, (w.size, model.dof))[..., None])[..., 0]
    reads = np.where(rates, 1j * w[:, None], -(w * w)[:, None])
    spectrum = reads * (q @ rows.T) * fft.rfft(a - a[0], nfft)[:, None]
    return fft.irfft(spectrum, nfft, axis=0)[:n]


def predicted_mps2(fs_hz: float, vehicle: AnyVehicle, params: np.ndarray, accel_x_mps2: np.ndarray,
                   columns: tuple[int, ...] | None = None) -> np.ndarray:
    """The load transfer's response at the sensors predicted at ``params``, demeaned."""
    y = load_transfer_mps2(vehicle.with_body_values(params), accel_x_mps2, fs_hz, columns)
    return y - y.mean(axis=0)


def fit_without_load_transfer(accel_mps2: np.ndarray, fs_hz: float, vehicle: AnyVehicle,
                              speed_mps: np.ndarray, start: np.ndarray | None,
                              fit: Callable[[np.ndarray, E | None], E],
                              params_of: Callable[[E], np.ndarray | None],
                              columns: tuple[int, ...] | None = None) -> E:
    """``fit(window, warm)`` on the (demeaned) window less its load transfer, predicted at
    ``start`` (None: the vehicle file's values) and, where the fit lands more than
    :data:`REPREDICT` away, at the fit (``warm`` the first fit; None: the caller's own)."""
    accel_x = longitudinal_acceleration_mps2(speed_mps, fs_hz)
    nominal = vehicle.body_values
    point = nominal if start is None or not _usable(vehicle, start) else np.asarray(start, dtype=float)
    response = predicted_mps2(fs_hz, vehicle, point, accel_x, columns)
    if np.sqrt(np.mean(response**2)) <= NEGLIGIBLE * np.sqrt(np.mean(accel_mps2**2)):
        return fit(accel_mps2, None)
    est = fit(accel_mps2 - response, None)
    found = params_of(est)
    if found is not None and _usable(vehicle, found) and np.abs(found[:3] / point[:3] - 1).max() > REPREDICT:
        est = fit(accel_mps2 - predicted_mps2(fs_hz, vehicle, found, accel_x, columns), est)
    return est


def _usable(vehicle: AnyVehicle, params: np.ndarray) -> bool:
    """Whether ``params`` make a vehicle (finite, in range, no zero for the ratio)."""
    p = np.asarray(params, dtype=float)
    if p.shape != vehicle.body_values.shape or not np.all(np.isfinite(p)) or np.any(p[:3] <= 0.0):
        return False
    try:
        vehicle.with_body_values(p)
    except ConfigError:
        return False
    return True


__all__ = ["ACCEL_LOWPASS_HZ", "carries_load_transfer", "fit_without_load_transfer", "load_transfer_mps2",
           "longitudinal_acceleration_mps2", "predicted_mps2"]
