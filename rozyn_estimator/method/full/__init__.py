"""The full car: Rozyn's pipeline and the likelihood refinement on three or four channels (corner
accelerometers, or a sensors block's: one IMU's accel_z, gyro_x, gyro_y), ROS-free.
``estimate_full`` runs one window; see :mod:`rozyn_estimator.method.full.stage`."""

from rozyn_estimator.method.full.fit import FULL_PARAM_NAMES
from rozyn_estimator.method.full.stage import FullEstimate, estimate_full

__all__ = ["FULL_PARAM_NAMES", "FullEstimate", "estimate_full"]
