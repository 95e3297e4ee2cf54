"""What every way of reading a bag shares: the :class:`MessageSource` protocol and its batches.

ROS-free. :class:`~rozyn_estimator.bag.reader.BagReader` is the facade; behind it one
strategy reads the messages (as rosbags puts its storage readers behind one
``ReaderProtocol``):

- :class:`~rozyn_estimator.bag.mcap_indexed.IndexedMcap`: indexed MCAP files, chunk by
  chunk through their message indexes, straight into numpy arrays (the fast path);
- :class:`~rozyn_estimator.bag.any_reader.AnyReaderSource`: rosbags' ``AnyReader``
  (SQLite3, ROS 1, an MCAP file without usable indexes);
- :class:`~rozyn_estimator.bag.salvage.SalvageScan`: MCAP files record by record,
  skipping damaged chunks (``--salvage``).

Each yields batches (:class:`RawBatch`): the topic, receive time and serialised bytes of
many messages at once, in bag order.
"""

from __future__ import annotations

from collections.abc import Iterator, Mapping, Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import Protocol

import numpy as np

from rozyn_estimator.bag.cdr import Packed
from rozyn_estimator.errors import BagError
from rozyn_estimator.yaml_file import one_line


@dataclass(frozen=True)
class TopicInfo:
    """One topic of a bag: name (absolute), type, message count."""

    name: str
    msgtype: str
    count: int


@dataclass
class RawBatch:
    """Messages of the requested topics in bag order (receive time; file order for ties).

    ``topic`` indexes the requested topic list, ``log_ns`` is the receive time [ns],
    ``messages`` the serialised messages.
    """

    topic: np.ndarray
    log_ns: np.ndarray
    messages: Packed

    def __len__(self) -> int:
        return self.topic.size


class MessageSource(Protocol):
    """One way of reading the messages of an open bag."""

    def batches(self, index: Mapping[str, int], size: int) -> Iterator[RawBatch]:
        """The messages of the topics in ``index`` in bag order, about ``size`` at a time.

        Args:
            index: absolute topic name -> the number its messages carry in
                :attr:`RawBatch.topic`; other topics are not read.
            size: messages per batch (a hint: the result does not depend on it).

        Returns:
            The batches, read lazily as they are taken.

        Raises:
            BagError: while iterating, when the storage turns out to be damaged.
        """
        ...

    def close(self) -> None:
        """Release what the source holds open (files, rosbags' reader); closing twice is fine."""
        ...


def batch_of(topics: list[int], times: list[int], data: list[bytes]) -> RawBatch:
    """A batch of messages collected one by one.

    Args:
        topics: the topic number of each message.
        times: the receive time of each [ns].
        data: the serialised messages.

    Returns:
        The batch (the messages copied into one buffer).
    """
    return RawBatch(np.array(topics, dtype=np.int16), np.array(times, dtype=np.int64), Packed.of(data))


def batched(messages: Iterator[tuple[int, int, bytes]], size: int) -> Iterator[RawBatch]:
    """``(topic, log_ns, data)`` messages gathered ``size`` at a time.

    Args:
        messages: the messages in bag order.
        size: messages per batch (the last one may hold fewer).

    Returns:
        The batches, lazily.
    """
    topics: list[int] = []
    times: list[int] = []
    data: list[bytes] = []
    for i, t, raw in messages:
        topics.append(i)
        times.append(t)
        data.append(raw)
        if len(data) >= size:
            yield batch_of(topics, times, data)
            topics, times, data = [], [], []
    if data:
        yield batch_of(topics, times, data)


def joined(parts: list[RawBatch]) -> RawBatch:
    """One batch of several (their buffers concatenated).

    Args:
        parts: batches in bag order (at least one).

    Returns:
        The batch holding all their messages in that order.
    """
    if len(parts) == 1:
        return parts[0]
    shifts = np.cumsum([0] + [p.messages.buf.size for p in parts[:-1]])
    return RawBatch(
        np.concatenate([p.topic for p in parts]),
        np.concatenate([p.log_ns for p in parts]),
        Packed(
            np.concatenate([p.messages.buf for p in parts]),
            np.concatenate([p.messages.starts + s for p, s in zip(parts, shifts, strict=True)]),
            np.concatenate([p.messages.lengths for p in parts]),
        ),
    )


def damaged(files: Sequence[Path], exc: BaseException, where: str = "", after: int | None = None) -> BagError:
    """The error for storage that fails while its messages are read.

    Args:
        files: the bag's storage files (named in the message).
        exc: what reading raised.
        where: the place in the file, e.g. ``chunk at byte 4096``.
        after: how many messages were read before.

    Returns:
        A :class:`~rozyn_estimator.errors.BagError` saying what to do (``--salvage``
        for MCAP).
    """
    hint = "; --salvage reads what can be read" if any(f.suffix == ".mcap" for f in files) else ""
    place = f" ({where}: {reason(exc)})" if where else f" ({reason(exc)})"
    count = f" after {after} messages" if after is not None else ""
    return BagError(f"{files_text(files)} is damaged{place}{count}{hint}")


def files_text(files: Sequence[Path]) -> str:
    """The files, comma separated, for a message."""
    return ", ".join(one_line(str(f), 300) for f in files)


def reason(exc: BaseException) -> str:
    """What went wrong, in words a user can act on (a missing MCAP footer: truncated), on one
    bounded line (garbled input makes long, many-line messages)."""
    text = " ".join(str(exc).split()).rstrip(".") or type(exc).__name__
    if "end magic" in text.lower():
        return "truncated: the file ends before its MCAP footer, as a recording that was killed leaves it"
    return one_line(text, 200)
