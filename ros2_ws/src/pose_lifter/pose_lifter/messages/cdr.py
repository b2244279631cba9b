"""The offline lift's messages in CDR straight from and to arrays: its input
(``Skeleton2DArray``, :func:`decode_skeleton2d_array`) and its two outputs.

:func:`pose_lifter.offline.lift.lift_bag` writes one ``Skeleton3DArray`` (``/skeletons_3d``) and one
``MarkerArray`` (``/skeleton_markers``) per keypoint message. Building them as rosbags message
objects (``Skeleton3D``, 12 ``Point`` and a ``CameraEstimate`` per skeleton, two ``Marker`` with
their sub-messages per track) and serialising those costs ~30 ms per 36-person message, more
than the learned prior's whole solve of those people. This module writes the same bytes
directly: the message layout is fixed (12 joints, the bones of
:data:`pose_lifter.core.model.skeleton.BONES_FOR_DRAWING`), so per skeleton only a few numbers are
packed and the constant parts (joint names, a marker's empty texture and mesh fields) are
encoded once.

The bytes are those ``typestore.serialize_cdr`` gives for the messages that
:func:`pose_lifter.messages.convert.result_to_skeleton3d`,
:func:`~pose_lifter.messages.convert.skeletons3d_array`
and :func:`~pose_lifter.messages.convert.skeleton_markers` build (the node's builders) from the same
lifts, with the rosbags defaults of :func:`pose_lifter.messages.typestore.message_factory` (a DELETE marker's
unset orientation is all zeros); ``tests/messages/test_cdr.py`` checks it byte for byte, and
:func:`check_definitions` refuses a typestore whose definitions of the two types differ from the
ones this module was written for.

The input side: rosbags deserialises a 36-person ``Skeleton2DArray`` into 36 x 17
``Keypoint2D`` objects that :func:`pose_lifter.messages.convert.skeleton2d_to_arrays` then reads one
attribute at a time; :func:`decode_skeleton2d_array` reads each skeleton's keypoints as one
(K, 3) array (``xyc``) instead, and ``skeleton2d_to_arrays`` takes it from there.

CDR here is what rosbags writes for ROS 2: little endian, a 4-byte encapsulation header, each
primitive aligned to its size (counted from the end of the header), strings and sequence
lengths as uint32 (strings with their NUL), the elements of an empty sequence not aligned.
"""

from __future__ import annotations

import struct
from collections.abc import Callable, Iterable, Sequence
from dataclasses import dataclass, fields
from functools import lru_cache
from typing import Any, Final

import numpy as np
from numpy.typing import NDArray

from pose_lifter.core.model.skeleton import BONES_FOR_DRAWING, JOINT_NAMES, N_JOINTS
from pose_lifter.messages.convert import checked_joint_std, marker_id, quaternions_xyzw, track_color
from pose_lifter.messages.names import MARKER_ARRAY, SKELETON2D_ARRAY, SKELETON3D_ARRAY

__all__ = [
    "DecodedHeader",
    "DecodedSkeleton2D",
    "DecodedSkeleton2DArray",
    "DecodedStamp",
    "SkeletonFrame",
    "check_definitions",
    "decode_skeleton2d_array",
    "header_cdr",
    "marker_array_cdr",
    "message_header",
    "read_skeleton2d_array",
    "skeleton3d_array_cdr",
    "stamp_cdr",
]

#: RIHS01 hashes of the definitions this module encodes (``typestore.hash_rihs01``).
_DEFINITIONS: Final[dict[str, str]] = {
    SKELETON2D_ARRAY: "RIHS01_9a9e20ea43808ca6e731cf1c13e2c7bc885bb847d487eaf55c5976ed8a473513",
    SKELETON3D_ARRAY: "RIHS01_e2c0cee7cbfab1c00f6004e2203f7f8251b6f4b9a2f907965c55c037474f07f0",
    MARKER_ARRAY: "RIHS01_86cb8800b6fb05b5eff1abd7a56f62a5641d3ae9a1c29e78e67e704f1d067dcf",
}

# visualization_msgs/Marker constants (fixed by the message definition)
_SPHERE_LIST: Final[int] = 7
_LINE_LIST: Final[int] = 5
_ADD: Final[int] = 0
_DELETE: Final[int] = 2
_DELETEALL: Final[int] = 3

_ENCAPSULATION: Final[bytes] = b"\x00\x01\x00\x00"  # CDR, little endian
_I32: Final = struct.Struct("<i")
_U32: Final = struct.Struct("<I")
_I64: Final = struct.Struct("<q")
_STAMP: Final = struct.Struct("<iI")
_MARKER_IDS: Final = struct.Struct("<iii")  # id, type, action
#: pose (position, orientation), scale: 10 float64
_POSE_SCALE: Final = struct.Struct("<10d")
#: color (4 float32), lifetime (int32 sec, uint32 nanosec), frame_locked
_COLOR_LIFETIME: Final = struct.Struct("<4fiI?")
#: iterations, converged
_ITER_CONVERGED: Final = struct.Struct("<I?")
#: solve_time, warm_started
_TIME_WARM: Final = struct.Struct("<d?")
#: The joints of the bones' LINE_LIST, two per bone.
_BONE_INDEX: Final[NDArray[np.intp]] = np.array([j for bone in BONES_FOR_DRAWING for j in bone],
                                                 dtype=np.intp)


class _Writer:
    """Append-only CDR writer; offsets are counted from the end of the encapsulation header."""

    __slots__ = ("buf",)

    def __init__(self, header: bool = True) -> None:
        self.buf = bytearray(_ENCAPSULATION if header else b"")

    def align(self, n: int) -> None:
        pad = -(len(self.buf) - 4) % n
        if pad:
            self.buf += b"\x00" * pad

    def u32(self, value: int) -> None:
        self.align(4)
        self.buf += _U32.pack(value)

    def string(self, text: str) -> None:
        data = text.encode()
        self.u32(len(data) + 1)
        self.buf += data
        self.buf += b"\x00"


def _string_bytes(text: str) -> bytes:
    """A CDR string (uint32 length with the NUL, bytes, NUL), for a 4-aligned position."""
    data = text.encode()
    return _U32.pack(len(data) + 1) + data + b"\x00"


def stamp_cdr(stamp_ns: int) -> bytes:
    """A ``builtin_interfaces/Time`` (sec, nanosec) of ``stamp_ns``."""
    return _STAMP.pack(*divmod(int(stamp_ns), 1_000_000_000))


def header_cdr(stamp: bytes, frame_id: str) -> bytes:
    """A ``std_msgs/Header`` for a 4-aligned position: ``stamp`` (a ``builtin_interfaces/Time``,
    e.g. :func:`stamp_cdr`), then ``frame_id``; the one header writer of every message here."""
    return stamp + _string_bytes(frame_id)


def message_header(header: Any) -> bytes:
    """:func:`header_cdr` of a message's ``header`` (``stamp.sec``, ``stamp.nanosec``, ``frame_id``)."""
    return header_cdr(_STAMP.pack(int(header.stamp.sec), int(header.stamp.nanosec)), str(header.frame_id))


def _constant(parts: Sequence[tuple[str, Any]]) -> bytes:
    """Bytes of fields with at most 4-byte alignment, written at a 4-aligned position."""
    w = _Writer(header=False)
    for kind, value in parts:
        if kind == "u32":
            w.u32(value)
        elif kind == "string":
            w.string(value)
        elif kind == "header":
            w.align(4)
            w.buf += header_cdr(bytes(_STAMP.size), value)
        else:  # "bool"
            w.buf += struct.pack("<?", value)
    return bytes(w.buf)


#: ``joint_names`` of a Skeleton3D: the count and the 12 names.
_JOINT_NAMES: Final[bytes] = _constant([("u32", N_JOINTS)] + [("string", n) for n in JOINT_NAMES])
#: A Marker's fields after ``points``, all at their defaults: colors, texture_resource, texture
#: (CompressedImage: header, format, data), uv_coordinates, text, mesh_resource, mesh_file
#: (filename, data), mesh_use_embedded_materials. No field needs more than 4-byte alignment.
_MARKER_TAIL: Final[bytes] = _constant([
    ("u32", 0), ("string", ""), ("header", ""), ("string", ""), ("u32", 0),
    ("u32", 0), ("string", ""), ("string", ""), ("string", ""), ("u32", 0), ("bool", False),
])


def check_definitions(store: Any) -> None:
    """Refuse a typestore whose ``Skeleton3DArray`` or ``MarkerArray`` differ from the layout
    this module encodes (e.g. a field added to a ``.msg`` file without updating it).

    Raises
    ------
    RuntimeError
        A definition's RIHS01 hash is not the expected one.
    """
    for name, expected in _DEFINITIONS.items():
        got = str(store.hash_rihs01(name))
        if got != expected:
            raise RuntimeError(f"pose_lifter.messages.cdr encodes {name} as {expected}, the typestore has "
                               f"{got}: update pose_lifter/messages/cdr.py "
                               "(tests/messages/test_cdr.py shows the difference)")


@dataclass(frozen=True)
class SkeletonFrame:
    """Lifted skeletons as arrays, one row each (``n``): the columnar record of the answers of a
    frame (in message order), or of a track's frames (what an offline worker sends back).

    The fields are those of ``pose_lifter_msgs/Skeleton3D`` as
    :func:`pose_lifter.messages.convert.result_to_skeleton3d` fills them, and the 2D input with
    the left/right labels its track gave it (:meth:`pose_lifter.messages.frame.LiftedSkeleton.labelled_2d`;
    the REP-155 ``skeleton2d`` and ``roi``).

    ``std_m`` (n, 12, 3) is each joint's standard deviation along x, y, z in metres
    (``Skeleton3D.joint_std``); a row that is not all finite is unknown (an empty ``joint_std``).
    None (the default) makes every row unknown: NaN rows.
    """

    track_ids: NDArray[np.int64]
    joints_m: NDArray[np.float64]  # (n, 12, 3)
    projection: NDArray[np.float64]  # (n, 6)
    scale: NDArray[np.float64]
    orientation_xyzw: NDArray[np.float64]  # (n, 4)
    translation: NDArray[np.float64]  # (n, 2)
    objective: NDArray[np.float64]
    reprojection_error: NDArray[np.float64]
    iterations: NDArray[np.int64]
    converged: NDArray[np.bool_]
    solve_time: NDArray[np.float64]
    warm_started: NDArray[np.bool_]
    weights: NDArray[np.float64]  # (n, 12)
    points: NDArray[np.float64]  # (n, 12, 2) pixels
    confidence: NDArray[np.float64]  # (n, 12)
    std_m: NDArray[np.float64] | None = None  # (n, 12, 3) metres, NaN rows: unknown

    def __post_init__(self) -> None:
        if self.std_m is None:
            object.__setattr__(self, "std_m", np.full((len(self.track_ids), N_JOINTS, 3), np.nan))

    @classmethod
    def from_results(cls, track_ids: Sequence[int], joints_m: Sequence[NDArray[np.float64]],
                     results: Sequence[Any], solve_times: Sequence[float],
                     warm_started: Sequence[bool], points: Sequence[NDArray[np.float64]] | None = None,
                     confidence: Sequence[NDArray[np.float64]] | None = None,
                     std_m: Sequence[NDArray[np.float64] | None] | None = None) -> SkeletonFrame:
        """From the lifts of one message (``LiftResult``-like: ``camera``, ``objective``,
        ``reprojection_error``, ``total_alternations``, ``converged``, ``weights``), their
        metric joints, their 2D (None: zeros) and their joints' standard deviations (each (12, 3)
        metres, finite and non-negative, or None: unknown; None: all unknown); the orientations of
        all of them in one :func:`pose_lifter.messages.convert.quaternions_xyzw` call."""
        n = len(results)
        if not (len(track_ids) == len(joints_m) == len(solve_times) == len(warm_started) == n):
            raise ValueError("one track id, joints array, solve time and warm flag per result")
        if n == 0:
            return cls(np.zeros(0, np.int64), np.zeros((0, N_JOINTS, 3)), np.zeros((0, 6)), np.zeros(0),
                       np.zeros((0, 4)), np.zeros((0, 2)), np.zeros(0), np.zeros(0), np.zeros(0, np.int64),
                       np.zeros(0, bool), np.zeros(0), np.zeros(0, bool), np.zeros((0, N_JOINTS)),
                       np.zeros((0, N_JOINTS, 2)), np.zeros((0, N_JOINTS)), np.zeros((0, N_JOINTS, 3)))
        cams = [r.camera for r in results]
        rotations = np.array([np.asarray(c.rotation, dtype=np.float64) for c in cams]).reshape(n, 3, 3)
        joints = np.array([np.asarray(j, dtype=np.float64) for j in joints_m])
        if joints.shape != (n, N_JOINTS, 3):
            raise ValueError(f"joints must be ({N_JOINTS}, 3) each, got {joints.shape[1:]}")
        if std_m is not None and len(std_m) != n:
            raise ValueError("one joint std (or None) per result")
        return cls(
            track_ids=np.array([int(t) for t in track_ids], dtype=np.int64),
            joints_m=joints,
            projection=np.array([np.asarray(c.projection, dtype=np.float64).reshape(6) for c in cams]),
            scale=np.array([float(c.scale) for c in cams]),
            orientation_xyzw=quaternions_xyzw(rotations),
            translation=np.array([np.asarray(c.translation, dtype=np.float64).reshape(2) for c in cams]),
            objective=np.array([float(r.objective) for r in results]),
            reprojection_error=np.array([float(r.reprojection_error) for r in results]),
            iterations=np.array([int(r.total_alternations) for r in results], dtype=np.int64),
            converged=np.array([bool(r.converged) for r in results]),
            solve_time=np.array([float(t) for t in solve_times]),
            warm_started=np.array([bool(w) for w in warm_started]),
            weights=np.array([np.asarray(r.weights, dtype=np.float64).reshape(N_JOINTS) for r in results]),
            points=(np.zeros((n, N_JOINTS, 2)) if points is None
                    else np.array(points, dtype=np.float64).reshape(n, N_JOINTS, 2)),
            confidence=(np.zeros((n, N_JOINTS)) if confidence is None
                        else np.array(confidence, dtype=np.float64).reshape(n, N_JOINTS)),
            std_m=(None if std_m is None
                   else np.array([_std_or_nan(s) for s in std_m]).reshape(n, N_JOINTS, 3)),
        )

    @classmethod
    def of(cls, lifted: Sequence[Any]) -> SkeletonFrame:
        """From lifted skeletons (:class:`pose_lifter.messages.frame.LiftedSkeleton`), in order."""
        labelled = [s.labelled_2d() for s in lifted]
        return cls.from_results([s.track_id for s in lifted], [s.joints_m for s in lifted],
                                [s.result for s in lifted], [s.solve_time for s in lifted],
                                [s.warm_started for s in lifted], [p for p, _ in labelled],
                                [c for _, c in labelled], [s.std_m for s in lifted])

    @classmethod
    def concat(cls, frames: Sequence[SkeletonFrame]) -> SkeletonFrame:
        """The rows of ``frames``, one after the other (at least one frame)."""
        return cls(*(np.concatenate([getattr(f, x.name) for f in frames]) for x in fields(cls)))

    def take(self, rows: NDArray[np.intp] | slice) -> SkeletonFrame:
        """These rows, in this order (a slice: views of these columns)."""
        return type(self)(*(getattr(self, name)[rows] for name in _FRAME_FIELDS))

    def __len__(self) -> int:
        return len(self.track_ids)


#: The columns of a :class:`SkeletonFrame`, in order.
_FRAME_FIELDS: Final = tuple(x.name for x in fields(SkeletonFrame))


def _std_or_nan(std_m: NDArray[np.float64] | None) -> NDArray[np.float64]:
    """A skeleton's checked joint standard deviations (12, 3) metres; NaN where unknown (None)."""
    std = checked_joint_std(std_m)
    return np.full((N_JOINTS, 3), np.nan) if std is None else std


def skeleton3d_array_cdr(header: bytes, frame: SkeletonFrame) -> bytes:
    """A serialised ``pose_lifter_msgs/Skeleton3DArray`` of ``header`` (a ``std_msgs/Header``'s
    CDR: :func:`header_cdr`, :func:`message_header`) and the skeletons of ``frame`` (``joint_std``
    empty for a row of ``frame.std_m`` that is not all finite)."""
    w = _Writer()
    w.buf += header
    n = len(frame)
    w.u32(n)
    buf = w.buf
    joints = frame.joints_m.astype("<f8", copy=False)
    camera = np.concatenate([frame.projection, frame.scale[:, None], frame.orientation_xyzw,
                             frame.translation, frame.objective[:, None],
                             frame.reprojection_error[:, None]], axis=1).astype("<f8", copy=False)
    observed = (frame.weights > 0).astype(np.bool_)
    weights32 = frame.weights.astype("<f4")
    std = np.full((n, N_JOINTS, 3), np.nan) if frame.std_m is None else frame.std_m.astype("<f8", copy=False)
    std_known = np.isfinite(std).all(axis=(1, 2))
    for i in range(n):
        w.align(8)
        buf += _I64.pack(int(frame.track_ids[i]))
        buf += _JOINT_NAMES  # 8-aligned + 8: 4-aligned
        w.u32(N_JOINTS)
        w.align(8)
        buf += joints[i].tobytes()
        buf += camera[i].tobytes()  # projection, scale, orientation, translation; objective, error
        buf += _ITER_CONVERGED.pack(int(frame.iterations[i]), bool(frame.converged[i]))
        w.align(8)
        buf += _TIME_WARM.pack(float(frame.solve_time[i]), bool(frame.warm_started[i]))
        w.u32(N_JOINTS)
        buf += observed[i].tobytes()
        w.u32(N_JOINTS)
        buf += weights32[i].tobytes()
        if std_known[i]:
            w.u32(N_JOINTS)
            w.align(8)
            buf += std[i].tobytes()
        else:
            w.u32(0)
    return bytes(buf)


@lru_cache(maxsize=4096)
def _track_color(track_id: int) -> tuple[float, float, float]:
    return track_color(track_id)


def _marker(w: _Writer, header_bytes: bytes, ns: bytes, ids: tuple[int, int, int], pose_scale: bytes,
            color_lifetime: bytes, points: NDArray[np.float64] | None) -> None:
    buf = w.buf
    w.align(4)
    buf += header_bytes
    w.align(4)
    buf += ns
    w.align(4)
    buf += _MARKER_IDS.pack(*ids)
    w.align(8)
    buf += pose_scale
    buf += color_lifetime
    n = 0 if points is None else len(points)
    w.u32(n)
    if n:
        assert points is not None
        w.align(8)
        buf += points.tobytes()
    w.align(4)
    buf += _MARKER_TAIL


def marker_array_cdr(
    header: bytes,
    track_ids: Sequence[int],
    joints_m: NDArray[np.float64],
    ns: str,
    lifetime: float,
    deleted_track_ids: Iterable[int] = (),
    joint_diameter: float = 0.05,
    line_width: float = 0.02,
    clear: bool = False,
    deleted_untracked: Iterable[int] = (),
) -> bytes:
    """A serialised ``visualization_msgs/MarkerArray``: the bytes of
    :func:`pose_lifter.messages.convert.skeleton_markers` (same arguments, ``header`` as its CDR:
    :func:`header_cdr`, :func:`message_header`; ``joints_m`` is (n, 12, 3) for the ``n`` track
    ids) as rosbags serialises it; with ``clear``, DELETEALL markers of both
    namespaces first, and DELETE markers for the untracked positions ``deleted_untracked`` last
    (ids ``-1 - position``, :func:`~pose_lifter.messages.convert.marker_id`)."""
    joints = np.asarray(joints_m, dtype="<f8").reshape(len(track_ids), N_JOINTS, 3)
    deleted = [int(t) for t in deleted_track_ids if t >= 0]
    positions = [int(p) for p in deleted_untracked]
    ns_joints, ns_bones = _string_bytes(f"{ns}/joints"), _string_bytes(f"{ns}/bones")
    ns_sec, ns_nsec = divmod(max(0, round(float(lifetime) * 1e9)), 1_000_000_000)
    identity = (0.0, 0.0, 0.0, 0.0, 0.0, 0.0, 1.0)  # position, orientation (x, y, z, w)
    joint_pose = _POSE_SCALE.pack(*identity, joint_diameter, joint_diameter, joint_diameter)
    bone_pose = _POSE_SCALE.pack(*identity, line_width, 0.0, 0.0)
    zero_pose = _POSE_SCALE.pack(*([0.0] * 10))
    zero_color = _COLOR_LIFETIME.pack(0.0, 0.0, 0.0, 0.0, 0, 0, False)
    w = _Writer()
    w.u32(2 * (len(track_ids) + len(deleted) + len(positions) + int(clear)))
    if clear:
        for kind in (ns_joints, ns_bones):
            _marker(w, header, kind, (0, 0, _DELETEALL), zero_pose, zero_color, None)
    untracked = 0
    for i, tid in enumerate(track_ids):
        track_id = int(tid)
        mid = marker_id(track_id, untracked)
        if track_id < 0:
            untracked += 1
        r, g, b = _track_color(track_id)
        color = _COLOR_LIFETIME.pack(r, g, b, 1.0, int(ns_sec), int(ns_nsec), False)
        _marker(w, header, ns_joints, (mid, _SPHERE_LIST, _ADD), joint_pose, color, joints[i])
        _marker(w, header, ns_bones, (mid, _LINE_LIST, _ADD), bone_pose, color, joints[i][_BONE_INDEX])
    for mid in [marker_id(t, 0) for t in deleted] + [marker_id(-1, p) for p in positions]:
        for kind in (ns_joints, ns_bones):
            _marker(w, header, kind, (mid, 0, _DELETE), zero_pose, zero_color, None)
    return bytes(w.buf)


# --------------------------------------------------------------------------- input


@dataclass(frozen=True)
class DecodedStamp:
    """``builtin_interfaces/Time``."""

    sec: int
    nanosec: int


@dataclass(frozen=True)
class DecodedHeader:
    """``std_msgs/Header``."""

    stamp: DecodedStamp
    frame_id: str


@dataclass(frozen=True)
class DecodedSkeleton2D:
    """A ``Skeleton2D`` whose keypoints are one array: ``xyc[k] = (x, y, confidence)``
    (confidence float32 on the wire, here float64 of the same value)."""

    track_id: int
    xyc: NDArray[np.float64]

    @property
    def keypoints(self) -> list[Any]:
        """The keypoints as ``Keypoint2D``-like objects (``x``, ``y``, ``confidence``), for
        duck-typed readers that do not know ``xyc``."""
        from types import SimpleNamespace

        return [SimpleNamespace(x=float(x), y=float(y), confidence=float(c)) for x, y, c in self.xyc]


@dataclass(frozen=True)
class DecodedSkeleton2DArray:
    """A ``Skeleton2DArray`` (``header``, ``layout``, ``skeletons``) from
    :func:`decode_skeleton2d_array`."""

    header: DecodedHeader
    layout: str
    skeletons: list[DecodedSkeleton2D]


#: One Keypoint2D in a sequence: x, y (float64), confidence (float32), 4 bytes to the next x.
_KEYPOINT: Final = np.dtype({"names": ["x", "y", "c"], "formats": ["<f8", "<f8", "<f4"],
                             "offsets": [0, 8, 16], "itemsize": 24})


def decode_skeleton2d_array(data: bytes | memoryview) -> DecodedSkeleton2DArray | None:
    """A serialised ``pose_lifter_msgs/Skeleton2DArray`` (little-endian CDR, today's
    definition) as arrays; None for anything else (big endian, another encapsulation, a
    malformed or truncated message, trailing bytes): the caller then deserialises it with rosbags,
    which reads or refuses it as it always did."""
    raw = bytes(data)
    if len(raw) < 4 or raw[:2] != b"\x00\x01":
        return None
    buf = raw + bytes(8)  # the last keypoint's 4 bytes of padding may lie past the end
    end = len(raw)
    try:
        pos = 4

        def string(pos: int) -> tuple[str, int]:
            pos = 4 + ((pos - 4 + 3) & -4)
            (n,) = _U32.unpack_from(buf, pos)
            if n < 1 or pos + 4 + n > end:
                raise ValueError("bad string")
            return buf[pos + 4:pos + 3 + n].decode(), pos + 4 + n

        sec, nanosec = _STAMP.unpack_from(buf, pos)
        frame_id, pos = string(pos + 8)
        layout, pos = string(pos)
        pos = 4 + ((pos - 4 + 3) & -4)
        (count,) = _U32.unpack_from(buf, pos)
        pos += 4
        skeletons = []
        for _ in range(count):
            pos = 4 + ((pos - 4 + 7) & -8)
            (track_id,) = _I64.unpack_from(buf, pos)
            (k,) = _U32.unpack_from(buf, pos + 8)
            pos += 12
            if k:
                pos = 4 + ((pos - 4 + 7) & -8)
                if pos + 24 * k - 4 > end:
                    return None
                kp = np.frombuffer(buf, dtype=_KEYPOINT, count=k, offset=pos)
                pos += 24 * k - 4
                xyc = np.empty((k, 3))
                xyc[:, 0], xyc[:, 1], xyc[:, 2] = kp["x"], kp["y"], kp["c"]
            else:
                xyc = np.zeros((0, 3))
            skeletons.append(DecodedSkeleton2D(int(track_id), xyc))
    except (struct.error, ValueError, UnicodeDecodeError):
        return None
    if pos > end or pos + 3 < end:  # as rosbags: at most 3 bytes of padding after the end
        return None
    return DecodedSkeleton2DArray(DecodedHeader(DecodedStamp(int(sec), int(nanosec)), frame_id), layout,
                                  skeletons)


def read_skeleton2d_array(data: Any, fallback: Callable[[bytes], Any]) -> Any:
    """A ``Skeleton2DArray`` read for the frame pipeline: serialised bytes as arrays
    (:func:`decode_skeleton2d_array`), or by ``fallback`` (e.g. rclpy's deserialiser) where that
    reader refuses them (another encoding); a message object is returned as it is."""
    if not isinstance(data, bytes | memoryview):
        return data
    decoded = decode_skeleton2d_array(data)
    return fallback(bytes(data)) if decoded is None else decoded
