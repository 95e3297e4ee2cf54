"""The full car's named cases of ``rozyn compare --model full --suite``, with their bars.

- ``acceptance``: issue 13's cases on the vehicle known exactly (``tolerances: {}``): the
  estimator's own statistics;
- ``mismatch``: a full car that departs from the estimator's model as real ones do
  (issue 10's departures at every corner: value errors with their tolerances set to their
  size, the sensors' gains and delay, nonlinear suspension, an IMU low-pass): the published
  uncertainty must cover the truth (≥ 90 %) without being uselessly wide (≤ 3x the rms
  error where a tolerance carries the departure).
"""

from __future__ import annotations

import dataclasses
from dataclasses import dataclass
from typing import cast

from rozyn_estimator.tools.trial_full import FullTrialSpec, told_vehicle
from rozyn_estimator.vehicle_full import FullTolerances, FullVehicle
from sim_node.departures import Departures
from sim_node.road import RoadSpec
from sim_node.simulation import SimConfig

FULL_SUITES = ("acceptance", "mismatch")
# A second full car, clearly different from Table 5-1 extended: an SUV's mass and inertias,
# a longer wheelbase and wider tracks (the rear wider), its CoG 3 cm left of the centreline,
# stiffer tyres and suspension, heavier wheels, anti-roll bars on both axles.
SECOND_FULL_VEHICLE = FullVehicle(
    sprung_mass_kg=1800.0, pitch_inertia_kgm2=3200.0, roll_inertia_kgm2=650.0, cog_from_front_axle_m=1.55,
    cog_lateral_m=0.03, wheelbase_m=3.2, track_front_m=1.62, track_rear_m=1.65,
    unsprung_mass_kg=(27.5, 27.5, 37.5, 37.5), tyre_stiffness_npm=(130e3, 130e3, 140e3, 140e3),
    tyre_damping_nspm=(50.0,) * 4, suspension_stiffness_npm=(30e3, 30e3, 45e3, 45e3),
    suspension_damping_nspm=(1900.0, 1900.0, 2250.0, 2250.0), anti_roll_stiffness_front_nmprad=25e3,
    anti_roll_stiffness_rear_nmprad=10e3, sensor_x_m=(0.0, 0.0, 3.2, 3.2),
    sensor_y_m=(0.81, -0.81, 0.825, -0.825),
)
FULL_PRESETS = {"table5-1": FullVehicle(), "second": SECOND_FULL_VEHICLE}


@dataclass(frozen=True)
class FullBars:
    """A case's bars: |bias| in per cent for m, I_xx, I_yy, l_f and in metres for y_c (None: no
    bar), the 95 % coverage's range, the failures' share, and at most how many times its rms
    error the mean published std may be (None: no bar)."""

    bias_pct: float | None = 0.5
    bias_lateral_m: float | None = 0.005
    coverage: tuple[float, float] = (0.90, 0.98)
    failure_share: float = 0.01
    max_std_per_rms: float | None = None


@dataclass(frozen=True)
class FullCase:
    label: str
    spec: FullTrialSpec
    bars: FullBars | None = None


GAUSSIAN = RoadSpec(amplitudes="gaussian")


def acceptance_cases(vehicle: FullVehicle) -> list[FullCase]:
    """Issue 13's cases on ``vehicle`` known exactly (the estimator's own statistics): Gaussian
    ISO A with 10 % sensor noise for 120 s at 30, 50, 70 and 100 km/h, and the Laplace road
    (ν = 1) at 100 km/h."""
    exact = dataclasses.replace(vehicle, tolerances=cast(FullTolerances, FullTolerances.none()))

    def case(label: str, road: RoadSpec, speed_kmh: float) -> FullCase:
        sim = SimConfig(model="full", full_vehicle=exact, road=road, speed_kmh=speed_kmh, duration_s=120.0)
        return FullCase(label, FullTrialSpec(sim=sim, noise_fraction=0.1), FullBars())

    return [case(f"Gaussian ISO A, {v:g} km/h", GAUSSIAN, v) for v in (30.0, 50.0, 70.0, 100.0)] + \
        [case("Laplace road (nu 1), 100 km/h", RoadSpec(kind="laplace", laplace_nu=1.0), 100.0)]


COVERS = FullBars(bias_pct=None, bias_lateral_m=None, coverage=(0.90, 1.0))
NOT_TOO_WIDE = dataclasses.replace(COVERS, max_std_per_rms=3.0)


def mismatch_cases(vehicle: FullVehicle) -> list[FullCase]:
    """``vehicle`` departing from the estimator's model (Gaussian ISO A, 100 km/h, 120 s, 10 %
    sensor noise): each value error with its tolerance set to the departure's size (the rest
    exact), the structural departures with the vehicle's own tolerances, a combination."""
    own = vehicle.tolerances

    def only(**tolerances: float) -> FullTolerances:
        return dataclasses.replace(cast(FullTolerances, FullTolerances.none()), **tolerances)

    def case(label: str, bars: FullBars, tolerances: FullTolerances, departures: Departures | None = None,
             **errors: float) -> FullCase:
        plant = dataclasses.replace(vehicle, tolerances=tolerances)
        sim = SimConfig(model="full", full_vehicle=plant, road=GAUSSIAN, speed_kmh=100.0, duration_s=120.0,
                        departures=departures or Departures())
        return FullCase(label, FullTrialSpec(sim=sim, noise_fraction=0.1, told=told_vehicle(plant, errors)),
                        bars)

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
