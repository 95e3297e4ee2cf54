"""Bags on disk, read: rosbag2 MCAP and SQLite3 bags and ROS 1 bags.

ROS-free. :func:`open_bag` opens a bag and returns a :class:`BagReader`, the facade the
rest of the project uses: topics, custom data, the typestore, and the messages in
batches. Behind it one :class:`~rozyn_estimator.bag.source.MessageSource` reads:

- normal mode: rosbags' AnyReader opens the bag (:mod:`~rozyn_estimator.bag.any_reader`);
  indexed MCAP files (rosbag2's and ours) are then read chunk by chunk through their
  message indexes, with no per-message Python work (:mod:`~rozyn_estimator.bag.mcap_indexed`),
  everything else through AnyReader;
- ``salvage=True``: MCAP files record by record, keeping every intact chunk of a
  truncated or damaged recording (:mod:`~rozyn_estimator.bag.salvage`).

Every failure becomes a :class:`~rozyn_estimator.errors.BagError` naming the file and
what to do: ``metadata.yaml`` is read bounded (size, nesting) and checked before use,
MCAP chunks are checked against their CRCs, and what no checksum protects is listed in
:attr:`BagReader.unverified`.
"""

from __future__ import annotations

import os
from collections.abc import Iterator, Sequence
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

from rozyn_estimator.bag.any_reader import AnyReaderSource
from rozyn_estimator.bag.mcap_indexed import IndexedMcap, unchecked_chunks
from rozyn_estimator.bag.salvage import SalvageScan
from rozyn_estimator.bag.source import MessageSource, RawBatch, TopicInfo, files_text, reason
from rozyn_estimator.bag.typestore import absolute_topic
from rozyn_estimator.bag.writer import CUSTOM_DATA_RECORD
from rozyn_estimator.errors import BagError
from rozyn_estimator.yaml_file import load_yaml_file, one_line

BAG_SUFFIXES = (".mcap", ".db3", ".bag")
MAX_METADATA_BYTES = 16 << 20  # rosbag2's metadata.yaml of thousands of files stays far below


@dataclass
class BagReader:
    """An open bag. Use :func:`open_bag`; close it (or use ``with``) when done.

    ``topics`` maps absolute topic names to :class:`~rozyn_estimator.bag.source.TopicInfo`;
    ``custom_data`` holds the bag's ``custom_data`` entries; ``damage`` says what salvage
    mode had to skip; ``unverified`` what no checksum protects (MCAP chunks written
    without a CRC, SQLite3 and ROS 1 storage), one line per file. The messages come from
    ``_source`` (rosbags' AnyReader, or the salvage scan), or from ``_indexed`` (the
    indexed MCAP fast path) when that is set.

    Example:
        >>> import struct, tempfile
        >>> from rozyn_estimator.bag.writer import BagWriter
        >>> path = Path(tempfile.mkdtemp(), "run")
        >>> with BagWriter(path) as writer:
        ...     x = writer.add_topic("/x", "std_msgs/msg/Float64")
        ...     for k in range(3):
        ...         writer.write(x, k * 10_000_000, bytes([0, 1, 0, 0]) + struct.pack("<d", k / 2))
        >>> with open_bag(path) as bag:
        ...     bag.topic("x")
        ...     [batch.log_ns.tolist() for batch in bag.batches(["/x"])]
        ...     bag.deserialize(next(bag.batches(["/x"])).messages.message(2), "std_msgs/msg/Float64").data
        TopicInfo(name='/x', msgtype='std_msgs/msg/Float64', count=3)
        [[0, 10000000, 20000000]]
        1.0
    """

    path: Path
    topics: dict[str, TopicInfo]
    custom_data: dict[str, str]
    message_count: int
    files: list[Path]
    typestore: Any
    cdr: bool  # messages are CDR (rosbag2); False: ROS 1 serialisation
    _source: MessageSource
    damage: list[str] = field(default_factory=list)
    unverified: list[str] = field(default_factory=list)
    _indexed: MessageSource | None = None  # the fast path, when the files allow it

    def topic(self, name: str) -> TopicInfo:
        """The topic named ``name``.

        Args:
            name: absolute, or relative to the root namespace.

        Returns:
            Its name, type and message count.

        Raises:
            BagError: the bag has no such topic (lists those it has).
        """
        info = self.topics.get(absolute_topic(name))
        if info is None:
            listing = ", ".join(f"{t.name} ({t.msgtype}, {t.count})" for t in self.topics.values())
            text = f"{self.path}: no topic {absolute_topic(name)}; the bag has: {listing or 'none'}"
            raise BagError(one_line(text, 4000))
        return info

    def deserialize(self, data: bytes, msgtype: str) -> Any:
        """One message as a rosbags object (slow: for the fields the fast path cannot read).

        Args:
            data: the serialised message.
            msgtype: its type, e.g. ``sensor_msgs/msg/Imu``.

        Returns:
            The rosbags message object.

        Raises:
            BagError: the bytes are not a ``msgtype`` message (garbled).
        """
        try:
            if self.cdr:
                return self.typestore.deserialize_cdr(data, msgtype)
            return self.typestore.deserialize_ros1(data, msgtype)
        except Exception as exc:  # garbled bytes fail rosbags' deserialisers in many ways
            raise BagError(f"{self.path}: a {msgtype} message cannot be decoded ({reason(exc)})") from None

    def batches(self, names: Sequence[str], size: int = 65536) -> Iterator[RawBatch]:
        """Messages of ``names`` in bag order, about ``size`` at a time.

        Indexed MCAP files are read chunk by chunk through their message indexes (no
        per-message Python work); other storage through rosbags' AnyReader; a salvaged
        bag record by record.

        Args:
            names: the topics (absolute or relative); :attr:`RawBatch.topic` holds
                positions in this list.
            size: messages per batch (a hint: the messages do not depend on it).

        Returns:
            The batches, read as they are taken.

        Raises:
            BagError: while iterating, when the storage is damaged (names the file).
        """
        index = {absolute_topic(n): i for i, n in enumerate(names)}
        return (self._indexed or self._source).batches(index, size)

    def close(self) -> None:
        """Release the files (closing twice is fine)."""
        for source in (self._indexed, self._source):
            if source:
                source.close()

    def __enter__(self) -> BagReader:
        return self

    def __exit__(self, *exc: object) -> None:
        self.close()


def open_bag(path: str | Path, *, salvage: bool = False) -> BagReader:
    """Open a bag: a rosbag2 directory, an ``.mcap`` / ``.db3`` file or a ROS 1 ``.bag``.

    Args:
        path: where the bag is.
        salvage: read MCAP files record by record, keeping every intact chunk, instead
            of trusting their summary (for a truncated or damaged recording).

    Returns:
        The open bag (see :class:`BagReader` for an example).

    Raises:
        BagError: not a bag, unreadable, damaged (names the file), a file listed in its
            ``metadata.yaml`` missing (salvage mode reads the others), or holding no messages.

    Example:
        >>> open_bag("no/such/bag")
        Traceback (most recent call last):
        ...
        rozyn_estimator.errors.BagError: no/such/bag: no such file or directory
    """
    path = Path(path)
    if not path.exists():
        raise BagError(f"{path}: no such file or directory")
    info = _bag_info(path)
    files = _bag_files(path, info)
    missing = [f for f in files if not os.path.isfile(f)]
    if missing and (not salvage or len(missing) == len(files)):
        verb = "is" if len(missing) == 1 else "are"
        hint = "; --salvage reads the others" if len(missing) < len(files) else ""
        raise BagError(f"{path}: metadata.yaml lists {files_text(missing)}, which {verb} missing{hint}")
    present = [f for f in files if f not in missing]
    reader = _open_salvage(path, present) if salvage else _open_normal(path, present, info)
    reader.damage[:0] = [f"{f.name}: missing (listed in metadata.yaml)" for f in missing]
    if reader.message_count == 0:
        reader.close()
        raise BagError(f"{path} holds no messages{' that could be salvaged' if salvage else ''}")
    return reader


def _open_normal(path: Path, files: list[Path], info: dict[str, Any] | None) -> BagReader:
    """AnyReader opens the bag; the indexed fast path reads it when it can."""
    source = AnyReaderSource.open(path, files)
    try:
        indexed = IndexedMcap.open(files)
    except BagError:
        source.close()
        raise
    return BagReader(
        path=path,
        topics=source.topics,
        custom_data=_custom_data(info, files),
        message_count=sum(t.count for t in source.topics.values()),
        files=files,
        typestore=source.typestore,
        cdr=source.cdr,
        _source=source,
        unverified=_unverified(files),
        _indexed=indexed,
    )


def _open_salvage(path: Path, files: list[Path]) -> BagReader:
    scan = SalvageScan.open(path, files)
    return BagReader(
        path=path,
        topics=scan.topics,
        custom_data=scan.custom_data,
        message_count=sum(t.count for t in scan.topics.values()),
        files=files,
        typestore=scan.typestore,
        cdr=scan.cdr,
        _source=scan,
        damage=scan.damage,
        unverified=scan.unverified,
    )


def _bag_info(path: Path) -> dict[str, Any] | None:
    """``rosbag2_bagfile_information`` of the bag's ``metadata.yaml``, checked; None without one."""
    meta = path / "metadata.yaml"
    if not path.is_dir() or not meta.is_file():
        return None
    data = load_yaml_file(meta, max_bytes=MAX_METADATA_BYTES, what="rosbag2 metadata file", error=BagError)
    info = data.get("rosbag2_bagfile_information") if isinstance(data, dict) else None
    names = info.get("relative_file_paths") if isinstance(info, dict) else None
    if not isinstance(names, list) or not all(isinstance(n, str) and n and "\0" not in n for n in names):
        raise BagError(f"{meta} is damaged (no list of file names under rosbag2_bagfile_information: "
                       "relative_file_paths)")
    custom = info.get("custom_data") if isinstance(info, dict) else None
    if custom is not None and not isinstance(custom, dict):
        raise BagError(f"{meta} is damaged (custom_data is not a mapping)")
    return info


def _bag_files(path: Path, info: dict[str, Any] | None) -> list[Path]:
    """The storage files of a bag; BagError if ``path`` is not a bag."""
    if path.is_file():
        if path.suffix not in BAG_SUFFIXES:
            raise BagError(
                f"{path} is not a bag (expected a rosbag2 directory or an .mcap, .db3 or .bag file)"
            )
        return [path]
    if info is not None:
        if not info["relative_file_paths"]:
            raise BagError(f"{path / 'metadata.yaml'} lists no storage files")
        return [path / name for name in info["relative_file_paths"]]
    files = sorted(p for p in path.iterdir() if p.suffix in BAG_SUFFIXES and p.is_file())
    if not files:
        raise BagError(f"{path} is not a bag: no metadata.yaml and no .mcap, .db3 or .bag file in it")
    return files


def _custom_data(info: dict[str, Any] | None, files: list[Path]) -> dict[str, str]:
    """``custom_data`` of ``metadata.yaml``, else the MCAP ``custom_data`` records."""
    if info is not None and info.get("custom_data"):
        return {str(k): str(v) for k, v in info["custom_data"].items()}
    out: dict[str, str] = {}
    for file in files:
        if file.suffix == ".mcap":
            out.update(_mcap_custom_data(file))
    return out


def _unverified(files: list[Path]) -> list[str]:
    """What of the files no checksum protects, one line per file (see :attr:`BagReader.unverified`)."""
    out = []
    for file in files:
        if file.suffix == ".mcap":
            note = unchecked_chunks(file)
            if note:
                out.append(note)
        else:
            kind = "SQLite3" if file.suffix == ".db3" else "ROS 1"
            out.append(f"{file.name}: {kind} storage carries no checksums: damage cannot be detected")
    return out


def _mcap_custom_data(file: Path) -> dict[str, str]:
    from mcap.reader import make_reader

    out: dict[str, str] = {}
    try:
        with file.open("rb") as f:
            for record in make_reader(f).iter_metadata():
                if record.name == CUSTOM_DATA_RECORD:
                    out.update(record.metadata)
    except Exception:  # no usable summary: salvage mode collects them while scanning
        return {}
    return out
