"""The conditions of a simulated trial, for either car: :class:`TrialSpec`.

The vehicle decides the car (:func:`~rozyn_estimator.tools.cars.car_of`): a
:class:`~rozyn_estimator.vehicle.Vehicle` is the half car (front and rear accelerometers), a
:class:`~rozyn_estimator.vehicle_full.FullVehicle` the full car (four corner accelerometers
on two road tracks).
"""

from __future__ import annotations

import dataclasses
from dataclasses import dataclass, field
from typing import Any

import numpy as np

from rozyn_estimator.method import METHODS, PipelineConfig
from rozyn_estimator.parameters import check, param
from rozyn_estimator.tools.cars import ERROR_FIELDS, AnyVehicle, Car, car_of
from rozyn_estimator.vehicle import Vehicle
from rozyn_estimator.vehicle_full import FullVehicle
from sim_node.departures import Departures
from sim_node.load_change import with_point_load
from sim_node.road import RoadSpec
from sim_node.simulation import SimConfig

TRIAL_ROADS = ("iso", "laplace", "free-decay")


def _told(what: str) -> str:
    return f"the estimator is told the {what} * (1 + error), at every corner; in (-1, 10)"


@dataclass(frozen=True)
class TrialSpec:
    """The conditions of a trial; the seed picks the road.

    Checked here: every field's type, and the trial's own rules (road, method, duration,
    relative noise, the estimator's vehicle errors, what the car takes); errors name the
    field. The ranges of the road, sensor and departure settings are the simulator's
    (:class:`SimConfig`, :class:`RoadSpec`, :class:`Departures`), checked as this spec's
    ``sim_config``.

    Two ways to depart from the estimator's model: ``departures`` change the simulated
    plant and sensors (the estimator is not told), the ``*_error`` fields change what the
    estimator is told of the vehicle (the simulated one stays true).
    """

    road: str = param("iso", "road model", choices=TRIAL_ROADS)
    road_class: str = param("A", "ISO 8608 class of the (base) road, A..H")
    amplitudes: str = param("fixed", "fixed: the thesis' generator; gaussian: a true Gaussian road",
                            choices=("fixed", "gaussian"))
    laplace_nu: float = param(1.0, "Laplace road: variance of the section gamma variable")
    waviness: float = param(2.0, "ISO 8608 waviness w")
    speed_kmh: float = param(100.0, "vehicle speed", unit="km/h")
    duration_s: float = param(100.0, "measurement time", unit="s", low=0.0, open_low=True)
    rate_hz: float = param(100.0, "accelerometer rate", unit="Hz")
    noise_std_mps2: float = param(0.0, "white sensor noise", unit="m/s^2")
    noise_fraction: float = param(0.0, "white noise std as a share of each channel's rms", low=0.0)
    gyro_noise_std_radps: float = param(0.0, "white noise of a gyro channel (a sensors block's)",
                                        unit="rad/s")
    bias_mps2: tuple[float, float] = param((0.0, 0.0), "constant sensor offsets (front, rear)", unit="m/s^2",
                                           length=2)
    speed_variation: float = param(0.0, "relative amplitude of a sinusoidal speed change")
    speed_period_s: float = param(60.0, "period of the speed change", unit="s")
    drive_cycle: str = param("", "drive cycle the vehicle follows instead of speed_kmh (a shipped name or a "
                             "CSV file; sim_node.drive_cycle)")
    load_change_kg: float = param(0.0, "a point load put in at a stop of the drive cycle "
                                  "(sim_node.load_change)", unit="kg")
    load_change_x_m: float = param(0.0, "where that load sits behind the CoG", unit="m")
    load_change_at_s: float = param(0.0, "when the load changes (the vehicle standing)", unit="s")
    speed_error: float = param(0.0, "the estimator is told the speed times (1 + this): a wrong speed topic",
                               low=-1.0, open_low=True, high=100.0)
    periodic: bool = param(True, "road period = the record's distance (thesis eq 4-7); false: endless road")
    vehicle: AnyVehicle = field(default_factory=Vehicle)  # the true vehicle; its type picks the car
    departures: Departures = param(description="the simulated plant's and sensors' departures from the "
                                   "estimator's model", default_factory=Departures)
    stiffness_error: float = param(0.0, _told("suspension stiffness k_s"))
    damping_error: float = param(0.0, _told("suspension damping c_s"))
    tyre_stiffness_error: float = param(0.0, _told("tyre stiffness k_t"))
    tyre_damping_error: float = param(0.0, _told("tyre damping c_t"))
    unsprung_mass_error: float = param(0.0, _told("unsprung mass m_t"))
    method: str = param("", "estimation method; empty: the car's default (the half car's Rozyn's pipeline, "
                        "the full car's Rozyn's stage and the likelihood refinement)",
                        choices=("", *METHODS))
    pipeline: PipelineConfig | None = None  # overrides the method's settings

    def __post_init__(self) -> None:
        if not self.method and isinstance(self.vehicle, Vehicle | FullVehicle):  # else refused below
            object.__setattr__(self, "method", self.car.default_method)
        errors = tuple((name, lambda t, n=name: -1.0 < getattr(t, n) < 10.0, "must lie in (-1, 10)")
                       for name in ERROR_FIELDS)
        check(self, (
            ("vehicle", lambda t: isinstance(t.vehicle, Vehicle | FullVehicle),
             "expected a half car's Vehicle or a full car's FullVehicle"),
            ("method", lambda t: t.method in t.car.methods,
             f"the full car has {', '.join(car_of(FullVehicle()).methods)}"),
            ("road", lambda t: t.car.name == "half" or t.road != "free-decay",
             "the full car drives over ISO 8608 or Laplace roads (free decay: the tests)"),
            *errors,
            ("pipeline", lambda t: t.pipeline is None or isinstance(t.pipeline, PipelineConfig),
             "expected PipelineConfig settings or None"),
        ))
        self.sim_config(0)  # validates road, sim and departure settings

    @property
    def car(self) -> Car:
        """The car the vehicle is."""
        return car_of(self.vehicle)

    def sim_config(self, seed: int) -> SimConfig:
        if self.road == "free-decay":
            road = RoadSpec(kind="flat")
        else:
            road = RoadSpec(
                kind=self.road, road_class=self.road_class, amplitudes=self.amplitudes,
                laplace_nu=self.laplace_nu, waviness=self.waviness,
            )
        car: dict[str, Any] = {"vehicle": self.vehicle} if self.car.name == "half" else \
            {"model": "full", "full_vehicle": self.vehicle}
        return SimConfig(
            **car, road=road, seed=seed, speed_kmh=self.speed_kmh, drive_cycle_file=self.drive_cycle,
            speed_variation=self.speed_variation, speed_period_s=self.speed_period_s,
            rate_hz=self.rate_hz, noise_std_mps2=self.noise_std_mps2, bias_mps2=self.bias_mps2,
            gyro_noise_std_radps=self.gyro_noise_std_radps,
            duration_s=self.duration_s if self.periodic else 0.0, departures=self.departures,
            load_change_kg=self.load_change_kg, load_change_x_m=self.load_change_x_m,
            load_change_at_s=self.load_change_at_s,
        )

    def pipeline_config(self, method: str | None = None) -> PipelineConfig:
        """The estimator's settings for ``method`` (default: this spec's method)."""
        cfg = METHODS[method] if method is not None else (self.pipeline or METHODS[self.method])
        if self.road == "free-decay":
            # The signal is itself the free decay (thesis section 5-1): no correlation, and
            # nothing for a road-driven likelihood to refine.
            cfg = cfg.replace(
                correlation="free-decay", variance="none", min_duration_s=min(cfg.min_duration_s, 0.5),
                refine="none",
            )
        return cfg

    @property
    def told_errors(self) -> dict[str, float]:
        """The ``*_error`` shares the estimator is told (of each value against the vehicle's)."""
        return {key: getattr(self, key) for key in ERROR_FIELDS}

    @property
    def estimator_vehicle(self) -> AnyVehicle:
        """The vehicle the estimator is told: the true one with the ``*_error`` fields applied."""
        return self.car.told(self.vehicle, self.told_errors)

    def replace(self, **changes: Any) -> TrialSpec:
        return dataclasses.replace(self, **changes)

    @property
    def truth(self) -> np.ndarray:
        """(k,) the true parameters, in the car's order, at the run's end (after a load change in it)."""
        if self.load_change_kg and self.load_change_at_s < self.duration_s:
            return self.car.truth(with_point_load(self.vehicle, self.load_change_kg, self.load_change_x_m))
        return self.car.truth(self.vehicle)
