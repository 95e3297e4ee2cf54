"""How the simulated vehicle departs from the estimator's model, the way real vehicles do.

The estimator models the exact linear half car (or full car) with ideal, synchronised
accelerometers. A real vehicle departs from it; the simulator can too, so that
the estimator's published uncertainty can be tested against a plant it does not describe
exactly. The estimator is never told: its vehicle file stays nominal. Every default is the
exact vehicle, and a run with every departure off is bit for bit the run without them.
The full car takes each departure at each corner: the suspension's laws at all four, the
front (rear) gain error in both front (rear) sensors plus each sensor's own
(``corner_gain_errors``), the time offset in both rear sensors.

Plant (the suspension of both axles; sign convention: the extension ``e`` of a corner is
the body point above the axle minus the wheel, ``e = x_s + l_f phi - x_t,f`` at the front
and ``x_s - l_r phi - x_t,r`` at the rear (eqs 3-8, 3-9), measured from the static ride
height; ``v = de/dt > 0`` is rebound, ``v < 0`` compression; the tension ``F`` pulls body
and wheel together, so the linear corner of eqs 3-5, 3-6 carries ``F = k e + c v``):

- asymmetric dampers: ``F_d = c_r v`` in rebound and ``c_c v`` in compression, with
  ``c_r / c_c = damper_ratio`` and the same mean ``(c_r + c_c) / 2 = c``, the vehicle's
  damping. Equivalently ``F_d = c v + a c |v|`` with ``a = (ratio - 1) / (ratio + 1)``.
- progressive springs: ``F_s = k e (1 + p (e / e_ref)^2)``: the linear rate ``k`` at the
  ride height, the force ``(1 + p)`` times the linear spring's at ``|e| = e_ref``
  (``p = spring_progression``, ``e_ref = spring_reference_m``), the same in bump and
  rebound.

Sensors (each accelerometer sample is the body's vertical specific force at its mount):

- gain errors: the front (rear) sensor reads ``(1 + gain_error_front)`` (``_rear``) times
  the specific force, gravity included (then its bias and noise are added);
- a time offset of the rear sensor behind the front one: the rear sample stamped ``t``
  holds the specific force at ``t - time_offset_s`` (negative: the front sample stamped
  ``t`` holds it at ``t + time_offset_s``), exactly (:class:`sim_node.vehicle_plant.VehiclePlant`);
- an IMU low-pass, the same in both sensors: a causal 2nd-order Butterworth at
  ``lowpass_hz``, run at the plant's internal rate before sampling
  (:mod:`sim_node.sensors`).
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import ClassVar

import numpy as np

from rozyn_estimator.parameters import check, param
from rozyn_estimator.vehicle import Vehicle
from rozyn_estimator.vehicle_full import FullVehicle

_GAIN = {"low": -0.5, "high": 0.5, "read_only": True}


@dataclass(frozen=True)
class Departures:
    """The plant's and the sensors' departures from the estimator's model (``departures.*``).

    Defaults: none (the exact half car with ideal, synchronised sensors).
    """

    PARAM_PREFIX: ClassVar[str] = "departures."

    damper_ratio: float = param(1.0, "rebound/compression damping ratio c_r/c_c at the vehicle's mean "
                                "damping (c_r + c_c)/2; rebound: the suspension extends; 1: linear dampers",
                                low=0.2, high=5.0, read_only=True)
    spring_progression: float = param(0.0, "p of progressive springs F = k e (1 + p (e/e_ref)^2), e the "
                                      "deflection from the ride height: the force at e_ref is (1 + p) times "
                                      "the linear spring's; 0: linear springs", low=0.0, high=10.0,
                                      read_only=True)
    spring_reference_m: float = param(0.05, "e_ref of the progressive springs", unit="m", low=0.0,
                                      open_low=True, high=1.0, read_only=True)
    gain_error_front: float = param(0.0, "front accelerometer scale factor error (model full: both front "
                                    "ones): it reads (1 + error) times the specific force", **_GAIN)
    gain_error_rear: float = param(0.0, "rear accelerometer scale factor error (model full: both rear ones): "
                                   "it reads (1 + error) times the specific force", **_GAIN)
    time_offset_s: float = param(0.0, "rear accelerometer (model full: both rear ones) late by this: its "
                                 "sample stamped t holds the specific force at t - offset (negative: the "
                                 "front one is late)", unit="s",
                                 low=-0.1, high=0.1, read_only=True)
    corner_gain_errors: tuple[float, float, float, float] = param(
        (0.0, 0.0, 0.0, 0.0), "model full: each accelerometer's own scale factor error (FL, FR, RL, RR), "
        "added to its axle's gain_error_front/rear", length=4, **_GAIN)
    lowpass_hz: float = param(0.0, "cutoff of a 2nd-order Butterworth low-pass in both accelerometers, "
                              "run at the plant's internal rate; 0: none", unit="Hz", low=0.0,
                              high=10_000.0, read_only=True)
    gyro_yaw_misalignment_rad: float = param(0.0, "model full, a sensors block: each IMU's gyros turned by "
                                             "this angle about z: gyro_x reads cos a roll rate + sin a pitch "
                                             "rate, gyro_y -sin a roll rate + cos a pitch rate (REP 103)",
                                             unit="rad", low=-0.5, high=0.5, read_only=True)

    def __post_init__(self) -> None:
        check(self)

    @property
    def nonlinear(self) -> bool:
        """Whether the suspension departs from the linear springs and dampers."""
        return self.damper_ratio != 1.0 or self.spring_progression != 0.0

    @property
    def gains(self) -> tuple[float, ...] | None:
        """(front, rear) factors on the specific force; None when both are exactly 1."""
        if self.gain_error_front == 0.0 and self.gain_error_rear == 0.0:
            return None
        return (1.0 + self.gain_error_front, 1.0 + self.gain_error_rear)

    @property
    def corner_gains(self) -> tuple[float, ...] | None:
        """The full car's (FL, FR, RL, RR) factors; None when all are exactly 1."""
        axle = (self.gain_error_front,) * 2 + (self.gain_error_rear,) * 2
        errors = tuple(a + c for a, c in zip(axle, self.corner_gain_errors, strict=True))
        return None if not any(errors) else tuple(1.0 + e for e in errors)

    @property
    def delays_s(self) -> tuple[float, float]:
        """(front, rear) delay of each sensor's samples behind their stamps [s], both >= 0."""
        return (max(-self.time_offset_s, 0.0), max(self.time_offset_s, 0.0))

    @property
    def corner_delays_s(self) -> tuple[float, ...]:
        """The full car's (FL, FR, RL, RR) delays [s]: each axle's as :attr:`delays_s`."""
        front, rear = self.delays_s
        return (front, front, rear, rear)

    def suspension(self, vehicle: Vehicle | FullVehicle) -> SuspensionLaw | None:
        """The nonlinear part of ``vehicle``'s suspension (per axle, or per corner of a full
        car); None when it is linear."""
        if not self.nonlinear:
            return None
        c = vehicle.corners
        return SuspensionLaw(stiffness_npm=tuple(c.suspension_stiffness_npm.tolist()),
                             damping_nspm=tuple(c.suspension_damping_nspm.tolist()),
                             damper_ratio=self.damper_ratio, progression=self.spring_progression,
                             reference_m=self.spring_reference_m)


def per_channel(values: tuple[float, ...], channels: int) -> tuple[float, ...]:
    """``values`` (the half car's front and rear, the full car's corners) for ``channels`` channel
    slots: slot ``i`` takes the ``i``-th, slots past the last the last (a sensors block's further
    channels are the rear's, as their tolerances)."""
    return tuple(values[min(i, len(values) - 1)] for i in range(channels))


@dataclass(frozen=True)
class SuspensionLaw:
    """The suspension tension beyond the linear ``k e + c v`` of each corner (the half car's
    front and rear, the full car's FL, FR, RL, RR).

    See the module's docstring for the sign convention and the laws.
    """

    stiffness_npm: tuple[float, ...]  # per corner
    damping_nspm: tuple[float, ...]  # per corner
    damper_ratio: float = 1.0
    progression: float = 0.0
    reference_m: float = 0.05

    @property
    def asymmetry(self) -> float:
        """``a = (c_r - c_c) / (c_r + c_c) = (ratio - 1) / (ratio + 1)``."""
        return (self.damper_ratio - 1.0) / (self.damper_ratio + 1.0)

    def extra_tension_n(self, extension_m: np.ndarray, velocity_mps: np.ndarray) -> np.ndarray:
        """``F - (k e + c v)`` [N] of each corner; arrays ``(..., corners)`` of ``e`` [m] and ``v`` [m/s]."""
        out = np.zeros(np.broadcast_shapes(np.shape(extension_m), np.shape(velocity_mps)))
        if self.damper_ratio != 1.0:
            out += self.asymmetry * np.asarray(self.damping_nspm) * np.abs(velocity_mps)
        if self.progression != 0.0:
            k = np.asarray(self.stiffness_npm) * (self.progression / self.reference_m**2)
            out += k * np.asarray(extension_m) ** 3
        return out

    def tension_n(self, extension_m: np.ndarray, velocity_mps: np.ndarray) -> np.ndarray:
        """The whole tension ``F`` [N] of each corner (linear part included)."""
        linear = np.asarray(self.stiffness_npm) * extension_m + np.asarray(self.damping_nspm) * velocity_mps
        return linear + self.extra_tension_n(extension_m, velocity_mps)


__all__ = ["Departures", "SuspensionLaw", "per_channel"]
