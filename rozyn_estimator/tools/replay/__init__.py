"""``rozyn replay``: bags through the online estimator, offline, no DDS.

- ``feed``: a bag fed through the node's own online class (:func:`replay`);
- ``outputs``: ``updates.csv`` and the output bag; ``report``: the summary table;
- ``plot``: the estimates over time (``estimates.png``);
- ``fleet``: many bags in parallel, one table and ``fleet.csv``;
- ``command``: the command line.
"""

from rozyn_estimator.tools.replay.feed import ReplayOptions, replay, replay_bag
from rozyn_estimator.tools.replay.outputs import ReplayResult

__all__ = ["ReplayOptions", "ReplayResult", "replay", "replay_bag"]
