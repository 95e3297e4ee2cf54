"""What a study's vehicle model estimates, and how its tables and figures name it.

``rozyn study --model half`` (the default: the half car, front and rear accelerometers,
three parameters) or ``--model full`` (the 7-DOF full car on two road tracks, four corner
accelerometers, five parameters). :class:`StudyModel` holds what differs between them:
the parameters (their columns, symbols, units, table formats), the modes a results row
records, the accelerometers of the correlation figure and the methods.

Relative statistics (bias, share within 6 %, precision, the shortest drive for 1 %) are
taken against the truth, except for the lateral CoG, whose truth is often 0: against the
half track (:attr:`Parameter.of_half_track`).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from rozyn_estimator.method import METHODS
from rozyn_estimator.tools.trial_full import METHODS_FULL
from rozyn_estimator.vehicle import Vehicle
from rozyn_estimator.vehicle_full import FullVehicle


@dataclass(frozen=True)
class Parameter:
    """One estimated parameter as the study's files show it."""

    name: str  # its column (``mass_kg``)
    vehicle_field: str  # the vehicle's field holding its truth
    symbol: str  # ``m``
    label: str  # ``mass``
    unit: str  # ``kg``
    value_fmt: str  # summary.md: a value
    spread_fmt: str  # summary.md: a spread
    of_half_track: bool = False  # relative statistics against the half track, not the truth

    @property
    def relative_to(self) -> str:
        """What its relative statistics are a share of: ``truth`` or ``half track``."""
        return "half track" if self.of_half_track else "truth"


@dataclass(frozen=True)
class StudyModel:
    """A vehicle model of the study: its parameters, modes, accelerometers and methods."""

    name: str  # "half" | "full"
    params: tuple[Parameter, ...]
    n_modes: int  # body modes recorded per trial (by frequency)
    channels: tuple[tuple[str, str], ...]  # the accelerometers: (label, subscript)
    methods: tuple[str, ...]
    default_method: str

    @property
    def names(self) -> tuple[str, ...]:
        return tuple(p.name for p in self.params)

    @property
    def scaled(self) -> np.ndarray:
        """(k,) bool: the parameters whose relative statistics are of the half track."""
        return np.array([p.of_half_track for p in self.params])

    def truth(self, vehicle: Vehicle | FullVehicle) -> np.ndarray:
        """(k,) the true values of the parameters."""
        return np.array([getattr(vehicle, p.vehicle_field) for p in self.params])

    def reference(self, vehicle: Vehicle | FullVehicle) -> np.ndarray:
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


_MASS = Parameter("mass_kg", "sprung_mass_kg", "m", "mass", "kg", "{:.1f}", "{:.2f}")
_PITCH = Parameter("pitch_inertia_kgm2", "pitch_inertia_kgm2", "I_yy", "pitch inertia", "kg m²", "{:.1f}",
                   "{:.2f}")
_COG = Parameter("cog_from_front_axle_m", "cog_from_front_axle_m", "l_f", "CoG position", "m", "{:.4f}",
                 "{:.4f}")
_ROLL = Parameter("roll_inertia_kgm2", "roll_inertia_kgm2", "I_xx", "roll inertia", "kg m²", "{:.1f}",
                  "{:.2f}")
_LATERAL = Parameter("cog_lateral_m", "cog_lateral_m", "y_c", "lateral CoG", "m", "{:.4f}", "{:.4f}",
                     of_half_track=True)

HALF = StudyModel("half", (_MASS, _PITCH, _COG), n_modes=2, channels=(("front", "f"), ("rear", "r")),
                  methods=tuple(METHODS), default_method="rozyn")
FULL = StudyModel("full", (_MASS, _ROLL, _PITCH, _COG, _LATERAL), n_modes=3,
                  channels=(("front left", "fl"), ("front right", "fr"), ("rear left", "rl"),
                            ("rear right", "rr")),
                  methods=METHODS_FULL, default_method="likelihood")
MODELS = {m.name: m for m in (HALF, FULL)}
