"""The last few results of a costly function of a window's arrays (:class:`Kept`): a window's
model and its variants, and the next window's, ask for the same ones."""

from __future__ import annotations

import threading
from collections.abc import Callable
from typing import Any

import numpy as np


class Kept:
    """The last ``size`` results, found by their arguments' equality (arrays by shape and
    value: a hash of a 120 s window's speeds cost 0.17 ms, a comparison a tenth of that);
    safe across threads (updates may run on several: the node's, a replay's). A result is
    shared: its users only read it."""

    def __init__(self, size: int) -> None:
        self._size, self._lock = size, threading.Lock()
        self._items: list[tuple[tuple[Any, ...], Any]] = []  # (arguments, result), the newest last

    def get(self, args: tuple[Any, ...], build: Callable[[], Any]) -> Any:
        """The result for ``args``, kept or made by ``build()``."""
        with self._lock:
            for i, (kept, value) in enumerate(self._items):
                if _same(kept, args):
                    self._items.append(self._items.pop(i))
                    return value
        value = build()
        frozen = tuple(np.array(a) if isinstance(a, np.ndarray) else a for a in args)  # copies
        with self._lock:
            self._items = [*self._items, (frozen, value)][-self._size:]
        return value


def _same(kept: tuple[Any, ...], args: tuple[Any, ...]) -> bool:
    """Equal arguments: arrays by shape and value, the rest as themselves."""
    return len(kept) == len(args) and all(
        (np.shape(a) == np.shape(b) and bool(np.array_equal(a, b))) if isinstance(b, np.ndarray) else
        (not isinstance(a, np.ndarray) and a == b) for a, b in zip(kept, args, strict=True))
