"""The one online/offline code path, ROS-free: window, pairing, resets and the schedule.

The estimator node feeds :class:`OnlineEstimator` from its callbacks, ``rozyn replay``
from bag messages; :class:`EstimatorConfig` is the node's configuration as it travels
in bags.
"""

from rozyn_estimator.online.config import OnlineConfig
from rozyn_estimator.online.estimator import OnlineEstimator, SpeedSamples
from rozyn_estimator.online.estimator_config import CUSTOM_DATA_KEY, SPEED_TOPIC_TYPES, EstimatorConfig
from rozyn_estimator.online.pairing import pair_channels
from rozyn_estimator.online.records import (
    ERROR,
    LEVEL_NAMES,
    NS,
    OK,
    STALE,
    WARN,
    Health,
    Job,
    Level,
    Update,
    update_values,
)

__all__ = [
    "CUSTOM_DATA_KEY", "ERROR", "LEVEL_NAMES", "NS", "OK", "SPEED_TOPIC_TYPES", "STALE", "WARN",
    "EstimatorConfig", "Health", "Job", "Level", "OnlineConfig", "OnlineEstimator", "SpeedSamples", "Update",
    "pair_channels", "update_values",
]
