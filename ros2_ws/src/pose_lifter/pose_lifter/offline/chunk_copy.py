"""A bag whose every chunk of an MCAP input is copied as it is, not decompressed and compressed
again, next to new messages in chunks of their own (:func:`copy_with`).

MCAP lets chunks overlap in time, and readers in log-time order merge them by (log time, file
offset), so a new message is read after every copied message of its log time:
:func:`pose_lifter.offline.lift.lift_bag` writes its answers after every input message of their
log time on either path (this one, or message by message), so both paths write the same messages
in the same order. The input's channels keep their ids, schemas and metadata (a copied chunk may
hold their records); a new topic gets the next id.
"""

from __future__ import annotations

from collections.abc import Sequence
from io import BytesIO
from pathlib import Path
from typing import Any, BinaryIO

from pose_lifter.offline.bags import BagWriter, mcap_storage
from pose_lifter.offline.mcap_index import ChunkedMcap

__all__ = ["NEW_CHUNK_BYTES", "Addition", "ChunkCopier", "copy_with", "copyable"]

#: A message to write: (topic, CDR bytes, type name).
Addition = tuple[str, bytes, str]
#: The size (uncompressed bytes) at which a chunk of new messages is closed: rosbags' own.
NEW_CHUNK_BYTES = 2**20


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
    from rosbags.rosbag2.storage_mcap import Channel, write_channel, write_string

    class CopyingMcapWriter(mcap_storage()):  # type: ignore[misc]
        """The MCAP storage of :func:`~pose_lifter.offline.bags.mcap_storage`; ``direct``: schema
        and channel records go to the file (before copied chunks), not into the pending chunk;
        ``channel_metadata``: the next channel's metadata bytes as they are."""

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
                me: Any = self  # the storage's own times (its base is made at run time)
                me.message_start_time = min(me.message_start_time, chunk.message_start_time)
                me.message_end_time = max(me.message_end_time, chunk.message_end_time)

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
