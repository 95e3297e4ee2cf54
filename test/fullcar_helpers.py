"""A full car shared by the full-car plant's tests."""

from __future__ import annotations

from rozyn_estimator.vehicle_full import FullVehicle

# An asymmetric car: every coupling term is at work (lateral CoG, corner values, bars).
ASYMMETRIC = FullVehicle(
    cog_lateral_m=0.08, track_rear_m=1.56, unsprung_mass_kg=(21.0, 19.0, 34.0, 31.0),
    tyre_stiffness_npm=(1.0e5, 1.1e5, 0.95e5, 1.05e5), tyre_damping_nspm=(20.0, 30.0, 25.0, 40.0),
    suspension_stiffness_npm=(22e3, 24e3, 41e3, 38e3),
    suspension_damping_nspm=(1300.0, 1500.0, 1800.0, 1700.0),
    anti_roll_stiffness_front_nmprad=15_000.0, anti_roll_stiffness_rear_nmprad=6000.0,
    sensor_x_m=(0.2, 0.1, 2.6, 2.9), sensor_y_m=(0.6, -0.5, 0.7, -0.65),
)
