"""What every vehicle file reduces to for the one vehicle model (:mod:`rozyn_estimator.body_model`):
the corners under the body and the anti-roll bars between them.

The half car's file (:class:`~rozyn_estimator.vehicle.Vehicle`) names its values per axle, the
full car's (:class:`~rozyn_estimator.vehicle_full.FullVehicle`) per corner; each builds its
:class:`Corners` (its ``corners`` property), so the model, the likelihood and the budgets read
any car the same way and never ask which file it came from.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

_BAR_PATTERN = np.array([[1.0, -1.0], [-1.0, 1.0]])


@dataclass(frozen=True)
class Bar:
    """An anti-roll bar joining corners ``first`` and ``first + 1`` (an axle's left and right)."""

    first: int  # the left corner's index
    track_m: float  # the distance it spans
    roll_stiffness_nmprad: float  # the roll stiffness it adds to its axle (0: none)

    @property
    def spring_npm(self) -> float:
        """The spring between the two corners' extensions: ``K / track²`` [N/m] (the bar's energy
        ``K/2 ((e_L - e_R)/track)²``)."""
        return self.roll_stiffness_nmprad / self.track_m**2


@dataclass(frozen=True)
class Corners:
    """A vehicle as its equations see it: the corners under its body, in the vehicle's order
    (front, rear; or FL, FR, RL, RR), and its bars (the half car: none)."""

    x_m: np.ndarray  # (n,) behind the front axle
    y_m: np.ndarray  # (n,) left of the centreline
    unsprung_mass_kg: np.ndarray  # (n,)
    suspension_stiffness_npm: np.ndarray  # (n,)
    suspension_damping_nspm: np.ndarray  # (n,)
    tyre_stiffness_npm: np.ndarray  # (n,)
    tyre_damping_nspm: np.ndarray  # (n,)
    bars: tuple[Bar, ...] = ()

    @property
    def count(self) -> int:
        return int(self.x_m.size)

    @property
    def bars_npm(self) -> np.ndarray:
        """(n, n) the bars' springs between the corners' extensions."""
        out = np.zeros((self.count, self.count))
        for bar in self.bars:
            pair = slice(bar.first, bar.first + 2)
            out[pair, pair] += bar.spring_npm * _BAR_PATTERN
        return out

    @property
    def values(self) -> np.ndarray:
        """The corner values, flat: each corner's (suspension stiffness, damping, tyre stiffness,
        damping, unsprung mass) by quantity, then each bar's roll stiffness [N m/rad]."""
        return np.concatenate([self.suspension_stiffness_npm, self.suspension_damping_nspm,
                               self.tyre_stiffness_npm, self.tyre_damping_nspm, self.unsprung_mass_kg,
                               [bar.roll_stiffness_nmprad for bar in self.bars]]).astype(float)


def corners_from(x_m: tuple[float, ...], y_m: tuple[float, ...], unsprung_mass_kg: tuple[float, ...],
                 suspension: tuple[tuple[float, ...], tuple[float, ...]],
                 tyre: tuple[tuple[float, ...], tuple[float, ...]], bars: tuple[Bar, ...] = ()) -> Corners:
    """:class:`Corners` from per-corner tuples; ``suspension`` and ``tyre`` each (stiffness [N/m],
    damping [N s/m])."""
    def a(values: tuple[float, ...]) -> np.ndarray:
        return np.array(values, dtype=float)

    return Corners(a(x_m), a(y_m), a(unsprung_mass_kg), a(suspension[0]), a(suspension[1]), a(tyre[0]),
                   a(tyre[1]), bars)


__all__ = ["Bar", "Corners", "corners_from"]
