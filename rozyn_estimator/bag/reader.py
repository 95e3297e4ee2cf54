"""Bags on disk, read: rosbag2 MCAP and SQLite3 bags and ROS 1 bags.

ROS-free. :func:`open_bag` opens a bag with ``rosbags.highlevel.AnyReader``. Indexed MCAP
files (rosbag2's and ours) are then read chunk by chunk through their message indexes,
with no per-message Python work (over a million messages a second); everything else
through AnyReader. With ``salvage=True`` MCAP files are read record by record instead,
keeping every intact chunk of a truncated or damaged recording. Every failure becomes a
:class:`~rozyn_estimator.errors.BagError` naming the file and what to do.
"""

from __future__ import annotations

import struct
from collections.abc import Iterator, Sequence
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np
import yaml

from rozyn_estimator.bag.cdr import Packed
from rozyn_estimator.bag.writer import CUSTOM_DATA_RECORD, absolute_topic, default_typestore
from rozyn_estimator.errors import BagError

BAG_SUFFIXES = (".mcap", ".db3", ".bag")


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


@dataclass
class BagReader:
    """An open bag. Use :func:`open_bag`; close it (or use ``with``) when done.

    ``topics`` maps absolute topic names to :class:`TopicInfo`; ``custom_data`` holds the
    bag's ``custom_data`` entries; ``damage`` says what salvage mode had to skip.
    """

    path: Path
    topics: dict[str, TopicInfo]
    custom_data: dict[str, str]
    message_count: int
    files: list[Path]
    typestore: Any
    cdr: bool  # messages are CDR (rosbag2); False: ROS 1 serialisation
    damage: list[str] = field(default_factory=list)
    _any: Any = None  # the open AnyReader (normal mode)
    _indexed: list[tuple[Path, Any]] = field(default_factory=list)  # MCAP summaries for the fast path

    def topic(self, name: str) -> TopicInfo:
        """The topic named ``name`` (relative names are taken from the root namespace)."""
        info = self.topics.get(absolute_topic(name))
        if info is None:
            listing = ", ".join(f"{t.name} ({t.msgtype}, {t.count})" for t in self.topics.values())
            raise BagError(f"{self.path}: no topic {absolute_topic(name)}; the bag has: {listing or 'none'}")
        return info

    def deserialize(self, data: bytes, msgtype: str) -> Any:
        """One message as a rosbags object (slow: for the fields the fast path cannot read)."""
        if self.cdr:
            return self.typestore.deserialize_cdr(data, msgtype)
        return self.typestore.deserialize_ros1(data, msgtype)

    def batches(self, names: Sequence[str], size: int = 65536) -> Iterator[RawBatch]:
        """Messages of ``names`` in bag order, about ``size`` at a time.

        Indexed MCAP files are read chunk by chunk through their message indexes (no
        per-message Python work); other storage through rosbags' AnyReader; a salvaged
        bag record by record.
        """
        index = {absolute_topic(n): i for i, n in enumerate(names)}
        if self._any is None:
            return _batched(self._salvaged(index), size)
        if self._indexed:
            return self._read_indexed(index, size)
        return self._read_any(index, size)

    def _damaged(self, exc: BaseException, where: str = "", after: int | None = None) -> BagError:
        hint = "; --salvage reads what can be read" if self.files[0].suffix == ".mcap" else ""
        place = f" ({where}: {_reason(exc)})" if where else f" ({_reason(exc)})"
        count = f" after {after} messages" if after is not None else ""
        return BagError(f"{_files_text(self.files)} is damaged{place}{count}{hint}")

    def _read_any(self, index: dict[str, int], size: int) -> Iterator[RawBatch]:
        connections = [c for c in self._any.connections if absolute_topic(c.topic) in index]
        by_name = {c.topic: index[absolute_topic(c.topic)] for c in connections}
        topics: list[int] = []
        times: list[int] = []
        data: list[bytes] = []
        done = 0
        try:  # the loop body cannot fail: an exception comes from reading the file
            for conn, t, raw in self._any.messages(connections=connections):
                topics.append(by_name[conn.topic])
                times.append(t)
                data.append(raw)
                if len(data) >= size:
                    done += len(data)
                    yield _batch(topics, times, data)
                    topics, times, data = [], [], []
        except Exception as exc:  # a damaged file fails in many ways (zstd, struct, sqlite …)
            raise self._damaged(exc, after=done + len(data)) from None
        if data:
            yield _batch(topics, times, data)

    def _read_indexed(self, index: dict[str, int], size: int) -> Iterator[RawBatch]:
        parts: list[RawBatch] = []
        count = 0
        for file, summary in self._indexed:
            wanted = {
                cid: index[absolute_topic(ch.topic)]
                for cid, ch in summary.channels.items()
                if absolute_topic(ch.topic) in index
            }
            with file.open("rb") as f:
                for chunk in summary.chunk_indexes:
                    ids = [cid for cid in chunk.message_index_offsets if cid in wanted]
                    if not ids:
                        continue
                    try:
                        part = _indexed_chunk(f, chunk, ids, wanted)
                    except Exception as exc:
                        raise self._damaged(exc, f"chunk at byte {chunk.chunk_start_offset}") from None
                    parts.append(part)
                    count += len(part)
                    if count >= size:
                        yield _joined(parts)
                        parts, count = [], 0
        if parts:
            yield _joined(parts)

    def _salvaged(self, index: dict[str, int]) -> Iterator[tuple[int, int, bytes]]:
        for file in self.files:
            channels: dict[int, str] = {}
            for kind, record in _mcap_records(file, []):
                if kind == "channel":
                    channels[record.id] = record.topic
                elif kind == "message" and channels.get(record.channel_id) in index:
                    yield index[channels[record.channel_id]], record.log_time, record.data

    def close(self) -> None:
        if self._any is not None:
            self._any.close()
            self._any = None

    def __enter__(self) -> BagReader:
        return self

    def __exit__(self, *exc: object) -> None:
        self.close()


def _batch(topics: list[int], times: list[int], data: list[bytes]) -> RawBatch:
    return RawBatch(np.array(topics, dtype=np.int16), np.array(times, dtype=np.int64), Packed.of(data))


def _batched(messages: Iterator[tuple[int, int, bytes]], size: int) -> Iterator[RawBatch]:
    topics: list[int] = []
    times: list[int] = []
    data: list[bytes] = []
    for i, t, raw in messages:
        topics.append(i)
        times.append(t)
        data.append(raw)
        if len(data) >= size:
            yield _batch(topics, times, data)
            topics, times, data = [], [], []
    if data:
        yield _batch(topics, times, data)


def _joined(parts: list[RawBatch]) -> RawBatch:
    """One batch of several (their buffers concatenated)."""
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


_CHUNK_HEAD = struct.Struct(
    "<BQQQQII"
)  # opcode, length, start, end, uncompressed size, crc, len(compression)
_INDEX_HEAD = struct.Struct("<BQHI")  # opcode, length, channel id, length of the entries


def _indexed_chunk(f: Any, chunk: Any, ids: list[int], wanted: dict[int, int]) -> RawBatch:
    """The wanted messages of one MCAP chunk, found through its message indexes."""
    times, offsets, topics = [], [], []
    for cid in ids:
        f.seek(chunk.message_index_offsets[cid])
        opcode, _, channel, n = _INDEX_HEAD.unpack(f.read(_INDEX_HEAD.size))
        if opcode != 0x07 or channel != cid:
            raise ValueError("a message index is garbled")
        entries = np.frombuffer(f.read(n), "<u8").reshape(-1, 2).astype(np.int64)
        times.append(entries[:, 0])
        offsets.append(entries[:, 1])
        topics.append(np.full(len(entries), wanted[cid], np.int16))
    f.seek(chunk.chunk_start_offset)
    opcode, _, _, _, size, _, n = _CHUNK_HEAD.unpack(f.read(_CHUNK_HEAD.size))
    compression = f.read(n).decode()
    (length,) = struct.unpack("<Q", f.read(8))
    if opcode != 0x06 or compression != chunk.compression:
        raise ValueError("the chunk record is garbled")
    buf = np.frombuffer(_decompress(compression, f.read(length), size), np.uint8)
    t, off, top = np.concatenate(times), np.concatenate(offsets), np.concatenate(topics)
    order = np.lexsort((off, t))  # receive time, then file order
    t, off, top = t[order], off[order], top[order]
    if off.size and (off.max() + 31 > buf.size or np.any(buf[off] != 0x05)):
        raise ValueError("a message index points outside the messages")
    lengths = buf[off[:, None] + np.arange(1, 9)].view("<u8").ravel().astype(np.int64) - 22
    starts = off + 31  # opcode 1, length 8, channel 2, sequence 4, log time 8, publish time 8
    if np.any(lengths < 0) or np.any(starts + lengths > buf.size):
        raise ValueError("a message overruns its chunk")
    return RawBatch(top, t, Packed(buf, starts, lengths))


def _decompress(compression: str, data: bytes, size: int) -> bytes:
    if compression == "zstd":
        import zstandard

        return zstandard.ZstdDecompressor().decompress(data, max_output_size=size)
    if compression == "lz4":
        import lz4.frame

        return lz4.frame.decompress(data)
    if compression:
        raise ValueError(f"unknown chunk compression {compression!r}")
    return data


def _indexed_summaries(files: list[Path]) -> list[tuple[Path, Any]]:
    """MCAP summaries usable for the indexed fast path, or [] (then AnyReader reads).

    Usable: every file MCAP with a summary whose chunks all carry message indexes and
    follow each other in time (so chunk order is time order), as rosbag2 and
    :class:`BagWriter` write them.
    """
    from mcap.reader import make_reader

    out: list[tuple[Path, Any]] = []
    last_end = -1
    for file in files:
        if file.suffix != ".mcap":
            return []
        try:
            with file.open("rb") as f:
                summary = make_reader(f).get_summary()
        except Exception:
            return []
        if summary is None or summary.statistics is None:
            return []
        chunks = sorted(summary.chunk_indexes, key=lambda c: c.chunk_start_offset)
        if summary.statistics.message_count and (
            not chunks or not all(c.message_index_offsets for c in chunks)
        ):
            return []
        for c in chunks:
            if c.message_start_time < last_end:
                return []
            last_end = c.message_end_time
        summary.chunk_indexes[:] = chunks
        out.append((file, summary))
    return out


def open_bag(path: str | Path, *, salvage: bool = False) -> BagReader:
    """Open a bag: a rosbag2 directory, an ``.mcap`` / ``.db3`` file or a ROS 1 ``.bag``.

    Args:
        path: where the bag is.
        salvage: read MCAP files record by record, keeping every intact chunk, instead
            of trusting their summary (for a truncated or damaged recording).

    Raises:
        BagError: not a bag, unreadable, damaged (names the file), or holding no messages.
    """
    path = Path(path)
    if not path.exists():
        raise BagError(f"{path}: no such file or directory")
    files = _bag_files(path)
    reader = _salvage(path, files) if salvage else _open_any(path, files)
    if reader.message_count == 0:
        reader.close()
        raise BagError(f"{path} holds no messages{' that could be salvaged' if salvage else ''}")
    return reader


def _bag_files(path: Path) -> list[Path]:
    """The storage files of a bag; BagError if ``path`` is not a bag."""
    if path.is_file():
        if path.suffix not in BAG_SUFFIXES:
            raise BagError(
                f"{path} is not a bag (expected a rosbag2 directory or an .mcap, .db3 or .bag file)"
            )
        return [path]
    meta = path / "metadata.yaml"
    if meta.is_file():
        try:
            info = yaml.safe_load(meta.read_text())["rosbag2_bagfile_information"]
            return [path / name for name in info["relative_file_paths"]]
        except (yaml.YAMLError, KeyError, TypeError) as exc:
            raise BagError(f"{meta} is damaged ({_reason(exc)})") from None
    files = sorted(p for p in path.iterdir() if p.suffix in BAG_SUFFIXES)
    if not files:
        raise BagError(f"{path} is not a bag: no metadata.yaml and no .mcap, .db3 or .bag file in it")
    return files


def _open_any(path: Path, files: list[Path]) -> BagReader:
    from rosbags.highlevel import AnyReader

    if path.is_dir() and not (path / "metadata.yaml").is_file():
        raise BagError(
            f"{path} has no metadata.yaml (the recording was not closed: killed or crashed?); "
            "--salvage reads its MCAP files directly"
        )
    missing = [f for f in files if not f.exists()]
    if missing:
        raise BagError(f"{path}: metadata.yaml lists {_files_text(missing)}, which is missing")
    try:
        reader = AnyReader([path], default_typestore=default_typestore())
        reader.open()
    except Exception as exc:
        raise BagError(
            f"{_files_text(files)} is damaged ({_reason(exc)})"
            + ("; --salvage reads what can be read" if any(f.suffix == ".mcap" for f in files) else "")
        ) from None
    topics = {
        absolute_topic(name): TopicInfo(absolute_topic(name), info.msgtype or "", info.msgcount)
        for name, info in reader.topics.items()
    }
    return BagReader(
        path=path,
        topics=topics,
        custom_data=_custom_data(path, files),
        message_count=sum(t.count for t in topics.values()),
        files=files,
        typestore=reader.typestore,
        cdr=reader.is2,
        _any=reader,
        _indexed=_indexed_summaries(files),
    )


def _custom_data(path: Path, files: list[Path]) -> dict[str, str]:
    """``custom_data`` of ``metadata.yaml``, else the MCAP ``custom_data`` records."""
    meta = path / "metadata.yaml"
    if meta.is_file():
        info = yaml.safe_load(meta.read_text())["rosbag2_bagfile_information"]
        if info.get("custom_data"):
            return {str(k): str(v) for k, v in info["custom_data"].items()}
    out: dict[str, str] = {}
    for file in files:
        if file.suffix == ".mcap":
            out.update(_mcap_custom_data(file))
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


def _salvage(path: Path, files: list[Path]) -> BagReader:
    """Scan MCAP files record by record: topics, counts, custom data and the damage."""
    from rosbags.typesys import Stores, get_types_from_msg, get_typestore

    if any(f.suffix != ".mcap" for f in files):
        raise BagError(f"--salvage reads MCAP files only; {path} is {_files_text(files)}")
    store = get_typestore(Stores.ROS2_JAZZY)  # plus the types the files define
    topics: dict[str, TopicInfo] = {}
    custom: dict[str, str] = {}
    damage: list[str] = []
    for file in files:
        schemas: dict[int, Any] = {}
        channels: dict[int, Any] = {}
        counts: dict[int, int] = {}
        for kind, record in _mcap_records(file, damage):
            if kind == "schema":
                schemas[record.id] = record
                if record.encoding == "ros2msg" and record.name not in store.fielddefs:
                    store.register(get_types_from_msg(record.data.decode(), record.name))
            elif kind == "channel":
                channels[record.id] = record
            elif kind == "message":
                counts[record.channel_id] = counts.get(record.channel_id, 0) + 1
            elif kind == "metadata" and record.name == CUSTOM_DATA_RECORD:
                custom.update(record.metadata)
        for cid, ch in channels.items():
            name = absolute_topic(ch.topic)
            msgtype = schemas[ch.schema_id].name if ch.schema_id in schemas else ""
            old = topics.get(name)
            topics[name] = TopicInfo(name, msgtype, counts.get(cid, 0) + (old.count if old else 0))
    return BagReader(
        path=path,
        topics=topics,
        custom_data=custom,
        message_count=sum(t.count for t in topics.values()),
        files=files,
        typestore=store,
        cdr=True,
        damage=damage,
    )


def _mcap_records(file: Path, damage: list[str]) -> Iterator[tuple[str, Any]]:
    """(kind, record) of an MCAP file in file order, skipping damaged chunks.

    Kinds: ``schema``, ``channel``, ``message``, ``metadata``. A chunk that fails its
    CRC or does not decompress is skipped; reading stops at a truncated or garbled
    record. Each problem is appended to ``damage``.
    """
    from mcap.records import Channel, Chunk, Message, Metadata, Schema
    from mcap.stream_reader import StreamReader, breakup_chunk

    kinds = {Schema: "schema", Channel: "channel", Message: "message", Metadata: "metadata"}
    with file.open("rb") as f:
        records = StreamReader(f, emit_chunks=True, record_size_limit=1 << 30).records
        offset = 0
        while True:
            try:
                offset = f.tell()
                record = next(records)
            except StopIteration:
                return
            except Exception as exc:
                size = file.stat().st_size
                damage.append(
                    f"{file.name}: ends at byte {offset} without its summary (the recording was not closed)"
                    if offset >= size
                    else f"{file.name}: truncated or garbled at byte {offset} of {size} ({_reason(exc)}); "
                    "the rest is lost"
                )
                return
            if isinstance(record, Chunk):
                try:
                    inner = breakup_chunk(record, validate_crc=True)
                except Exception as exc:
                    damage.append(f"{file.name}: chunk at byte {offset} skipped ({_reason(exc)})")
                    continue
                for r in inner:
                    if type(r) in kinds:
                        yield kinds[type(r)], r
            elif type(record) in kinds:
                yield kinds[type(record)], record


def _files_text(files: Sequence[Path]) -> str:
    return ", ".join(str(f) for f in files)


def _reason(exc: BaseException) -> str:
    text = str(exc).strip().rstrip(".") or type(exc).__name__
    if "end magic" in text.lower():
        return "truncated: the file ends before its MCAP footer"
    return text
