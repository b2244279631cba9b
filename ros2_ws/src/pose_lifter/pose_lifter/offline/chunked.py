"""A single MCAP file read and copied through its index: messages read by number, and the chunks
copied into a new bag as they are.

An MCAP file written by rosbag2 or rosbags holds its messages in compressed chunks and, after each
chunk, a message index (each message's log time and offset inside the chunk); the summary at the
file's end lists the chunks (:func:`chunked_mcap`). Through it:

* :class:`IndexedMessages` reads the messages of some topics by their number in the file's read
  order (log time, then chunk offset, then offset in the chunk: what rosbags' and the ``mcap``
  package's readers give), decompressing only the chunk that holds one and keeping only the last
  chunk: random access to a large topic (a depth camera's images) in bounded memory;
* :class:`ChunkCopier` writes a bag whose every input chunk (with its message index) is copied
  byte for byte, not decompressed and compressed again, and whose new messages go into chunks of
  their own after them. MCAP lets chunks overlap in time and readers in log-time order merge them by
  (log time, file offset), so a new message is read after every copied message of its log time:
  :func:`pose_lifter.offline.lift.lift_bag` writes its answers after every input message of their
  log time on either path, so both paths write the same messages in the same order.
"""

from __future__ import annotations

import struct
from collections.abc import Iterable, Sequence
from dataclasses import dataclass
from io import BytesIO
from pathlib import Path
from typing import Any, BinaryIO, Final

from pose_lifter.offline.bags import BagWriter, bag_path

__all__ = ["ChunkCopier", "ChunkedMcap", "IndexedMessages", "chunked_mcap"]

#: A message to write: (topic, CDR bytes, type name).
Addition = tuple[str, bytes, str]

#: The size (uncompressed bytes) at which a chunk of new messages is closed: rosbags' own.
NEW_CHUNK_BYTES = 2**20

_MESSAGE: Final[int] = 0x05
_MESSAGE_INDEX: Final[int] = 0x07
_U64: Final = struct.Struct("<Q")
_ENTRY: Final = struct.Struct("<QQ")  # a message index entry: log time, offset in the chunk


@dataclass(frozen=True)
class ChunkedMcap:
    """The index of a single MCAP file whose every message lies in an indexed chunk.

    Attributes
    ----------
    path : Path
    chunks : tuple of rosbags ``ChunkInfo``
        In file order: offsets, sizes, compression, time range, each channel's message index
        offset and message count.
    channels : dict of int -> rosbags ``Channel``
    schemas : dict of int -> rosbags ``Schema``
    connections : tuple of rosbags ``Connection``
        Per channel (ids as the channels'): topic, type, message definition.
    """

    path: Path
    chunks: tuple[Any, ...]
    channels: dict[int, Any]
    schemas: dict[int, Any]
    connections: tuple[Any, ...]

    def channel_ids(self, topics: Iterable[str]) -> list[int]:
        """The ids of the channels of ``topics``."""
        wanted = set(topics)
        return sorted(k for k, c in self.channels.items() if c.topic in wanted)

    def positions(self, channel_ids: Sequence[int]) -> list[tuple[int, int, int]]:
        """``(log time, chunk number, offset in the chunk)`` of every message of ``channel_ids``,
        in read order (log time, chunk offset, offset; read from the message indexes, nothing
        decompressed)."""
        out: list[tuple[int, int, int, int]] = []
        with self.path.open("rb") as f:
            for k, chunk in enumerate(self.chunks):
                for cid in channel_ids:
                    at = chunk.message_index_offsets.get(cid)
                    if at is None:
                        continue
                    f.seek(at)
                    head = f.read(15)  # opcode, record length, channel id, entries' length
                    if len(head) != 15 or head[0] != _MESSAGE_INDEX:
                        raise ValueError(f"{self.path}: no message index at {at}")
                    n = struct.unpack_from("<I", head, 11)[0]
                    entries = f.read(n)
                    out.extend((t, chunk.chunk_start_offset, k, o) for t, o in _ENTRY.iter_unpack(entries))
        out.sort()
        return [(t, k, o) for t, _, k, o in out]


def chunked_mcap(path: str | Path) -> ChunkedMcap | None:
    """The index of the MCAP file ``path``, or None when it is not one whose messages all lie in
    indexed chunks (a rosbag2 directory, a ``.db3`` file, an MCAP file without a summary, with
    messages outside chunks, or with attachments)."""
    from rosbags.rosbag2.storage_mcap import McapReader

    p = bag_path(path)
    if not p.is_file() or p.suffix != ".mcap" or not _has_summary(p):
        return None
    reader = McapReader(p)
    try:
        reader.open()
    except Exception:  # not readable here: the caller's reader says why
        return None
    try:
        stats = reader.statistics
        chunks = tuple(sorted(reader.chunks, key=lambda c: c.chunk_start_offset))
        in_chunks = sum(sum(c.channel_count.values()) for c in chunks)
        if stats is None or not chunks or stats.attachement_count or in_chunks != stats.message_count:
            return None
        return ChunkedMcap(p, chunks, dict(reader.channels), dict(reader.schemas),
                           tuple(reader.connections))
    finally:
        reader.close()


def _has_summary(path: Path) -> bool:
    """The file ends in an MCAP footer that points at a summary section."""
    with path.open("rb") as f:
        size = f.seek(0, 2)
        if size < 8 + 37:
            return False
        f.seek(size - 37)
        footer = f.read(37)
    return footer[0] == 0x02 and footer[-8:] == b"\x89MCAP0\r\n" and _U64.unpack_from(footer, 9)[0] > 0


def _chunk_data(f: BinaryIO, chunk: Any) -> bytes:
    """The decompressed records of ``chunk`` (checked against its CRC when it has one)."""
    from rosbags.rosbag2.storage_mcap import decompress

    f.seek(chunk.chunk_start_offset + 9 + 24)
    crc = struct.unpack("<I", f.read(4))[0]
    f.seek(chunk.chunk_start_offset + 9 + 40 + len(chunk.compression))
    data = f.read(chunk.compressed_size)
    return bytes(decompress(data, chunk.compression, chunk.uncompressed_size, crc))


class IndexedMessages:
    """The messages at ``positions`` (:meth:`ChunkedMcap.positions`) of an MCAP file, read by
    number: the chunk that holds one is decompressed (the last one is kept, so neighbours cost
    nothing), and its bytes are returned as a view into it. A context manager."""

    def __init__(self, mcap: ChunkedMcap, positions: Sequence[tuple[int, int, int]]) -> None:
        self.mcap = mcap
        self.positions = positions
        self._file: BinaryIO | None = None
        self._chunk: tuple[int, memoryview] | None = None  # (chunk number, its records)
        self.n_decompressed = 0

    def __enter__(self) -> IndexedMessages:
        return self

    def __exit__(self, *exc: object) -> None:
        self.close()

    def close(self) -> None:
        f, self._file, self._chunk = self._file, None, None
        if f is not None:
            f.close()

    def __len__(self) -> int:
        return len(self.positions)

    def data(self, index: int) -> memoryview:
        """The serialised bytes of message ``index`` (in read order)."""
        _, k, offset = self.positions[index]
        if self._chunk is None or self._chunk[0] != k:
            if self._file is None:
                self._file = self.mcap.path.open("rb")
            self._chunk = (k, memoryview(_chunk_data(self._file, self.mcap.chunks[k])))
            self.n_decompressed += 1
        records = self._chunk[1]
        if records[offset] != _MESSAGE:
            raise ValueError(f"{self.mcap.path}: no message at offset {offset} of chunk {k}")
        length = _U64.unpack_from(records, offset + 1)[0]
        return records[offset + 9 + 22:offset + 9 + length]


class ChunkCopier(BagWriter):
    """A :class:`~pose_lifter.offline.bags.BagWriter` that copies the chunks of a
    :class:`ChunkedMcap` as they are (:meth:`copy_chunk`) and writes new messages into chunks of
    its own (zstd, as the writer's).

    The input's channels keep their ids, schemas and metadata (the copied chunks refer to them),
    their records written before the first chunk; a new topic gets the next id. :func:`copyable`
    says first whether a file's channels can be kept so.
    """

    def __init__(self, path: str | Path, source: ChunkedMcap, definitions: dict[int, tuple[str, str]],
                 overwrite: bool = False) -> None:
        from rosbags.rosbag2 import StoragePlugin

        super().__init__(path, overwrite=overwrite)
        self._writer.STORAGE_PLUGINS = {StoragePlugin.MCAP: _copying_storage()}
        self.source = source
        self._definitions = definitions
        self._in: BinaryIO | None = None

    def open(self) -> ChunkCopier:
        super().open()
        storage: Any = self._writer.storage
        storage.direct = True  # the input's schemas and channels: before the first copied chunk
        for cid in sorted(self.source.channels):
            ch = self.source.channels[cid]
            msgdef, rihs01 = self._definitions[cid]
            storage.channel_metadata = ch.metadata
            conn = self._writer.add_connection(ch.topic, ch.schema, msgdef=msgdef, rihs01=rihs01,
                                               serialization_format=ch.message_encoding)
            if conn.id != cid:  # copyable() rules this out
                raise ValueError(f"channel {cid} of {self.source.path} would be {conn.id}")
            self._connections[ch.topic] = conn
        storage.direct, storage.channel_metadata = False, None
        self._in = self.source.path.open("rb")
        return self

    def copy_chunk(self, index: int) -> None:
        """Copy chunk ``index`` of the source (and its message index) as it is."""
        assert self._in is not None
        chunk = self.source.chunks[index]
        storage: Any = self._writer.storage
        storage.copy_chunk(self._in, chunk)
        for cid, n in chunk.channel_count.items():
            self._writer.counts[cid] += n
        if chunk.channel_count:
            self._writer.min_timestamp = min(self._writer.min_timestamp, chunk.message_start_time)
            self._writer.max_timestamp = max(self._writer.max_timestamp, chunk.message_end_time)

    def close(self, discard: bool = False) -> None:
        f, self._in = self._in, None
        if f is not None:
            f.close()
        super().close(discard)


def copyable(mcap: ChunkedMcap, schema_of: dict[int, str]) -> bool:
    """The channels of ``mcap`` can keep their ids in a rosbags writer: ids 1..n, each schema's id
    the order in which the channels (by id) first use it, one channel per (topic, type), a schema
    per channel with the encoding rosbags gives its text (``schema_of``: channel id -> the schema
    name it uses)."""
    ids = sorted(mcap.channels)
    if ids != list(range(1, len(ids) + 1)):
        return False
    names = [s.name for s in mcap.schemas.values()]
    if len(set(names)) != len(names) or "__schemaless__" in schema_of.values():
        return False
    order: dict[str, int] = {}
    for cid in ids:
        order.setdefault(schema_of[cid], len(order) + 1)
    if {s.id: s.name for s in mcap.schemas.values()} != {v: k for k, v in order.items()}:
        return False
    pairs = [(c.topic, c.schema) for c in mcap.channels.values()]
    idl = "=" * 80 + "\nIDL: "
    return len(set(pairs)) == len(pairs) and all(
        s.encoding == ("ros2idl" if s.data.startswith(idl) else "ros2msg") for s in mcap.schemas.values())


def _write_u64(bio: Any, value: int) -> None:
    bio.write(value.to_bytes(8, "little"))


def _make_storage() -> type:
    """rosbags' MCAP storage writer with the copying of chunks (imported when first needed)."""
    from rosbags.rosbag2.storage_mcap import Channel, McapWriter, write_channel, write_string

    class CopyingMcapWriter(McapWriter):
        """rosbags' MCAP storage; ``direct``: schema and channel records go to the file (before
        copied chunks), not into the pending chunk; ``channel_metadata``: the next channel's
        metadata bytes as they are."""

        direct = False
        channel_metadata: bytes | None = None

        def add_msgtype(self, connection: Any) -> None:
            if not self.direct:
                super().add_msgtype(connection)
                return
            pending: Any = self.chunk
            chunk, pending.bio = pending.bio, self.bio
            try:
                super().add_msgtype(connection)
            finally:
                pending.bio = chunk

        def add_connection(self, connection: Any, offered_qos_profiles: str) -> None:
            if self.channel_metadata is None:
                super().add_connection(connection, offered_qos_profiles)
                return
            self.channels.append(Channel(connection.id, connection.msgtype, connection.topic,
                                         connection.ext.serialization_format, self.channel_metadata))
            self.channel_stats[connection.id] = 0
            write_channel(self.bio if self.direct else self.chunk.bio, self.channels[-1], self.schemas)

        def write(self, connection: Any, timestamp: int, data: bytes | memoryview) -> None:
            super().write(connection, timestamp, data)
            if self.chunk.bio.tell() > NEW_CHUNK_BYTES:
                self.close_chunk()

        def copy_chunk(self, source: BinaryIO, chunk: Any) -> None:
            start = self.bio.tell()
            source.seek(chunk.chunk_start_offset)
            n = chunk.chunk_length + chunk.message_index_length
            data = source.read(n)
            if len(data) != n:
                raise ValueError(f"truncated chunk at {chunk.chunk_start_offset}")
            self.bio.write(data)
            shift = start - chunk.chunk_start_offset
            rec = BytesIO()
            for value in (chunk.message_start_time, chunk.message_end_time, start, chunk.chunk_length):
                _write_u64(rec, value)
            rec.write((10 * len(chunk.message_index_offsets)).to_bytes(4, "little"))
            for cid, at in chunk.message_index_offsets.items():
                rec.write(cid.to_bytes(2, "little"))
                _write_u64(rec, at + shift)
            _write_u64(rec, chunk.message_index_length)
            write_string(rec, chunk.compression)
            _write_u64(rec, chunk.compressed_size)
            _write_u64(rec, chunk.uncompressed_size)
            self.chunks.append(rec)
            for cid, n_msgs in chunk.channel_count.items():
                self.channel_stats[cid] += n_msgs
            if chunk.channel_count:
                self.message_start_time = min(self.message_start_time, chunk.message_start_time)
                self.message_end_time = max(self.message_end_time, chunk.message_end_time)

    return CopyingMcapWriter


_STORAGE: type | None = None


def _copying_storage() -> type:
    global _STORAGE
    if _STORAGE is None:
        _STORAGE = _make_storage()
    return _STORAGE


def copy_with(mcap: ChunkedMcap, out_path: str | Path, additions: Sequence[tuple[int, Sequence[Addition]]],
              overwrite: bool = False) -> bool:
    """Write ``out_path``: every chunk of ``mcap`` copied as it is, and ``additions`` (per log
    time, in log-time order: its messages ``(topic, CDR bytes, type)``) in chunks of their own,
    each read after every copied message of its log time (written once every chunk that starts at
    or before it is in the file). False, and nothing written, when the file's channels cannot keep
    their ids (:func:`copyable`) or one is of our own types in an older layout (which
    :func:`~pose_lifter.offline.bags.read_raw` upgrades, so it cannot be copied as it is)."""
    from pose_lifter.messages.typestore import pose_lifter_typestore
    from pose_lifter.offline.bags import _definition, _stale

    definitions = {c.id: _definition(c) for c in mcap.connections}
    if set(definitions) != set(mcap.channels):
        return False
    stale = _stale(mcap.connections, {k: d[1] for k, d in definitions.items()}, pose_lifter_typestore())
    if stale or not copyable(mcap, {c.id: c.msgtype for c in mcap.connections}):
        return False
    stamps = [s for s, _ in additions]
    if stamps != sorted(stamps):
        raise ValueError("additions must be in log-time order")
    # the earliest start of the chunks from each one on: additions before it may be written
    later = [2**63] * (len(mcap.chunks) + 1)
    for k in range(len(mcap.chunks) - 1, -1, -1):
        later[k] = min(later[k + 1], mcap.chunks[k].message_start_time)
    j = 0
    w = ChunkCopier(out_path, mcap, definitions, overwrite=overwrite)
    with w:
        for k in range(len(mcap.chunks)):
            w.copy_chunk(k)
            while j < len(additions) and additions[j][0] < later[k + 1]:
                stamp, messages = additions[j]
                for topic, data, msgtype in messages:
                    w.write_cdr(topic, stamp, data, msgtype)
                j += 1
        for stamp, messages in additions[j:]:
            for topic, data, msgtype in messages:
                w.write_cdr(topic, stamp, data, msgtype)
    return True
