"""rosbags MCAP read/write of the pose_lifter messages, without building anything.

The ``pose_lifter_msgs`` types are registered into a ROS 2 Jazzy typestore from their
``.msg`` text (the rosbags way: ``typestore.register(get_types_from_msg(text, name))``).
The ``.msg`` files are read from the source tree (``ros2_ws/src/pose_lifter_msgs/msg``) when
it is next to this package, otherwise from the copies shipped as package data
(``pose_lifter/msg/*.msg``; a test keeps the copies equal to the originals).

Bags are written as single ``.mcap`` files (rosbag2 storage, version 9 metadata is
embedded in the MCAP file; ``ros2 bag play file.mcap``, Foxglove and RViz read them).
"""

from __future__ import annotations

import shutil
import tempfile
from collections.abc import Callable, Iterable, Iterator, Mapping
from dataclasses import dataclass
from functools import lru_cache
from pathlib import Path
from types import TracebackType
from typing import Any, Final

import numpy as np

from pose_lifter.core.errors import BagError, BagReadError

__all__ = [
    "MSG_NAMES",
    "MSG_PACKAGE",
    "BagError",
    "BagMessage",
    "BagReadError",
    "BagWriter",
    "RawMessage",
    "bag_topics",
    "check_output",
    "message_factory",
    "msg_dir",
    "pose_lifter_typestore",
    "read_messages",
    "read_raw",
    "register_msg_package",
    "upgrade_message",
]

MSG_PACKAGE: Final[str] = "pose_lifter_msgs"
#: Our message names in dependency order.
MSG_NAMES: Final[tuple[str, ...]] = (
    "Keypoint2D", "Skeleton2D", "Skeleton2DArray", "CameraEstimate", "Skeleton3D", "Skeleton3DArray",
)
_PACKAGE_MSG_DIR: Final[Path] = Path(__file__).resolve().parents[1] / "msg"
_SOURCE_MSG_DIR: Final[Path] = Path(__file__).resolve().parents[3] / MSG_PACKAGE / "msg"


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


def msg_dir() -> Path:
    """Directory of the ``pose_lifter_msgs`` ``.msg`` files (source tree first, then package data)."""
    for d in (_SOURCE_MSG_DIR, _PACKAGE_MSG_DIR):
        if all((d / f"{n}.msg").is_file() for n in MSG_NAMES):
            return d
    raise BagError(f"pose_lifter_msgs .msg files not found in {_SOURCE_MSG_DIR} or {_PACKAGE_MSG_DIR}")


@lru_cache(maxsize=1)
def pose_lifter_typestore() -> Any:
    """A ROS 2 Jazzy typestore with the ``pose_lifter_msgs`` types registered (cached)."""
    from rosbags.typesys import Stores, get_types_from_msg, get_typestore

    store = get_typestore(Stores.ROS2_JAZZY)
    d = msg_dir()
    types: dict[str, Any] = {}
    for name in MSG_NAMES:
        types.update(get_types_from_msg((d / f"{name}.msg").read_text(), f"{MSG_PACKAGE}/msg/{name}"))
    store.register(types)
    return store


def register_msg_package(store: Any, package: str, directory: str | Path) -> list[str]:
    """Register every ``<directory>/*.msg`` as ``<package>/msg/<Name>`` in a rosbags typestore.

    This is how another project's messages (``yolo_msgs``, ``hri_msgs``) are written to bags
    without building them: from the text of their ``.msg`` files, as ours are.

    Returns
    -------
    list of str
        The registered type names.
    """
    from rosbags.typesys import get_types_from_msg

    files = sorted(Path(directory).glob("*.msg"))
    if not files:
        raise BagError(f"no .msg files in {directory}")
    types: dict[str, Any] = {}
    for f in files:
        types.update(get_types_from_msg(f.read_text(), f"{package}/msg/{f.stem}"))
    store.register(types)
    return [f"{package}/msg/{f.stem}" for f in files]


_NUMPY_DTYPES: Final[dict[str, str]] = {
    "bool": "bool", "byte": "uint8", "char": "uint8", "int8": "int8", "uint8": "uint8",
    "int16": "int16", "uint16": "uint16", "int32": "int32", "uint32": "uint32",
    "int64": "int64", "uint64": "uint64", "float32": "float32", "float64": "float64",
}


#: A field of a message plan: (name, default maker, numpy dtype a list/tuple value becomes or None).
_Field = tuple[str, Callable[[], Any], str | None]


def _default_maker(store: Any, desc: tuple[Any, Any]) -> Callable[[], Any]:
    """A callable returning a fresh ROS default for a field (nothing mutable is shared)."""
    from rosbags.interfaces import Nodetype

    kind, sub = desc
    if kind == Nodetype.BASE:
        typ = sub[0]
        value: Any = "" if typ in ("string", "wstring") else False if typ == "bool" else \
            0.0 if typ.startswith("float") else 0
        return lambda: value
    if kind == Nodetype.NAME:
        return _plan(store, sub)[1]
    inner, size = sub
    if inner[0] == Nodetype.BASE and inner[1][0] in _NUMPY_DTYPES:
        n, dtype = (size if kind == Nodetype.ARRAY else 0), _NUMPY_DTYPES[inner[1][0]]
        return lambda: np.zeros(n, dtype=dtype)
    if kind == Nodetype.ARRAY:
        element = _default_maker(store, inner)
        return lambda: [element() for _ in range(size)]
    return list


def _plan(store: Any, msgtype: str) -> tuple[list[_Field], Callable[..., Any]]:
    """The fields of ``msgtype`` with their default makers and coercions, and a constructor
    filling every field with its default; built once per (typestore, type)."""
    key = (id(store), msgtype)
    plan = _PLANS.get(key)
    if plan is None:
        from rosbags.interfaces import Nodetype

        cls = store.types[msgtype]
        fields: list[_Field] = []
        for name, desc in store.fielddefs[msgtype][1]:
            kind, sub = desc
            numeric = (kind in (Nodetype.ARRAY, Nodetype.SEQUENCE) and sub[0][0] == Nodetype.BASE
                       and sub[0][1][0] in _NUMPY_DTYPES)
            dtype = _NUMPY_DTYPES[sub[0][1][0]] if numeric else None
            fields.append((name, _default_maker(store, desc), dtype))

        def default() -> Any:
            return cls(**{name: make() for name, make, _ in fields})

        plan = _PLANS[key] = (fields, default)
        _STORES[id(store)] = store  # keeps id(store) from being reused while its plans exist
    return plan


_PLANS: dict[tuple[int, str], tuple[list[_Field], Callable[..., Any]]] = {}
_STORES: dict[int, Any] = {}


def _default_message(store: Any, msgtype: str, **fields: Any) -> Any:
    """A ``msgtype`` of ``store`` with ``fields`` set and every other field at its ROS default;
    lists and tuples for numeric array fields become the numpy arrays rosbags serialises (rclpy
    takes lists, so code that builds messages for both can pass lists)."""
    plan, default = _plan(store, msgtype)
    if not fields:
        return default()
    values: dict[str, Any] = {}
    for name, make, dtype in plan:
        if name in fields:
            value = fields[name]
            if dtype is not None and isinstance(value, list | tuple):
                value = np.asarray(value, dtype=dtype)
            values[name] = value
        else:
            values[name] = make()
    if len(fields) != sum(name in fields for name, _, _ in plan):
        unknown = sorted(set(fields) - {name for name, _, _ in plan})
        raise TypeError(f"{msgtype} has no field(s) {unknown}")
    return store.types[msgtype](**values)


def message_factory(msgtype: str, store: Any | None = None) -> Callable[..., Any]:
    """A constructor for a rosbags message class that fills omitted fields with defaults.

    rosbags message classes are dataclasses without defaults; rclpy classes have defaults.
    The factory makes both usable the same way: ``factory(x=1.0, y=2.0)``. The field
    definitions are read once per type (not on every call).
    """
    st = store if store is not None else pose_lifter_typestore()
    if msgtype not in st.types:
        raise BagError(f"message type {msgtype!r} is not in the typestore")

    def make(**fields: Any) -> Any:
        return _default_message(st, msgtype, **fields)

    make.__name__ = msgtype.rsplit("/", 1)[-1]
    make.__qualname__ = make.__name__
    make.__doc__ = f"Build a {msgtype} (omitted fields get their ROS defaults)."
    return make


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
        self._writer.write(self._connections[raw.topic], int(raw.stamp_ns), raw.data)

    def write(self, topic: str, stamp_ns: int, msg: Any, msgtype: str | None = None) -> None:
        """Serialise and write one message (the topic is added on first use)."""
        if topic not in self._connections:
            self.add_topic(topic, msgtype or str(msg.__msgtype__))
        conn = self._connections[topic]
        self._writer.write(conn, int(stamp_ns), self.store.serialize_cdr(msg, conn.msgtype))

    def write_cdr(self, topic: str, stamp_ns: int, data: bytes, msgtype: str) -> None:
        """Write one message already serialised (CDR, e.g. by :mod:`pose_lifter.messages.cdr`) as a
        ``msgtype`` of our typestore (the topic is added on first use)."""
        if topic not in self._connections:
            self.add_topic(topic, msgtype)
        conn = self._connections[topic]
        if conn.msgtype != msgtype:
            raise BagError(f"topic {topic} is {conn.msgtype}, not {msgtype}")
        self._writer.write(conn, int(stamp_ns), data)

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


def read_raw(path: str | Path, topics: Iterable[str] | None = None) -> Iterator[RawMessage]:
    """Serialised messages of a bag in time order, one at a time (nothing is deserialised).

    Memory stays bounded whatever the bag size. The message definitions come from the bag
    itself, so topics of any type (e.g. ``sensor_msgs/msg/Image``, ``yolo_msgs/...``) are read.
    """
    from rosbags.highlevel import AnyReader

    p = _existing(path)
    with AnyReader([p], default_typestore=pose_lifter_typestore()) as reader:
        wanted = set(topics) if topics is not None else None
        conns = [c for c in reader.connections if wanted is None or c.topic in wanted]
        ours = pose_lifter_typestore()
        meta = {c.id: _definition(c) for c in conns}
        # our own types written by an older pose_lifter_msgs (e.g. Skeleton3D before `observed`):
        # upgraded to today's definition, so one output bag never holds two layouts of one type
        stale = {c.id for c in conns if c.msgtype.startswith(f"{MSG_PACKAGE}/") and c.msgtype in ours.types
                 and meta[c.id][1] != ours.hash_rihs01(c.msgtype)}
        for conn, stamp, raw in reader.messages(connections=conns):
            msgdef, rihs01 = meta[conn.id]
            data = bytes(raw)
            if conn.id in stale:
                new = upgrade_message(reader.deserialize(raw, conn.msgtype), conn.msgtype, ours)
                data = bytes(ours.serialize_cdr(new, conn.msgtype))
                msgdef = ours.generate_msgdef(conn.msgtype, ros_version=2)[0]
                rihs01 = ours.hash_rihs01(conn.msgtype)
            yield RawMessage(conn.topic, conn.msgtype, int(stamp), data, msgdef, rihs01)


def upgrade_message(msg: Any, msgtype: str, store: Any) -> Any:
    """A message of an older definition of ``msgtype`` rebuilt in ``store``'s definition: fields
    copied by name (nested messages too), fields it lacks get their ROS defaults."""
    from rosbags.interfaces import Nodetype

    _, fielddefs = store.fielddefs[msgtype]
    values: dict[str, Any] = {}
    for name, (kind, sub) in fielddefs:
        if not hasattr(msg, name):
            continue
        value = getattr(msg, name)
        if kind == Nodetype.NAME:
            value = upgrade_message(value, sub, store)
        elif kind in (Nodetype.ARRAY, Nodetype.SEQUENCE) and sub[0][0] == Nodetype.NAME:
            value = [upgrade_message(v, sub[0][1], store) for v in value]
        values[name] = value
    return _default_message(store, msgtype, **values)


def bag_topics(path: str | Path) -> dict[str, str]:
    """Topic -> message type of a bag."""
    from rosbags.highlevel import AnyReader

    p = _existing(path)
    with AnyReader([p], default_typestore=pose_lifter_typestore()) as reader:
        return {c.topic: c.msgtype for c in reader.connections}


def _existing(path: str | Path) -> Path:
    p = Path(path)
    if not p.exists():
        raise BagError(f"bag not found: {p}")
    return p


def read_messages(
    path: str | Path,
    topics: Iterable[str] | None = None,
    decoders: Mapping[str, Callable[[bytes], Any | None]] | None = None,
) -> Iterator[BagMessage]:
    """Deserialised messages of a bag (MCAP file or rosbag2 directory), in time order.

    Parameters
    ----------
    path : str or Path
    topics : iterable of str, optional
        Only these topics (all when None).
    decoders : mapping of message type -> callable, optional
        Faster decoders for some of our types (e.g. :func:`pose_lifter.messages.cdr.decode_skeleton2d_array`):
        used on a ROS 2 bag whose definition of the type is ours; a decoder returning None hands
        the message to rosbags.
    """
    from rosbags.highlevel import AnyReader

    p = _existing(path)
    with AnyReader([p], default_typestore=pose_lifter_typestore()) as reader:
        wanted = set(topics) if topics is not None else None
        conns = [c for c in reader.connections if wanted is None or c.topic in wanted]
        if wanted is not None:
            missing = wanted - {c.topic for c in conns}
            if missing:
                raise BagError(f"{p} has no topic(s) {sorted(missing)}")
        fast: dict[int, Callable[[bytes], Any | None]] = {}
        if decoders and reader.is2:
            ours = pose_lifter_typestore()
            fast = {c.id: decoders[c.msgtype] for c in conns if c.msgtype in decoders
                    and reader.typestore.hash_rihs01(c.msgtype) == ours.hash_rihs01(c.msgtype)}
        for conn, stamp, raw in reader.messages(connections=conns):
            decode = fast.get(conn.id)
            msg = decode(raw) if decode is not None else None
            if msg is None:
                msg = reader.deserialize(raw, conn.msgtype)
            yield BagMessage(conn.topic, conn.msgtype, int(stamp), msg)
