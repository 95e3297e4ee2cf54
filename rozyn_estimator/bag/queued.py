"""A :class:`~rozyn_estimator.bag.writer.BagWriter` on a thread of its own (the recorder's).

ROS-free. Subscription callbacks only enqueue; the writer thread compresses, writes and
flushes, so a signal arriving at any moment leaves a consistent file.
"""

from __future__ import annotations

import queue
import threading
import time
from collections.abc import Sequence
from pathlib import Path
from typing import Any

from rozyn_estimator.bag.qos import Qos
from rozyn_estimator.bag.writer import BagWriter


class QueuedBagWriter:
    """A :class:`BagWriter` on a thread of its own, fed through a queue.

    Callers (subscription callbacks) only enqueue, which no signal can interrupt
    halfway; the writer thread compresses, writes and flushes every ``flush_period_s``.
    A signal arriving at any moment therefore leaves a consistent file, and
    :meth:`close` writes everything enqueued before it. The thread is not a daemon, so
    an interpreter that exits early waits for a started close to finish; and if the
    program ends without closing (an exception on the way out), the thread closes the
    bag itself once the main thread is gone.

    Args:
        writer: the bag to write.
        flush_period_s: at most this long between flushes of the pending chunk [s].
    """

    _CLOSE = object()

    def __init__(self, writer: BagWriter, flush_period_s: float = 1.0) -> None:
        self.writer = writer
        self.flush_period_s = flush_period_s
        self.enqueued = 0  # messages handed to write()
        self.error: BaseException | None = None  # what stopped the writer thread, if anything
        self._topics = 0
        self._queue: queue.SimpleQueue[Any] = queue.SimpleQueue()
        self._thread = threading.Thread(target=self._run, name="bag-writer", daemon=False)
        self._thread.start()

    @property
    def path(self) -> Path:
        """The bag directory."""
        return self.writer.path

    def add_topic(
        self, name: str, msgtype: str, qos: Sequence[Qos] = (), *, type_hash: str | None = None
    ) -> int:
        """As :meth:`BagWriter.add_topic` (the id is known at once).

        Args:
            name: the topic name.
            msgtype: its message type, e.g. ``sensor_msgs/msg/Imu``.
            qos: the profiles offered on it.
            type_hash: its RIHS01 hash (default: looked up by the writer).

        Returns:
            The id to :meth:`write` with.
        """
        self._queue.put(("topic", name, msgtype, tuple(qos), type_hash))
        self._topics += 1
        return self._topics - 1

    def write(self, topic_id: int, log_time_ns: int, data: bytes) -> None:
        """Enqueue one serialised message (``log_time_ns``: the receive time [ns])."""
        self._queue.put((topic_id, log_time_ns, data))
        self.enqueued += 1

    def set_custom_data(self, key: str, value: str) -> None:
        """Enqueue a ``custom_data`` entry (see :meth:`BagWriter.set_custom_data`)."""
        self._queue.put(("custom", key, value))

    def close(self) -> None:
        """Write what is queued, finish the bag and stop the thread."""
        if self._thread.is_alive():
            self._queue.put(self._CLOSE)
            self._thread.join()

    def _run(self) -> None:
        w = self.writer
        due = time.monotonic() + self.flush_period_s
        try:
            while True:
                try:
                    item = self._queue.get(timeout=max(0.0, min(due - time.monotonic(), 0.2)))
                except queue.Empty:
                    item = None
                if item is self._CLOSE or (item is None and not threading.main_thread().is_alive()):
                    break
                if item is not None:
                    if isinstance(item[0], int):
                        w.write(*item)
                    elif item[0] == "topic":
                        w.add_topic(item[1], item[2], item[3], type_hash=item[4])
                    else:
                        w.set_custom_data(item[1], item[2])
                if time.monotonic() >= due:
                    w.flush()
                    due = time.monotonic() + self.flush_period_s
        except BaseException as exc:  # disk full, …: keep it for the owner to report
            self.error = exc
        finally:
            try:
                w.close()
            except Exception as exc:
                self.error = self.error or exc
