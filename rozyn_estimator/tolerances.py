"""Tolerances of the values the estimator assumes: a standard uncertainty for each.

The estimator identifies the sprung mass, pitch inertia and CoG; everything else about
the vehicle it takes from the vehicle file. On a real vehicle those values are known only
to a tolerance, and the published covariance must carry its consequences (the budget in
:mod:`rozyn_estimator.method.budget`). Shared (ROS-free, the simulator imports the vehicle).

A tolerance is a *standard uncertainty* (one sigma): for stiffness, damping and masses a
share of the value (``0.05``: 5 %), for the wheelbase and the sensor offsets metres, for
the sensor gains a share, and for the time offset (rear sensor minus front) seconds.
The defaults describe a vehicle known from its data sheet (README, "What the covariance
means", justifies each). In a vehicle file, a ``tolerances`` mapping lists the ones that
apply: keys it leaves out are exactly known (``tolerances: {}`` is today's estimator);
without the mapping the defaults apply. :class:`FullTolerances` adds the full car's (tracks,
anti-roll bars, lateral positions, an IMU's gyros' turn about z, in radians).
"""

from __future__ import annotations

import dataclasses
from collections.abc import Mapping
from dataclasses import dataclass
from typing import Any, ClassVar

from rozyn_estimator.errors import ConfigError
from rozyn_estimator.parameters import check, param

_SHARE = {"low": 0.0, "high": 1.0}


@dataclass(frozen=True)
class Tolerances:
    """Standard uncertainties of the assumed values (the ``vehicle.tolerances.*`` parameters)."""

    PARAM_PREFIX: ClassVar[str] = "vehicle.tolerances."

    suspension_stiffness_front_npm: float = param(0.05, "front spring rate, share of its value", **_SHARE)
    suspension_stiffness_rear_npm: float = param(0.05, "rear spring rate, share of its value", **_SHARE)
    suspension_damping_front_nspm: float = param(0.15, "front damping, share of its value", **_SHARE)
    suspension_damping_rear_nspm: float = param(0.15, "rear damping, share of its value", **_SHARE)
    tyre_stiffness_front_npm: float = param(0.10, "front tyre stiffness, share of its value", **_SHARE)
    tyre_stiffness_rear_npm: float = param(0.10, "rear tyre stiffness, share of its value", **_SHARE)
    tyre_damping_front_nspm: float = param(0.5, "front tyre damping, share of its value", **_SHARE)
    tyre_damping_rear_nspm: float = param(0.5, "rear tyre damping, share of its value", **_SHARE)
    unsprung_mass_front_kg: float = param(0.10, "front unsprung mass, share of its value", **_SHARE)
    unsprung_mass_rear_kg: float = param(0.10, "rear unsprung mass, share of its value", **_SHARE)
    wheelbase_m: float = param(0.005, "wheelbase", unit="m", low=0.0, high=1.0)
    sensor_front_offset_m: float = param(0.01, "front accelerometer position along the body", unit="m",
                                         low=0.0, high=1.0)
    sensor_rear_offset_m: float = param(0.01, "rear accelerometer position along the body", unit="m",
                                        low=0.0, high=1.0)
    cog_height_m: float = param(0.03, "centre of gravity's height (applies where the vehicle gives its "
                                "heights)", unit="m", low=0.0, high=1.0)
    wheel_centre_height_m: float = param(0.005, "wheel centres' height (applies where the vehicle gives its "
                                         "heights)", unit="m", low=0.0, high=1.0)
    sensor_gain_front: float = param(0.02, "front accelerometer scale factor, share", **_SHARE)
    sensor_gain_rear: float = param(0.02, "rear accelerometer scale factor, share", **_SHARE)
    sensor_time_offset_s: float = param(0.002, "time offset between the sensors (rear minus front)",
                                        unit="s", low=0.0, high=1.0)

    def __post_init__(self) -> None:
        check(self)

    @classmethod
    def none(cls) -> Tolerances:
        """Every assumed value exactly known: the estimator as it was before tolerances."""
        return cls(**{f.name: 0.0 for f in dataclasses.fields(cls)})

    @classmethod
    def from_mapping(cls, data: Any, source: str = "vehicle") -> Tolerances:
        """The tolerances a vehicle file lists; those it leaves out are zero.

        Raises:
            ConfigError: not a mapping, an unknown key (named), or an invalid value.
        """
        if isinstance(data, Tolerances):
            return data
        if not isinstance(data, Mapping):
            raise ConfigError(f"{source}: vehicle.tolerances: expected a mapping, got {type(data).__name__}")
        names = [f.name for f in dataclasses.fields(cls)]  # a subclass' too (the full car's)
        unknown = sorted(str(k) for k in set(data) - set(names))
        if unknown:
            known = ", ".join(names)
            raise ConfigError(f"{source}: unknown tolerance(s) {', '.join(unknown)}; known: {known}")
        return dataclasses.replace(cls.none(), **data)

    def to_dict(self) -> dict[str, float]:
        return {f.name: float(getattr(self, f.name)) for f in dataclasses.fields(self)}

    def applying(self, vehicle: Any) -> dict[str, float]:
        """The non-zero tolerances that apply to ``vehicle`` (as given: shares or units): the
        heights' only where it gives them (otherwise the geometry is not carried)."""
        given = getattr(vehicle, "cog_height_m", 0.0) > 0
        return {key: value for key, value in self.to_dict().items()
                if value > 0 and (given or key not in HEIGHT_KEYS)}

    def absolute(self, vehicle: Any) -> dict[str, float]:
        """:meth:`applying`'s tolerances in the units of their values (N/m, kg, m, share, s)."""
        return {key: value * abs(getattr(vehicle, key)) if key in RELATIVE_FIELDS else value
                for key, value in self.applying(vehicle).items()}

    @property
    def any(self) -> bool:
        """True when some assumed value carries a tolerance."""
        return any(v > 0 for v in self.to_dict().values())


@dataclass(frozen=True)
class FullTolerances(Tolerances):
    """The half car's tolerances (an axle's share applies to both its corners; the sensor
    offsets to the ``x`` of that axle's sensors) and the full car's own."""

    track_front_m: float = param(0.005, "front track width", unit="m", low=0.0, high=1.0)
    track_rear_m: float = param(0.005, "rear track width", unit="m", low=0.0, high=1.0)
    anti_roll_stiffness_front_nmprad: float = param(0.10, "front anti-roll bar, share of its value", **_SHARE)
    anti_roll_stiffness_rear_nmprad: float = param(0.10, "rear anti-roll bar, share of its value", **_SHARE)
    sensor_lateral_m: float = param(0.01, "accelerometers' lateral positions", unit="m", low=0.0, high=1.0)
    gyro_misalignment_rad: float = param(0.01, "an IMU's gyros' turn about z (a sensors block with gyros)",
                                         unit="rad", low=0.0, high=0.5)

    def applying(self, vehicle: Any) -> dict[str, float]:
        """As the half car's, the gyros' turn only where the vehicle has gyros."""
        out = super().applying(vehicle)
        if all(kind == "accel_z" for kind in getattr(vehicle, "channel_kinds", ())):
            out.pop("gyro_misalignment_rad", None)
        return out

    def half_car(self) -> Tolerances:
        """The half car's part."""
        return Tolerances(**{f.name: getattr(self, f.name) for f in dataclasses.fields(Tolerances)})


KEYS: tuple[str, ...] = tuple(f.name for f in dataclasses.fields(Tolerances))
RELATIVE_FIELDS: tuple[str, ...] = tuple(k for k in KEYS if k.endswith(("_npm", "_nspm", "_kg")))
"""Vehicle fields whose tolerance is a share of the value (the rest are in metres or seconds)."""
HEIGHT_KEYS = ("cog_height_m", "wheel_centre_height_m")
SENSOR_KEYS = ("sensor_gain_front", "sensor_gain_rear", "sensor_time_offset_s")


def shown(tolerances: Mapping[str, float]) -> str:
    """``tyre_stiffness_front_npm 10 %, sensor_time_offset_s 2 ms`` (the non-zero ones)."""
    parts = []
    for key, value in tolerances.items():
        if value <= 0:
            continue
        if key.endswith("_s"):
            parts.append(f"{key} {value * 1e3:g} ms")
        elif key.endswith("_m"):
            parts.append(f"{key} {value * 1e3:g} mm")
        else:
            parts.append(f"{key} {value * 100:g} %")
    return ", ".join(parts) or "none"
