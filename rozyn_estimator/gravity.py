"""Gravity through the geometry: what the body's weight adds to its pitch and roll when the
centre of gravity sits above the wheel centres.

The suspension's axes are fixed in the body and the wheels ride on them, so the wheels (and the
tyres' vertical forces) move horizontally with the body's points at the wheel centres' height.
A body pitching (or rolling) by a small angle ``φ`` about its centre of gravity moves those
points by ``h φ`` (``h`` the CoG's height above the wheel centres): the supports of the body's
weight ``m g`` shift under it and the weight turns the body further, a moment ``m g h φ``,
and the wheels (nothing pushes the car horizontally at the body's frequencies) swing with
the body while the whole car's centre of mass stays put. On the rotation, per radian:

    stiffness  -m g h             [N m/rad]   (the inverted pendulum's)
    inertia    +μ h²,  μ = m M_u / (m + M_u)   [kg m²]   (the wheels' horizontal swing)

with ``M_u`` the unsprung masses together. At ``h = 0`` both vanish (the thesis' model); for a
car (``h`` about 0.25 m) the pitch and roll frequencies drop by about 1 %, and an estimator
without them reads I_yy about 2 % high. The simulator's plants and the estimator's spectral
models share these functions; a test checks them against a multibody integration of the
geometry (``test/test_gravity_geometry.py``).

The heights come from the vehicle file (``cog_height_m``, ``wheel_centre_height_m``, above the
road); both 0 means they are not given and the geometry is not carried.
"""

from __future__ import annotations

STANDARD_GRAVITY_MPS2 = 9.80665


def gravity_height_m(vehicle: object) -> float:
    """The CoG's height above the wheel centres ``h`` [m] (0 where the file gives no heights)."""
    cog = float(getattr(vehicle, "cog_height_m", 0.0))
    wheel = float(getattr(vehicle, "wheel_centre_height_m", 0.0))
    return cog - wheel if cog > 0.0 else 0.0


def rotation_stiffness_nmprad(mass_kg: float, height_m: float) -> float:
    """What the weight adds to the body's pitch (and roll) stiffness, ``-m g h`` [N m/rad];
    linear in ``m``, so it is also its derivative by ``ln m``."""
    return -mass_kg * STANDARD_GRAVITY_MPS2 * height_m


def rotation_inertia_kgm2(mass_kg: float, height_m: float, unsprung_kg: float) -> tuple[float, float]:
    """(what the wheels' swing adds to the body's pitch (and roll) inertia ``μ h²`` [kg m²], its
    derivative by ``ln m``)."""
    total = mass_kg + unsprung_kg
    reduced = mass_kg * unsprung_kg / total
    return reduced * height_m**2, mass_kg * (unsprung_kg / total) ** 2 * height_m**2
