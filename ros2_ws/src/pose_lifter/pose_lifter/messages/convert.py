"""Duck-typed conversion between ROS messages and the core's arrays.

Every function reads message fields by attribute name (``msg.keypoints``, ``kp.x``) and builds
messages through a ``types`` namespace, never by ``isinstance``, so the same code serves rclpy
message classes (the node) and rosbags typestore classes (bags, CLI, tests).

``types`` is any object with these attributes, each a callable taking keyword fields:
``Keypoint2D, Skeleton2D, Skeleton2DArray, CameraEstimate, Skeleton3D, Skeleton3DArray``
(pose_lifter_msgs), ``Point, Quaternion, Pose, Vector3`` (geometry_msgs), ``Header, ColorRGBA``
(std_msgs), ``Time, Duration`` (builtin_interfaces), ``Marker, MarkerArray``
(visualization_msgs) and ``CameraInfo`` (sensor_msgs). :func:`rosbags_types` and
:func:`rclpy_types` build it.

Frames: 3D joints are in the camera optical frame (x right, y down, z forward), metres.
"""

from __future__ import annotations

import colorsys
from collections.abc import Iterable, Sequence
from types import SimpleNamespace
from typing import Any, Final

import numpy as np
from numpy.typing import NDArray

from pose_lifter.core.errors import InvalidInputError
from pose_lifter.core.model.skeleton import BONES_FOR_DRAWING, JOINT_NAMES, N_JOINTS
from pose_lifter.core.results import LiftResult
from pose_lifter.messages import names
from pose_lifter.messages.layouts import Layout, frame_joints, get_layout

__all__ = [
    "MESSAGE_TYPES",
    "arrays_to_skeleton2d",
    "camera_estimate",
    "camera_info",
    "checked_joint_std",
    "delete_all_markers",
    "delete_markers",
    "delete_untracked_markers",
    "intrinsics_from_camera_info",
    "joint_points",
    "make_header",
    "marker_id",
    "ns_to_stamp",
    "quaternions_xyzw",
    "rclpy_types",
    "result_to_skeleton3d",
    "rosbags_types",
    "skeleton2d_array",
    "skeleton2d_to_arrays",
    "skeleton3d_from_joints",
    "skeleton3d_to_joints",
    "skeleton3d_to_std",
    "skeleton_markers",
    "skeletons3d_array",
    "stamp_to_ns",
    "track_color",
]

#: Attribute of the ``types`` namespace -> full ROS message type name.
MESSAGE_TYPES: Final[dict[str, str]] = {
    "Keypoint2D": "pose_lifter_msgs/msg/Keypoint2D",
    "Skeleton2D": "pose_lifter_msgs/msg/Skeleton2D",
    "Skeleton2DArray": names.SKELETON2D_ARRAY,
    "CameraEstimate": "pose_lifter_msgs/msg/CameraEstimate",
    "Skeleton3D": "pose_lifter_msgs/msg/Skeleton3D",
    "Skeleton3DArray": names.SKELETON3D_ARRAY,
    "Point": "geometry_msgs/msg/Point",
    "Quaternion": "geometry_msgs/msg/Quaternion",
    "Pose": "geometry_msgs/msg/Pose",
    "Vector3": "geometry_msgs/msg/Vector3",
    "Header": "std_msgs/msg/Header",
    "ColorRGBA": "std_msgs/msg/ColorRGBA",
    "Time": "builtin_interfaces/msg/Time",
    "Duration": "builtin_interfaces/msg/Duration",
    "Marker": "visualization_msgs/msg/Marker",
    "MarkerArray": names.MARKER_ARRAY,
    "CameraInfo": names.CAMERA_INFO,
}

# visualization_msgs/Marker constants (fixed by the message definition)
_SPHERE_LIST: Final[int] = 7
_LINE_LIST: Final[int] = 5
_ADD: Final[int] = 0
_DELETE: Final[int] = 2
_DELETEALL: Final[int] = 3


def rosbags_types(store: Any | None = None) -> SimpleNamespace:
    """The ``types`` namespace from a rosbags typestore (default: ours,
    :mod:`pose_lifter.messages.typestore`).

    Each attribute is a factory that fills omitted fields with ROS defaults, like rclpy classes.
    """
    from pose_lifter.messages.typestore import message_factory, pose_lifter_typestore

    st = store if store is not None else pose_lifter_typestore()
    return SimpleNamespace(**{attr: message_factory(name, st) for attr, name in MESSAGE_TYPES.items()})


def rclpy_types() -> SimpleNamespace:
    """The ``types`` namespace from the rclpy message packages (needs a sourced ROS workspace)."""
    import importlib

    out: dict[str, Any] = {}
    for attr, name in MESSAGE_TYPES.items():
        pkg, _, cls = name.split("/")
        out[attr] = getattr(importlib.import_module(f"{pkg}.msg"), cls)
    return SimpleNamespace(**out)


# --------------------------------------------------------------------------- stamps, headers


def stamp_to_ns(stamp: Any) -> int:
    """``builtin_interfaces/Time`` -> integer nanoseconds."""
    return int(stamp.sec) * 1_000_000_000 + int(stamp.nanosec)


def ns_to_stamp(ns: int, types: Any) -> Any:
    """Integer nanoseconds -> ``builtin_interfaces/Time``."""
    sec, nsec = divmod(int(ns), 1_000_000_000)
    return types.Time(sec=sec, nanosec=nsec)


def make_header(stamp_ns: int, frame_id: str, types: Any) -> Any:
    """A ``std_msgs/Header``."""
    return types.Header(stamp=ns_to_stamp(stamp_ns, types), frame_id=frame_id)


# --------------------------------------------------------------------------- 2D


def skeleton2d_to_arrays(skel: Any, layout: str | Layout) -> tuple[NDArray[np.float64], NDArray[np.float64]]:
    """The paper's 12 joints of a ``Skeleton2D``.

    Keypoints whose confidence is 0 (missing) may carry non-finite coordinates; they are
    returned as 0. Any other non-finite value raises.

    Parameters
    ----------
    skel : Skeleton2D-like
        Has ``keypoints``, each with ``x``, ``y``, ``confidence`` (or ``xyc``, the keypoints as
        one (K, 3) array, as :class:`pose_lifter.messages.cdr.DecodedSkeleton2D` has).
    layout : str or Layout
        The enclosing array's layout (``coco17``, ``h36m17``, ``body25``, ``wang12``, ...), by name
        or as the :class:`~pose_lifter.messages.layouts.Layout` a frame looked up once.

    Returns
    -------
    points : ndarray, shape (12, 2)
        Pixels.
    confidence : ndarray, shape (12,)

    Raises
    ------
    UnknownLayoutError
        Unknown layout name.
    InvalidInputError
        Wrong number of keypoints for the layout, or non-finite values.
    """
    (read,) = frame_joints([skel], layout)
    if isinstance(read, Exception):
        raise read
    return read


def arrays_to_skeleton2d(
    keypoints: NDArray[np.float64], confidence: NDArray[np.float64], track_id: int, types: Any
) -> Any:
    """A ``Skeleton2D`` from keypoints in some layout's order.

    Parameters
    ----------
    keypoints : ndarray, shape (K, 2)
    confidence : ndarray, shape (K,)
    track_id : int
    types : namespace of message factories
    """
    kp = np.asarray(keypoints, dtype=np.float64)
    cf = np.asarray(confidence, dtype=np.float64)
    if kp.ndim != 2 or kp.shape[1] != 2 or cf.shape != (kp.shape[0],):
        raise InvalidInputError(f"keypoints (K, 2) and confidence (K,) expected, got {kp.shape}, {cf.shape}")
    return types.Skeleton2D(
        track_id=int(track_id),
        keypoints=[types.Keypoint2D(x=float(x), y=float(y), confidence=float(c))
                   for (x, y), c in zip(kp, cf, strict=True)],
    )


def skeleton2d_array(header: Any, layout: str, skeletons: Sequence[Any], types: Any) -> Any:
    """A ``Skeleton2DArray``."""
    get_layout(layout)
    return types.Skeleton2DArray(header=header, layout=layout, skeletons=list(skeletons))


# --------------------------------------------------------------------------- 3D


def quaternions_xyzw(rotations: NDArray[np.float64]) -> NDArray[np.float64]:
    """Unit quaternions (x, y, z, w) of rotation matrices, shape (..., 3, 3) -> (..., 4).

    The numbers of ``scipy.spatial.transform.Rotation.from_matrix(r).as_quat()`` bit for bit
    (scipy 1.17's algorithm, checked against it in ``tests/messages/test_cdr.py``), without importing
    ``scipy.spatial`` (0.3 s) and without its per-call overhead (~0.2 ms): a matrix that is not
    orthogonal to 1e-12 is replaced by the nearest rotation (``U @ Vt`` of its SVD), then
    Shepperd's method picks the largest of the diagonal and the trace, and the result is
    normalised.

    Raises
    ------
    ValueError
        A matrix with a non-positive determinant (as scipy).
    """
    m = np.array(rotations, dtype=np.float64)
    shape = m.shape[:-2]
    if m.shape[-2:] != (3, 3):
        raise ValueError(f"rotation matrices must be (..., 3, 3), got {m.shape}")
    m = m.reshape(-1, 3, 3)
    if np.any(np.linalg.det(m) <= 0):
        raise ValueError("non-positive determinant (left-handed or null frame) in a rotation matrix")
    orthogonal = np.all(np.isclose(m @ np.swapaxes(m, -1, -2), np.eye(3), atol=1e-12), axis=(-2, -1))
    if not np.all(orthogonal):
        u, _, vt = np.linalg.svd(m[~orthogonal], full_matrices=False)
        m[~orthogonal] = u @ vt
    trace = m[:, 0, 0] + m[:, 1, 1] + m[:, 2, 2]
    choice = np.argmax(np.stack([m[:, 0, 0], m[:, 1, 1], m[:, 2, 2], trace], axis=-1), axis=-1)
    q = np.empty((len(m), 4))
    for i in range(3):  # the largest diagonal element is m[i, i]
        sel = choice == i
        j, k = (i + 1) % 3, (i + 2) % 3
        ms = m[sel]
        q[sel, i] = 1 - trace[sel] + 2 * ms[:, i, i]
        q[sel, j] = ms[:, j, i] + ms[:, i, j]
        q[sel, k] = ms[:, k, i] + ms[:, i, k]
        q[sel, 3] = ms[:, k, j] - ms[:, j, k]
    sel = choice == 3  # the trace is the largest
    ms = m[sel]
    q[sel, 0] = ms[:, 2, 1] - ms[:, 1, 2]
    q[sel, 1] = ms[:, 0, 2] - ms[:, 2, 0]
    q[sel, 2] = ms[:, 1, 0] - ms[:, 0, 1]
    q[sel, 3] = 1 + trace[sel]
    return np.asarray(q / np.linalg.norm(q, axis=-1, keepdims=True)).reshape(*shape, 4)


def camera_estimate(result: LiftResult, types: Any) -> Any:
    """``CameraEstimate`` of a lift (projection row-major, scale, body->camera rotation, translation)."""
    cam = result.camera
    q = quaternions_xyzw(cam.rotation)
    return types.CameraEstimate(
        projection=np.asarray(cam.projection, dtype=np.float64).reshape(6).copy(),
        scale=float(cam.scale),
        orientation=types.Quaternion(x=float(q[0]), y=float(q[1]), z=float(q[2]), w=float(q[3])),
        translation=np.asarray(cam.translation, dtype=np.float64).reshape(2).copy(),
    )


def joint_points(joints_m: NDArray[np.float64], types: Any) -> list[Any]:
    """The 12 ``geometry_msgs/Point`` of metric joints (12, 3): a ``Skeleton3D``'s ``joints``,
    and the points of its markers (:func:`skeleton_markers`)."""
    j = np.asarray(joints_m, dtype=np.float64)
    if j.shape != (N_JOINTS, 3):
        raise InvalidInputError(f"joints must be ({N_JOINTS}, 3), got {j.shape}")
    return [types.Point(x=float(a), y=float(b), z=float(c)) for a, b, c in j]


def checked_joint_std(std_m: NDArray[np.float64] | None) -> NDArray[np.float64] | None:
    """A skeleton's joint standard deviations, shape (12, 3), metres along x, y, z of its frame, as
    float64; None stays None (unknown).

    Raises
    ------
    InvalidInputError
        Another shape, or a value that is not finite and non-negative.
    """
    if std_m is None:
        return None
    std = np.asarray(std_m, dtype=np.float64)
    if std.shape != (N_JOINTS, 3):
        raise InvalidInputError(f"joint std must be ({N_JOINTS}, 3) metres, got shape {std.shape}")
    if not (np.all(np.isfinite(std)) and np.all(std >= 0)):
        raise InvalidInputError("joint std must be finite and non-negative metres (None when unknown)")
    return std


def result_to_skeleton3d(
    result: LiftResult,
    track_id: int,
    joints_m: NDArray[np.float64],
    types: Any,
    solve_time: float = 0.0,
    warm_started: bool = False,
    std_m: NDArray[np.float64] | None = None,
) -> Any:
    """A ``Skeleton3D`` from a lift and its metric joints
    (see :func:`pose_lifter.core.track.placement.place_in_camera`).

    Parameters
    ----------
    result : LiftResult
    track_id : int
    joints_m : ndarray, shape (12, 3)
        Metres, camera optical frame.
    types : namespace of message factories
    solve_time : float
        Seconds.
    warm_started : bool
    std_m : ndarray, shape (12, 3), optional
        Each joint's standard deviation along x, y, z, metres (``joint_std``; None: unknown, empty).
    """
    std = checked_joint_std(std_m)
    return types.Skeleton3D(
        track_id=int(track_id),
        joint_names=list(JOINT_NAMES),
        joints=joint_points(joints_m, types),
        camera=camera_estimate(result, types),
        objective=float(result.objective),
        reprojection_error=float(result.reprojection_error),
        iterations=int(result.total_alternations),
        converged=bool(result.converged),
        solve_time=float(solve_time),
        warm_started=bool(warm_started),
        observed=[bool(w > 0) for w in np.asarray(result.weights, dtype=np.float64)],
        joint_weights=[float(w) for w in np.asarray(result.weights, dtype=np.float64)],
        joint_std=[] if std is None else [types.Vector3(x=float(a), y=float(b), z=float(c))
                                          for a, b, c in std],
    )


def skeleton3d_from_joints(track_id: int, joints_m: NDArray[np.float64], types: Any) -> Any:
    """A ``Skeleton3D`` carrying only joints (ground truth); the solver fields stay default (and
    ``joint_std`` empty: the truth has no uncertainty to publish)."""
    return types.Skeleton3D(
        track_id=int(track_id), joint_names=list(JOINT_NAMES), joints=joint_points(joints_m, types),
        converged=True,
    )


def skeleton3d_to_joints(skel: Any) -> NDArray[np.float64]:
    """Joints of a ``Skeleton3D`` as an array (12, 3) in the core order.

    ``joint_names`` (when filled) are used to reorder; unknown or missing names raise.
    """
    return _in_core_order(skel, skel.joints, "joints")


def skeleton3d_to_std(skel: Any) -> NDArray[np.float64]:
    """Joint standard deviations of a ``Skeleton3D`` (``joint_std``) as an array (12, 3), metres
    along x, y, z, in the core order (reordered by ``joint_names`` as
    :func:`skeleton3d_to_joints`); all NaN where unknown: an empty ``joint_std``, or a message of a
    definition without the field (an older bag read with its own types).
    """
    vectors = getattr(skel, "joint_std", None)
    if vectors is None or len(vectors) == 0:
        return np.full((N_JOINTS, 3), np.nan)
    return _in_core_order(skel, vectors, "joint_std")


def _in_core_order(skel: Any, vectors: Sequence[Any], field: str) -> NDArray[np.float64]:
    """A per-joint field of a ``Skeleton3D`` (``x``, ``y``, ``z`` each, in the order of its
    ``joint_names`` when filled) as an array (12, 3) in the core order."""
    pts = np.array([[float(p.x), float(p.y), float(p.z)] for p in vectors], dtype=np.float64).reshape(-1, 3)
    names = list(skel.joint_names)
    if names:
        if len(names) != len(pts):
            raise InvalidInputError(f"Skeleton3D joint_names and {field} differ in length")
        index = {n: i for i, n in enumerate(names)}
        missing = [n for n in JOINT_NAMES if n not in index]
        if missing:
            raise InvalidInputError(f"Skeleton3D lacks joints {missing}")
        pts = pts[[index[n] for n in JOINT_NAMES]]
    if pts.shape != (N_JOINTS, 3):
        raise InvalidInputError(f"Skeleton3D must have {N_JOINTS} {field}, got {len(pts)}")
    return pts


def skeletons3d_array(header: Any, skeletons: Sequence[Any], types: Any) -> Any:
    """A ``Skeleton3DArray``."""
    return types.Skeleton3DArray(header=header, skeletons=list(skeletons))


# --------------------------------------------------------------------------- markers


def track_color(track_id: int) -> tuple[float, float, float]:
    """A stable, distinct RGB colour per track (golden-ratio hues); grey for untracked (< 0)."""
    if track_id < 0:
        return (0.7, 0.7, 0.7)
    hue = (0.12 + 0.618033988749895 * int(track_id)) % 1.0
    r, g, b = colorsys.hsv_to_rgb(hue, 0.85, 0.95)
    return (r, g, b)


def marker_id(track_id: int, position: int) -> int:
    """int32 marker id: the track id, or ``-1 - position`` for untracked skeletons."""
    if track_id >= 0:
        return int(track_id) % (2**31 - 1)
    return -1 - int(position)


def _duration(seconds: float, types: Any) -> Any:
    ns = max(0, round(float(seconds) * 1e9))
    sec, nsec = divmod(ns, 1_000_000_000)
    return types.Duration(sec=int(sec), nanosec=int(nsec))


def skeleton_markers(
    header: Any,
    tracks: Iterable[tuple[int, NDArray[np.float64]]],
    ns: str,
    lifetime: float,
    types: Any,
    deleted_track_ids: Iterable[int] = (),
    joint_diameter: float = 0.05,
    line_width: float = 0.02,
) -> Any:
    """``MarkerArray``: per track a SPHERE_LIST of joints (namespace ``{ns}/joints``) and a
    LINE_LIST of bones (``{ns}/bones``, :data:`BONES_FOR_DRAWING`), both with id = track id
    (untracked skeletons get ids -1, -2, ... by position), coloured per track.

    Parameters
    ----------
    header : Header
        Frame of the joints (camera optical frame) and stamp.
    tracks : iterable of (track_id, joints)
        ``joints``: a skeleton's metric joints (12, 3) (:func:`joint_points`).
    ns : str
        Marker namespace prefix.
    lifetime : float
        Seconds (0 = forever).
    types : namespace of message factories
    deleted_track_ids : iterable of int
        Tracks that vanished: DELETE markers for them are appended.
    """
    markers: list[Any] = []
    untracked = 0
    for track_id, joints in tracks:
        pts = joint_points(joints, types)
        mid = marker_id(int(track_id), untracked)
        if track_id < 0:
            untracked += 1
        r, g, b = track_color(int(track_id))
        common = {
            "header": header, "id": mid, "action": _ADD,
            "pose": types.Pose(orientation=types.Quaternion(x=0.0, y=0.0, z=0.0, w=1.0)),
            "color": types.ColorRGBA(r=float(r), g=float(g), b=float(b), a=1.0),
            "lifetime": _duration(lifetime, types), "frame_locked": False,
        }
        markers.append(types.Marker(
            ns=f"{ns}/joints", type=_SPHERE_LIST, points=list(pts),
            scale=types.Vector3(x=joint_diameter, y=joint_diameter, z=joint_diameter), **common,
        ))
        markers.append(types.Marker(
            ns=f"{ns}/bones", type=_LINE_LIST, points=[pts[j] for bone in BONES_FOR_DRAWING for j in bone],
            scale=types.Vector3(x=line_width, y=0.0, z=0.0), **common,
        ))
    markers.extend(delete_markers(header, deleted_track_ids, ns, types))
    return types.MarkerArray(markers=markers)


def delete_markers(header: Any, track_ids: Iterable[int], ns: str, types: Any) -> list[Any]:
    """DELETE markers (joints and bones) for tracks that vanished."""
    out: list[Any] = []
    for track_id in track_ids:
        if track_id < 0:
            continue
        for kind in ("joints", "bones"):
            out.append(types.Marker(header=header, ns=f"{ns}/{kind}", id=marker_id(int(track_id), 0),
                                    action=_DELETE))
    return out


def delete_untracked_markers(header: Any, positions: Iterable[int], ns: str, types: Any) -> list[Any]:
    """DELETE markers (joints and bones) for untracked skeletons' positions no longer used (their
    ids are ``-1 - position``, :func:`marker_id`)."""
    return [types.Marker(header=header, ns=f"{ns}/{kind}", id=marker_id(-1, position), action=_DELETE)
            for position in positions for kind in ("joints", "bones")]


def delete_all_markers(header: Any, ns: str, types: Any) -> list[Any]:
    """DELETEALL markers for our namespaces (joints and bones): clears what an earlier run of the
    node left on screen (markers with lifetime 0 outlive the node)."""
    return [types.Marker(header=header, ns=f"{ns}/{kind}", id=0, action=_DELETEALL)
            for kind in ("joints", "bones")]


# --------------------------------------------------------------------------- camera info


def camera_info(
    header: Any, width: int, height: int, fx: float, fy: float, cx: float, cy: float, types: Any
) -> Any:
    """A distortion-free pinhole ``sensor_msgs/CameraInfo``."""
    k = np.array([fx, 0.0, cx, 0.0, fy, cy, 0.0, 0.0, 1.0], dtype=np.float64)
    p = np.array([fx, 0.0, cx, 0.0, 0.0, fy, cy, 0.0, 0.0, 0.0, 1.0, 0.0], dtype=np.float64)
    return types.CameraInfo(
        header=header, height=int(height), width=int(width), distortion_model="plumb_bob",
        d=np.zeros(5, dtype=np.float64), k=k, r=np.eye(3, dtype=np.float64).reshape(9), p=p,
    )


def intrinsics_from_camera_info(msg: Any) -> tuple[tuple[float, float], tuple[float, float]]:
    """``((fx, fy), (cx, cy))`` from a ``CameraInfo`` (reads ``msg.k`` like image_geometry)."""
    k = np.asarray(msg.k, dtype=np.float64).reshape(-1)
    if k.shape != (9,) or not np.all(np.isfinite(k)) or k[0] <= 0 or k[4] <= 0:
        raise InvalidInputError("CameraInfo.k must be a finite 3x3 matrix with positive focal lengths")
    return (float(k[0]), float(k[4])), (float(k[2]), float(k[5]))
