"""Command-line options shared by the tools that simulate runs (``rozyn trial``, ``rozyn compare``).

Only argparse here: the commands that use these options import the simulator themselves
(the ``*_values`` helpers return keyword arguments for its classes).
"""

from __future__ import annotations

import argparse
from collections.abc import Sequence
from typing import Any

from rozyn_estimator.sensors import Sensor, SensorSet
from rozyn_estimator.vehicle import Vehicle


def add_run_options(p: argparse.ArgumentParser, roads: Sequence[str], amplitudes: str) -> None:
    """Road, speed, duration and rate of simulated runs (``trial`` and ``compare``)."""
    p.add_argument("--road", choices=roads, default="iso", help="road model (default: iso)")
    p.add_argument("--road-class", default="A", metavar="A..H", help="ISO 8608 class (default: A)")
    p.add_argument("--amplitudes", choices=("fixed", "gaussian"), default=amplitudes,
                   help="fixed: the thesis' generator; gaussian: a true Gaussian road "
                        f"(default: {amplitudes})")
    p.add_argument("--laplace-nu", type=float, default=1.0, metavar="NU",
                   help="Laplace road: variance of the section gamma variable (default: 1.0)")
    p.add_argument("--waviness", type=float, default=2.0, metavar="W", help="ISO waviness w (default: 2)")
    p.add_argument("--speed-kmh", type=float, default=100.0, help="vehicle speed (default: 100)")
    add_drive_options(p)
    p.add_argument("--duration-s", type=float, default=100.0, help="measurement time (default: 100)")
    p.add_argument("--rate-hz", type=float, default=100.0, help="accelerometer rate (default: 100)")


def add_drive_options(p: argparse.ArgumentParser) -> None:
    """A drive cycle and a load change at one of its stops."""
    p.add_argument("--drive-cycle", default="", metavar="NAME|FILE.csv",
                   help="follow a drive cycle instead of --speed-kmh: udds (urban stop-and-go), hwfet "
                        "(highway), wltc3b, or a CSV of time_s and speed_kmh (docs/simulator.md); the "
                        "cycle repeats for longer runs (default: none)")
    p.add_argument("--load-change-kg", type=float, default=0.0, metavar="KG",
                   help="put a point load in at a stop of the drive cycle (negative: take it out); the "
                        "truth switches with it (default: 0, none)")
    p.add_argument("--load-change-x-m", type=float, default=0.0, metavar="X",
                   help="where that load sits behind the centre of gravity [m] (default: 0)")
    p.add_argument("--load-change-at-s", type=float, default=0.0, metavar="T",
                   help="when the load changes [s]: the vehicle must stand then (default: 0)")


def load_change_values(args: argparse.Namespace) -> dict[str, Any]:
    """The load change options as the simulator's parameters."""
    return {"load_change_kg": args.load_change_kg, "load_change_x_m": args.load_change_x_m,
            "load_change_at_s": args.load_change_at_s}


def drive_label(args: argparse.Namespace) -> str:
    """How the vehicle drives, for a title: the drive cycle or the speed."""
    return f"the drive cycle {args.drive_cycle}" if args.drive_cycle else f"{args.speed_kmh:g} km/h"


def add_vehicle_option(p: argparse.ArgumentParser) -> None:
    """``--vehicle FILE.yaml``: the vehicle's parameters (default: the thesis' Table 5-1), and
    ``--sensors``: where the half car's sensors are."""
    p.add_argument("--vehicle", metavar="FILE.yaml", help="vehicle parameters (default: thesis Table 5-1)")
    add_sensors_option(p)


def add_sensors_option(p: argparse.ArgumentParser) -> None:
    """``--sensors axles|imu``: where the sensors are (:func:`with_sensor_preset`)."""
    p.add_argument("--sensors", choices=SENSOR_PRESETS, default=None,
                   help="axles: the accelerometers at the vehicle's offsets (the full car's at its corners); "
                        f"imu: one IMU on /imu/data {IMU_BEHIND_COG_M:g} m behind the CoG (accel_z, gyro_y; "
                        f"the full car's {IMU_LEFT_OF_COG_M:g} m left of it too, with gyro_x) (default: the "
                        "vehicle file's sensors block, else axles)")


SENSOR_PRESETS = ("axles", "imu")
IMU_BEHIND_COG_M = 0.3  # a production car's IMU sits near the CoG (the ESC's or the airbag unit's)
IMU_LEFT_OF_COG_M = 0.2  # the full car's: off the centreline, where it sees roll in its accel_z too


def with_sensor_preset(vehicle: Any, preset: str | None) -> Any:
    """``vehicle`` (a half or a full car) with ``--sensors``' preset (None: as it is)."""
    if preset is None:
        return vehicle
    if preset == "axles":
        return vehicle.with_sensors(None)
    x = vehicle.cog_from_front_axle_m + IMU_BEHIND_COG_M
    if isinstance(vehicle, Vehicle):
        return vehicle.with_sensors(SensorSet((Sensor("imu", "/imu/data", x, 0.0, ("accel_z", "gyro_y")),)))
    y = vehicle.cog_lateral_m + IMU_LEFT_OF_COG_M
    imu = Sensor("imu", "/imu/data", x, y, ("accel_z", "gyro_x", "gyro_y"))
    return vehicle.with_sensors(SensorSet((imu,)))


def add_departure_options(p: argparse.ArgumentParser) -> None:
    """The simulated vehicle's departures from the estimator's model (``sim_node.departures``);
    the defaults are the exact half car with ideal, synchronised sensors."""
    g = p.add_argument_group("departures of the simulated vehicle from the estimator's model (the "
                             "estimator is not told)")
    g.add_argument("--damper-ratio", type=float, default=1.0, metavar="R",
                   help="dampers R times stiffer in rebound (the suspension extending) than in compression, "
                        "at the vehicle's mean damping (c_r + c_c)/2, at every corner (default: 1, linear)")
    g.add_argument("--spring-progression", type=float, default=0.0, metavar="P",
                   help="progressive springs F = k e (1 + P (e/E)^2), e the deflection from the ride "
                        "height [m]: the force P x 100 %% above the linear spring's at e = E "
                        "(default: 0, linear)")
    g.add_argument("--spring-reference-m", type=float, default=0.05, metavar="E",
                   help="E of --spring-progression [m] (default: 0.05)")
    g.add_argument("--gain-error", type=float, nargs=2, default=(0.0, 0.0), metavar=("FRONT", "REAR"),
                   help="accelerometer scale factor errors, shares: 0.03 reads 3 %% high (default: 0 0)")
    g.add_argument("--corner-gain-errors", type=float, nargs=4, default=(0.0,) * 4,
                   metavar=("FL", "FR", "RL", "RR"),
                   help="--model full: each accelerometer's own scale factor error, added to its axle's "
                        "--gain-error (default: 0 0 0 0)")
    g.add_argument("--time-offset-s", type=float, default=0.0, metavar="TAU",
                   help="the rear accelerometer (--model full: both rear ones) is TAU s late: its sample "
                        "stamped t holds the specific force at t - TAU; negative: the front one is late "
                        "(default: 0)")
    g.add_argument("--lowpass-hz", type=float, default=0.0, metavar="F",
                   help="a 2nd-order Butterworth low-pass at F Hz in both accelerometers (default: 0, none)")
    g.add_argument("--gyro-yaw-misalignment-rad", type=float, default=0.0, metavar="A",
                   help="--model full with an IMU: its gyros turned A rad about z, so gyro_x and gyro_y "
                        "each read part of the other's rate (default: 0)")


def departure_values(args: argparse.Namespace) -> dict[str, Any]:
    """The ``Departures`` fields the options of :func:`add_departure_options` give."""
    return {
        "damper_ratio": args.damper_ratio, "spring_progression": args.spring_progression,
        "spring_reference_m": args.spring_reference_m, "gain_error_front": args.gain_error[0],
        "gain_error_rear": args.gain_error[1], "time_offset_s": args.time_offset_s,
        "lowpass_hz": args.lowpass_hz, "corner_gain_errors": tuple(args.corner_gain_errors),
        "gyro_yaw_misalignment_rad": args.gyro_yaw_misalignment_rad,
    }


VEHICLE_ERROR_OPTIONS = {  # option -> (TrialSpec field, what the estimator is told wrong)
    "--stiffness-error": ("stiffness_error", "suspension stiffness"),
    "--damping-error": ("damping_error", "suspension damping"),
    "--tyre-stiffness-error": ("tyre_stiffness_error", "tyre stiffness"),
    "--tyre-damping-error": ("tyre_damping_error", "tyre damping"),
    "--unsprung-mass-error": ("unsprung_mass_error", "unsprung masses"),
}


def add_vehicle_error_options(p: argparse.ArgumentParser) -> None:
    """Wrong vehicle values told to the estimator (``TrialSpec``'s ``*_error`` fields)."""
    g = p.add_argument_group("wrong vehicle values told to the estimator (the simulated vehicle stays "
                             "the vehicle file's)")
    for option, (_, what) in VEHICLE_ERROR_OPTIONS.items():
        g.add_argument(option, type=float, default=0.0, metavar="SHARE",
                       help=f"the estimator is told the {what} times (1 + SHARE), both axles: 0.1 is "
                            "10 %% high, -0.1 10 %% low (default: 0)")


def vehicle_error_values(args: argparse.Namespace) -> dict[str, Any]:
    """The ``TrialSpec`` ``*_error`` fields the options of :func:`add_vehicle_error_options` give."""
    return {field: getattr(args, field) for field, _ in VEHICLE_ERROR_OPTIONS.values()}


def add_speed_error_option(p: argparse.ArgumentParser) -> None:
    """``--speed-error SHARE``: a speed topic that reads wrong (``TrialSpec.speed_error``)."""
    p.add_argument("--speed-error", type=float, default=0.0, metavar="SHARE",
                   help="the estimator is told the speed times (1 + SHARE), as a wrong speed topic would "
                        "tell it: 2.6 is km/h sent as m/s, 0.1 reads 10 %% high (default: 0)")
