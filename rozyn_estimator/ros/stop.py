"""A stop request: SIGINT and SIGTERM set a flag instead of interrupting whatever runs.

The nodes' console scripts install it before anything else (before the seconds spent
importing rclpy, numpy and scipy), so a signal at any moment of a node's life, start-up
included, only asks the node to stop; the spin loop then shuts it down in order
(:func:`rozyn_estimator.ros.glue.spin_node`). Standard library only: importing this
module is instant.

Example:
    >>> with StopRequest() as stop:
    ...     stop.requested
    False
"""

from __future__ import annotations

import signal
import threading
from types import FrameType, TracebackType
from typing import Any

SIGNALS = (signal.SIGINT, signal.SIGTERM)


class StopRequest:
    """SIGINT/SIGTERM handlers that set :attr:`event` (in the main thread; elsewhere the
    handlers cannot be installed and only :meth:`set` stops).

    A context manager: the handlers are installed on entry and the previous ones restored
    on exit. A Python handler runs in the main thread between two bytecodes, so a loop
    that waits in C (``executor.spin_once``) sees the request when that call returns:
    give it a short timeout.
    """

    def __init__(self) -> None:
        self.event = threading.Event()
        self.signal: int | None = None  # the signal that asked to stop, if one did
        self._previous: dict[int, Any] = {}

    @property
    def requested(self) -> bool:
        return self.event.is_set()

    def install(self) -> StopRequest:
        """Install the handlers (no-op outside the main thread or when installed already)."""
        if self._previous or threading.current_thread() is not threading.main_thread():
            return self
        self._previous = {sig: signal.signal(sig, self._handle) for sig in SIGNALS}
        return self

    def restore(self) -> None:
        """Put the previous handlers back."""
        for sig, handler in self._previous.items():
            signal.signal(sig, handler)
        self._previous = {}

    def set(self, signum: int | None = None) -> None:
        """Ask to stop (what the handlers do)."""
        if signum is not None and self.signal is None:
            self.signal = signum
        self.event.set()

    def _handle(self, signum: int, _frame: FrameType | None) -> None:
        self.set(signum)

    def __enter__(self) -> StopRequest:
        return self.install()

    def __exit__(
        self, exc_type: type[BaseException] | None, exc: BaseException | None, tb: TracebackType | None
    ) -> None:
        self.restore()
