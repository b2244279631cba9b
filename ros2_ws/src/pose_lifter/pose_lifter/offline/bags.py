"""Bag files: rosbags MCAP read/write of the pose_lifter messages, and the errors of bags.

Messages are (de)serialised with the type store of :mod:`pose_lifter.messages.typestore` (the
``pose_lifter_msgs`` types registered from their ``.msg`` text, no build needed). Bags are
written as single ``.mcap`` files (rosbag2 storage, version 9 metadata is embedded in the MCAP
file; ``ros2 bag play file.mcap``, Foxglove and RViz read them).

A bag read is a single ``.mcap`` (or ``.db3``) file or a rosbag2 directory, what ``ros2 bag
record`` writes: a folder holding ``metadata.yaml`` and the storage files it lists, several when
the recording was split (``--max-bag-duration``, ``--max-bag-size``). A directory is one bag, its
files one recording read as one stream in time order; naming its ``metadata.yaml`` names the
directory (:func:`bag_path`).
"""

from __future__ import annotations

import hashlib
import heapq
import shutil
import struct
import tempfile
from collections.abc import Callable, Iterable, Iterator, Mapping
from contextlib import contextmanager
from dataclasses import dataclass
from pathlib import Path
from types import TracebackType
from typing import Any, Final

from pose_lifter.core.errors import PoseLifterError
from pose_lifter.messages.typestore import MSG_PACKAGE, pose_lifter_typestore, upgrade_message

__all__ = [
    "METADATA_NAME",
    "BagError",
    "BagMessage",
    "BagReadError",
    "BagWriter",
    "RawMessage",
    "bag_files",
    "bag_path",
    "bag_sha256",
    "bag_stat",
    "bag_topics",
    "check_output",
    "is_rosbag2_dir",
    "read_messages",
    "read_raw",
    "write_messages",
]

#: The file that makes a directory a rosbag2 recording (one bag).
METADATA_NAME: Final[str] = "metadata.yaml"


class BagError(PoseLifterError, RuntimeError):
    """A bag cannot be read or written (missing file, missing topic, bad type)."""


class BagReadError(BagError):
    """A bag file exists but its content cannot be read (truncated, empty, not a bag)."""


def check_output(path: str | Path, suffixes: tuple[str, ...], overwrite: bool = False) -> Path:
    """Refuse an output path before any work: wrong suffix, a directory, an existing file
    (without ``overwrite``), or a missing parent directory."""
    out = Path(path)
    if out.suffix not in suffixes:
        raise BagError(f"output must end in {' or '.join(suffixes)}, got {out}")
    if out.is_dir():
        raise BagError(f"output {out} is a directory")
    if out.exists() and not overwrite:
        raise BagError(f"{out} exists already (pass --overwrite to replace it)")
    if not out.parent.resolve().is_dir():
        raise BagError(f"output directory {out.parent} does not exist")
    return out


class BagWriter:
    """Write messages to a single ``.mcap`` file (rosbag2 MCAP storage, metadata version 9,
    zstd-compressed chunks unless ``compress=False``).

    rosbags writes a rosbag2 directory; on close the MCAP file inside it is moved to
    ``path`` and the directory is removed.

    Examples
    --------
    >>> with BagWriter("out.mcap") as w:                           # doctest: +SKIP
    ...     w.add_topic("/keypoints_2d", "pose_lifter_msgs/msg/Skeleton2DArray")
    ...     w.write("/keypoints_2d", stamp_ns, msg)
    """

    def __init__(self, path: str | Path, overwrite: bool = False, compress: bool = True) -> None:
        from rosbags.rosbag2 import CompressionFormat, CompressionMode, StoragePlugin, Writer

        self.path = Path(path)
        if self.path.suffix != ".mcap":
            raise BagError(f"bag path must end in .mcap, got {self.path}")
        if self.path.exists() and not overwrite:
            raise BagError(f"{self.path} exists already (pass overwrite=True to replace it)")
        self.store = pose_lifter_typestore()
        self._tmp = Path(tempfile.mkdtemp(prefix=".bagwriter-", dir=self.path.parent.resolve()))
        self._bagdir = self._tmp / self.path.stem
        self._writer = Writer(self._bagdir, version=9, storage_plugin=StoragePlugin.MCAP)
        self._writer.STORAGE_PLUGINS = {StoragePlugin.MCAP: mcap_storage()}
        if compress:  # zstd-compressed MCAP chunks (rosbag2 "storage" compression)
            self._writer.set_compression(CompressionMode.STORAGE, CompressionFormat.ZSTD)
        self._connections: dict[str, Any] = {}
        self._open = False

    def open(self) -> BagWriter:
        self._writer.open()
        self._open = True
        return self

    def __enter__(self) -> BagWriter:
        return self.open()

    def __exit__(
        self, exc_type: type[BaseException] | None, exc: BaseException | None, tb: TracebackType | None
    ) -> None:
        self.close(discard=exc_type is not None)

    def add_topic(self, topic: str, msgtype: str) -> None:
        """Declare a topic (once) with its message type, e.g. ``sensor_msgs/msg/CameraInfo``."""
        if topic in self._connections:
            return
        if msgtype not in self.store.types:
            raise BagError(f"message type {msgtype!r} is not in the typestore")
        self._connections[topic] = self._writer.add_connection(topic, msgtype, typestore=self.store)

    def write_raw(self, raw: RawMessage) -> None:
        """Copy one serialised message as it is (its type need not be in our typestore)."""
        if raw.topic not in self._connections:
            self._connections[raw.topic] = self._writer.add_connection(
                raw.topic, raw.msgtype, msgdef=raw.msgdef, rihs01=raw.rihs01)
        self._put(self._connections[raw.topic], int(raw.stamp_ns), raw.data)

    def write(self, topic: str, stamp_ns: int, msg: Any, msgtype: str | None = None) -> None:
        """Serialise and write one message (the topic is added on first use)."""
        if topic not in self._connections:
            self.add_topic(topic, msgtype or str(msg.__msgtype__))
        conn = self._connections[topic]
        self._put(conn, int(stamp_ns), self.store.serialize_cdr(msg, conn.msgtype))

    def write_cdr(self, topic: str, stamp_ns: int, data: bytes, msgtype: str) -> None:
        """Write one message already serialised (CDR, e.g. by :mod:`pose_lifter.messages.cdr`) as a
        ``msgtype`` of our typestore (the topic is added on first use)."""
        conn = self._connections.get(topic)
        if conn is None:
            self.add_topic(topic, msgtype)
            conn = self._connections[topic]
        if conn.msgtype != msgtype:
            raise BagError(f"topic {topic} is {conn.msgtype}, not {msgtype}")
        self._put(conn, int(stamp_ns), data)

    def _put(self, conn: Any, stamp_ns: int, data: bytes | memoryview) -> None:
        """What rosbags' ``Writer.write`` does for a connection of this writer (storage
        compression: no per-message step), without its search of the connection list."""
        if not self._open:
            raise BagError(f"{self.path} is not open")
        w, storage = self._writer, self._writer.storage
        assert storage is not None
        storage.write(conn, stamp_ns, data)
        w.counts[conn.id] += 1
        if stamp_ns < w.min_timestamp:
            w.min_timestamp = stamp_ns
        if stamp_ns > w.max_timestamp:
            w.max_timestamp = stamp_ns

    def close(self, discard: bool = False) -> None:
        """Finish the file (or throw it away with ``discard``)."""
        try:
            if self._open:
                self._writer.close()
                self._open = False
                if not discard:
                    files = sorted(self._bagdir.glob("*.mcap"))
                    if len(files) != 1:
                        raise BagError(f"expected one .mcap file in {self._bagdir}, found {files}")
                    shutil.move(str(files[0]), str(self.path))
        finally:
            shutil.rmtree(self._tmp, ignore_errors=True)


#: An MCAP message record's opcode, length, channel id, sequence, log and publish times.
_MESSAGE_HEAD: Final = struct.Struct("<BQHIQQ")
_STORAGE: Any = None


def mcap_storage() -> Any:
    """rosbags' MCAP storage writer with a message record written in one ``struct`` pack: the
    same bytes as its own ``write`` (a test compares them), about half its time a message."""
    global _STORAGE
    if _STORAGE is not None:
        return _STORAGE
    from rosbags.rosbag2.storage_mcap import McapWriter

    class FastMcapWriter(McapWriter):
        def write(self, connection: Any, timestamp: int, data: bytes | memoryview) -> None:
            cid = connection.id
            self.message_start_time = min(timestamp, self.message_start_time)
            self.message_end_time = max(timestamp, self.message_end_time)
            self.channel_stats[cid] += 1
            chunk = self.chunk
            chunk.message_start_time = min(timestamp, chunk.message_start_time)
            chunk.message_end_time = max(timestamp, chunk.message_end_time)
            bio = chunk.bio
            chunk.msgs[cid].append((timestamp, bio.tell()))
            bio.write(_MESSAGE_HEAD.pack(0x05, 22 + len(data), cid, 0, timestamp, timestamp))
            bio.write(data)
            if bio.tell() > 2**20:  # rosbags' own chunk size
                self.close_chunk()

    _STORAGE = FastMcapWriter
    return _STORAGE


@dataclass(frozen=True)
class BagMessage:
    """One deserialised message of a bag."""

    topic: str
    msgtype: str
    stamp_ns: int
    msg: Any


@dataclass(frozen=True)
class RawMessage:
    """One serialised (CDR) message of a bag, with what is needed to copy it to another bag."""

    topic: str
    msgtype: str
    stamp_ns: int
    data: bytes
    msgdef: str
    rihs01: str


def write_messages(path: str | Path, messages: Iterable[tuple[str, int, Any, str]], overwrite: bool = False
                   ) -> int:
    """Write ``(topic, stamp_ns, message, type name)`` tuples (rosbags messages, e.g. a filmed
    scene's, :func:`pose_lifter.mocap.scenes.scene_messages`) to the MCAP bag ``path``, in order.
    Returns the number written."""
    n = 0
    with BagWriter(path, overwrite=overwrite) as w:
        for topic, stamp_ns, msg, msgtype in messages:
            w.write(topic, stamp_ns, msg, msgtype)
            n += 1
    return n


def _definition(conn: Any) -> tuple[str, str]:
    """(msgdef text, RIHS01 hash) of a connection, from the bag's own definition: a copy keeps the
    layout its bytes were written with (an older bag's types may differ from ours)."""
    from rosbags.typesys import Stores, get_types_from_msg, get_typestore

    text = str(conn.msgdef.data)
    if conn.digest and conn.digest.startswith("RIHS01_"):
        return text, str(conn.digest)
    store = get_typestore(Stores.ROS2_JAZZY)
    store.register(get_types_from_msg(text, conn.msgtype))
    return text, str(store.hash_rihs01(conn.msgtype))


def is_rosbag2_dir(path: str | Path) -> bool:
    """``path`` is a rosbag2 directory: a folder holding ``metadata.yaml``."""
    p = Path(path)
    return p.is_dir() and (p / METADATA_NAME).is_file()


def bag_path(path: str | Path) -> Path:
    """The bag a path names: a rosbag2 directory's ``metadata.yaml`` names its directory; any
    other path names itself."""
    p = Path(path)
    return p.parent if p.name == METADATA_NAME and p.is_file() else p


def bag_files(path: str | Path) -> list[Path]:
    """The files a bag is made of, sorted: the file itself, or every regular file of a rosbag2
    directory (``metadata.yaml`` and its storage files; not recursive)."""
    p = bag_path(path)
    if p.is_dir():
        return sorted(x for x in p.iterdir() if x.is_file())
    return [p]


def bag_stat(path: str | Path) -> tuple[int, int]:
    """(bytes, latest modification time in ns) of a bag's files (:func:`bag_files`)."""
    stats = [f.stat() for f in bag_files(path)]
    return sum(st.st_size for st in stats), max((st.st_mtime_ns for st in stats), default=0)


def bag_sha256(path: str | Path) -> str:
    """SHA-256 (hex) of a bag file's bytes; of a rosbag2 directory, over the name and the SHA-256
    of each of its files (:func:`bag_files`)."""
    from pose_lifter.offline.settings import file_sha256

    p = bag_path(path)
    if not p.is_dir():
        return file_sha256(p)
    h = hashlib.sha256()
    for f in bag_files(p):
        h.update(f"{f.name}\0{file_sha256(f)}\n".encode())
    return h.hexdigest()


def _existing(path: str | Path) -> Path:
    """The bag ``path`` names (:func:`bag_path`), refused when missing or a directory that is not a
    rosbag2 recording."""
    p = bag_path(path)
    if not p.exists():
        raise BagError(f"bag not found: {p}")
    if p.is_dir() and not (p / METADATA_NAME).is_file():
        raise BagError(f"{p} is a directory without {METADATA_NAME}: not a rosbag2 recording")
    return p


def _reading_error(p: Path, exc: BaseException) -> BagReadError:
    text = " ".join(str(exc).split()) or type(exc).__name__
    return BagReadError(f"cannot read {p}: {text}")


@contextmanager
def _open_reader(path: str | Path) -> Iterator[tuple[Path, Any]]:
    """(the bag's path, an open rosbags ``AnyReader``); a bag that cannot be opened (truncated,
    empty or foreign; a rosbag2 directory whose metadata is damaged or whose files are missing)
    is a :class:`BagReadError`."""
    from rosbags.highlevel import AnyReader

    p = _existing(path)
    try:
        reader = AnyReader([p], default_typestore=pose_lifter_typestore())
        reader.open()
    except Exception as exc:
        raise _reading_error(p, exc) from None
    try:
        yield p, reader
    finally:
        reader.close()


class _OneFile:
    """A rosbag2 directory reader seen through one of its storage files (what rosbags'
    ``DirectoryReader.messages`` reads of it: the storages and the compression mode)."""

    def __init__(self, whole: Any, storage: Any) -> None:
        self.storages = [storage]
        self.metadata = whole.metadata


def _messages(p: Path, reader: Any, conns: list[Any], heads: Mapping[int, int] | None = None
              ) -> Iterator[tuple[Any, int, Any]]:
    """(connection, stamp, raw) of ``conns`` in time order; a rosbag2 directory's files are merged
    by stamp (rosbags reads them one after the other); a single chunked MCAP file is read through
    its index (:func:`_chunked`: ``heads``, connection id -> only the first so many bytes of each
    of its messages are wanted). A read that fails on the way (a damaged file) is a
    :class:`BagReadError`."""
    from rosbags.rosbag2.reader import DirectoryReader

    storage = getattr(reader.readers[0], "storage", None) if len(reader.readers) == 1 else None
    chunked = _chunked(p, conns, heads or {})
    if chunked is not None:
        stream: Iterator[tuple[Any, int, Any]] = chunked
    elif isinstance(storage, DirectoryReader) and len(storage.storages) > 1:
        wanted = conns or reader.connections
        parts = [DirectoryReader.messages(_OneFile(storage, s), wanted)  # type: ignore[arg-type]
                 for s in storage.storages]
        stream = heapq.merge(*parts, key=lambda x: int(x[1]))
    else:
        stream = iter(reader.messages(connections=conns))
    while True:
        try:
            item = next(stream)
        except StopIteration:
            return
        except Exception as exc:
            raise _reading_error(p, exc) from None
        yield item


def _chunked(p: Path, conns: list[Any], heads: Mapping[int, int]) -> Iterator[tuple[Any, int, Any]] | None:
    """(connection, stamp, data view) of ``conns`` read through the index of a single chunked MCAP
    file (:func:`pose_lifter.offline.mcap_index.iter_chunked`: the order of rosbags' reader, each
    chunk decompressed once and only as far as needed, no copy of a message); None when ``p`` is
    not one or a connection is not one channel of it."""
    from pose_lifter.offline.mcap_index import chunked_mcap, iter_chunked

    mcap = chunked_mcap(p) if conns else None
    if mcap is None:
        return None
    of_channel: dict[int, Any] = {}
    for conn in conns:
        ids = [k for k, ch in mcap.channels.items() if (ch.topic, ch.schema) == (conn.topic, conn.msgtype)]
        if len(ids) != 1 or ids[0] in of_channel:
            return None
        of_channel[ids[0]] = conn
    cut = {k: heads[c.id] for k, c in of_channel.items() if c.id in heads}
    return ((of_channel[k], t, data) for k, t, data in iter_chunked(mcap, of_channel, cut))


def read_raw(path: str | Path, topics: Iterable[str] | None = None) -> Iterator[RawMessage]:
    """Serialised messages of a bag in time order, one at a time (nothing is deserialised).

    Memory stays bounded whatever the bag size. The message definitions come from the bag
    itself, so topics of any type (e.g. ``sensor_msgs/msg/Image``, ``yolo_msgs/...``) are read.
    """
    with _open_reader(path) as (p, reader):
        wanted = set(topics) if topics is not None else None
        conns = [c for c in reader.connections if wanted is None or c.topic in wanted]
        ours = pose_lifter_typestore()
        meta = {c.id: _definition(c) for c in conns}
        # our own types written by an older pose_lifter_msgs (e.g. Skeleton3D before `observed`):
        # upgraded to today's definition, so one output bag never holds two layouts of one type
        stale = _stale(conns, {c.id: meta[c.id][1] for c in conns}, ours)
        for conn, stamp, raw in _messages(p, reader, conns):
            msgdef, rihs01 = meta[conn.id]
            data = bytes(raw)
            if conn.id in stale:
                new = upgrade_message(reader.deserialize(data, conn.msgtype), conn.msgtype, ours)
                data = bytes(ours.serialize_cdr(new, conn.msgtype))
                msgdef = ours.generate_msgdef(conn.msgtype, ros_version=2)[0]
                rihs01 = ours.hash_rihs01(conn.msgtype)
            yield RawMessage(conn.topic, conn.msgtype, int(stamp), data, msgdef, rihs01)


def bag_topics(path: str | Path) -> dict[str, str]:
    """Topic -> message type of a bag (:class:`BagReadError` when it cannot be opened)."""
    with _open_reader(path) as (_, reader):
        return {c.topic: c.msgtype for c in reader.connections}


def read_messages(
    path: str | Path,
    topics: Iterable[str] | None = None,
    decoders: Mapping[str, Callable[[bytes], Any | None]] | None = None,
    heads: Mapping[str, int] | None = None,
) -> Iterator[BagMessage]:
    """Deserialised messages of a bag (MCAP file or rosbag2 directory), in time order.

    Parameters
    ----------
    path : str or Path
        A bag file, a rosbag2 directory or its ``metadata.yaml``.
    topics : iterable of str, optional
        Only these topics (all when None).
    decoders : mapping of message type -> callable, optional
        Faster decoders for some of our types (e.g. :func:`pose_lifter.messages.cdr.decode_skeleton2d_array`):
        used on a ROS 2 bag whose definition of the type is ours; a decoder returning None hands
        the message to rosbags.
    heads : mapping of message type -> int, optional
        Types of ``decoders`` that need only the first so many bytes of each message (e.g. an
        image's header): where the bag allows (a single chunked MCAP file), the rest is not read
        and the decoder is given the first bytes alone.
    """
    with _open_reader(path) as (p, reader):
        wanted = set(topics) if topics is not None else None
        conns = [c for c in reader.connections if wanted is None or c.topic in wanted]
        if wanted is not None:
            missing = wanted - {c.topic for c in conns}
            if missing:
                raise BagError(f"{p} has no topic(s) {sorted(missing)}")
        ours = pose_lifter_typestore()
        stale = _stale(conns, {c.id: reader.typestore.hash_rihs01(c.msgtype) for c in conns}, ours)
        fast: dict[int, Callable[[bytes], Any | None]] = {}
        if decoders and reader.is2:
            fast = {c.id: decoders[c.msgtype] for c in conns if c.msgtype in decoders and c.id not in stale
                    and reader.typestore.hash_rihs01(c.msgtype) == ours.hash_rihs01(c.msgtype)}
        head_of = heads or {}
        cut = {c.id: head_of[c.msgtype] for c in conns if c.id in fast and c.msgtype in head_of}
        for conn, stamp, raw in _messages(p, reader, conns, cut):
            decode = fast.get(conn.id)
            msg = decode(raw) if decode is not None else None
            if msg is None:
                msg = reader.deserialize(bytes(raw), conn.msgtype)
                if conn.id in stale:
                    msg = upgrade_message(msg, conn.msgtype, ours)
            yield BagMessage(conn.topic, conn.msgtype, int(stamp), msg)


def _stale(conns: Iterable[Any], hashes: Mapping[int, str], ours: Any) -> set[int]:
    """The connections (ids) of our own types written by an older pose_lifter_msgs (e.g. Skeleton3D
    before ``joint_std``): read as today's definition (:func:`upgrade_message`), so that a message
    read from a recording is one of today's, whatever wrote it."""
    return {c.id for c in conns if c.msgtype.startswith(f"{MSG_PACKAGE}/") and c.msgtype in ours.types
            and hashes[c.id] != ours.hash_rihs01(c.msgtype)}
