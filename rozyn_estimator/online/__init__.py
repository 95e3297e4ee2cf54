"""The one online/offline code path, ROS-free: window, pairing, resets and the schedule, for the
half car's two accelerometers or the full car's three or four.

The estimator node feeds :class:`OnlineEstimator` from its callbacks, ``rozyn replay``
from bag messages; :class:`EstimatorConfig` is the node's configuration as it travels
in bags.
"""

from rozyn_estimator.online.batch import SpeedSamples
from rozyn_estimator.online.config import OnlineConfig
from rozyn_estimator.online.estimator import OnlineEstimator
from rozyn_estimator.online.estimator_config import CUSTOM_DATA_KEY, SPEED_TOPIC_TYPES, EstimatorConfig
from rozyn_estimator.online.pairing import align_channels, pair_channels
from rozyn_estimator.online.records import (
    ERROR,
    HALF_LAYOUT,
    LEVEL_NAMES,
    NS,
    OK,
    STALE,
    WARN,
    Health,
    Job,
    Layout,
    Level,
    Update,
    layout_of,
    update_values,
)

__all__ = [
    "CUSTOM_DATA_KEY", "ERROR", "HALF_LAYOUT", "LEVEL_NAMES", "NS", "OK", "SPEED_TOPIC_TYPES", "STALE",
    "WARN", "EstimatorConfig", "Health", "Job", "Layout", "Level", "OnlineConfig", "OnlineEstimator",
    "SpeedSamples", "Update", "align_channels", "layout_of", "pair_channels", "update_values",
]
