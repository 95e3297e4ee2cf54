"""Bags on disk: rosbag2 directories (``metadata.yaml`` + MCAP), written.

ROS-free (``mcap``, ``rosbags``' message definitions, yaml). The recorder node, the demo
and ``rozyn replay`` all write with :class:`BagWriter` (the recorder through
:class:`~rozyn_estimator.bag.queued.QueuedBagWriter`); :mod:`rozyn_estimator.bag.reader`
reads.

What :class:`BagWriter` writes is what ``ros2 bag record -s mcap`` on Jazzy writes:

- ``<dir>/<dir name>_0.mcap``: MCAP with profile ``ros2``, one schema per type (encoding
  ``ros2msg``, the full concatenated ``.msg`` text), one channel per topic (message
  encoding ``cdr``, channel metadata ``offered_qos_profiles`` and ``topic_type_hash``),
  zstd-compressed chunks with CRCs, message and chunk indexes, statistics, and a
  ``rosbag2`` metadata record holding the serialised bag information;
- ``<dir>/metadata.yaml``: rosbag2 version 9 (storage ``mcap``, per-topic type,
  serialisation ``cdr``, offered QoS, RIHS01 type hash, message counts, start and
  duration, ``custom_data``, ``ros_distro``), written when the bag is closed.

Custom data (e.g. the estimator's configuration) is also written at once as an MCAP
metadata record named ``custom_data``, so it survives a crash. :meth:`BagWriter.flush`
closes the pending chunk and flushes the file: a recording killed without warning loses
only what came after the last flush, and ``rozyn replay --salvage`` reads the rest.
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass
from functools import cache
from importlib import metadata as importlib_metadata
from pathlib import Path
from typing import Any

import yaml

from rozyn_estimator.bag.qos import Qos, qos_yaml
from rozyn_estimator.bag.typestore import message_definition
from rozyn_estimator.errors import BagError

ROSBAG2_VERSION = 9
CUSTOM_DATA_RECORD = "custom_data"  # MCAP metadata record holding custom_data entries


@dataclass
class _Topic:
    name: str
    msgtype: str
    qos: tuple[Qos, ...]
    type_hash: str
    channel_id: int
    count: int = 0


class BagWriter:
    """Writes one rosbag2 directory (MCAP storage). Not thread-safe: one writer thread.

    Args:
        path: the bag directory to create (must not exist yet).
        compression: ``"zstd"`` (chunk compression) or ``"none"``.
        chunk_size: uncompressed bytes per chunk before it is written.

    Raises:
        BagError: the directory exists or cannot be created.
    """

    def __init__(self, path: str | Path, *, compression: str = "zstd", chunk_size: int = 1 << 20) -> None:
        from mcap.writer import CompressionType, Writer

        if compression not in ("zstd", "none"):
            raise BagError(f"compression must be zstd or none, got {compression!r}")
        self.path = Path(path)
        if self.path.exists():
            raise BagError(f"{self.path} exists already; a bag is never overwritten")
        try:
            self.path.mkdir(parents=True)
        except OSError as exc:
            raise BagError(f"cannot create {self.path}: {exc.strerror}") from None
        self.file = self.path / f"{self.path.name}_0.mcap"
        self._stream = self.file.open("xb")
        self._mcap = Writer(
            self._stream,
            chunk_size=chunk_size,
            compression=CompressionType.ZSTD if compression == "zstd" else CompressionType.NONE,
            enable_crcs=True,
        )
        self._mcap.start(profile="ros2", library=f"rozyn_estimator {_version()}")
        self._schemas: dict[str, int] = {}
        self._topics: list[_Topic] = []
        self.custom_data: dict[str, str] = {}
        self.start_ns: int | None = None
        self.end_ns: int | None = None
        self.closed = False

    # ------------------------------------------------------------------ writing
    def add_topic(
        self,
        name: str,
        msgtype: str,
        qos: Sequence[Qos] = (),
        *,
        msgdef: str | None = None,
        type_hash: str | None = None,
    ) -> int:
        """Register a topic.

        Args:
            name: the topic name (as it is to appear in the bag).
            msgtype: its message type, e.g. ``sensor_msgs/msg/Imu``.
            qos: the profiles offered on it.
            msgdef: full ``ros2msg`` text (default: what
                :func:`~rozyn_estimator.bag.typestore.message_definition` finds; a type
                found nowhere gets an empty schema).
            type_hash: RIHS01 hash (default: likewise).

        Returns:
            The id to :meth:`write` with.
        """
        if msgdef is None or not type_hash:
            known_def, known_hash = message_definition(msgtype)
            msgdef = known_def if msgdef is None else msgdef
            type_hash = type_hash or known_hash
        if msgtype not in self._schemas:
            encoding = "ros2msg" if msgdef else ""
            self._schemas[msgtype] = self._mcap.register_schema(msgtype, encoding, msgdef.encode())
        qos = tuple(qos)
        channel = self._mcap.register_channel(
            topic=name,
            message_encoding="cdr",
            schema_id=self._schemas[msgtype],
            metadata={"offered_qos_profiles": qos_yaml(qos), "topic_type_hash": type_hash},
        )
        self._topics.append(_Topic(name, msgtype, qos, type_hash, channel))
        return len(self._topics) - 1

    def write(self, topic_id: int, log_time_ns: int, data: bytes, publish_time_ns: int | None = None) -> None:
        """One serialised (CDR) message.

        Args:
            topic_id: what :meth:`add_topic` returned.
            log_time_ns: the receive time [ns].
            data: the CDR bytes.
            publish_time_ns: the publish time [ns] (default: ``log_time_ns``).
        """
        topic = self._topics[topic_id]
        self._mcap.add_message(
            topic.channel_id,
            log_time=log_time_ns,
            data=data,
            publish_time=log_time_ns if publish_time_ns is None else publish_time_ns,
            sequence=topic.count,
        )
        topic.count += 1
        if self.start_ns is None or log_time_ns < self.start_ns:
            self.start_ns = log_time_ns
        if self.end_ns is None or log_time_ns > self.end_ns:
            self.end_ns = log_time_ns

    def set_custom_data(self, key: str, value: str) -> None:
        """A ``custom_data`` entry of ``metadata.yaml``, also written to the MCAP at once."""
        self.custom_data[key] = value
        self._mcap.add_metadata(CUSTOM_DATA_RECORD, {key: value})

    def flush(self) -> None:
        """Write the pending chunk and flush the file (a crash now loses nothing before)."""
        self._mcap.flush()

    def close(self) -> None:
        """Finish the MCAP (summary, indexes, footer) and write ``metadata.yaml``."""
        if self.closed:
            return
        self.closed = True
        info = self.info()
        self._mcap.add_metadata("rosbag2", {"serialized_metadata": yaml.safe_dump(info, sort_keys=False)})
        self._mcap.finish()
        self._stream.close()
        text = yaml.safe_dump({"rosbag2_bagfile_information": info}, sort_keys=False)
        tmp = self.path / "metadata.yaml.tmp"
        tmp.write_text(text)
        tmp.replace(self.path / "metadata.yaml")

    @property
    def counts(self) -> dict[str, int]:
        """Messages written per topic."""
        return {t.name: t.count for t in self._topics}

    def info(self) -> dict[str, Any]:
        """The rosbag2 bag information (``metadata.yaml`` under its top key)."""
        start = self.start_ns or 0
        duration = (self.end_ns - start) if self.end_ns is not None else 0
        total = sum(t.count for t in self._topics)
        return {
            "version": ROSBAG2_VERSION,
            "storage_identifier": "mcap",
            "duration": {"nanoseconds": duration},
            "starting_time": {"nanoseconds_since_epoch": start},
            "message_count": total,
            "topics_with_message_count": [
                {
                    "topic_metadata": {
                        "name": t.name,
                        "type": t.msgtype,
                        "serialization_format": "cdr",
                        "offered_qos_profiles": [q.to_yaml_dict() for q in t.qos],
                        "type_description_hash": t.type_hash,
                    },
                    "message_count": t.count,
                }
                for t in self._topics
            ],
            "compression_format": "",
            "compression_mode": "",
            "relative_file_paths": [self.file.name],
            "files": [
                {
                    "path": self.file.name,
                    "starting_time": {"nanoseconds_since_epoch": start},
                    "duration": {"nanoseconds": duration},
                    "message_count": total,
                }
            ],
            "custom_data": dict(self.custom_data),
            "ros_distro": "jazzy",
        }

    def __enter__(self) -> BagWriter:
        return self

    def __exit__(self, *exc: object) -> None:
        self.close()  # also on an error: what was written stays readable


@cache
def _version() -> str:
    try:
        return importlib_metadata.version("rozyn_estimator")
    except importlib_metadata.PackageNotFoundError:
        return "dev"
