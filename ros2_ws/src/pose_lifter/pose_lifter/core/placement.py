"""The metric placement of a lifted pose in the camera optical frame, and its defaults.

A lifted pose is in units of its right lower leg; :func:`place_in_camera` makes it metric with a
leg length and puts its centroid at the depth the camera scale gives, or at a default distance
when no camera intrinsics are known. The node, the offline lift (both through
:mod:`pose_lifter.messages.frame`) and the CLI use these defaults; the CLI's parser reads them
without loading numpy or the solver (this module imports nothing until a pose is placed).
"""

from __future__ import annotations

import math
from typing import TYPE_CHECKING, Final

if TYPE_CHECKING:
    import numpy as np
    from numpy.typing import NDArray

    from pose_lifter.core.results import LiftResult

__all__ = ["DEFAULT_DISTANCE_M", "DEFAULT_LEG_LENGTH_M", "LEG_LENGTH_RANGE_M", "place_in_camera",
           "ray_rotation"]

#: Right lower leg (knee-ankle) in metres that makes lifted poses metric (CMU adults: 0.41-0.44).
DEFAULT_LEG_LENGTH_M: Final[float] = 0.43
#: Accepted leg lengths in metres (the node's ``lower_leg_length`` and ``--leg-length``).
LEG_LENGTH_RANGE_M: Final[tuple[float, float]] = (0.05, 2.0)
#: Depth of the pose centroid in metres when no CameraInfo is available.
DEFAULT_DISTANCE_M: Final[float] = 5.0


def place_in_camera(
    result: LiftResult,
    leg_length_m: float,
    focal: tuple[float, float] | None,
    principal_point: tuple[float, float] | None,
    default_distance_m: float,
) -> NDArray[np.float64]:
    """Metric 3D joints in the camera optical frame (x right, y down, z forward).

    The lifted pose is centred and in right-lower-leg units; it becomes metric with
    ``leg_length_m``. The weak-perspective scale fixes the depth of the centroid when the
    focal length is known: ``Z = f * leg_length_m / scale`` (``f`` = mean of ``fx, fy``), and
    the image position of the centroid gives ``X = (t_x - c_x) Z / f_x``,
    ``Y = (t_y - c_y) Z / f_y``; the pose is then turned from the ray to its centroid into the
    camera frame (:func:`ray_rotation`: a weak-perspective camera sees a person off the optical
    axis along that ray). Without camera intrinsics the centroid is put at
    ``(0, 0, default_distance_m)`` (defaults: :data:`DEFAULT_LEG_LENGTH_M`,
    :data:`DEFAULT_DISTANCE_M`). The lift is trusted to be finite (the core checks it); the
    node checks what it publishes once, after this.

    Parameters
    ----------
    result : LiftResult
        ``pose_camera`` (12, 3) in the camera frame, centred on the joints' mean (as the core
        returns it: the centroid is placed, not recomputed); ``camera.scale`` in pixels per leg unit;
        ``camera.translation`` (2,) the image position of the pose centroid (pixels).
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
    ndarray, shape (12, 3)
        Metres.
    """
    import numpy as np

    from pose_lifter.core.errors import InvalidInputError
    from pose_lifter.core.skeleton import N_JOINTS

    if not math.isfinite(leg_length_m) or leg_length_m <= 0:
        raise InvalidInputError(f"leg_length_m must be > 0, got {leg_length_m!r}")
    pose = np.asarray(result.pose_camera, dtype=np.float64)
    if pose.shape != (N_JOINTS, 3):
        raise InvalidInputError(f"pose_camera must be a ({N_JOINTS}, 3) array")
    local = pose * float(leg_length_m)  # the core's pose_camera is centred on the joints' mean
    if focal is None:
        if not math.isfinite(default_distance_m) or default_distance_m <= 0:
            raise InvalidInputError(f"default_distance_m must be > 0, got {default_distance_m!r}")
        centroid = np.array([0.0, 0.0, float(default_distance_m)])
    else:
        fx, fy = (float(focal[0]), float(focal[1]))
        scale = float(result.camera.scale)
        if not (fx > 0 and fy > 0 and math.isfinite(fx) and math.isfinite(fy)):
            raise InvalidInputError(f"focal lengths must be > 0, got {focal!r}")
        if not math.isfinite(scale) or scale <= 0:
            raise InvalidInputError(f"camera scale must be > 0, got {scale!r}")
        z = 0.5 * (fx + fy) * float(leg_length_m) / scale
        t = np.asarray(result.camera.translation, dtype=np.float64)
        if principal_point is None:
            x = y = 0.0
        else:
            x = (float(t[0]) - float(principal_point[0])) * z / fx
            y = (float(t[1]) - float(principal_point[1])) * z / fy
        centroid = np.array([x, y, z])
        if principal_point is not None:
            local = local @ ray_rotation(centroid).T
    return np.asarray(local + centroid)


def ray_rotation(point: NDArray[np.float64]) -> NDArray[np.float64]:
    """The smallest rotation (3, 3) taking the optical axis (0, 0, 1) onto the ray to ``point``
    (3,; camera frame, in front of the camera): Rodrigues' formula about ``(0, 0, 1) x d``."""
    import numpy as np

    d = np.asarray(point, dtype=np.float64) / float(np.linalg.norm(point))
    axis = np.array([-d[1], d[0], 0.0])
    s, c = float(np.linalg.norm(axis)), float(d[2])
    if s < 1e-12:
        return np.eye(3)
    k = axis / s
    kx = np.array([[0.0, -k[2], k[1]], [k[2], 0.0, -k[0]], [-k[1], k[0], 0.0]])
    return np.asarray(np.eye(3) + s * kx + (1.0 - c) * (kx @ kx))
