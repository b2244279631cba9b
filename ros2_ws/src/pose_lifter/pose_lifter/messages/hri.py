"""REP-155 (ros4hri) messages of the lifted bodies: ids, TF, joint states, URDF, 2D skeleton, ROI.

For each tracked person the node publishes, under ``/humans/bodies``:

- ``tracked`` (``hri_msgs/IdsList``): the body ids of the live tracks;
- ``<id>/skeleton2d`` (``hri_msgs/Skeleton2D``, 18 OpenPose-COCO points normalised by the image
  size) and ``<id>/roi`` (``hri_msgs/NormalizedRegionOfInterest2D``): the 2D input;
- ``<id>/joint_states`` (``sensor_msgs/JointState``): the REP-155 model's joint angles
  (:mod:`pose_lifter.messages.body`), names suffixed ``_<id>``;
- ``<id>/urdf`` (``std_msgs/String``, latched): the body's URDF, from its first lifted skeleton;

and on ``/tf`` (``tf2_msgs/TFMessage``) every link of the body, ``body_<id>`` under the input's
frame. The messages are written as CDR bytes straight from the arrays (27 transforms per body
built as rclpy objects cost ~2 ms a body; the bytes of a 30-body frame ~0.4 ms), which rclpy
publishes as they are and a bag stores as they are. A body's constant bytes (its frame and joint
names with their padding) are encoded once per body id and cached; per frame only the numbers are
written, the 2D fields of all the frame's bodies in one numpy pass. :data:`LAYOUTS` are the
field layouts these bytes follow; :func:`layout_mismatches` compares them with the installed
message classes, and ``tests/messages/test_body.py`` compares the bytes with rosbags'
serialisation of the same messages.
"""

from __future__ import annotations

import struct
from collections.abc import Callable, Sequence
from dataclasses import dataclass, field
from functools import lru_cache
from typing import Any, Final

import numpy as np
from numpy.typing import NDArray

from pose_lifter.messages import body
from pose_lifter.messages.cdr import (
    _ENCAPSULATION,
    _STAMP,
    _U32,
    SkeletonFrame,
    _string_bytes,
    _Writer,
    header_cdr,
    stamp_cdr,
)
from pose_lifter.messages.layouts import get_layout
from pose_lifter.messages.names import BODIES_NS, PER_BODY, TF_TOPIC

__all__ = [
    "BODIES_NS",
    "LAYOUTS",
    "PER_BODY",
    "TF_TOPIC",
    "BodyBook",
    "BodyFrame",
    "LaterBodies",
    "body_id",
    "ids_list_cdr",
    "joint_state_cdr",
    "layout_mismatches",
    "roi_cdr",
    "skeleton2d_cdr",
    "string_cdr",
    "tf_message_cdr",
]

#: The field layouts the CDR writers follow (``get_fields_and_field_types()`` of rclpy's classes).
LAYOUTS: Final[dict[str, dict[str, str]]] = {
    "hri_msgs/msg/IdsList": {"header": "std_msgs/Header", "ids": "sequence<string>"},
    "hri_msgs/msg/Skeleton2D": {"header": "std_msgs/Header",
                                "skeleton": "hri_msgs/NormalizedPointOfInterest2D[18]"},
    "hri_msgs/msg/NormalizedPointOfInterest2D": {"x": "float", "y": "float", "c": "float"},
    "hri_msgs/msg/NormalizedRegionOfInterest2D": {"header": "std_msgs/Header", "xmin": "float",
                                                  "ymin": "float", "xmax": "float", "ymax": "float",
                                                  "c": "float"},
    "tf2_msgs/msg/TFMessage": {"transforms": "sequence<geometry_msgs/TransformStamped>"},
    "geometry_msgs/msg/TransformStamped": {"header": "std_msgs/Header", "child_frame_id": "string",
                                           "transform": "geometry_msgs/Transform"},
    "sensor_msgs/msg/JointState": {"header": "std_msgs/Header", "name": "sequence<string>",
                                   "position": "sequence<double>", "velocity": "sequence<double>",
                                   "effort": "sequence<double>"},
    "std_msgs/msg/String": {"data": "string"},
}
_COCO18: Final = get_layout("coco18")
_N_COCO18: Final[int] = 18
_NECK: Final[int] = 1  # OpenPose-COCO's neck: the shoulders' midpoint
_LETTERS: Final[str] = "abcdefghijklmnopqrstuvwxyz"
_N_IDS: Final[int] = 26**5
_ID_MULTIPLIER: Final[int] = 7_654_321  # coprime with 26**5 (odd, not a multiple of 13)
_ID_OFFSET: Final[int] = 4_242_424
_TRANSFORM: Final = struct.Struct("<7d")  # translation (3), rotation (x, y, z, w)


def layout_mismatches(classes: Sequence[Any]) -> list[str]:
    """The installed message classes (rclpy) whose fields differ from :data:`LAYOUTS`: the bytes
    written here would not be those messages (e.g. another hri_msgs release)."""
    out = []
    for cls in classes:
        pkg = cls.__module__.split(".")[0]
        name = f"{pkg}/msg/{cls.__name__}"
        if name in LAYOUTS and dict(cls.get_fields_and_field_types()) != LAYOUTS[name]:
            out.append(name)
    return out


def body_id(track_id: int) -> str:
    """The REP-155 body id of a track: five lowercase letters, the same for the same track id
    (in the node and offline). Track ids that differ by less than 26**5 get different ids (an
    affine permutation of 0..26**5-1, so consecutive ids do not look alike)."""
    if track_id < 0:
        raise ValueError("an untracked skeleton (track_id < 0) has no body id")
    value = (_ID_MULTIPLIER * (int(track_id) % _N_IDS) + _ID_OFFSET) % _N_IDS
    letters = []
    for _ in range(5):
        value, k = divmod(value, 26)
        letters.append(_LETTERS[k])
    return "".join(letters)


def _header_block(header: bytes) -> bytes:
    """The encapsulation and a std_msgs/Header's CDR (:func:`~pose_lifter.messages.cdr.header_cdr`)
    padded to 4: the start of every message here whose header is followed by 4-aligned fields,
    shared by the frame's messages that have the input's frame."""
    data = _ENCAPSULATION + header
    return data + b"\x00" * (-len(data) % 4)


def ids_list_cdr(stamp_ns: int, frame_id: str, ids: Sequence[str]) -> bytes:
    """``hri_msgs/IdsList`` of ``ids``."""
    return _ids_list(header_cdr(stamp_cdr(stamp_ns), frame_id), ids)


def _ids_list(header: bytes, ids: Sequence[str]) -> bytes:
    """:func:`ids_list_cdr` with its header's CDR."""
    buf = bytearray(_header_block(header))
    buf += _U32.pack(len(ids))
    for i in ids:
        buf += b"\x00" * (-len(buf) % 4)
        buf += _string_bytes(i)
    return bytes(buf)


@dataclass(frozen=True, eq=False)
class _TfLayout:
    """Where one body's transforms in a ``TFMessage`` hold their stamps and values (the same for
    every body whose frame names have the same lengths, compared by identity).

    Attributes
    ----------
    phase : int
        The body's first byte modulo 8 (CDR offsets): 4 for the message's first body (after the
        sequence's count), 0 for the others (after a transform's float64).
    stamp_words : ndarray, shape (len(LINKS),)
        Each transform's stamp, in 4-byte words from the body's first byte.
    translation_words, rotation_words : ndarray, shape (3 * len(LINKS),), (4 * len(LINKS),)
        Each transform's translation (3 float64) and rotation (4 float64, right after it), in
        8-byte words from the body's first byte minus ``phase``.
    """

    phase: int
    stamp_words: NDArray[np.intp]
    translation_words: NDArray[np.intp]
    rotation_words: NDArray[np.intp]


@lru_cache(maxsize=256)
def _tf_layout(phase: int, stamps: tuple[int, ...], values: tuple[int, ...]) -> _TfLayout:
    """The one :class:`_TfLayout` of these byte offsets (from the body's first byte)."""
    words = (phase + np.array(values, dtype=np.intp)[:, None]) // 8 + np.arange(7, dtype=np.intp)
    return _TfLayout(phase, np.array(stamps, dtype=np.intp) // 4, words[:, :3].ravel(), words[:, 3:].ravel())


@dataclass(frozen=True)
class _TfBlock:
    """One body's transforms in a ``TFMessage``: the bytes with zero stamps and values (names and
    padding in place) and where those go."""

    data: bytes
    layout: _TfLayout


@lru_cache(maxsize=1024)
def _tf_block(bid: str, root: bytes, phase: int) -> _TfBlock:
    """The :class:`_TfBlock` of body ``bid`` starting at a CDR offset of ``phase`` modulo 8, its
    ``body_<id>`` a child of ``root`` (the input's frame, as a CDR string)."""
    buf = bytearray(phase)  # offsets in buf have the message's alignment
    stamps, values = [], []
    for parent, child in body.LINKS:
        buf += b"\x00" * (-len(buf) % 4)  # the header: stamp (written per frame), frame_id
        stamps.append(len(buf) - phase)
        buf += header_cdr(bytes(_STAMP.size), f"{parent}_{bid}") if parent else bytes(_STAMP.size) + root
        buf += b"\x00" * (-len(buf) % 4)  # child_frame_id
        buf += _string_bytes(f"{child}_{bid}")
        buf += b"\x00" * (-len(buf) % 8)  # translation, rotation: float64
        values.append(len(buf) - phase)
        buf += bytes(_TRANSFORM.size)
    return _TfBlock(bytes(buf[phase:]), _tf_layout(phase, tuple(stamps), tuple(values)))


def tf_message_cdr(stamp_ns: int, frame_id: str, bodies: Sequence[tuple[str, body.BodyPose]]) -> bytes:
    """``tf2_msgs/TFMessage`` with every link of each ``(body id, pose)``, ``body_<id>`` a child
    of ``frame_id`` (the joints' frame), the others of their REP-155 parent.

    Each body's names and padding are cached (:func:`_tf_block`); the frame's stamp and the
    bodies' transforms are written into them with one numpy assignment per layout."""
    return _tf_message(header_cdr(stamp_cdr(stamp_ns), frame_id), bodies)


def _tf_message(header: bytes, bodies: Sequence[tuple[str, body.BodyPose]]) -> bytes:
    """:func:`tf_message_cdr` with the stamp and frame of a header's CDR."""
    n_links = len(body.LINKS)
    if not bodies:
        return _ENCAPSULATION + _U32.pack(0)
    translations = np.array([pose.translations for _, pose in bodies], dtype=np.float64)
    rotations = np.array([pose.quaternions for _, pose in bodies], dtype=np.float64)
    if translations.shape != (len(bodies), n_links, 3) or rotations.shape != (len(bodies), n_links, 4):
        raise ValueError(f"each pose needs {n_links} translations (3) and quaternions (4)")
    t = _tf_template(header[_STAMP.size:], tuple(bid for bid, _ in bodies))
    buf = bytearray(t.data)
    words = np.frombuffer(buf, dtype="<u4")  # CDR offset c: word (c + 8) / 4
    doubles = np.frombuffer(buf, dtype="<f8", offset=8)  # CDR offset c: double c / 8
    sec, nanosec = np.frombuffer(header[:_STAMP.size], dtype="<u4")
    words[t.stamp_words] = sec
    words[t.stamp_words + 1] = nanosec
    doubles[t.translation_words] = translations.reshape(-1)
    doubles[t.rotation_words] = rotations.reshape(-1)
    return bytes(memoryview(buf)[4:])


@dataclass(frozen=True)
class _TfTemplate:
    """A ``TFMessage`` of some bodies with zero stamps and values, 4 bytes ahead of it (its float64,
    at CDR offsets multiple of 8, then aligned in memory), and where the stamps and values go:
    each transform's ``stamp.sec`` in 4-byte words of ``data``, the translations' and rotations'
    values (bodies, links, then 3 or 4 values) in 8-byte words from byte 8."""

    data: bytes
    stamp_words: NDArray[np.intp]
    translation_words: NDArray[np.intp]
    rotation_words: NDArray[np.intp]


@lru_cache(maxsize=256)
def _tf_template(root: bytes, bids: tuple[str, ...]) -> _TfTemplate:
    """The :class:`_TfTemplate` of these bodies in this order, ``body_<id>`` a child of ``root``
    (the input's frame, as a CDR string): made of each body's :func:`_tf_block` once, then reused
    while the same bodies are shown."""
    buf = bytearray(4) + _ENCAPSULATION + _U32.pack(len(body.LINKS) * len(bids))
    stamps, translations, rotations = [], [], []
    for k, bid in enumerate(bids):
        block = _tf_block(bid, root, 4 if k == 0 else 0)
        at = len(buf) - 8  # the block's CDR offset
        layout = block.layout
        stamps.append((at + 8) // 4 + layout.stamp_words)
        first = (at - layout.phase) // 8
        translations.append(first + layout.translation_words)
        rotations.append(first + layout.rotation_words)
        buf += block.data
    return _TfTemplate(bytes(buf), np.concatenate(stamps), np.concatenate(translations),
                       np.concatenate(rotations))


@lru_cache(maxsize=1024)
def _joint_state_names(bid: str, n_angles: int) -> bytes:
    """A ``JointState``'s bytes from its header's frame_id to its positions' values: the empty
    frame_id, the names ``<joint>_<id>``, the positions' count and padding; constant per body, as
    the empty frame_id fixes every offset."""
    w = _Writer()
    w.buf += header_cdr(bytes(_STAMP.size), "")
    w.u32(len(body.REVOLUTE_JOINTS))
    for name in body.REVOLUTE_JOINTS:
        w.string(f"{name}_{bid}")
    w.u32(n_angles)
    w.align(8)
    return bytes(w.buf[len(_ENCAPSULATION) + _STAMP.size:])


#: A ``JointState``'s velocity and effort: two empty sequences right after the float64 positions.
_NO_VELOCITY_EFFORT: Final[bytes] = bytes(8)


def _joint_state(stamp: bytes, bid: str, angles: NDArray[np.float64]) -> bytes:
    """:func:`joint_state_cdr` with the stamp as :func:`~pose_lifter.messages.cdr.stamp_cdr` bytes."""
    positions = np.ascontiguousarray(angles, dtype="<f8")
    return b"".join((_ENCAPSULATION, stamp, _joint_state_names(bid, len(positions)), positions.tobytes(),
                     _NO_VELOCITY_EFFORT))


def joint_state_cdr(stamp_ns: int, bid: str, pose: body.BodyPose) -> bytes:
    """``sensor_msgs/JointState`` of one body: the REP-155 joint angles (radians), names
    ``<joint>_<id>`` in the order of :data:`body.REVOLUTE_JOINTS`, no velocity or effort."""
    return _joint_state(stamp_cdr(stamp_ns), bid, pose.angles)


def string_cdr(text: str) -> bytes:
    """``std_msgs/String``."""
    w = _Writer()
    w.string(text)
    return bytes(w.buf)


def _float32(values: NDArray[np.float64]) -> NDArray[np.float32]:
    """``values`` as little-endian float32; a finite value float32 cannot hold is refused, as
    ``struct`` refuses it."""
    with np.errstate(over="ignore"):
        out: NDArray[np.float32] = values.astype("<f4")
    if np.isinf(out).any() and (np.isinf(out) & np.isfinite(values)).any():
        raise OverflowError("float too large to pack with f format")
    return out


def _skeleton2d_and_roi(points: Sequence[NDArray[np.float64]], confidence: Sequence[NDArray[np.float64]],
                        image_size: tuple[float, float]) -> tuple[NDArray[np.float32], NDArray[np.float32]]:
    """The float32 fields of the ``Skeleton2D`` and the ``NormalizedRegionOfInterest2D`` of
    several bodies (:func:`skeleton2d_cdr`, :func:`roi_cdr`), one numpy pass over the bodies.

    Parameters
    ----------
    points : per body, shape (12, 2), pixels
    confidence : per body, shape (12,), 0 where missing
    image_size : (width, height)

    Returns
    -------
    skeletons : ndarray, shape (B, 54)
        Per body the 18 points' (x, y, c).
    boxes : ndarray, shape (B, 5)
        Per body (xmin, ymin, xmax, ymax, c): the bounds of its observed points (confidence > 0)
        and their mean confidence; zeros (an empty box with c = 0) for a body without one.
    """
    n = len(points)
    w, h = image_size
    xy = np.array(points, dtype=np.float64)
    conf = np.array(confidence, dtype=np.float64)
    norm = np.clip(xy / np.array([w, h]), 0.0, 1.0)
    xyc = np.zeros((n, _N_COCO18, 3))
    xyc[:, _COCO18.index_array, :2] = norm
    xyc[:, _COCO18.index_array, 2] = conf
    ls, rs = _COCO18.model_indices[0], _COCO18.model_indices[3]  # left / right shoulder slots
    neck = (xyc[:, ls, 2] > 0) & (xyc[:, rs, 2] > 0)
    xyc[neck, _NECK, :2] = 0.5 * (xyc[neck, ls, :2] + xyc[neck, rs, :2])
    xyc[neck, _NECK, 2] = np.minimum(xyc[neck, ls, 2], xyc[neck, rs, 2])

    seen = conf > 0
    counts = seen.sum(axis=1)
    boxes = np.zeros((n, 5))
    # joints first: the reductions run over whole (bodies, 2) slabs
    by_joint, seen_by_joint = np.ascontiguousarray(norm.transpose(1, 0, 2)), np.ascontiguousarray(seen.T)
    boxes[:, :2] = np.where(seen_by_joint[..., None], by_joint, np.inf).min(axis=0)
    boxes[:, 2:4] = np.where(seen_by_joint[..., None], by_joint, -np.inf).max(axis=0)
    boxes[:, 4] = np.where(seen, conf, 0.0).sum(axis=1) / np.maximum(counts, 1)
    boxes[counts == 0] = 0.0
    return _float32(xyc.reshape(n, -1)), _float32(boxes)


def skeleton2d_cdr(stamp_ns: int, frame_id: str, points: NDArray[np.float64], confidence: NDArray[np.float64],
                   image_size: tuple[float, float]) -> bytes:
    """``hri_msgs/Skeleton2D``: the 12 joints (pixels, shape (12, 2); confidence (12,), 0 where
    missing) at their OpenPose-COCO slots normalised by ``image_size`` (width, height), the neck
    at the shoulders' midpoint; the points the model has no joint for (nose, eyes, ears) have
    confidence 0."""
    skeletons, _ = _skeleton2d_and_roi([points], [confidence], image_size)
    return _header_block(header_cdr(stamp_cdr(stamp_ns), frame_id)) + bytes(skeletons[0].tobytes())


def roi_cdr(stamp_ns: int, frame_id: str, points: NDArray[np.float64], confidence: NDArray[np.float64],
            image_size: tuple[float, float]) -> bytes:
    """``hri_msgs/NormalizedRegionOfInterest2D``: the box of the observed joints (confidence > 0),
    normalised; ``c`` their mean confidence (an empty box with c = 0 when none is observed)."""
    _, boxes = _skeleton2d_and_roi([points], [confidence], image_size)
    return _header_block(header_cdr(stamp_cdr(stamp_ns), frame_id)) + bytes(boxes[0].tobytes())


@dataclass(frozen=True)
class BodyFrame:
    """The REP-155 outputs of one frame (:meth:`BodyBook.frame`), serialised (CDR).

    Attributes
    ----------
    tracked : bytes
        ``IdsList`` of the bodies alive after the frame.
    tf : bytes or None
        ``TFMessage`` of the bodies lifted in the frame (None when there is none).
    bodies : dict
        Per body lifted in the frame: ``{"joint_states": ..., "skeleton2d": ..., "roi": ...}``
        (the 2D ones only when the image size is known).
    new : dict
        The URDF (``String``) of each body that appeared in this frame (publish latched).
    gone : list of str
        The bodies whose track ended (their topics and frames stop).
    """

    tracked: bytes
    tf: bytes | None
    bodies: dict[str, dict[str, bytes]] = field(default_factory=dict)
    new: dict[str, bytes] = field(default_factory=dict)
    gone: list[str] = field(default_factory=list)

    def messages(self) -> list[tuple[str, bytes, str]]:
        """Everything to publish, in order, as (topic, CDR, type): the new bodies' URDFs, each
        body's messages, ``/tf``, ``tracked`` (the node and the offline lift alike)."""
        out = [(f"{BODIES_NS}/{bid}/urdf", data, PER_BODY["urdf"]) for bid, data in self.new.items()]
        for bid, per_kind in self.bodies.items():
            out += [(f"{BODIES_NS}/{bid}/{kind}", data, PER_BODY[kind]) for kind, data in per_kind.items()]
        if self.tf is not None:
            out.append((TF_TOPIC, self.tf, "tf2_msgs/msg/TFMessage"))
        out.append((f"{BODIES_NS}/tracked", self.tracked, "hri_msgs/msg/IdsList"))
        return out


def tracked_body_poses(frames: Sequence[SkeletonFrame]) -> list[list[body.BodyPose | None]]:
    """Per frame, the :func:`~pose_lifter.messages.body.body_poses` of its tracked rows (track id
    >= 0, in order), of all the frames in one pass (each skeleton's pose is its own, whatever the
    pass: what :meth:`BodyBook.frame` computes of one frame)."""
    rows = [np.flatnonzero(f.track_ids >= 0) for f in frames]
    joints = [f.joints_m[r] for f, r in zip(frames, rows, strict=True) if r.size]
    poses = body.body_poses(np.concatenate(joints)) if joints else []
    ends = np.cumsum([r.size for r in rows]).tolist()
    return [poses[end - r.size:end] for r, end in zip(rows, ends, strict=True)]


class LaterBodies:
    """A frame's REP-155 messages, computed once, when first called (:meth:`BodyBook.later`)."""

    def __init__(self, compute: Callable[[], BodyFrame]) -> None:
        self._compute: Callable[[], BodyFrame] | None = compute
        self._frame: BodyFrame | None = None

    def __call__(self) -> BodyFrame:
        if self._compute is not None:
            self._frame, self._compute = self._compute(), None
        assert self._frame is not None
        return self._frame


class BodyBook:
    """The bodies on the REP-155 topics, from one frame to the next.

    A body appears with its track's first lifted skeleton (its URDF is built then) and leaves
    when its track has not been lifted for more than ``timeout_s`` (input stamps), as the
    lifter forgets a track. Untracked skeletons (track id < 0) have no body; a skeleton the
    model cannot be fitted to (no hip line, a zero-length segment) is left out of the frame.

    Parameters
    ----------
    timeout_s : float
        The node's ``track_timeout``.
    """

    def __init__(self, timeout_s: float) -> None:
        self.timeout_ns = round(float(timeout_s) * 1e9)
        self._bodies: dict[int, str] = {}  # track id -> body id
        self._seen: dict[int, int] = {}  # track id -> stamp of its last lifted skeleton
        self._pending: LaterBodies | None = None  # a frame asked for with later(), not yet computed

    def __len__(self) -> int:
        return len(self._bodies)

    def clear(self) -> list[str]:
        """Forget every body; returns their ids (gone)."""
        self.settle()
        gone = sorted(self._bodies.values())
        self._bodies.clear()
        self._seen.clear()
        return gone

    def later(self, stamp_ns: int, header: bytes, lifted: SkeletonFrame,
              image_size: tuple[float, float] | None,
              poses: Sequence[body.BodyPose | None] | None = None) -> LaterBodies:
        """:meth:`frame`, computed when first asked for (after the frame's skeletons are out), and at
        the latest before the book's next frame: the book sees its frames in order."""
        self.settle()
        self._pending = LaterBodies(lambda: self._frame(stamp_ns, header, lifted, image_size, poses))
        return self._pending

    def settle(self) -> None:
        """Compute the frame asked for with :meth:`later`, if it is not yet."""
        pending, self._pending = self._pending, None
        if pending is not None:
            pending()

    def frame(self, stamp_ns: int, header: bytes, lifted: SkeletonFrame,
              image_size: tuple[float, float] | None,
              poses: Sequence[body.BodyPose | None] | None = None) -> BodyFrame:
        """The outputs of one frame (any frame asked for with :meth:`later` computed first).

        Parameters
        ----------
        stamp_ns : the input's stamp
        header : the bodies' ``std_msgs/Header`` as CDR (:func:`~pose_lifter.messages.cdr.header_cdr`
            of ``stamp_ns`` and the input's frame, the joints' frame)
        lifted : the frame's lifted skeletons (read: ``track_ids``, ``joints_m`` in metres in
            ``frame_id``, the 2D ``points`` in pixels and their ``confidence``)
        image_size : (width, height) in pixels, or None (no ``skeleton2d`` / ``roi``)
        poses : the :func:`~pose_lifter.messages.body.body_poses` of the frame's tracked rows (track
            id >= 0, in order), computed ahead (an offline lift's, for all of its frames in one
            pass: :func:`tracked_body_poses`), or None: computed here
        """
        self.settle()
        return self._frame(stamp_ns, header, lifted, image_size, poses)

    def _frame(self, stamp_ns: int, header: bytes, lifted: SkeletonFrame,
               image_size: tuple[float, float] | None,
               poses: Sequence[body.BodyPose | None] | None = None) -> BodyFrame:
        new: dict[str, bytes] = {}
        shown: list[tuple[str, body.BodyPose, int]] = []  # body id, pose, row of lifted
        tracked = np.flatnonzero(lifted.track_ids >= 0)
        if poses is None:
            poses = body.body_poses(lifted.joints_m[tracked]) if tracked.size else []
        for k, pose in zip(tracked.tolist(), poses, strict=True):
            if pose is None:  # a degenerate skeleton: no body this frame
                continue
            track_id = int(lifted.track_ids[k])
            if track_id not in self._bodies:
                bid = body_id(track_id)
                self._bodies[track_id] = bid
                new[bid] = string_cdr(body.body_urdf(bid, body.body_dimensions(lifted.joints_m[k])))
            self._seen[track_id] = stamp_ns
            shown.append((self._bodies[track_id], pose, k))
        stale = [tid for tid, seen in self._seen.items() if stamp_ns - seen > self.timeout_ns]
        gone = sorted(self._bodies.pop(tid) for tid in stale)
        for tid in stale:
            del self._seen[tid]
        stamp = header[:_STAMP.size]
        outputs = {bid: {"joint_states": _joint_state(stamp, bid, pose.angles)} for bid, pose, _ in shown}
        if shown and image_size is not None:
            block = _header_block(header)
            rows = [k for _, _, k in shown]
            skeletons, boxes = _skeleton2d_and_roi(list(lifted.points[rows]), list(lifted.confidence[rows]),
                                                   image_size)
            for (bid, _, _), skeleton, box in zip(shown, skeletons, boxes, strict=True):
                outputs[bid]["skeleton2d"] = block + skeleton.tobytes()
                outputs[bid]["roi"] = block + box.tobytes()
        tf = _tf_message(header, [(bid, pose) for bid, pose, _ in shown]) if shown else None
        return BodyFrame(tracked=_ids_list(header, sorted(self._bodies.values())), tf=tf,
                         bodies=outputs, new=new, gone=gone)
