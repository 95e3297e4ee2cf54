"""A load change at a stop: passengers or cargo put in (or taken out) while the vehicle stands.

The load is a point mass ``Δm`` [kg] at ``x`` [m] behind the centre of gravity, on its
centreline and at its height (so the CoG's height and lateral position stay, and the roll
inertia about the CoG gains nothing). The sprung body's new values (parallel axes):

    m' = m + Δm,   l_f' = l_f + Δm x / m',   I_yy' = I_yy + m (l_f' - l_f)² + Δm (l_f + x - l_f')²

The vehicle must stand at the moment (a load does not change while driving): the simulator
then restarts its plant at rest on the road under the tyres with the new body, which is
where the body settles once loaded (the settling itself, while standing, carries no road
information and is not simulated). The truth (``sim/ground_truth``) switches with it.
"""

from __future__ import annotations

import dataclasses

from rozyn_estimator.errors import ConfigError
from rozyn_estimator.vehicle import Vehicle
from rozyn_estimator.vehicle_full import FullVehicle

STANDING_MPS = 0.5  # the vehicle stands below this speed (a load may change then)


def with_point_load(vehicle: Vehicle | FullVehicle, mass_kg: float,
                    behind_cog_m: float) -> Vehicle | FullVehicle:
    """``vehicle`` with a point load ``mass_kg`` at ``behind_cog_m`` behind its CoG (see the module).

    Raises:
        ConfigError: the load would leave no body (``m + Δm <= 0``) or put the CoG off the
            wheelbase, or the result is not a vehicle.
    """
    m, lf = vehicle.sprung_mass_kg, vehicle.cog_from_front_axle_m
    total = m + mass_kg
    if total <= 0.0:
        raise ConfigError(f"load_change_kg: {mass_kg:g} kg takes more than the sprung mass {m:g} kg away")
    new_lf = lf + mass_kg * behind_cog_m / total
    load_lf = lf + behind_cog_m
    inertia = vehicle.pitch_inertia_kgm2 + m * (new_lf - lf) ** 2 + mass_kg * (load_lf - new_lf) ** 2
    if not 0.0 < new_lf < vehicle.wheelbase_m or inertia <= 0.0:
        raise ConfigError(f"load_change_x_m: a load of {mass_kg:g} kg at {behind_cog_m:g} m behind the CoG "
                          f"puts the CoG {new_lf:.3f} m behind the front axle, off the wheelbase")
    try:
        return dataclasses.replace(vehicle, sprung_mass_kg=total, cog_from_front_axle_m=new_lf,
                                   pitch_inertia_kgm2=inertia)
    except ConfigError as exc:
        raise ConfigError(f"load_change_kg: the loaded vehicle is not one: {exc}") from None


__all__ = ["STANDING_MPS", "with_point_load"]
