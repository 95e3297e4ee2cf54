"""Bags read by rosbags' ``AnyReader``: rosbag2 SQLite3 and MCAP, ROS 1.

ROS-free. Opening a bag in normal mode always goes through here: AnyReader reads
``metadata.yaml`` (or the ROS 1 index), gives the topics and builds the typestore from
the message definitions the bag carries. Its messages are read here too unless the
indexed MCAP fast path (:mod:`rozyn_estimator.bag.mcap_indexed`) can read the files.
"""

from __future__ import annotations

from collections.abc import Iterator, Mapping
from pathlib import Path
from typing import Any

from rozyn_estimator.bag.source import RawBatch, TopicInfo, batch_of, damaged
from rozyn_estimator.bag.typestore import absolute_topic, default_typestore
from rozyn_estimator.errors import BagError


class AnyReaderSource:
    """An open ``rosbags.highlevel.AnyReader`` (a :class:`MessageSource
    <rozyn_estimator.bag.source.MessageSource>`). Use :meth:`open`.

    Attributes:
        files: the bag's storage files.
        topics: absolute topic name -> :class:`~rozyn_estimator.bag.source.TopicInfo`.
        typestore: rosbags typestore with every type the bag uses.
        cdr: the messages are CDR (rosbag2); False for ROS 1 serialisation.
    """

    def __init__(self, reader: Any, files: list[Path]) -> None:
        self._reader: Any = reader
        self.files = files
        self.topics = {
            absolute_topic(name): TopicInfo(absolute_topic(name), info.msgtype or "", info.msgcount)
            for name, info in reader.topics.items()
        }
        self.typestore: Any = reader.typestore
        self.cdr: bool = reader.is2

    @classmethod
    def open(cls, path: Path, files: list[Path]) -> AnyReaderSource:
        """Open a bag with AnyReader.

        Args:
            path: the bag (a rosbag2 directory or a storage file).
            files: its storage files.

        Returns:
            The open source.

        Raises:
            BagError: a directory without ``metadata.yaml`` (an unclosed recording), or
                a file AnyReader cannot open (names it).
        """
        from rosbags.highlevel import AnyReader

        if path.is_dir() and not (path / "metadata.yaml").is_file():
            raise BagError(
                f"{path} has no metadata.yaml (the recording was not closed: killed or crashed?); "
                "--salvage reads its MCAP files directly"
            )
        try:
            reader = AnyReader([path], default_typestore=default_typestore())
            reader.open()
        except Exception as exc:
            raise damaged(files, exc) from None
        return cls(reader, files)

    def batches(self, index: Mapping[str, int], size: int) -> Iterator[RawBatch]:
        """See :meth:`MessageSource.batches <rozyn_estimator.bag.source.MessageSource.batches>`.

        Raises:
            BagError: reading fails (says after how many messages).
        """
        connections = [c for c in self._reader.connections if absolute_topic(c.topic) in index]
        by_name = {c.topic: index[absolute_topic(c.topic)] for c in connections}
        topics: list[int] = []
        times: list[int] = []
        data: list[bytes] = []
        done = 0
        try:  # the loop body cannot fail: an exception comes from reading the file
            for conn, t, raw in self._reader.messages(connections=connections):
                topics.append(by_name[conn.topic])
                times.append(t)
                data.append(raw)
                if len(data) >= size:
                    done += len(data)
                    yield batch_of(topics, times, data)
                    topics, times, data = [], [], []
        except Exception as exc:  # a damaged file fails in many ways (zstd, struct, sqlite …)
            raise damaged(self.files, exc, after=done + len(data)) from None
        if data:
            yield batch_of(topics, times, data)

    def close(self) -> None:
        """Close rosbags' reader (the typestore stays usable)."""
        if self._reader is not None:
            self._reader.close()
            self._reader = None
