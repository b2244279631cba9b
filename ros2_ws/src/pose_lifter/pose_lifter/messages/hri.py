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
built as rclpy objects cost ~2 ms a body; the bytes ~0.1 ms), which rclpy publishes as they are
and a bag stores as they are. :data:`LAYOUTS` are the field layouts these bytes follow;
:func:`layout_mismatches` compares them with the installed message classes, and
``tests/messages/test_body.py`` compares the bytes with rosbags' serialisation of the same
messages.
"""

from __future__ import annotations

import struct
from collections.abc import Sequence
from dataclasses import dataclass, field
from functools import lru_cache
from typing import Any, Final

import numpy as np
from numpy.typing import NDArray

from pose_lifter.core.layouts import get_layout
from pose_lifter.messages import body
from pose_lifter.messages.cdr import _STAMP, _U32, _Writer

__all__ = [
    "BODIES_NS",
    "LAYOUTS",
    "PER_BODY",
    "TF_TOPIC",
    "BodyBook",
    "BodyFrame",
    "LiftedBody",
    "body_id",
    "ids_list_cdr",
    "joint_state_cdr",
    "layout_mismatches",
    "roi_cdr",
    "skeleton2d_cdr",
    "string_cdr",
    "tf_message_cdr",
]

#: The REP-155 namespace of bodies.
BODIES_NS: Final[str] = "/humans/bodies"
#: The topic of the bodies' frames.
TF_TOPIC: Final[str] = "/tf"
#: Each body's topics (``BODIES_NS/<id>/<kind>``) and their types; ``urdf`` is latched.
PER_BODY: Final[dict[str, str]] = {"urdf": "std_msgs/msg/String", "skeleton2d": "hri_msgs/msg/Skeleton2D",
                                   "roi": "hri_msgs/msg/NormalizedRegionOfInterest2D",
                                   "joint_states": "sensor_msgs/msg/JointState"}
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
_POINTS: Final = struct.Struct(f"<{3 * _N_COCO18}f")
_BOX: Final = struct.Struct("<5f")


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


def _header(w: _Writer, stamp_ns: int, frame_id: str) -> None:
    """A std_msgs/Header at a 4-aligned position."""
    w.align(4)
    w.buf += _STAMP.pack(*divmod(int(stamp_ns), 1_000_000_000))
    w.string(frame_id)


def ids_list_cdr(stamp_ns: int, frame_id: str, ids: Sequence[str]) -> bytes:
    """``hri_msgs/IdsList`` of ``ids``."""
    w = _Writer()
    _header(w, stamp_ns, frame_id)
    w.u32(len(ids))
    for i in ids:
        w.string(i)
    return bytes(w.buf)


@lru_cache(maxsize=4096)
def _link_names(bid: str) -> tuple[tuple[bytes, bytes], ...]:
    """Per link of :data:`body.LINKS`: its parent's and its own frame name as CDR strings
    (the body's root parent, the input's frame, is ``b""``)."""
    def enc(name: str) -> bytes:
        data = name.encode()
        return _U32.pack(len(data) + 1) + data + b"\x00"

    return tuple((enc(f"{parent}_{bid}") if parent else b"", enc(f"{child}_{bid}"))
                 for parent, child in body.LINKS)


def tf_message_cdr(stamp_ns: int, frame_id: str, bodies: Sequence[tuple[str, body.BodyPose]]) -> bytes:
    """``tf2_msgs/TFMessage`` with every link of each ``(body id, pose)``, ``body_<id>`` a child
    of ``frame_id`` (the joints' frame), the others of their REP-155 parent."""
    w = _Writer()
    w.u32(len(body.LINKS) * len(bodies))
    buf = w.buf
    stamp = _STAMP.pack(*divmod(int(stamp_ns), 1_000_000_000))
    root = frame_id.encode()
    root = _U32.pack(len(root) + 1) + root + b"\x00"
    for bid, pose in bodies:
        names = _link_names(bid)
        rows = zip(names, pose.translations.tolist(), pose.quaternions.tolist(), strict=True)
        for (parent, child), t, q in rows:
            buf += b"\x00" * (-(len(buf) - 4) % 4)  # the header: stamp, frame_id
            buf += stamp
            buf += parent or root
            buf += b"\x00" * (-(len(buf) - 4) % 4)  # child_frame_id
            buf += child
            buf += b"\x00" * (-(len(buf) - 4) % 8)  # translation, rotation: float64
            buf += _TRANSFORM.pack(*t, *q)
    return bytes(buf)


def joint_state_cdr(stamp_ns: int, bid: str, pose: body.BodyPose) -> bytes:
    """``sensor_msgs/JointState`` of one body: the REP-155 joint angles (radians), names
    ``<joint>_<id>`` in the order of :data:`body.REVOLUTE_JOINTS`, no velocity or effort."""
    w = _Writer()
    _header(w, stamp_ns, "")
    w.u32(len(body.REVOLUTE_JOINTS))
    for name in body.REVOLUTE_JOINTS:
        w.string(f"{name}_{bid}")
    w.u32(len(pose.angles))
    w.align(8)
    w.buf += np.ascontiguousarray(pose.angles, dtype="<f8").tobytes()
    w.u32(0)  # velocity
    w.u32(0)  # effort
    return bytes(w.buf)


def string_cdr(text: str) -> bytes:
    """``std_msgs/String``."""
    w = _Writer()
    w.string(text)
    return bytes(w.buf)


def _normalised(points: NDArray[np.float64], image_size: tuple[float, float]) -> NDArray[np.float64]:
    w, h = image_size
    out: NDArray[np.float64] = np.clip(np.asarray(points, dtype=np.float64) / np.array([w, h]), 0.0, 1.0)
    return out


def skeleton2d_cdr(stamp_ns: int, frame_id: str, points: NDArray[np.float64], confidence: NDArray[np.float64],
                   image_size: tuple[float, float]) -> bytes:
    """``hri_msgs/Skeleton2D``: the 12 joints (pixels, shape (12, 2); confidence (12,), 0 where
    missing) at their OpenPose-COCO slots normalised by ``image_size`` (width, height), the neck
    at the shoulders' midpoint; the points the model has no joint for (nose, eyes, ears) have
    confidence 0."""
    xyc = np.zeros((_N_COCO18, 3))
    xyc[_COCO18.index_array, :2] = _normalised(points, image_size)
    xyc[_COCO18.index_array, 2] = np.asarray(confidence, dtype=np.float64)
    ls, rs = _COCO18.model_indices[0], _COCO18.model_indices[3]  # left / right shoulder slots
    if xyc[ls, 2] > 0 and xyc[rs, 2] > 0:
        xyc[_NECK] = [*(0.5 * (xyc[ls, :2] + xyc[rs, :2])), min(xyc[ls, 2], xyc[rs, 2])]
    w = _Writer()
    _header(w, stamp_ns, frame_id)
    w.align(4)
    w.buf += _POINTS.pack(*xyc.ravel().tolist())
    return bytes(w.buf)


def roi_cdr(stamp_ns: int, frame_id: str, points: NDArray[np.float64], confidence: NDArray[np.float64],
            image_size: tuple[float, float]) -> bytes:
    """``hri_msgs/NormalizedRegionOfInterest2D``: the box of the observed joints (confidence > 0),
    normalised; ``c`` their mean confidence (an empty box with c = 0 when none is observed)."""
    seen = np.asarray(confidence) > 0
    box = [0.0] * 5
    if seen.any():
        norm = _normalised(np.asarray(points)[seen], image_size)
        (x0, y0), (x1, y1) = norm.min(axis=0), norm.max(axis=0)
        box = [float(x0), float(y0), float(x1), float(y1), float(np.mean(np.asarray(confidence)[seen]))]
    w = _Writer()
    _header(w, stamp_ns, frame_id)
    w.align(4)
    w.buf += _BOX.pack(*box)
    return bytes(w.buf)


@dataclass(frozen=True)
class LiftedBody:
    """One lifted skeleton as :meth:`BodyBook.frame` takes it.

    Attributes
    ----------
    track_id : int
    joints_m : ndarray, shape (12, 3)
        Metres, in the frame's ``frame_id``.
    points : ndarray, shape (12, 2)
        The 2D input, pixels.
    confidence : ndarray, shape (12,)
    """

    track_id: int
    joints_m: NDArray[np.float64]
    points: NDArray[np.float64]
    confidence: NDArray[np.float64]


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

    def __len__(self) -> int:
        return len(self._bodies)

    def clear(self) -> list[str]:
        """Forget every body; returns their ids (gone)."""
        gone = sorted(self._bodies.values())
        self._bodies.clear()
        self._seen.clear()
        return gone

    def frame(self, stamp_ns: int, frame_id: str, lifted: Sequence[LiftedBody],
              image_size: tuple[float, float] | None) -> BodyFrame:
        """The outputs of one frame.

        Parameters
        ----------
        stamp_ns, frame_id : the input's stamp and frame (the joints' frame)
        lifted : the frame's lifted skeletons
        image_size : (width, height) in pixels, or None (no ``skeleton2d`` / ``roi``)
        """
        new: dict[str, bytes] = {}
        shown: list[tuple[str, body.BodyPose, LiftedBody]] = []
        tracked = [p for p in lifted if p.track_id >= 0]
        poses = body.body_poses(np.stack([p.joints_m for p in tracked])) if tracked else []
        for person, pose in zip(tracked, poses, strict=True):
            if pose is None:  # a degenerate skeleton: no body this frame
                continue
            if person.track_id not in self._bodies:
                bid = body_id(person.track_id)
                self._bodies[person.track_id] = bid
                new[bid] = string_cdr(body.body_urdf(bid, body.body_dimensions(person.joints_m)))
            self._seen[person.track_id] = stamp_ns
            shown.append((self._bodies[person.track_id], pose, person))
        stale = [tid for tid, seen in self._seen.items() if stamp_ns - seen > self.timeout_ns]
        gone = sorted(self._bodies.pop(tid) for tid in stale)
        for tid in stale:
            del self._seen[tid]
        outputs: dict[str, dict[str, bytes]] = {}
        for bid, pose, p in shown:
            out = {"joint_states": joint_state_cdr(stamp_ns, bid, pose)}
            if image_size is not None:
                out["skeleton2d"] = skeleton2d_cdr(stamp_ns, frame_id, p.points, p.confidence, image_size)
                out["roi"] = roi_cdr(stamp_ns, frame_id, p.points, p.confidence, image_size)
            outputs[bid] = out
        tf = tf_message_cdr(stamp_ns, frame_id, [(bid, pose) for bid, pose, _ in shown]) if shown else None
        return BodyFrame(tracked=ids_list_cdr(stamp_ns, frame_id, sorted(self._bodies.values())), tf=tf,
                         bodies=outputs, new=new, gone=gone)
