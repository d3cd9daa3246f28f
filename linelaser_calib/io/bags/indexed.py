"""The messages of chosen topics of an indexed MCAP file, read through its indexes.

rosbags' reader parses every record of every chunk in Python and merges the chunks message
by message: ~4.5 µs a message, 0.65 s for the 143,512 messages of a 1,600-profile
``ur_scancontrol`` recording (most of them flange poses). An MCAP file as rosbag2 and rosbags
write it ends with a summary that locates each chunk and, per chunk and channel, a message
index: the log time and the offset in the chunk of each message. Read through them, one
chunk's messages of one topic come out as one :class:`~.records.RawMessages` (a few array
operations, nothing per message).

:func:`indexed_topics` reads only a file whose indexes account for every message of the
topics asked for (one storage file, uncompressed as a whole, chunks with message indexes,
the counts rosbags reports); for any other (SQLite 3, an unchunked or unindexed MCAP, a
bag split into several files) it gives None and the caller reads with rosbags. A chunk whose
bytes contradict its index raises :class:`ReaderError`, as a damaged chunk does in rosbags.
"""

from __future__ import annotations

from collections.abc import Iterator, Sequence
from pathlib import Path
from typing import Any, BinaryIO, NamedTuple

import numpy as np
import yaml
from mcap.reader import make_reader
from mcap.records import ChunkIndex
from numpy.typing import NDArray
from rosbags.rosbag2.errors import ReaderError
from rosbags.rosbag2.storage_mcap import decompress

from linelaser_calib.io.bags.records import RawMessages

#: MCAP record opcodes (https://mcap.dev/spec).
_MESSAGE, _CHUNK, _MESSAGE_INDEX = 0x05, 0x06, 0x07
#: Bytes of a record's opcode and length, and of a message record's fields before its data
#: (channel id u16, sequence u32, log time u64, publish time u64).
_PREFIX, _MESSAGE_FIELDS = 9, 22


class _Channel(NamedTuple):
    """The connection (the caller's) whose messages an MCAP channel holds."""

    connection: Any
    channel_id: int


class IndexedFile(NamedTuple):
    """An MCAP file and the chunks that hold messages of the chosen channels."""

    path: Path
    channels: list[_Channel]
    chunks: list[ChunkIndex]


def _storage_file(part: Path) -> Path | None:
    """The one MCAP file of a bag part (its directory or the file itself), or None."""
    if part.is_file():
        return part if part.suffix == ".mcap" else None
    try:
        info = yaml.safe_load((part / "metadata.yaml").read_text(encoding="utf-8"))
        info = info["rosbag2_bagfile_information"]
        names = [str(n) for n in info["relative_file_paths"]]
        mode = str(info.get("compression_mode") or "").lower()
    except (OSError, UnicodeDecodeError, yaml.YAMLError, KeyError, TypeError, AttributeError):
        return None
    if info.get("storage_identifier") != "mcap" or mode not in {"", "none"} or len(names) != 1:
        return None
    return part / Path(names[0]).name


def indexed_topics(part: Path, connections: Sequence[Any]) -> IndexedFile | None:
    """The indexed MCAP file of ``part`` holding the messages of ``connections`` (rosbags
    connections: ``topic``, ``msgtype``, ``msgcount``), or None when it must be read with
    rosbags (see the module docstring)."""
    path = _storage_file(part)
    if path is None or not connections:
        return None
    try:
        with path.open("rb") as stream:
            summary = make_reader(stream).get_summary()
    # The mcap reader raises various errors on a damaged summary; rosbags then reads the
    # file (and reports the damage its own way).
    except Exception:
        return None
    if summary is None or not summary.chunk_indexes:
        return None
    if any(not chunk.message_index_offsets for chunk in summary.chunk_indexes):
        return None  # chunks indexed, their messages not
    channels = []
    for connection in connections:
        ids = [
            channel.id
            for channel in summary.channels.values()
            if channel.topic == connection.topic
            and channel.message_encoding == "cdr"
            and channel.schema_id in summary.schemas
            and summary.schemas[channel.schema_id].name == connection.msgtype
        ]
        if len(ids) != 1:
            return None
        channels.append(_Channel(connection, ids[0]))
    chunks = [
        chunk
        for chunk in summary.chunk_indexes
        if any(c.channel_id in chunk.message_index_offsets for c in channels)
    ]
    counts = summary.statistics.channel_message_counts if summary.statistics else {}
    for channel in channels:
        if counts.get(channel.channel_id) != channel.connection.msgcount:
            return None
    if any(chunk.message_index_length == 0 for chunk in chunks):
        return None
    return IndexedFile(path, channels, sorted(chunks, key=lambda c: c.chunk_start_offset))


def _gather(data: NDArray[np.uint8], at: NDArray[np.int64], dtype: str) -> NDArray[Any]:
    """The little-endian ``dtype`` value at each byte offset ``at`` of ``data``."""
    size = np.dtype(dtype).itemsize
    values: NDArray[Any] = data[at[:, None] + np.arange(size)].view(dtype)[:, 0]
    return values


def _message_index(records: bytes, start: int, channel_id: int) -> NDArray[np.int64]:
    """The (K, 2) log times and chunk offsets of one message index record at ``start``."""
    if records[start] != _MESSAGE_INDEX:
        raise ReaderError(f"no message index record at byte {start} of a chunk's indexes")
    length = int.from_bytes(records[start + 1 : start + _PREFIX], "little")
    body = records[start + _PREFIX : start + _PREFIX + length]
    if len(body) != length or length < 6 or int.from_bytes(body[:2], "little") != channel_id:
        raise ReaderError(f"message index record of channel {channel_id} is damaged")
    entries = int.from_bytes(body[2:6], "little")
    if entries % 16 or 6 + entries > length:
        raise ReaderError(f"message index record of channel {channel_id} is damaged")
    return (
        np.frombuffer(body, dtype="<u8", count=entries // 8, offset=6)
        .reshape(-1, 2)
        .astype(np.int64)
    )


def _chunk_messages(
    stream: BinaryIO, chunk: ChunkIndex, channels: Sequence[_Channel]
) -> Iterator[tuple[int, RawMessages]]:
    """Each chosen channel's messages in one chunk (in their index's order), with the
    channel's position in ``channels``."""
    stream.seek(chunk.chunk_start_offset)
    record = stream.read(chunk.chunk_length)
    indexes = stream.read(chunk.message_index_length)
    if len(record) != chunk.chunk_length or len(indexes) != chunk.message_index_length:
        raise ReaderError(f"chunk at byte {chunk.chunk_start_offset} is truncated")
    data_start = _PREFIX + 28 + 4 + len(chunk.compression.encode()) + 8
    if record[0] != _CHUNK or data_start + chunk.compressed_size > len(record):
        raise ReaderError(f"no chunk record at byte {chunk.chunk_start_offset}")
    crc = int.from_bytes(record[_PREFIX + 24 : _PREFIX + 28], "little")
    raw = decompress(
        record[data_start : data_start + chunk.compressed_size],
        chunk.compression,
        chunk.uncompressed_size,
        crc,
    )
    data = np.frombuffer(raw, dtype=np.uint8)
    index_start = chunk.chunk_start_offset + chunk.chunk_length
    for k, channel in enumerate(channels):
        at = chunk.message_index_offsets.get(channel.channel_id)
        if at is None:
            continue
        offsets = _message_index(indexes, at - index_start, channel.channel_id)[:, 1]
        if np.any(offsets < 0) or np.any(offsets + _PREFIX + _MESSAGE_FIELDS > len(data)):
            raise ReaderError(f"message index of channel {channel.channel_id} points outside")
        lengths = _gather(data, offsets + 1, "<u8").astype(np.int64)
        if (
            np.any(data[offsets] != _MESSAGE)
            or np.any(_gather(data, offsets + _PREFIX, "<u2") != channel.channel_id)
            or np.any(lengths < _MESSAGE_FIELDS)
            or np.any(offsets + _PREFIX + lengths > len(data))
        ):
            raise ReaderError(f"chunk at byte {chunk.chunk_start_offset} disagrees with its index")
        log_ns = _gather(data, offsets + _PREFIX + 6, "<u8").astype(np.int64)
        starts = offsets + _PREFIX + _MESSAGE_FIELDS
        yield k, RawMessages(data, starts, lengths - _MESSAGE_FIELDS, log_ns)


def indexed_messages(indexed: IndexedFile) -> Iterator[tuple[Any, RawMessages]]:
    """The messages of the chosen topics, a chunk and topic at a time, with the connection
    they belong to; chunk by chunk in file order (the caller sorts by stamp).

    Raises
    ------
    ReaderError
        A chunk that is truncated, fails its checksum or contradicts its index, or indexes
        that miss messages the file's statistics count.
    """
    read = dict.fromkeys(range(len(indexed.channels)), 0)
    with indexed.path.open("rb") as stream:
        for chunk in indexed.chunks:
            for k, messages in _chunk_messages(stream, chunk, indexed.channels):
                read[k] += len(messages)
                yield indexed.channels[k].connection, messages
    for k, channel in enumerate(indexed.channels):
        if read[k] != channel.connection.msgcount:
            raise ReaderError(
                f"the message indexes of {channel.connection.topic} list {read[k]} messages, "
                f"its statistics {channel.connection.msgcount}"
            )
