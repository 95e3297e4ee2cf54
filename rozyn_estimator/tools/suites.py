"""The named cases of ``rozyn compare --suite``, with their acceptance bars.

The first three measure the estimator on the simulator's own vehicle, known exactly
(``tolerances: {}``), whatever tolerances the base vehicle carries:

- ``issue6``: the four conditions issue 6 measured Rozyn's method on;
- ``acceptance``: issue 6's acceptance cases (speeds, a Laplace road, waviness);
- ``robustness``: sensor noise, bias and position, sample rate, road waviness, a window of
  an endless road, speed variation, off-nominal suspension;
- ``mismatch``: issue 10's vehicles that depart from the model as real ones do, with
  tolerances that contain the departures.
"""

from __future__ import annotations

import dataclasses
from dataclasses import dataclass

from rozyn_estimator.errors import ConfigError
from rozyn_estimator.tolerances import Tolerances
from rozyn_estimator.tools.trial import TrialSpec
from rozyn_estimator.vehicle import Vehicle
from sim_node.departures import Departures

SUITES = ("issue6", "acceptance", "robustness", "mismatch")
# A second vehicle, clearly different from Table 5-1: heavier, longer wheelbase, CoG further
# back, stiffer and more damped suspension, heavier wheels, stiffer and more damped tyres.
SECOND_VEHICLE = Vehicle(
    sprung_mass_kg=1800.0, pitch_inertia_kgm2=3200.0, cog_from_front_axle_m=1.55, wheelbase_m=3.2,
    unsprung_mass_front_kg=55.0, unsprung_mass_rear_kg=75.0,
    tyre_stiffness_front_npm=260_000.0, tyre_stiffness_rear_npm=280_000.0,
    tyre_damping_front_nspm=100.0, tyre_damping_rear_nspm=100.0,
    suspension_stiffness_front_npm=60_000.0, suspension_stiffness_rear_npm=90_000.0,
    suspension_damping_front_nspm=3800.0, suspension_damping_rear_nspm=4500.0,
)
VEHICLE_PRESETS = {"table5-1": Vehicle(), "second": SECOND_VEHICLE}


@dataclass(frozen=True)
class Bars:
    """Acceptance bars for one case (std in the parameters' units; None: no bar)."""

    bias_pct: float | None = 1.0
    std: tuple[float, float, float] | None = (10.0, 25.0, 0.01)
    coverage: tuple[float, float] = (0.90, 0.98)
    failure_share: float = 0.01
    max_std_per_rms: float | None = None  # the mean published std at most this x the rms error


@dataclass(frozen=True)
class Case:
    """One condition of a suite: a label, the trial spec and (acceptance only) its bars."""

    label: str
    spec: TrialSpec
    bars: Bars | None = None


def suite(name: str, base: TrialSpec) -> list[Case]:
    """The cases of a named suite, on ``base``'s vehicle (and methods).

    Raises:
        ConfigError: unknown suite name.
    """
    # The simulator's own vehicle, known exactly (tolerances {}): the estimator's statistics.
    # The mismatch suite sets the tolerances each of its cases calls for.
    exact = base.vehicle.replace(tolerances=Tolerances.none())
    iso = base.replace(road="iso", amplitudes="gaussian", road_class="A", speed_kmh=100.0, duration_s=100.0,
                       rate_hz=100.0, waviness=2.0, noise_std_mps2=0.0, noise_fraction=0.0, vehicle=exact)
    noisy = iso.replace(noise_fraction=0.1)
    if name == "issue6":
        return [
            Case("Gaussian ISO A, 100 km/h, 100 s", iso),
            Case("+10 % white sensor noise", noisy),
            Case("ISO A, 30 km/h, 120 s", iso.replace(speed_kmh=30.0, duration_s=120.0)),
            Case("Laplace nu = 1, 100 km/h, 100 s", iso.replace(road="laplace", laplace_nu=1.0)),
        ]
    if name == "acceptance":
        bars = Bars()
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
    if name == "mismatch":
        return mismatch(noisy.replace(duration_s=120.0, vehicle=base.vehicle))
    raise ConfigError(f"suite: must be one of {', '.join(SUITES)}, got {name!r}")


# Issue 10's acceptance: coverage at least 90 %; in the value-error cases also not uselessly wide
COVERS = Bars(bias_pct=None, std=None, coverage=(0.90, 1.0))
NOT_TOO_WIDE = dataclasses.replace(COVERS, max_std_per_rms=3.0)


def mismatch(noisy: TrialSpec) -> list[Case]:
    """Vehicles that depart from the estimator's model as real ones do (issue 10): each value
    error with its tolerance set to the size of the departure (the rest exact), the
    structural departures with the default tolerances, two combinations, and the model
    itself with and without tolerances."""
    v = noisy.vehicle

    def case(label: str, bars: Bars, tolerances: Tolerances, vehicle: Vehicle = v, **changes: object) -> Case:
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
