"""Per-joint uncertainty of a placed lift: the standard deviation of each joint along x, y, z.

A placed monocular lift errs two ways. Its shape: each joint's position relative to the body,
a few centimetres across the image and more along the depth (the depths come from the limbs'
foreshortening), more for a joint the 2D did not show (:data:`SHAPE_STD_M`,
:data:`UNOBSERVED_FACTOR`). Its place: the body's distance comes from an assumed leg length, so the
whole body slides along the rays by a relative error (:data:`MONOCULAR_SCALE_STD`), which moves a
joint by that fraction of its own position. The two are independent; :func:`body_std` adds them.
The depth fusion shrinks the second (the distance is read) and, where a joint is read, the first
(:func:`pose_lifter.core.depth.fuse.fuse_depth`). The constants are fitted on the training split
so that the per-axis 1-sigma and 2-sigma coverage is Gaussian (``tools/depth_calibration.py``).
"""

from __future__ import annotations

from typing import TYPE_CHECKING, Final

import numpy as np
from numpy.typing import NDArray

if TYPE_CHECKING:
    from pose_lifter.core.track.placement import CameraIntrinsics

__all__ = ["MONOCULAR_SCALE_STD", "SHAPE_STD_M", "UNINFORMED_SCALE_STD", "UNOBSERVED_FACTOR", "body_std",
           "monocular_std", "shape_std"]

#: Standard deviation of an observed joint's position relative to the body, metres, per joint
#: (order of :data:`pose_lifter.core.model.skeleton.JOINT_NAMES`): columns across the image (x
#: and y) and along the depth (z).
SHAPE_STD_M: Final[NDArray[np.float64]] = np.array(
    [[0.035, 0.06], [0.05, 0.09], [0.07, 0.12], [0.035, 0.06], [0.05, 0.09], [0.07, 0.12],
     [0.035, 0.06], [0.05, 0.08], [0.06, 0.10], [0.035, 0.06], [0.05, 0.08], [0.06, 0.10]])
#: A joint the 2D did not show (weight below the threshold) is this much less certain.
UNOBSERVED_FACTOR: Final[float] = 2.0
#: Relative standard deviation of a monocular placement's distance (the leg length assumed, the
#: image scale measured): the body's position along the rays.
MONOCULAR_SCALE_STD: Final[float] = 0.07
#: The same without camera intrinsics (the body put at a default distance): nothing is known.
UNINFORMED_SCALE_STD: Final[float] = 0.5


def shape_std(observed: NDArray[np.bool_]) -> NDArray[np.float64]:
    """The shape's standard deviations (n, 12, 3; metres) of ``n`` bodies whose 2D showed the
    joints ``observed`` (n, 12): :data:`SHAPE_STD_M` (x and y across, z along the depth), times
    :data:`UNOBSERVED_FACTOR` where not observed."""
    factor = np.where(np.asarray(observed), 1.0, UNOBSERVED_FACTOR)[:, :, None]
    return np.asarray(SHAPE_STD_M[:, [0, 0, 1]][None, :, :] * factor)


def body_std(joints_m: NDArray[np.float64], observed: NDArray[np.bool_], scale_std: NDArray[np.float64]
             ) -> NDArray[np.float64]:
    """Per-axis standard deviations (n, 12, 3; metres) of ``n`` placed bodies.

    Parameters
    ----------
    joints_m : ndarray, shape (n, 12, 3)
        The joints, camera optical frame, metres.
    observed : ndarray of bool, shape (n, 12)
        The joints the 2D showed.
    scale_std : ndarray, shape (n,)
        Relative standard deviation of each body's distance (its scale about the camera centre).

    Returns
    -------
    ndarray, shape (n, 12, 3)
        ``sqrt(shape^2 + (scale_std * |x|)^2)`` per axis: the shape's spread
        (:data:`SHAPE_STD_M`, times :data:`UNOBSERVED_FACTOR` where not observed) and the body's
        slide along the rays.
    """
    x = np.asarray(joints_m, dtype=np.float64)
    shape = shape_std(observed)
    root = np.asarray(scale_std, dtype=np.float64)[:, None, None] * np.abs(x)
    return np.asarray(np.sqrt(shape * shape + root * root))


def monocular_std(joints_m: NDArray[np.float64], weights: NDArray[np.float64],
                  intrinsics: CameraIntrinsics | None, confidence_threshold: float = 0.1
                  ) -> NDArray[np.float64]:
    """Per-axis standard deviations (n, 12, 3; metres) of ``n`` monocular lifts placed by
    :func:`pose_lifter.core.track.placement.place_results` (:func:`body_std` with
    :data:`MONOCULAR_SCALE_STD`, or :data:`UNINFORMED_SCALE_STD` without ``intrinsics``).

    Parameters
    ----------
    joints_m : ndarray, shape (n, 12, 3)
    weights : ndarray, shape (n, 12)
        The joints' 2D weights; observed where at least ``confidence_threshold``.
    intrinsics : ((fx, fy), (cx, cy)) or None
    confidence_threshold : float
    """
    x = np.asarray(joints_m, dtype=np.float64)
    s = MONOCULAR_SCALE_STD if intrinsics is not None else UNINFORMED_SCALE_STD
    return body_std(x, np.asarray(weights) >= confidence_threshold, np.full(len(x), s))
