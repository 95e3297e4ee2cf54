"""Bag storage, ROS-free: rosbag2 bags written as Jazzy writes them, and read fast.

Writing: :class:`BagWriter` (rosbag2 v9 + MCAP), :class:`QueuedBagWriter` (on a thread
of its own, for the recorder), :class:`Qos` and its two common profiles. Reading:
:func:`open_bag` gives a :class:`BagReader` whose :meth:`~BagReader.batches` hold
serialised messages (:class:`RawBatch`), and :class:`FieldReader` decodes numeric
fields of many messages at once (:class:`Decoded`: garbled messages marked, never raised).
"""

from rozyn_estimator.bag.cdr import Decoded, FieldReader, Packed
from rozyn_estimator.bag.qos import LATCHED_QOS, SENSOR_QOS, Qos
from rozyn_estimator.bag.queued import QueuedBagWriter
from rozyn_estimator.bag.reader import BagReader, open_bag
from rozyn_estimator.bag.source import MessageSource, RawBatch, TopicInfo
from rozyn_estimator.bag.typestore import absolute_topic, default_typestore
from rozyn_estimator.bag.writer import BagWriter

__all__ = [
    "LATCHED_QOS", "SENSOR_QOS", "BagReader", "BagWriter", "Decoded", "FieldReader", "MessageSource",
    "Packed", "Qos", "QueuedBagWriter", "RawBatch", "TopicInfo", "absolute_topic", "default_typestore",
    "open_bag",
]
