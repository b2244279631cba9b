"""A single MCAP file read through its index: a topic's messages in read order, each chunk
decompressed once and only as far as needed, or read by number.

An MCAP file written by rosbag2 or rosbags holds its messages in compressed chunks and, after each
chunk, a message index (each message's log time and offset inside the chunk); the summary at the
file's end lists the chunks (:func:`chunked_mcap`). Through it:

* :func:`iter_chunked` gives the messages of some channels in the file's read order (log time, then
  chunk offset, then offset in the chunk: what rosbags' and the ``mcap`` package's readers give),
  each chunk decompressed up to the last message wanted of it, the messages as views of the chunk
  (nothing copied); of a large message whose header alone is wanted (an image's stamp) only that;
* :class:`IndexedMessages` reads the messages of some channels by their number in that order,
  decompressing only the chunk that holds one and keeping only the last chunk: random access to a
  large topic (a depth camera's images) in bounded memory.
"""

from __future__ import annotations

import heapq
import itertools
import struct
from collections.abc import Iterable, Iterator, Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import Any, BinaryIO, Final

__all__ = ["ChunkedMcap", "IndexedMessages", "chunked_mcap", "iter_chunked"]

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

    p = Path(path)
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


class _Records:
    """A chunk's records, decompressed as far as asked (:meth:`upto`): a zstd chunk without a CRC
    a piece at a time, any other whole (its CRC checked). Views of the records given out stay
    valid (more records are a new buffer)."""

    def __init__(self, f: BinaryIO, chunk: Any) -> None:
        from rosbags.rosbag2.storage_mcap import decompress

        f.seek(chunk.chunk_start_offset + 9 + 24)
        crc = struct.unpack("<I", f.read(4))[0]
        f.seek(chunk.chunk_start_offset + 9 + 40 + len(chunk.compression))
        data = f.read(chunk.compressed_size)
        self.size = chunk.uncompressed_size
        self._dec: Any = None
        self._input = b""
        if chunk.compression == "zstd" and not crc:
            from backports import zstd

            self.view = memoryview(b"")
            self._dec, self._input = zstd.ZstdDecompressor(), data
        else:
            self.view = memoryview(decompress(data, chunk.compression, self.size, crc))

    def upto(self, n: int) -> memoryview:
        """The records, decompressed at least to byte ``n`` (the rest perhaps not)."""
        n = min(n, self.size)
        pieces = [self.view] if len(self.view) else []
        have = len(self.view)
        while have < n:
            piece = self._dec.decompress(self._input, max_length=n - have)
            self._input = b""
            if not piece:
                raise ValueError(f"a chunk ends after {have} of its {self.size} bytes")
            pieces.append(piece)
            have += len(piece)
        if len(pieces) > 1 or (pieces and pieces[0] is not self.view):
            self.view = memoryview(pieces[0] if len(pieces) == 1 else b"".join(pieces))
        return self.view


def _message_at(records: memoryview, offset: int, head: int | None = None) -> tuple[int, memoryview]:
    """(log time, data) of the message record at ``offset`` of a chunk's records (``head``: only
    the first ``head`` bytes of its data, or fewer when the record ends sooner)."""
    if records[offset] != _MESSAGE:
        raise ValueError(f"no message at offset {offset} of a chunk")
    length = _U64.unpack_from(records, offset + 1)[0]
    end = offset + 9 + length if head is None else min(offset + 9 + length, offset + 31 + head)
    if end > len(records):
        raise ValueError(f"a message at offset {offset} runs past its chunk")
    return _U64.unpack_from(records, offset + 15)[0], records[offset + 31:end]


def iter_chunked(mcap: ChunkedMcap, channel_ids: Iterable[int], heads: dict[int, int] | None = None
                 ) -> Iterator[tuple[int, int, memoryview]]:
    """``(channel id, log time, data)`` of every message of ``channel_ids``, in read order (log
    time, chunk offset, offset in the chunk: rosbags' and the ``mcap`` package's order). The
    chunks are merged as rosbags merges them: a chunk's message index is read, and the chunk
    decompressed, when the merge reaches its first log time, so memory holds only the chunks whose
    time ranges overlap; each is decompressed once, only as far as its last message wanted here
    ends. ``heads``: channel id -> only the first so many bytes of each of its messages are wanted
    (e.g. an image's header: its pixels are not decompressed unless a later message of the chunk
    is wanted). The data are views into the chunk (copy what is kept)."""
    wanted = set(channel_ids)
    with mcap.path.open("rb") as f:
        merged = heapq.merge(*[_chunk_messages(f, chunk, wanted, heads or {}) for chunk in mcap.chunks
                               if any(chunk.channel_count.get(cid) for cid in wanted)])
        for t, _, offset, cid, data in merged:
            if data is not None:
                yield cid, t, data


def _chunk_messages(f: BinaryIO, chunk: Any, wanted: set[int], heads: dict[int, int]
                    ) -> Iterator[tuple[int, int, int, int, memoryview | None]]:
    """The messages of ``wanted`` of one chunk for :func:`iter_chunked`'s merge, ``(log time,
    chunk offset, offset, channel id, data)`` in read order, after a first item without data that
    sorts before them (the chunk's start): nothing is read before the merge reaches it."""
    yield chunk.message_start_time, chunk.chunk_start_offset, -1, -1, None
    f.seek(chunk.chunk_start_offset + chunk.chunk_length)
    mine, ends = _index_entries(f.read(chunk.message_index_length), wanted)
    needed = 0
    for _, offset, cid in mine:
        after = ends.get(offset, chunk.uncompressed_size)
        head = heads.get(cid)
        needed = max(needed, after if head is None else min(after, offset + 31 + head))
    records = _Records(f, chunk).upto(needed)
    for t, offset, cid in sorted(mine):
        log_time, data = _message_at(records, offset, heads.get(cid))
        if log_time != t:
            raise ValueError(f"{f.name}: the message index of the chunk at {chunk.chunk_start_offset} "
                             "does not match it")
        yield t, chunk.chunk_start_offset, offset, cid, data


def _index_entries(index: bytes, wanted: set[int]) -> tuple[list[tuple[int, int, int]], dict[int, int]]:
    """The message index records after a chunk: ``(log time, offset, channel)`` of the ``wanted``
    channels' messages, and each of those offsets -> the offset of the next message of any channel
    (where its record ends at the latest; absent: the chunk's end)."""
    mine: list[tuple[int, int, int]] = []
    offsets: list[int] = []
    at = 0
    while at < len(index):
        if index[at] != _MESSAGE_INDEX:
            raise ValueError(f"a record of kind {index[at]} among the message indexes")
        length = _U64.unpack_from(index, at + 1)[0]
        cid = struct.unpack_from("<H", index, at + 9)[0]
        n = struct.unpack_from("<I", index, at + 11)[0]
        pairs = list(_ENTRY.iter_unpack(index[at + 15:at + 15 + n]))
        offsets.extend(o for _, o in pairs)
        if cid in wanted:
            mine.extend((t, o, cid) for t, o in pairs)
        at += 9 + length
    offsets.sort()
    following = dict(itertools.pairwise(offsets))
    return mine, {o: following[o] for _, o, _ in mine if o in following}


class IndexedMessages:
    """The messages at ``positions`` (:meth:`ChunkedMcap.positions`) of an MCAP file, read by
    number: the chunk that holds one is decompressed (whole: its neighbours are likely wanted
    next, and one pass over it is the cheapest), and the last ``keep``
    chunks read are kept (so neighbours, and messages asked for in turns among a few chunks, cost
    nothing more); a message's bytes are a view into its chunk. :meth:`close` closes the file."""

    def __init__(self, mcap: ChunkedMcap, positions: Sequence[tuple[int, int, int]], keep: int = 1) -> None:
        self.mcap = mcap
        self.positions = positions
        self.keep = max(1, keep)
        self._file: BinaryIO | None = None
        self._chunks: dict[int, _Records] = {}  # chunk number -> its records, the last used last
        self.n_decompressed = 0

    def close(self) -> None:
        f, self._file = self._file, None
        self._chunks.clear()
        if f is not None:
            f.close()

    def __len__(self) -> int:
        return len(self.positions)

    def data(self, index: int) -> memoryview:
        """The serialised bytes of message ``index`` (in read order)."""
        _, k, offset = self.positions[index]
        records = self._chunks.pop(k, None)
        if records is None:
            if self._file is None:
                self._file = self.mcap.path.open("rb")
            records = _Records(self._file, self.mcap.chunks[k])
            self.n_decompressed += 1
            while len(self._chunks) >= self.keep:
                del self._chunks[next(iter(self._chunks))]
        self._chunks[k] = records
        return _message_at(records.upto(records.size), offset)[1]
