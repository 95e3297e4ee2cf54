"""The fast path: indexed MCAP files read chunk by chunk through their message indexes.

ROS-free (``mcap`` for the summary, ``zstandard``/``lz4`` for the chunks, numpy). For
each chunk holding a wanted channel, the message index records (log time, offset) are
read as one numpy array, the chunk is decompressed once, and the messages are located
in the decompressed buffer by vectorised arithmetic: no Python object per message. The
result is a :class:`~rozyn_estimator.bag.source.RawBatch` whose
:class:`~rozyn_estimator.bag.cdr.Packed` shares the chunk's buffer, which
:class:`~rozyn_estimator.bag.cdr.FieldReader` then decodes column by column.

Usable when every file is MCAP with a summary whose chunks all carry message indexes
and follow each other in time (so chunk order is time order), as rosbag2 and
:class:`~rozyn_estimator.bag.writer.BagWriter` write them; otherwise
:func:`~rozyn_estimator.bag.reader.open_bag` leaves the reading to rosbags' AnyReader.

Why we keep our own: the libraries make a Python object (and rosbags a connection
lookup, a heap merge) per message. Measured on an hour of 2 × 100 Hz ``sensor_msgs/Imu``
(720 000 messages, a 27 MB zstd MCAP written by ``BagWriter``; 2-core machine, best of 3;
runs vary by about 10 %):

======================================================  ========  ==========
reading the two topics                                  time      vs. ours
======================================================  ========  ==========
this module: raw batches (CRCs checked)                 0.29 s    1
rosbags ``AnyReader.messages``: raw bytes               2.27 s    8×
``mcap`` ``iter_messages``: raw bytes                   7.67 s    26×
this module + ``FieldReader``: stamps and ``z``         0.42 s    1
rosbags ``AnyReader`` + ``deserialize_cdr``, per msg    10.4 s    25×
``mcap_ros2`` ``iter_decoded_messages``                 28.1 s    67×
======================================================  ========  ==========

An hour-long recording replays in well under a second of reading instead of 10 s to
half a minute; the libraries stay the reference (``test_bag`` checks that this path
reads exactly what AnyReader reads) and the fallback for everything else.

Every chunk is checked against its CRC (CRC-32 of the decompressed records, as the
``mcap`` and rosbags readers check it), and every message index entry against the
channel and time of the record it points at (the indexes lie outside the CRC), so a
flipped bit in a recording is an error naming the chunk, never a silently different
estimate. On the hour above that costs 0.10 s of CPU (0.31 s before, read and decoded;
the CRC 0.07 s of it: zlib's CRC-32 at about 3.5 GB/s over the 256 MB the chunks
decompress to, the index check 0.03 s). A chunk written without a CRC (0) cannot be
checked: :func:`unchecked_chunks` says so, and :attr:`BagReader.unverified
<rozyn_estimator.bag.reader.BagReader.unverified>` reports it.
"""

from __future__ import annotations

import struct
import zlib
from collections.abc import Iterator, Mapping
from dataclasses import dataclass
from pathlib import Path
from typing import Any, BinaryIO

import numpy as np

from rozyn_estimator.bag.cdr import Packed
from rozyn_estimator.bag.source import RawBatch, damaged, joined
from rozyn_estimator.bag.typestore import absolute_topic

# opcode, length, start, end, uncompressed size, crc, len(compression)
_CHUNK_HEAD = struct.Struct("<BQQQQII")
_INDEX_HEAD = struct.Struct("<BQHI")  # opcode, length, channel id, length of the entries
_MAX_CHUNK_BYTES = 1 << 32  # larger claims are garbled (the recorder's chunks are at most 1 GiB)


@dataclass
class IndexedMcap:
    """Indexed MCAP files, read through their message indexes (a :class:`MessageSource
    <rozyn_estimator.bag.source.MessageSource>`).

    Args:
        files: the bag's storage files (named in errors).
        summaries: ``(file, mcap Summary)`` of each file, chunk indexes in file order.
    """

    files: list[Path]
    summaries: list[tuple[Path, Any]]

    @classmethod
    def open(cls, files: list[Path]) -> IndexedMcap | None:
        """The fast path for these files, or None when it cannot read them.

        Args:
            files: the bag's storage files.

        Returns:
            The source, or None (not all MCAP, no summary, chunks without message
            indexes or overlapping in time): then rosbags' AnyReader reads.
        """
        summaries = _indexed_summaries(files)
        return cls(files, summaries) if summaries else None

    def batches(self, index: Mapping[str, int], size: int) -> Iterator[RawBatch]:
        """See :meth:`MessageSource.batches <rozyn_estimator.bag.source.MessageSource.batches>`.

        Raises:
            BagError: a chunk or message index is garbled (names the chunk's byte offset).
        """
        parts: list[RawBatch] = []
        count = 0
        for file, summary in self.summaries:
            wanted = {
                cid: index[absolute_topic(ch.topic)]
                for cid, ch in summary.channels.items()
                if absolute_topic(ch.topic) in index
            }
            with file.open("rb") as f:
                file_size = f.seek(0, 2)
                for chunk in summary.chunk_indexes:
                    ids = [cid for cid in chunk.message_index_offsets if cid in wanted]
                    if not ids:
                        continue
                    try:
                        part = _indexed_chunk(f, chunk, ids, wanted, file_size)
                    except Exception as exc:
                        raise damaged(self.files, exc, f"chunk at byte {chunk.chunk_start_offset}") from None
                    parts.append(part)
                    count += len(part)
                    if count >= size:
                        yield joined(parts)
                        parts, count = [], 0
        if parts:
            yield joined(parts)

    def close(self) -> None:
        """Nothing to release: each :meth:`batches` opens and closes its files."""


def _indexed_chunk(
    f: BinaryIO, chunk: Any, ids: list[int], wanted: dict[int, int], file_size: int
) -> RawBatch:
    """The wanted messages of one MCAP chunk, found through its message indexes, its CRC checked."""
    times, offsets, channels = [], [], []
    for cid in ids:
        f.seek(chunk.message_index_offsets[cid])
        opcode, _, channel, n = _INDEX_HEAD.unpack(f.read(_INDEX_HEAD.size))
        if opcode != 0x07 or channel != cid or n > file_size:
            raise ValueError("a message index is garbled")
        entries = np.frombuffer(f.read(n), "<u8").reshape(-1, 2).astype(np.int64)
        times.append(entries[:, 0])
        offsets.append(entries[:, 1])
        channels.append(np.full(len(entries), cid, np.int64))
    buf = np.frombuffer(_chunk_records(f, chunk, file_size), np.uint8)
    t, off, cids = np.concatenate(times), np.concatenate(offsets), np.concatenate(channels)
    order = np.lexsort((off, t))  # receive time, then file order
    t, off, cids = t[order], off[order], cids[order]
    if off.size and (off.min() < 0 or off.max() + 31 > buf.size or np.any(buf[off] != 0x05)):
        raise ValueError("a message index points outside the messages")
    # the indexes are outside the CRC: each entry must name the channel and time of its record
    if np.any(_field(buf, off + 9, "<u2") != cids) or np.any(_field(buf, off + 15, "<u8") != t):
        raise ValueError("a message index does not match its messages")
    lookup = np.zeros(max(ids) + 1, np.int16)
    lookup[ids] = [wanted[cid] for cid in ids]
    top = lookup[cids]
    lengths = _field(buf, off + 1, "<u8").astype(np.int64) - 22
    starts = off + 31  # opcode 1, length 8, channel 2, sequence 4, log time 8, publish time 8
    if np.any(lengths < 0) or np.any(starts + lengths > buf.size):
        raise ValueError("a message overruns its chunk")
    return RawBatch(top, t, Packed(buf, starts, lengths))


def _field(buf: np.ndarray, at: np.ndarray, dtype: str) -> np.ndarray:
    """A little-endian number at each offset of ``buf``."""
    size = np.dtype(dtype).itemsize
    return buf[at[:, None] + np.arange(size)].view(dtype).ravel()


def _chunk_records(f: BinaryIO, chunk: Any, file_size: int) -> bytes:
    """The records of one chunk, decompressed and checked against the chunk's CRC.

    Args:
        f: the open MCAP file.
        chunk: the chunk's index record (``mcap`` ``ChunkIndex``).
        file_size: the file's size in bytes (bounds what the chunk may claim).

    Returns:
        The decompressed records.

    Raises:
        ValueError: the chunk record is garbled, does not decompress to its size, or
            fails its CRC (the data changed after it was written).
    """
    f.seek(chunk.chunk_start_offset)
    opcode, _, _, _, size, crc, n = _CHUNK_HEAD.unpack(f.read(_CHUNK_HEAD.size))
    compression = f.read(min(n, 64)).decode(errors="replace")
    (length,) = struct.unpack("<Q", f.read(8))
    if (opcode != 0x06 or compression != chunk.compression or length > file_size
            or size > _MAX_CHUNK_BYTES):
        raise ValueError("the chunk record is garbled")
    data = _decompress(compression, f.read(length), size)
    if len(data) != size:
        raise ValueError(f"the chunk decompresses to {len(data)} bytes, not the {size} it records")
    if crc and zlib.crc32(data) != crc:
        raise ValueError("its CRC does not match: the data changed after it was written")
    return data


def unchecked_chunks(file: Path) -> str | None:
    """What of an MCAP file no CRC protects, in words, or None when every chunk has one.

    Args:
        file: the MCAP file (with a summary: otherwise None, and the readers that scan
            the file note unprotected chunks as they meet them).

    Returns:
        E.g. ``run_0.mcap: 12 of 12 chunks carry no CRC: damage in them cannot be detected``.
    """
    from mcap.reader import make_reader

    try:
        with file.open("rb") as f:
            summary = make_reader(f).get_summary()
            if summary is None:
                return None
            chunks = summary.chunk_indexes
            crcs = []
            for chunk in chunks:
                f.seek(chunk.chunk_start_offset)
                crcs.append(_CHUNK_HEAD.unpack(f.read(_CHUNK_HEAD.size))[5])
    except Exception:  # an unreadable summary: the reader that reads the file will say so
        return None
    bare = crcs.count(0)
    if not chunks and summary.statistics is not None and summary.statistics.message_count:
        return f"{file.name}: its messages are not in chunks, no CRC protects them: damage cannot be detected"
    if bare:
        return f"{file.name}: {bare} of {len(chunks)} chunks carry no CRC: damage in them cannot be detected"
    return None


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

    Raises:
        BagError: a summary fails its CRC (it locates the chunks: a damaged one would
            silently lose or repeat them).
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
                intact = _summary_intact(f)
        except Exception:
            return []
        if not intact:
            raise damaged(files, ValueError(f"{file.name}: the CRC of its summary (the index at its end) "
                                            "does not match"))
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


def _summary_intact(f: BinaryIO) -> bool:
    """The summary section matches the CRC in the footer (True when there is none to check)."""
    end = f.seek(0, 2)
    footer = end - 8 - (1 + 8 + 8 + 8 + 4)  # the footer record, then the closing magic
    f.seek(footer + 1 + 8)
    summary_start, _, crc = struct.unpack("<QQI", f.read(20))
    if not crc or not summary_start:
        return True
    if not 0 < summary_start <= footer:
        return False
    f.seek(summary_start)
    return zlib.crc32(f.read(footer + 1 + 8 + 8 + 8 - summary_start)) == crc
