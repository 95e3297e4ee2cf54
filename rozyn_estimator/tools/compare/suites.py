"""The named cases of ``rozyn compare --suite``, for either car, with their acceptance bars.

The half car's:

- ``methods``: the four conditions the methods are first compared on (Gaussian ISO A at
  100 km/h, with 10 % noise, at 30 km/h, a Laplace road);
- ``acceptance``: the refinement's acceptance cases (speeds, a Laplace road, waviness);
- ``robustness``: sensor noise, bias and position, sample rate, road waviness, a window of
  an endless road, speed variation, off-nominal suspension;
- ``mismatch``: vehicles that depart from the model as real ones do, with tolerances that
  contain the departures.

The full car's ``acceptance`` (four speeds and a Laplace road) and ``mismatch`` (the same
departures at every corner). Both cars' ``drive-cycles``: 300 s of each shipped cycle from its
start (urban, highway, WLTC), one with the heights given (the load transfer on), one with the
default tolerances. Both cars' ``sensors``: one IMU against the accelerometers on the same
roads (the full car's mixed sets and a turned IMU too). ``methods``, ``acceptance`` and
``robustness`` measure the
estimator on the simulator's own vehicle known exactly (``tolerances: {}``), whatever
tolerances the base vehicle carries.
"""

from __future__ import annotations

import dataclasses
import math
from dataclasses import dataclass
from typing import Any, cast

from rozyn_estimator.errors import ConfigError
from rozyn_estimator.sensors import Sensor, SensorSet
from rozyn_estimator.tolerances import Tolerances
from rozyn_estimator.tools.options import with_sensor_preset
from rozyn_estimator.tools.trial.spec import TrialSpec
from rozyn_estimator.vehicle import Vehicle
from rozyn_estimator.vehicle_full import CORNERS, FullTolerances
from sim_node.departures import Departures

SUITES = {"half": ("methods", "acceptance", "robustness", "mismatch", "drive-cycles", "sensors"),
          "full": ("acceptance", "mismatch", "drive-cycles", "sensors")}


@dataclass(frozen=True)
class Bars:
    """Acceptance bars for one case (None: no bar)."""

    bias_pct: float | None = 1.0  # |bias| of every parameter but the lateral CoG, per cent of the truth
    bias_lateral_m: float | None = 0.005  # |bias| of the lateral CoG (the full car)
    std: tuple[float, ...] | None = None  # the spread's ceiling per parameter, in its units
    coverage: tuple[float, float] = (0.90, 0.98)
    failure_share: float = 0.01
    max_std_per_rms: float | None = None  # the mean published std at most this x the rms error


@dataclass(frozen=True)
class Case:
    """One condition of a suite: a label, the trial spec and (acceptance only) its bars."""

    label: str
    spec: TrialSpec
    bars: Bars | None = None


# Where the departures are carried by a tolerance of their size: coverage at least 90 %, and
# (value errors) not uselessly wide.
COVERS = Bars(bias_pct=None, bias_lateral_m=None, coverage=(0.90, 1.0))
NOT_TOO_WIDE = dataclasses.replace(COVERS, max_std_per_rms=3.0)


def suite(name: str, base: TrialSpec) -> list[Case]:
    """The cases of a named suite, on ``base``'s vehicle (its car's suites).

    Raises:
        ConfigError: a suite its car does not have.
    """
    car = base.car.name
    if name not in SUITES[car]:
        raise ConfigError(f"suite: the {base.car.title} has the suites {', '.join(SUITES[car])}; "
                          f"got {name!r}")
    # The simulator's own vehicle, known exactly (tolerances {}): the estimator's statistics.
    # The mismatch suites set the tolerances each of their cases calls for.
    vehicle: Any = base.vehicle  # either car's: each replaces its own tolerances' type
    exact = dataclasses.replace(vehicle, tolerances=vehicle.tolerances.none())
    iso = base.replace(road="iso", amplitudes="gaussian", road_class="A", speed_kmh=100.0, duration_s=100.0,
                       rate_hz=100.0, waviness=2.0, noise_std_mps2=0.0, noise_fraction=0.0, vehicle=exact)
    noisy = iso.replace(noise_fraction=0.1)
    if name == "drive-cycles":
        return _drive_cycles(noisy, base.vehicle)
    if name == "sensors":
        return _sensor_sets(noisy.replace(duration_s=120.0), base.vehicle)
    if car == "full":
        return _full_acceptance(noisy) if name == "acceptance" else \
            _full_mismatch(noisy.replace(duration_s=120.0, vehicle=base.vehicle))
    if name == "methods":
        return [
            Case("Gaussian ISO A, 100 km/h, 100 s", iso),
            Case("+10 % white sensor noise", noisy),
            Case("ISO A, 30 km/h, 120 s", iso.replace(speed_kmh=30.0, duration_s=120.0)),
            Case("Laplace nu = 1, 100 km/h, 100 s", iso.replace(road="laplace", laplace_nu=1.0)),
        ]
    if name == "acceptance":
        bars = Bars(std=(10.0, 25.0, 0.01))
        cases = [Case("ISO A, 100 km/h, 100 s, 10 % noise", noisy, bars)]
        cases += [
            Case(f"ISO A, {v:g} km/h, 120 s, 10 % noise", noisy.replace(speed_kmh=v, duration_s=120.0), bars)
            for v in (30.0, 50.0, 70.0, 100.0)
        ]
        cases += [
            Case("Laplace nu = 1, 100 km/h, 100 s, 10 % noise", noisy.replace(road="laplace"), bars),
            Case("waviness w = 2.5, 100 km/h, 100 s, 10 % noise", noisy.replace(waviness=2.5),
                 dataclasses.replace(bars, bias_pct=2.0)),
        ]
        return cases
    if name == "robustness":
        moved = noisy.vehicle.replace(sensor_front_offset_m=0.4, sensor_rear_offset_m=-0.5)
        return [
            Case("no sensor noise", iso),
            Case("10 % white sensor noise", noisy),
            Case("30 % white sensor noise", iso.replace(noise_fraction=0.3)),
            Case("sensor bias +0.2 / -0.3 m/s^2", noisy.replace(bias_mps2=(0.2, -0.3))),
            Case("sensors 0.4 m behind front, 0.5 m ahead of rear axle", noisy.replace(vehicle=moved)),
            *[Case(f"sample rate {r:g} Hz", noisy.replace(rate_hz=r)) for r in (50.0, 200.0, 400.0)],
            *[Case(f"road waviness w = {w:g}", noisy.replace(waviness=w)) for w in (1.5, 2.5, 3.0)],
            Case("window from an endless road (not periodic)", noisy.replace(periodic=False)),
            Case("speed 100 km/h +-10 % (60 s period)", noisy.replace(speed_variation=0.1)),
            *[Case(f"known stiffness {e:+.0%}", noisy.replace(stiffness_error=e)) for e in (0.1, -0.1)],
            *[Case(f"known damping {e:+.0%}", noisy.replace(damping_error=e)) for e in (0.1, -0.1)],
        ]
    return _half_mismatch(noisy.replace(duration_s=120.0, vehicle=base.vehicle))


def _half_mismatch(noisy: TrialSpec) -> list[Case]:
    """Vehicles that depart from the estimator's model as real ones do: each value error with
    its tolerance set to the size of the departure (the rest exact), the structural
    departures with the default tolerances, two combinations, and the model itself with and
    without tolerances."""
    v = noisy.vehicle
    assert isinstance(v, Vehicle)

    def case(label: str, bars: Bars, tolerances: Tolerances, vehicle: Any = v, **changes: object) -> Case:
        return Case(label, noisy.replace(vehicle=vehicle.replace(tolerances=tolerances), **changes), bars)

    def only(**tolerances: float) -> Tolerances:
        return Tolerances.from_mapping(tolerances)

    tyres = {"tyre_stiffness_front_npm": 0.10, "tyre_stiffness_rear_npm": 0.10}
    heavier = v.replace(unsprung_mass_front_kg=1.15 * v.unsprung_mass_front_kg,
                        unsprung_mass_rear_kg=1.15 * v.unsprung_mass_rear_kg)
    default = Tolerances()
    return [
        case("the model itself, tolerances {}", COVERS, Tolerances.none()),
        case("the model itself, default tolerances", COVERS, default),
        case("front accelerometer gain +3 %, its tolerance 3 %", NOT_TOO_WIDE, only(sensor_gain_front=0.03),
             departures=Departures(gain_error_front=0.03)),
        case("rear accelerometer 5 ms late, its tolerance 5 ms", NOT_TOO_WIDE,
             only(sensor_time_offset_s=0.005), departures=Departures(time_offset_s=0.005)),
        case("tyre stiffness 10 % below the vehicle file, tolerance 10 %", NOT_TOO_WIDE, only(**tyres),
             tyre_stiffness_error=1 / 0.9 - 1),
        case("unsprung masses 15 % above the vehicle file, tolerance 15 %", NOT_TOO_WIDE,
             only(unsprung_mass_front_kg=0.15, unsprung_mass_rear_kg=0.15), heavier,
             unsprung_mass_error=1 / 1.15 - 1),
        case("suspension stiffness 10 % off, tolerance 10 %", NOT_TOO_WIDE,
             only(suspension_stiffness_front_npm=0.10, suspension_stiffness_rear_npm=0.10),
             stiffness_error=0.10),
        case("dampers 2x stiffer in rebound (same mean), default tolerances", COVERS, default,
             departures=Departures(damper_ratio=2.0)),
        case("progressive springs (+100 % at 50 mm), default tolerances", COVERS, default,
             departures=Departures(spring_progression=1.0)),
        case("20 Hz low-pass in both accelerometers, default tolerances", COVERS, default,
             departures=Departures(lowpass_hz=20.0)),
        case("front gain +3 % and rear 5 ms late, tolerances 3 % and 5 ms", NOT_TOO_WIDE,
             only(sensor_gain_front=0.03, sensor_time_offset_s=0.005),
             departures=Departures(gain_error_front=0.03, time_offset_s=0.005)),
        case("tyres 10 % soft and dampers 2x in rebound, default tolerances with tyres 10 %", COVERS,
             dataclasses.replace(default, **tyres), tyre_stiffness_error=1 / 0.9 - 1,
             departures=Departures(damper_ratio=2.0)),
    ]


def _drive_cycles(noisy: TrialSpec, vehicle: Any) -> list[Case]:
    """300 s of each shipped cycle from its start (idling, pulling away, stops), the vehicle
    known exactly, 10 % noise; the urban cycle with the heights given (accelerating and braking
    pitch the body) and with the vehicle's own tolerances."""
    bars = Bars(bias_pct=0.5)
    drive = noisy.replace(duration_s=300.0)
    heights = drive.vehicle.replace(cog_height_m=0.55, wheel_centre_height_m=0.30)
    return [
        Case("urban (udds), 300 s", drive.replace(drive_cycle="udds"), bars),
        Case("highway (hwfet), 300 s", drive.replace(drive_cycle="hwfet"), bars),
        Case("WLTC class 3b, 300 s", drive.replace(drive_cycle="wltc3b"), bars),
        Case("urban, CoG 0.55 m and wheel centres 0.30 m up (load transfer)",
             drive.replace(drive_cycle="udds", vehicle=heights), bars),
        Case("urban, the vehicle's own tolerances", drive.replace(drive_cycle="udds", vehicle=vehicle),
             COVERS),
    ]


def _sensor_sets(noisy: TrialSpec, vehicle: Any) -> list[Case]:
    """The accelerometers (the half car's two at the axles, the full car's four at the corners)
    and one IMU (``rozyn trial --sensors imu``'s) on the same roads, the vehicle known exactly,
    10 % noise of each channel's rms; the IMU with the vehicle's own tolerances; mixed sets (an
    IMU and two accelerometers at the axles' centres; the half car's three accelerometers along
    it; the full car's IMU and rear accelerometer, three corner accelerometers) and the full car's
    IMU turned 2° about z, with its own tolerances."""
    bars = Bars(bias_pct=0.5)
    exact = noisy.vehicle
    imu = with_sensor_preset(exact, "imu")
    toleranced = with_sensor_preset(vehicle, "imu")
    cases = [Case("the accelerometers", noisy.replace(vehicle=exact.with_sensors(None)), bars),
             Case("one IMU", noisy.replace(vehicle=imu), bars),
             Case("one IMU, the vehicle's own tolerances", noisy.replace(vehicle=toleranced), COVERS)]
    own = imu.sensors.sensors[0]
    axles = (Sensor("front", "/accel/front", 0.0, 0.0), Sensor("rear", "/accel/rear", exact.wheelbase_m, 0.0))
    mixed = [Case("one IMU and two accelerometers at the axles' centres",
                  noisy.replace(vehicle=exact.with_sensors(SensorSet((own, *axles)))), bars)]
    if isinstance(exact, Vehicle):
        mid = Sensor("mid", "/accel/mid", exact.wheelbase_m / 2, 0.0)
        three = SensorSet((axles[0], mid, axles[1]))
        return [*cases, *mixed, Case("three accelerometers (the axles and mid-wheelbase)",
                                     noisy.replace(vehicle=exact.with_sensors(three)), bars)]
    x, y = exact.corner_x_m, exact.corner_y_m
    rear = SensorSet((own, axles[1]))
    three = SensorSet(tuple(Sensor(c, f"/accel/{c}", x[i], y[i]) for i, c in enumerate(CORNERS[:3])))
    turn = Departures(gyro_yaw_misalignment_rad=math.radians(2.0))
    turned = noisy.replace(vehicle=toleranced, departures=turn)
    return [*cases, *mixed,
            Case("one IMU and an accelerometer at the rear axle",
                 noisy.replace(vehicle=exact.with_sensors(rear)), bars),
            Case("three corner accelerometers (FL, FR, RL)", noisy.replace(vehicle=exact.with_sensors(three)),
                 bars),
            Case("one IMU turned 2 deg about z, its own tolerances", turned, COVERS)]


def _full_acceptance(noisy: TrialSpec) -> list[Case]:
    """The full car known exactly: Gaussian ISO A with 10 % sensor noise for 120 s at 30, 50, 70
    and 100 km/h, and the Laplace road (ν = 1, the thesis' fixed amplitudes) at 100 km/h."""
    bars = Bars(bias_pct=0.5)
    cases = [Case(f"Gaussian ISO A, {v:g} km/h", noisy.replace(speed_kmh=v, duration_s=120.0), bars)
             for v in (30.0, 50.0, 70.0, 100.0)]
    laplace = noisy.replace(road="laplace", amplitudes="fixed", laplace_nu=1.0, duration_s=120.0)
    return [*cases, Case("Laplace road (nu 1), 100 km/h", laplace, bars)]


def _full_mismatch(noisy: TrialSpec) -> list[Case]:
    """The full car departing from the estimator's model (Gaussian ISO A, 100 km/h, 120 s, 10 %
    sensor noise): each value error with its tolerance set to the departure's size (the rest
    exact), the structural departures with the vehicle's own tolerances, a combination."""
    own = cast(FullTolerances, noisy.vehicle.tolerances)

    def only(**tolerances: float) -> FullTolerances:
        return dataclasses.replace(cast(FullTolerances, FullTolerances.none()), **tolerances)

    def case(label: str, bars: Bars, tolerances: FullTolerances, departures: Departures | None = None,
             **errors: float) -> Case:
        plant = dataclasses.replace(noisy.vehicle, tolerances=tolerances)
        spec = noisy.replace(vehicle=plant, departures=departures or Departures(), **errors)
        return Case(label, spec, bars)

    gains = Departures(corner_gain_errors=(0.03, -0.02, 0.0, 0.02))
    return [
        case("the model itself, the vehicle's tolerances", COVERS, own),
        case("accelerometer gains +3 / -2 / 0 / +2 %, tolerances 3 %", NOT_TOO_WIDE,
             only(sensor_gain_front=0.03, sensor_gain_rear=0.03), gains),
        case("rear accelerometers 5 ms late, tolerance 5 ms", NOT_TOO_WIDE, only(sensor_time_offset_s=0.005),
             Departures(time_offset_s=0.005)),
        case("tyre stiffness 10 % below the vehicle file, tolerance 10 %", NOT_TOO_WIDE,
             only(tyre_stiffness_front_npm=0.10, tyre_stiffness_rear_npm=0.10),
             tyre_stiffness_error=1 / 0.9 - 1),
        case("suspension stiffness 10 % off, tolerance 10 %", NOT_TOO_WIDE,
             only(suspension_stiffness_front_npm=0.10, suspension_stiffness_rear_npm=0.10),
             stiffness_error=0.10),
        case("dampers 2x stiffer in rebound (same mean), the vehicle's tolerances", COVERS, own,
             Departures(damper_ratio=2.0)),
        case("progressive springs (+100 % at 50 mm), the vehicle's tolerances", COVERS, own,
             Departures(spring_progression=1.0)),
        case("20 Hz low-pass in every accelerometer, the vehicle's tolerances", COVERS, own,
             Departures(lowpass_hz=20.0)),
        case("gains off, rear 5 ms late and dampers 2x in rebound, tolerances 3 % and 5 ms", COVERS,
             dataclasses.replace(own, sensor_gain_front=0.03, sensor_gain_rear=0.03,
                                 sensor_time_offset_s=0.005),
             dataclasses.replace(gains, time_offset_s=0.005, damper_ratio=2.0)),
    ]
