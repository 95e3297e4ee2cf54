"""The two cars the tools simulate and estimate, and what differs between them, in one place.

The half car (front and rear accelerometers: m, I_yy, l_f) and the full car (three or four
corner accelerometers on two road tracks: m, I_xx, I_yy, l_f, y_c). A :class:`Car` holds
its parameters (columns, symbols, units, formats), the body modes it records, its
accelerometers, its methods and built-in vehicles, how its values are told wrong to the
estimator (``--stiffness-error`` …) and its estimator. ``rozyn trial``, ``compare`` and
``study`` take the car from the vehicle (:func:`car_of`) or from ``--model``.

Relative statistics (bias, share within 6 %, precision, the shortest drive for 1 %) are
taken against the truth, except for the lateral CoG, whose truth is often 0: against the
half track (:attr:`Parameter.of_half_track`).
"""

from __future__ import annotations

import dataclasses
from collections.abc import Callable
from dataclasses import dataclass
from typing import Any

import numpy as np

from rozyn_estimator.body_model import AnyVehicle
from rozyn_estimator.errors import ConfigError
from rozyn_estimator.method import METHODS
from rozyn_estimator.vehicle import Vehicle, load_vehicle
from rozyn_estimator.vehicle_full import FullVehicle, load_full_vehicle


@dataclass(frozen=True)
class Parameter:
    """One estimated parameter as the tools show it."""

    name: str  # its column and JSON key (``mass_kg``)
    vehicle_field: str  # the vehicle's field holding its truth
    symbol: str  # ``m``
    label: str  # ``mass``
    description: str  # a report's row: ``mass``, ``CoG from front axle``
    unit: str  # ``kg``
    value_fmt: str  # a value in a table
    spread_fmt: str  # a spread in a table
    of_half_track: bool = False  # relative statistics against the half track, not the truth

    @property
    def relative_to(self) -> str:
        """What its relative statistics are a share of: ``truth`` or ``half track``."""
        return "half track" if self.of_half_track else "truth"


# The told-wrong options (``--stiffness-error`` …): TrialSpec field -> the value it scales.
ERROR_FIELDS = ("stiffness_error", "damping_error", "tyre_stiffness_error", "tyre_damping_error",
                "unsprung_mass_error")
HALF_ERRORS = {  # the half car's per-axle fields, both axles
    "stiffness_error": ("suspension_stiffness_front_npm", "suspension_stiffness_rear_npm"),
    "damping_error": ("suspension_damping_front_nspm", "suspension_damping_rear_nspm"),
    "tyre_stiffness_error": ("tyre_stiffness_front_npm", "tyre_stiffness_rear_npm"),
    "tyre_damping_error": ("tyre_damping_front_nspm", "tyre_damping_rear_nspm"),
    "unsprung_mass_error": ("unsprung_mass_front_kg", "unsprung_mass_rear_kg"),
}
FULL_ERRORS = {  # the full car's per-corner fields, all four corners
    "stiffness_error": "suspension_stiffness_npm", "damping_error": "suspension_damping_nspm",
    "tyre_stiffness_error": "tyre_stiffness_npm", "tyre_damping_error": "tyre_damping_nspm",
    "unsprung_mass_error": "unsprung_mass_kg",
}


def _told_half(vehicle: Any, errors: dict[str, float]) -> Any:
    changes = {name: getattr(vehicle, name) * (1.0 + e) for key, names in HALF_ERRORS.items()
               if (e := errors.get(key, 0.0)) != 0.0 for name in names}
    return vehicle.replace(**changes) if changes else vehicle


def _told_full(vehicle: Any, errors: dict[str, float]) -> Any:
    changes = {name: tuple(x * (1.0 + e) for x in getattr(vehicle, name)) for key, name in FULL_ERRORS.items()
               if (e := errors.get(key, 0.0)) != 0.0}
    return dataclasses.replace(vehicle, **changes) if changes else vehicle


@dataclass(frozen=True)
class Car:
    """A vehicle model of the tools: what it estimates, senses, simulates and runs."""

    name: str  # "half" | "full": ``--model``, SimConfig.model
    title: str  # "half car", "full car"
    params: tuple[Parameter, ...]
    n_modes: int  # body modes recorded per trial (by frequency)
    channels: tuple[tuple[str, str], ...]  # the accelerometers: (label, subscript)
    methods: tuple[str, ...]  # the estimation methods it has
    default_method: str  # a trial's and ``rozyn study``'s when none is given
    vehicle_type: type
    presets: dict[str, Any]  # the built-in vehicles (``--vehicle-preset``)
    noise_stream: int  # the relative sensor noise's random stream per seed (the simulator's are below)
    load: Callable[[str], Any]  # reads its vehicle file
    told: Callable[[Any, dict[str, float]], Any]  # the vehicle with the ``*_error`` shares applied

    @property
    def names(self) -> tuple[str, ...]:
        return tuple(p.name for p in self.params)

    @property
    def scaled(self) -> np.ndarray:
        """(k,) bool: the parameters whose relative statistics are of the half track."""
        return np.array([p.of_half_track for p in self.params])

    def truth(self, vehicle: AnyVehicle) -> np.ndarray:
        """(k,) the true values of the parameters."""
        return np.array([getattr(vehicle, p.vehicle_field) for p in self.params])

    def reference(self, vehicle: AnyVehicle) -> np.ndarray:
        """(k,) what relative statistics are a share of: the truth, or the half track."""
        truth = self.truth(vehicle)
        if not self.scaled.any():
            return truth
        assert isinstance(vehicle, FullVehicle)
        half_track = 0.25 * (vehicle.track_front_m + vehicle.track_rear_m)
        return np.where(self.scaled, half_track, truth)

    def relative_pct(self, values: np.ndarray, truth: np.ndarray, reference: np.ndarray) -> np.ndarray:
        """Errors of ``values`` (..., k) in per cent: of the truth (value / truth − 1), or of
        the half track ((value − truth) / half track)."""
        scaled = self.scaled
        with np.errstate(divide="ignore", invalid="ignore"):  # a zero truth where the half track is used
            of_truth = (values / truth - 1.0) * 100.0
        if not scaled.any():
            return of_truth
        return np.where(scaled, (values - truth) / reference * 100.0, of_truth)

    def check_method(self, method: str) -> None:
        """Raises ConfigError unless the car has ``method``."""
        if method not in self.methods:
            raise ConfigError(f"method: the {self.title} has {', '.join(self.methods)}; got {method!r}")

    def vehicle(self, path: str | None, preset: str = "table5-1") -> Any:
        """The vehicle of ``path`` (its file), else the preset's."""
        return self.load(path) if path else self.presets[preset]


_MASS = Parameter("mass_kg", "sprung_mass_kg", "m", "mass", "mass", "kg", "{:.1f}", "{:.2f}")
_PITCH = Parameter("pitch_inertia_kgm2", "pitch_inertia_kgm2", "I_yy", "pitch inertia", "pitch inertia",
                   "kg m²", "{:.1f}", "{:.2f}")
_COG = Parameter("cog_from_front_axle_m", "cog_from_front_axle_m", "l_f", "CoG position",
                 "CoG from front axle", "m", "{:.4f}", "{:.4f}")
_ROLL = Parameter("roll_inertia_kgm2", "roll_inertia_kgm2", "I_xx", "roll inertia", "roll inertia", "kg m²",
                  "{:.1f}", "{:.2f}")
_LATERAL = Parameter("cog_lateral_m", "cog_lateral_m", "y_c", "lateral CoG", "CoG left of centre", "m",
                     "{:.4f}", "{:.4f}", of_half_track=True)

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

HALF = Car("half", "half car", (_MASS, _PITCH, _COG), n_modes=2, channels=(("front", "f"), ("rear", "r")),
           methods=tuple(METHODS), default_method="rozyn", vehicle_type=Vehicle,
           presets={"table5-1": Vehicle(), "second": SECOND_VEHICLE}, noise_stream=3, load=load_vehicle,
           told=_told_half)
FULL = Car("full", "full car", (_MASS, _ROLL, _PITCH, _COG, _LATERAL), n_modes=3,
           channels=(("front left", "fl"), ("front right", "fr"), ("rear left", "rl"), ("rear right", "rr")),
           methods=("likelihood", "rozyn"), default_method="likelihood", vehicle_type=FullVehicle,
           presets={"table5-1": FullVehicle(), "second": SECOND_FULL_VEHICLE},
           # its own stream: the roads' are 0 and 1, the simulator's noise 2, the right track's 3
           noise_stream=4, load=load_full_vehicle, told=_told_full)
CARS = {c.name: c for c in (HALF, FULL)}


def car_of(vehicle: AnyVehicle) -> Car:
    """The car a vehicle is: a FullVehicle the full car's, a Vehicle the half car's."""
    return FULL if isinstance(vehicle, FullVehicle) else HALF
