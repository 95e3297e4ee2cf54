"""The full car (issue "Full vehicle"): Rozyn's pipeline on three or four corner
accelerometers, ROS-free. ``estimate_full`` runs one window; see
:mod:`rozyn_estimator.method.full.stage`."""

from rozyn_estimator.method.full.fit import FULL_PARAM_NAMES
from rozyn_estimator.method.full.stage import FullEstimate, estimate_full

__all__ = ["FULL_PARAM_NAMES", "FullEstimate", "estimate_full"]
