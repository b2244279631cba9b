"""The metric placement of a lifted pose in the camera optical frame, its defaults, and the 2D of a
pinhole camera corrected to the weak-perspective image the fit reads (:func:`perspective_corrected`).

A lifted pose is in units of its right lower leg; :func:`place_poses` (the people of a frame or
the frames of a track at once; :func:`place_results` of lifts, the node's and the offline lift's
placement) and :func:`place_in_camera` (one lift) make it metric with a
leg length and put its centroid at the depth the camera scale gives, or at a default distance
when no camera intrinsics are known. The node, the offline lift (both through
:mod:`pose_lifter.messages.frame`) and the CLI use these defaults; the CLI's parser reads them
without loading numpy or the solver (this module imports nothing until a pose is placed).
"""

from __future__ import annotations

import math
from typing import TYPE_CHECKING, Final

if TYPE_CHECKING:
    from collections.abc import Sequence

    import numpy as np
    from numpy.typing import NDArray

    from pose_lifter.core.results import LiftResult

__all__ = ["DEFAULT_DISTANCE_M", "DEFAULT_LEG_LENGTH_M", "LEG_LENGTH_RANGE_M", "CameraIntrinsics",
           "perspective_corrected", "perspective_corrected_rows", "place_at", "place_in_camera",
           "place_poses", "place_results", "placed_centroids", "ray_rotation", "ray_rotations",
           "result_centroids"]

#: Right lower leg (knee-ankle) in metres that makes lifted poses metric (CMU adults: 0.41-0.44).
DEFAULT_LEG_LENGTH_M: Final[float] = 0.43
#: Accepted leg lengths in metres (the node's ``lower_leg_length``, ``pose-lifter lift --lower-leg-length``).
LEG_LENGTH_RANGE_M: Final[tuple[float, float]] = (0.05, 2.0)
#: Depth of the pose centroid in metres when no CameraInfo is available.
DEFAULT_DISTANCE_M: Final[float] = 5.0


#: A pinhole camera's ``((fx, fy), (cx, cy))`` in pixels (its ``camera_info``).
CameraIntrinsics = tuple[tuple[float, float], tuple[float, float]]


def perspective_corrected(points: NDArray[np.float64], intrinsics: CameraIntrinsics,
                          depths: NDArray[np.float64], scale: float, centre: NDArray[np.float64]
                          ) -> NDArray[np.float64]:
    """The 2D (12, 2, pixels) a weak-perspective camera looking at the person would see of a person
    the pinhole camera ``intrinsics`` ``((fx, fy), (cx, cy))`` filmed as ``points``:
    ``m + (x_j - m) Z_j / Z_0`` about the person's image centre ``m`` (``centre``, (2,)), with
    ``Z_j / Z_0 = 1 + z_j s / f`` the depth of joint ``j`` over the centroid's, from the person's
    depths ``depths`` (12,; centred camera frame, leg units: the track's last pose) and the
    weak-perspective ``scale`` ``s`` (pixels per leg unit; ``Z_0 = f L / s`` for a leg of ``L``
    metres, so ``L`` cancels). Exact for a pinhole camera and a person on the optical axis when the
    depths are right; a person off the axis is seen along its own ray, which the placement turns
    into the camera frame (:func:`pose_lifter.core.track.placement.place_in_camera`): correcting about
    the principal point instead would move each joint by the depths' error times its distance from
    the axis (docs/accuracy.md)."""
    import numpy as np

    (fx, fy), _ = intrinsics
    out = perspective_corrected_rows(np.asarray(points, dtype=np.float64)[None],
                                     np.array([0.5 * (float(fx) + float(fy))]),
                                     np.asarray(depths, dtype=np.float64)[None], np.array([float(scale)]),
                                     np.asarray(centre, dtype=np.float64)[None])
    return np.asarray(out[0])


def perspective_corrected_rows(points: NDArray[np.float64], focal: NDArray[np.float64],
                               depths: NDArray[np.float64], scale: NDArray[np.float64],
                               centre: NDArray[np.float64]) -> NDArray[np.float64]:
    """:func:`perspective_corrected` of n people at once, as arrays (elementwise: each row what
    it gives alone): their 2D ``points`` (n, 12, 2), each camera's mean focal length ``focal``
    (n,; pixels), the last poses' ``depths`` (n, 12), ``scale`` (n,) and image ``centre`` (n, 2).
    A row whose correction is not finite or would shrink a joint's depth below a fifth of the
    centroid's keeps its 2D."""
    import numpy as np

    x = np.array(points, dtype=np.float64)
    ratio = 1.0 + depths * scale[:, None] / focal[:, None]
    m = centre[:, None, :]
    ok = np.isfinite(ratio).all(axis=1) & (ratio > 0.2).all(axis=1) & np.isfinite(centre).all(axis=1)
    x[ok] = (m + (x - m) * ratio[:, :, None])[ok]
    return x


def place_in_camera(
    result: LiftResult,
    leg_length_m: float,
    focal: tuple[float, float] | None,
    principal_point: tuple[float, float] | None,
    default_distance_m: float,
) -> NDArray[np.float64]:
    """Metric 3D joints (12, 3) of one lift in the camera optical frame (x right, y down, z
    forward): :func:`place_poses` of ``result.pose_camera``, ``result.camera.scale`` and
    ``result.camera.translation``."""
    import numpy as np

    cam = result.camera
    placed = place_poses(np.asarray(result.pose_camera, dtype=np.float64)[None],
                         np.array([float(cam.scale)]),
                         np.asarray(cam.translation, dtype=np.float64).reshape(1, 2),
                         leg_length_m, focal, principal_point, default_distance_m)
    return np.asarray(placed[0], dtype=np.float64)


def place_results(
    poses: NDArray[np.float64],
    results: Sequence[LiftResult],
    leg_length_m: float,
    intrinsics: CameraIntrinsics | None,
    default_distance_m: float,
) -> NDArray[np.float64]:
    """Metric 3D joints (n, 12, 3) of ``n`` lifts seen by one camera (``intrinsics``; None: at the
    default distance): :func:`place_poses` of ``poses`` (n, 12, 3; each lift's ``pose_camera``,
    or a refinement of it) with each lift's camera scale and translation. The one placement of
    the node, the lagged node and the offline lift."""
    focal, centre = intrinsics if intrinsics is not None else (None, None)
    return place_poses(poses, *_cameras(results), leg_length_m, focal, centre, default_distance_m)


def result_centroids(results: Sequence[LiftResult], leg_length_m: float, intrinsics: CameraIntrinsics | None,
                     default_distance_m: float) -> NDArray[np.float64]:
    """The centroids (n, 3; metres) :func:`place_results` puts ``n`` lifts of one camera at, for
    any pose (:func:`placed_centroids` of their cameras); raises as it does."""
    focal, centre = intrinsics if intrinsics is not None else (None, None)
    return placed_centroids(*_cameras(results), leg_length_m, focal, centre, default_distance_m)


def _cameras(results: Sequence[LiftResult]) -> tuple[NDArray[np.float64], NDArray[np.float64]]:
    """The camera scales (n,) and translations (n, 2) of ``n`` lifts."""
    import numpy as np

    return (np.array([float(r.camera.scale) for r in results], dtype=np.float64),
            np.array([r.camera.translation for r in results], dtype=np.float64).reshape(-1, 2))


def place_poses(
    pose_camera: NDArray[np.float64],
    scale: NDArray[np.float64],
    translation: NDArray[np.float64],
    leg_length_m: float,
    focal: tuple[float, float] | None,
    principal_point: tuple[float, float] | None,
    default_distance_m: float,
) -> NDArray[np.float64]:
    """Metric 3D joints of ``n`` lifts seen by one camera, in its optical frame (x right, y down,
    z forward), as arrays (the people of a frame, the frames of a track).

    A lifted pose is centred and in the bases' units (right lower leg about 1:
    :attr:`~pose_lifter.core.results.LiftResult.pose`); it becomes metric with
    ``leg_length_m``. The weak-perspective scale fixes the depth of the centroid when the
    focal length is known: ``Z = f * leg_length_m / scale`` (``f`` = mean of ``fx, fy``), and
    the image position of the centroid gives ``X = (t_x - c_x) Z / f_x``,
    ``Y = (t_y - c_y) Z / f_y``; the pose is then turned from the ray to its centroid into the
    camera frame (:func:`ray_rotation`: a weak-perspective camera sees a person off the optical
    axis along that ray). Without camera intrinsics the centroid is put at
    ``(0, 0, default_distance_m)`` (defaults: :data:`DEFAULT_LEG_LENGTH_M`,
    :data:`DEFAULT_DISTANCE_M`). The lifts are trusted to be finite (the core checks them); the
    node checks what it publishes once, after this.

    Parameters
    ----------
    pose_camera : ndarray, shape (n, 12, 3)
        Each pose in the camera frame, centred on its joints' mean (as the core returns it: the
        centroid is placed, not recomputed), leg units.
    scale : ndarray, shape (n,)
        Each camera's scale, pixels per leg unit.
    translation : ndarray, shape (n, 2)
        The image position of each pose's centroid (pixels).
    leg_length_m : float
        Length of the right lower leg in metres (> 0).
    focal : (fx, fy) or None
        Pixels.
    principal_point : (cx, cy) or None
        Pixels; None with a focal length puts the centroid on the optical axis.
    default_distance_m : float
        Centroid depth when ``focal`` is None (> 0).

    Returns
    -------
    ndarray, shape (n, 12, 3)
        Metres.

    Raises
    ------
    InvalidInputError
        A length, focal length or (with a focal length) a camera scale is not finite and > 0, or
        the shapes disagree.
    """
    import numpy as np

    from pose_lifter.core.errors import InvalidInputError
    from pose_lifter.core.model.skeleton import N_JOINTS

    if not math.isfinite(leg_length_m) or leg_length_m <= 0:
        raise InvalidInputError(f"leg_length_m must be > 0, got {leg_length_m!r}")
    pose = np.asarray(pose_camera, dtype=np.float64)
    if pose.shape != (len(pose), N_JOINTS, 3):
        raise InvalidInputError(f"pose_camera must be an (n, {N_JOINTS}, 3) array")
    centroid = placed_centroids(scale, translation, leg_length_m, focal, principal_point, default_distance_m)
    if len(centroid) != len(pose):
        raise InvalidInputError(f"{len(centroid)} camera scales for {len(pose)} poses")
    rotation = ray_rotations(centroid) if focal is not None and principal_point is not None else None
    return place_at(pose, leg_length_m, centroid, rotation)  # pose_camera is centred on the joints' mean


def placed_centroids(scale: NDArray[np.float64], translation: NDArray[np.float64], leg_length_m: float,
                     focal: tuple[float, float] | None, principal_point: tuple[float, float] | None,
                     default_distance_m: float) -> NDArray[np.float64]:
    """The centroids (n, 3; metres) :func:`place_poses` puts ``n`` poses at, from their cameras'
    ``scale`` (n,) and ``translation`` (n, 2) (see there); raises as it does."""
    import numpy as np

    from pose_lifter.core.errors import InvalidInputError

    s = np.asarray(scale, dtype=np.float64).reshape(-1)
    n = len(s)
    centroid = np.zeros((n, 3))
    if focal is None:  # at (0, 0, default_distance_m)
        if not math.isfinite(default_distance_m) or default_distance_m <= 0:
            raise InvalidInputError(f"default_distance_m must be > 0, got {default_distance_m!r}")
        centroid[:, 2] = float(default_distance_m)
        return centroid
    fx, fy = (float(focal[0]), float(focal[1]))
    if not (fx > 0 and fy > 0 and math.isfinite(fx) and math.isfinite(fy)):
        raise InvalidInputError(f"focal lengths must be > 0, got {focal!r}")
    bad = ~(np.isfinite(s) & (s > 0))
    if bad.any():
        raise InvalidInputError(f"camera scale must be > 0, got {float(s[np.argmax(bad)])!r}")
    centroid[:, 2] = 0.5 * (fx + fy) * float(leg_length_m) / s  # at the depth of the scale
    if principal_point is None:  # on the optical axis
        return centroid
    t = np.asarray(translation, dtype=np.float64).reshape(n, 2)  # on the ray to the translation
    centroid[:, 0] = (t[:, 0] - float(principal_point[0])) * centroid[:, 2] / fx
    centroid[:, 1] = (t[:, 1] - float(principal_point[1])) * centroid[:, 2] / fy
    return centroid


def place_at(poses: NDArray[np.float64], leg_m: float | NDArray[np.float64], centroids: NDArray[np.float64],
             rotations: NDArray[np.float64] | None) -> NDArray[np.float64]:
    """The last step of :func:`place_poses`: ``n`` poses (n, 12, 3; camera frame, centred, leg
    units) in metres, ``leg_m * pose @ rotation.T + centroid``, with the legs ``leg_m`` (metres,
    one or (n,)), the ``centroids`` (n, 3) and the rays' ``rotations`` (n, 3, 3; None: none).
    The centroid and the rotation follow from a lift's camera, not from its pose, so a
    refinement of a pose is placed as the lift was."""
    import numpy as np

    local = poses * np.reshape(np.asarray(leg_m, dtype=np.float64), (-1, 1, 1))
    if rotations is None:
        return np.asarray(local + centroids[:, None, :])
    return np.asarray(local @ rotations.transpose(0, 2, 1) + centroids[:, None, :])


def ray_rotation(point: NDArray[np.float64]) -> NDArray[np.float64]:
    """The smallest rotation (3, 3) taking the optical axis (0, 0, 1) onto the ray to ``point``
    (3,; camera frame, in front of the camera): Rodrigues' formula about ``(0, 0, 1) x d``."""
    import numpy as np

    return np.asarray(ray_rotations(np.asarray(point, dtype=np.float64).reshape(1, 3))[0], dtype=np.float64)


def ray_rotations(points: NDArray[np.float64]) -> NDArray[np.float64]:
    """:func:`ray_rotation` of each of ``points`` (n, 3): rotations (n, 3, 3)."""
    import numpy as np

    p = np.asarray(points, dtype=np.float64)
    d = p / np.sqrt((p * p).sum(axis=1))[:, None]
    s = np.sqrt(d[:, 0] ** 2 + d[:, 1] ** 2)  # |(0, 0, 1) x d|
    on_axis = s < 1e-12
    s_safe = np.where(on_axis, 1.0, s)
    kx_, ky_ = -d[:, 1] / s_safe, d[:, 0] / s_safe  # the unit axis (kx, ky, 0)
    k = np.zeros((len(p), 3, 3))  # its cross-product matrix
    k[:, 0, 2], k[:, 1, 2] = ky_, -kx_
    k[:, 2, 0], k[:, 2, 1] = -ky_, kx_
    out = np.eye(3) + s[:, None, None] * k + (1.0 - d[:, 2])[:, None, None] * (k @ k)
    out[on_axis] = np.eye(3)
    return np.asarray(out)
