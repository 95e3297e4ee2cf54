"""Bags on disk: rosbag2 directories (``metadata.yaml`` + MCAP), written.

ROS-free (``mcap``, ``rosbags``' message definitions, yaml). The recorder node, the demo
and ``rozyn replay`` all write with :class:`BagWriter` (the recorder through
:class:`QueuedBagWriter`); :mod:`rozyn_estimator.bag.reader` reads.

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

import os
from collections.abc import Sequence
from dataclasses import dataclass
from functools import cache
from importlib import metadata as importlib_metadata
from pathlib import Path
from typing import Any

import yaml

from rozyn_estimator.errors import BagError

ROSBAG2_VERSION = 9
INFINITE_NS = 9_223_372_036_854_775_807  # rmw's "infinite" duration, as DDS discovery reports it
NS = 1_000_000_000
CUSTOM_DATA_RECORD = "custom_data"  # MCAP metadata record holding custom_data entries


@dataclass(frozen=True)
class Qos:
    """A QoS profile as rosbag2 stores it (``offered_qos_profiles``, version 9).

    Policies are rosbag2's lower-case names (``keep_last``, ``best_effort``,
    ``transient_local``, ``automatic``, ``unknown`` …); durations in nanoseconds.
    """

    history: str = "keep_last"
    depth: int = 10
    reliability: str = "reliable"
    durability: str = "volatile"
    deadline_ns: int = INFINITE_NS
    lifespan_ns: int = INFINITE_NS
    liveliness: str = "automatic"
    liveliness_lease_duration_ns: int = INFINITE_NS
    avoid_ros_namespace_conventions: bool = False

    def to_yaml_dict(self) -> dict[str, Any]:
        """The mapping rosbag2 writes for one profile."""

        def duration(ns: int) -> dict[str, int]:
            return {"sec": ns // NS, "nsec": ns % NS}

        return {
            "history": self.history,
            "depth": self.depth,
            "reliability": self.reliability,
            "durability": self.durability,
            "deadline": duration(self.deadline_ns),
            "lifespan": duration(self.lifespan_ns),
            "liveliness": self.liveliness,
            "liveliness_lease_duration": duration(self.liveliness_lease_duration_ns),
            "avoid_ros_namespace_conventions": self.avoid_ros_namespace_conventions,
        }


SENSOR_QOS = Qos(depth=5, reliability="best_effort")  # rclpy's qos_profile_sensor_data
LATCHED_QOS = Qos(depth=1, durability="transient_local")


@dataclass
class _Topic:
    name: str
    msgtype: str
    qos: tuple[Qos, ...]
    type_hash: str
    channel_id: int
    count: int = 0


@cache
def default_typestore() -> Any:
    """The ROS 2 Jazzy message definitions shipped with rosbags."""
    from rosbags.typesys import Stores, get_typestore

    return get_typestore(Stores.ROS2_JAZZY)


def absolute_topic(name: str) -> str:
    """``accel/front`` -> ``/accel/front`` (names relative to the root namespace)."""
    return name if name.startswith("/") else f"/{name}"


def message_definition(msgtype: str) -> tuple[str, str]:
    """(full ``ros2msg`` text, RIHS01 hash) of a message type, or ``("", "")`` if unknown.

    Looks in rosbags' Jazzy store first, then for ``share/<pkg>/msg/<Type>.msg`` files
    under ``AMENT_PREFIX_PATH`` (custom messages of a sourced workspace).
    """
    store = default_typestore()
    if msgtype not in store.fielddefs and not _register_from_ament(store, msgtype):
        return "", ""
    text, _ = store.generate_msgdef(msgtype, ros_version=2)
    return text, store.hash_rihs01(msgtype)


def _register_from_ament(store: Any, msgtype: str) -> bool:
    """Register ``msgtype`` (and the types it uses) from ``.msg`` files; False if not found."""
    from rosbags.typesys import get_types_from_msg

    pending, found = [msgtype], {}
    while pending:
        name = pending.pop()
        if name in store.fielddefs or name in found:
            continue
        pkg, _, short = name.partition("/msg/")
        text = next(
            (
                path.read_text()
                for prefix in os.environ.get("AMENT_PREFIX_PATH", "").split(os.pathsep)
                if prefix and (path := Path(prefix, "share", pkg, "msg", f"{short}.msg")).is_file()
            ),
            None,
        )
        if text is None:
            return False
        types = get_types_from_msg(text, name)
        found.update(types)
        for _, fields in types.values():
            for _, (_kind, detail) in fields:
                pending += [t for t in _type_names(detail) if "/msg/" in t]
    store.register(found)
    return True


def _type_names(detail: Any) -> list[str]:
    """Message type names referenced by a rosbags field definition."""
    if isinstance(detail, str):
        return [detail]
    if isinstance(detail, tuple):
        return [name for part in detail for name in _type_names(part)]
    return []


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
        """Register a topic; returns the id to :meth:`write` with.

        ``msgdef`` (full ``ros2msg`` text) and ``type_hash`` (RIHS01) default to what
        :func:`message_definition` finds; a type found nowhere gets an empty schema.
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
            metadata={"offered_qos_profiles": _qos_yaml(qos), "topic_type_hash": type_hash},
        )
        self._topics.append(_Topic(name, msgtype, qos, type_hash, channel))
        return len(self._topics) - 1

    def write(self, topic_id: int, log_time_ns: int, data: bytes, publish_time_ns: int | None = None) -> None:
        """One serialised (CDR) message; ``log_time_ns`` is the receive time."""
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
        import queue
        import threading

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
        return self.writer.path

    def add_topic(
        self, name: str, msgtype: str, qos: Sequence[Qos] = (), *, type_hash: str | None = None
    ) -> int:
        """As :meth:`BagWriter.add_topic` (the id is known at once)."""
        self._queue.put(("topic", name, msgtype, tuple(qos), type_hash))
        self._topics += 1
        return self._topics - 1

    def write(self, topic_id: int, log_time_ns: int, data: bytes) -> None:
        self._queue.put((topic_id, log_time_ns, data))
        self.enqueued += 1

    def set_custom_data(self, key: str, value: str) -> None:
        self._queue.put(("custom", key, value))

    def close(self) -> None:
        """Write what is queued, finish the bag and stop the thread."""
        if self._thread.is_alive():
            self._queue.put(self._CLOSE)
            self._thread.join()

    def _run(self) -> None:
        import queue
        import threading
        import time

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


def _qos_yaml(qos: Sequence[Qos]) -> str:
    return yaml.safe_dump([q.to_yaml_dict() for q in qos], sort_keys=False).strip() if qos else ""


@cache
def _version() -> str:
    try:
        return importlib_metadata.version("rozyn_estimator")
    except importlib_metadata.PackageNotFoundError:
        return "dev"
