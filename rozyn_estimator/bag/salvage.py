"""Salvage: MCAP files read record by record, keeping every intact chunk (``--salvage``).

ROS-free (``mcap``'s stream reader). For a recording that was killed (no summary, no
``metadata.yaml``), truncated or damaged: the files are scanned from the start, each
chunk checked against its CRC and decompressed on its own; a bad chunk is skipped, a
truncated or garbled record ends the file. Topics, counts, custom data and message
definitions come from the records themselves, and :attr:`SalvageScan.damage` says
what was lost (a message definition that does not parse included: its topic cannot be
decoded), :attr:`SalvageScan.unverified` what no CRC protects.
"""

from __future__ import annotations

from collections.abc import Iterator, Mapping
from pathlib import Path
from typing import Any

from rozyn_estimator.bag.source import RawBatch, TopicInfo, batched, files_text, reason
from rozyn_estimator.bag.typestore import absolute_topic
from rozyn_estimator.bag.writer import CUSTOM_DATA_RECORD
from rozyn_estimator.errors import BagError
from rozyn_estimator.yaml_file import one_line


class SalvageScan:
    """MCAP files read record by record (a :class:`MessageSource
    <rozyn_estimator.bag.source.MessageSource>`). Use :meth:`open`.

    Attributes:
        files: the bag's MCAP files.
        topics: absolute topic name -> :class:`~rozyn_estimator.bag.source.TopicInfo`
            (the messages found intact).
        custom_data: the ``custom_data`` records found.
        typestore: Jazzy's types plus those the files define.
        damage: what was skipped or lost, one line per problem.
        unverified: what no CRC protects (chunks written without one), one line per file.
    """

    cdr = True  # MCAP files from rosbag2: CDR messages

    def __init__(
        self,
        files: list[Path],
        topics: dict[str, TopicInfo],
        custom_data: dict[str, str],
        typestore: Any,
        damage: list[str],
        unverified: list[str],
    ) -> None:
        self.files = files
        self.topics = topics
        self.custom_data = custom_data
        self.typestore = typestore
        self.damage = damage
        self.unverified = unverified

    @classmethod
    def open(cls, path: Path, files: list[Path]) -> SalvageScan:
        """Scan the files once: topics, counts, custom data, types and the damage.

        Args:
            path: the bag (for messages).
            files: its storage files.

        Returns:
            The scan, ready to read the messages again with :meth:`batches`.

        Raises:
            BagError: a file is not MCAP.
        """
        from rosbags.typesys import Stores, get_types_from_msg, get_typestore

        if any(f.suffix != ".mcap" for f in files):
            raise BagError(f"--salvage reads MCAP files only; {path} is {files_text(files)}")
        store = get_typestore(Stores.ROS2_JAZZY)  # plus the types the files define
        topics: dict[str, TopicInfo] = {}
        custom: dict[str, str] = {}
        damage: list[str] = []
        unverified: list[str] = []
        for file in files:
            schemas: dict[int, Any] = {}
            channels: dict[int, Any] = {}
            counts: dict[int, int] = {}
            chunks = bare = 0
            for kind, record in mcap_records(file, damage):
                if kind == "chunk":
                    chunks += 1
                    bare += record.uncompressed_crc == 0
                elif kind == "schema":
                    schemas[record.id] = record
                    if record.encoding == "ros2msg" and record.name not in store.fielddefs:
                        try:
                            store.register(get_types_from_msg(record.data.decode(), record.name))
                        except Exception as exc:  # a garbled definition fails the parser in many ways
                            damage.append(f"{file.name}: the definition of {one_line(str(record.name), 80)} "
                                          f"does not parse ({reason(exc)}); its messages cannot be decoded")
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
            if bare:
                unverified.append(f"{file.name}: {bare} of {chunks} chunks carry no CRC: damage in them "
                                  "cannot be detected")
        return cls(files, topics, custom, store, damage, unverified)

    def batches(self, index: Mapping[str, int], size: int) -> Iterator[RawBatch]:
        """See :meth:`MessageSource.batches <rozyn_estimator.bag.source.MessageSource.batches>`.

        What :meth:`open` found damaged is skipped again; nothing raises.
        """
        return batched(self._messages(index), size)

    def _messages(self, index: Mapping[str, int]) -> Iterator[tuple[int, int, bytes]]:
        for file in self.files:
            channels: dict[int, str] = {}
            for kind, record in mcap_records(file, []):
                if kind == "channel":
                    channels[record.id] = record.topic
                elif kind == "message" and channels.get(record.channel_id) in index:
                    yield index[channels[record.channel_id]], record.log_time, record.data

    def close(self) -> None:
        """Nothing to release: each scan opens and closes its files."""


def mcap_records(file: Path, damage: list[str]) -> Iterator[tuple[str, Any]]:
    """(kind, record) of an MCAP file in file order, skipping damaged chunks.

    Kinds: ``chunk`` (each chunk, before its records), ``schema``, ``channel``,
    ``message``, ``metadata``. A chunk that fails its CRC or does not decompress is
    skipped; reading stops at a truncated or garbled record, or a file that cannot be
    read. Each problem is appended to ``damage``.

    Args:
        file: the MCAP file.
        damage: where the problems are noted.

    Returns:
        The records, lazily (the file is open while they are taken).
    """
    from mcap.records import Channel, Chunk, Message, Metadata, Schema
    from mcap.stream_reader import StreamReader, breakup_chunk

    kinds = {Schema: "schema", Channel: "channel", Message: "message", Metadata: "metadata"}
    try:
        f = file.open("rb")
    except OSError as exc:
        damage.append(f"{file.name}: cannot be read ({exc.strerror or exc})")
        return
    with f:
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
                    else f"{file.name}: truncated or garbled at byte {offset} of {size} ({reason(exc)}); "
                    "the rest is lost"
                )
                return
            if isinstance(record, Chunk):
                yield "chunk", record
                try:
                    inner = breakup_chunk(record, validate_crc=True)
                except Exception as exc:
                    damage.append(f"{file.name}: chunk at byte {offset} skipped ({reason(exc)})")
                    continue
                for r in inner:
                    if type(r) in kinds:
                        yield kinds[type(r)], r
            elif type(record) in kinds:
                yield kinds[type(record)], record
