"""The rosbags type store of the pose_lifter messages, built from their ``.msg`` text.

The ``pose_lifter_msgs`` types are registered into a ROS 2 Jazzy typestore from their
``.msg`` definitions (the rosbags way: ``typestore.register(get_types_from_msg(text, name))``),
read from the source tree (``ros2_ws/src/pose_lifter_msgs/msg``) when it is next to this package,
otherwise from the copies shipped as package data (``pose_lifter/msg/*.msg``; a test keeps the
copies equal to the originals). Those definitions are the only files this module reads: the bag
files themselves are :mod:`pose_lifter.offline.bags`'.

:func:`message_factory` builds rosbags messages with every omitted field at its ROS default,
as rclpy's classes do, so that the same code (:mod:`pose_lifter.messages.convert`) builds both.
"""

from __future__ import annotations

from collections.abc import Callable
from functools import lru_cache
from pathlib import Path
from typing import Any, Final

import numpy as np

from pose_lifter.core.errors import PoseLifterError

__all__ = [
    "HRI_MSG_DIR",
    "MSG_NAMES",
    "MSG_PACKAGE",
    "TypestoreError",
    "message_factory",
    "msg_dir",
    "pose_lifter_typestore",
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
#: The REP-155 messages the node publishes (``hri_msgs``, not in rosbags' Jazzy store): the pinned
#: copies of ``ros2_ws/vendor/hri_msgs/msg``, shipped as package data (a test keeps them equal).
HRI_MSG_DIR: Final[Path] = _PACKAGE_MSG_DIR / "hri_msgs"


class TypestoreError(PoseLifterError, RuntimeError):
    """The type store cannot be built (no ``.msg`` files) or has no such message type."""


def msg_dir() -> Path:
    """Directory of the ``pose_lifter_msgs`` ``.msg`` files (source tree first, then package data)."""
    for d in (_SOURCE_MSG_DIR, _PACKAGE_MSG_DIR):
        if all((d / f"{n}.msg").is_file() for n in MSG_NAMES):
            return d
    raise TypestoreError(f"pose_lifter_msgs .msg files not found in {_SOURCE_MSG_DIR} or {_PACKAGE_MSG_DIR}")


@lru_cache(maxsize=1)
def pose_lifter_typestore() -> Any:
    """A ROS 2 Jazzy typestore with the ``pose_lifter_msgs`` and ``hri_msgs`` types registered
    (cached)."""
    from rosbags.typesys import Stores, get_types_from_msg, get_typestore

    store = get_typestore(Stores.ROS2_JAZZY)
    d = msg_dir()
    types: dict[str, Any] = {}
    for name in MSG_NAMES:
        types.update(get_types_from_msg((d / f"{name}.msg").read_text(), f"{MSG_PACKAGE}/msg/{name}"))
    store.register(types)
    register_msg_package(store, "hri_msgs", HRI_MSG_DIR)
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
        raise TypestoreError(f"no .msg files in {directory}")
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
        raise TypestoreError(f"message type {msgtype!r} is not in the typestore")

    def make(**fields: Any) -> Any:
        return _default_message(st, msgtype, **fields)

    make.__name__ = msgtype.rsplit("/", 1)[-1]
    make.__qualname__ = make.__name__
    make.__doc__ = f"Build a {msgtype} (omitted fields get their ROS defaults)."
    return make



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


