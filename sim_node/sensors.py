"""The simulated accelerometers: what each reads of the body's motion at its mount.

A sample is the vertical specific force (REP 145: gravity included, +g at rest) of the
body at the sensor, through the sensor's departures (:mod:`sim_node.departures`):

1. an IMU low-pass, the same in both sensors (``lowpass_hz``; 0: none): a causal
   2nd-order Butterworth (bilinear, cutoff pre-warped: -3 dB exactly at ``lowpass_hz``)
   run at the plant's internal rate on the body's acceleration before sampling; its state
   carries over between blocks and starts settled on the first value. Gravity is a
   constant and the filter's gain at 0 Hz is 1, so filtering before adding it is the same;
2. sampling at the output rate (every ``oversample``-th plant step);
3. a gain per sensor on the specific force: ``(1 + gain_error) (a + g)`` (the full car's:
   its axle's error plus the sensor's own, :attr:`Departures.corner_gains`);
4. the sensor's bias (then the simulation adds its white noise).

The time offset between the sensors is the plant's (a delayed output,
:class:`sim_node.vehicle_plant.VehiclePlant`), exact at any offset.
"""

from __future__ import annotations

import numpy as np
from scipy.signal import butter, sosfilt, sosfilt_zi

from sim_node.departures import Departures, per_channel

GRAVITY_MPS2 = 9.80665
LOWPASS_ORDER = 2
# A consumer MEMS accelerometer's white noise, the simulator's and the tools' default: the
# InvenSense MPU-6000's datasheet gives a noise density of 400 µg/√Hz, which a sensor sampled
# at 100 Hz behind a ~40 Hz low-pass reads as 400e-6 g √40 ≈ 0.025 m/s² rms (7 % of the body's
# vertical acceleration on an ISO A road at 100 km/h; automotive IMUs are within a factor of 2).
MEMS_NOISE_MPS2 = 0.025
# The same part's gyro: 0.005 °/s/√Hz behind the same ~40 Hz low-pass reads 0.005 √40 ≈ 0.032 °/s
# ≈ 5.5e-4 rad/s rms (3 % of the pitch rate on an ISO A road at 100 km/h); a bias of 0.5 °/s
# after the unit's calibration (the estimator removes each window's mean).
MEMS_GYRO_NOISE_RADPS = 5.5e-4
MEMS_GYRO_BIAS_RADPS = 0.0087


class Accelerometers:
    """The accelerometers (front and rear; the full car's four), streaming.

    Args:
        departures: the sensors' gains and low-pass (the plant's are not used here).
        plant_rate_hz: the rate of the accelerations given to :meth:`lowpass`.
        bias_mps2: constant offsets, one per channel (front, rear).
        include_gravity: add +g to the specific force (REP 145).
        full_car: the full car's four sensors (FL, FR, RL, RR), else the half car's two.
        gyros: (channels,) bool: these channels are gyros (rates, no gravity; None: none).
    """

    def __init__(self, departures: Departures, plant_rate_hz: float, bias_mps2: tuple[float, ...],
                 include_gravity: bool, full_car: bool = False, gyros: np.ndarray | None = None) -> None:
        self._sos = None
        if departures.lowpass_hz > 0.0:
            self._sos = butter(LOWPASS_ORDER, departures.lowpass_hz, fs=plant_rate_hz, output="sos")
        self._state: np.ndarray | None = None
        gains = departures.corner_gains if full_car else departures.gains
        self._gains = None if gains is None else np.asarray(per_channel(gains, len(bias_mps2)))
        self._bias = np.asarray(bias_mps2, dtype=float)
        self._gravity: float | np.ndarray = GRAVITY_MPS2 if include_gravity else 0.0
        if include_gravity and gyros is not None and np.any(gyros):  # a gyro reads no gravity
            self._gravity = np.where(gyros, 0.0, GRAVITY_MPS2)

    def lowpass(self, accel_mps2: np.ndarray) -> np.ndarray:
        """The IMU low-pass over (n, channels) accelerations at the plant's rate (continuing)."""
        if self._sos is None or accel_mps2.shape[0] == 0:
            return accel_mps2
        if self._state is None:  # settled on the first value: (sections, 2 states, 2 channels)
            self._state = sosfilt_zi(self._sos)[:, :, None] * accel_mps2[0]
        out, self._state = sosfilt(self._sos, accel_mps2, axis=0, zi=self._state)
        return np.asarray(out)

    def read(self, accel_mps2: np.ndarray) -> np.ndarray:
        """(n, channels) sampled body accelerations -> what the sensors read (before noise)."""
        if self._gains is None:  # today's operations, so runs without departures stay bit for bit
            accel = accel_mps2 + self._bias
            return accel + self._gravity if np.any(self._gravity) else accel
        return self._gains * (accel_mps2 + self._gravity) + self._bias


__all__ = ["GRAVITY_MPS2", "MEMS_GYRO_BIAS_RADPS", "MEMS_GYRO_NOISE_RADPS", "MEMS_NOISE_MPS2",
           "Accelerometers"]
