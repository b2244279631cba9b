"""Per-joint uncertainty of a placed lift: the standard deviation of each joint along x, y, z.

A placed monocular lift errs two ways. Its shape: each joint's position relative to the body,
a few centimetres across the image and more along the depth (the depths come from the limbs'
foreshortening), more for a joint the 2D did not show (:data:`SHAPE_STD_M`,
:data:`UNOBSERVED_FACTOR`). Its place: the body's distance comes from an assumed leg length, so the
whole body slides along the rays by a relative error (:data:`MONOCULAR_SCALE_STD`), which moves a
joint by that fraction of its own position. Both grow when the 2D shows less of the body
(:data:`OBSERVED_BINS`, :data:`SHAPE_FACTOR`): a person close to the camera, cut by the image's
border, is lifted from a part of the body. The two are independent; :func:`body_std` adds them.
The depth fusion shrinks the second (the distance is read) and, where a joint is read, the first
(:func:`pose_lifter.core.depth.fuse.fuse_depth`). The constants are measured on the training
split's trials the packaged prior was not fitted on, at 1.5, 3 and 5 m (``make depth-calibration``,
:mod:`pose_lifter.mocap.depth_calibration`: each the 68th percentile of its error's absolute
value, a Gaussian's standard deviation).
"""

from __future__ import annotations

from typing import TYPE_CHECKING, Final

import numpy as np
from numpy.typing import NDArray

if TYPE_CHECKING:
    from pose_lifter.core.track.placement import CameraIntrinsics

__all__ = ["LAGGED_STD_FACTOR", "MONOCULAR_SCALE_STD", "OBSERVED_BINS", "SHAPE_CORR_Z", "SHAPE_FACTOR",
           "SHAPE_STD_M", "SMOOTHED_STD_FACTOR", "UNINFORMED_SCALE_STD", "UNOBSERVED_FACTOR", "body_std",
           "monocular_scale_std", "monocular_std", "observed_bin", "shape_std"]

#: Standard deviation of an observed joint's position relative to the body, metres, per joint
#: (order of :data:`pose_lifter.core.model.skeleton.JOINT_NAMES`), of a body the 2D shows whole:
#: columns across the image (x and y) and along the depth (z).
SHAPE_STD_M: Final[NDArray[np.float64]] = np.array(
    [[0.018, 0.057], [0.020, 0.056], [0.021, 0.071], [0.018, 0.057], [0.020, 0.056], [0.021, 0.071],
     [0.019, 0.028], [0.023, 0.059], [0.030, 0.105], [0.019, 0.028], [0.023, 0.059], [0.030, 0.105]])
#: Correlation between the joints (order of :data:`pose_lifter.core.model.skeleton.JOINT_NAMES`) of
#: the shape's errors along the depth: a limb leaning wrongly takes its elbow and wrist along, both
#: shoulders move together, and an arm placed too near leaves the legs too far once the body's
#: distance is right. The fusion carries a reading's correction to the joints the depth does not
#: read through it (:func:`pose_lifter.core.depth.fuse.fuse_readings`).
SHAPE_CORR_Z: Final[NDArray[np.float64]] = np.array([
    [1.00, 0.56, 0.27, 0.83, 0.33, 0.09, 0.05, -0.42, -0.56, -0.07, -0.46, -0.55],
    [0.56, 1.00, 0.73, 0.33, 0.23, 0.00, -0.22, -0.48, -0.47, -0.37, -0.49, -0.39],
    [0.27, 0.73, 1.00, 0.09, 0.00, -0.04, -0.32, -0.34, -0.33, -0.45, -0.37, -0.28],
    [0.83, 0.33, 0.09, 1.00, 0.56, 0.27, -0.07, -0.46, -0.55, 0.05, -0.42, -0.56],
    [0.33, 0.23, 0.00, 0.56, 1.00, 0.73, -0.37, -0.49, -0.39, -0.22, -0.48, -0.47],
    [0.09, 0.00, -0.04, 0.27, 0.73, 1.00, -0.45, -0.37, -0.28, -0.32, -0.34, -0.33],
    [0.05, -0.22, -0.32, -0.07, -0.37, -0.45, 1.00, 0.30, 0.07, 0.81, 0.16, 0.00],
    [-0.42, -0.48, -0.34, -0.46, -0.49, -0.37, 0.30, 1.00, 0.72, 0.16, 0.08, -0.03],
    [-0.56, -0.47, -0.33, -0.55, -0.39, -0.28, 0.07, 0.72, 1.00, 0.00, -0.03, 0.01],
    [-0.07, -0.37, -0.45, 0.05, -0.22, -0.32, 0.81, 0.16, 0.00, 1.00, 0.30, 0.07],
    [-0.46, -0.49, -0.37, -0.42, -0.48, -0.34, 0.16, 0.08, -0.03, 0.30, 1.00, 0.72],
    [-0.55, -0.39, -0.28, -0.56, -0.47, -0.33, 0.00, -0.03, 0.01, 0.07, 0.72, 1.00],
])
#: The bins of a body by how many of its 12 joints the 2D shows (each the least count of its bin):
#: a body cut by the image's border (a person close to the camera) or hidden in part is lifted
#: and placed worse.
OBSERVED_BINS: Final[tuple[int, ...]] = (12, 10, 8, 0)
#: Per bin of :data:`OBSERVED_BINS`: the shape's spread relative to :data:`SHAPE_STD_M`.
SHAPE_FACTOR: Final[NDArray[np.float64]] = np.array([1.000, 1.076, 1.303, 1.476])
#: Per bin of :data:`OBSERVED_BINS`: relative standard deviation of a monocular placement's
#: distance (the leg length assumed, the image scale measured): the body's position along the rays.
MONOCULAR_SCALE_STD: Final[NDArray[np.float64]] = np.array([0.055, 0.059, 0.117, 0.147])
#: Per bin of :data:`OBSERVED_BINS`: how much less certain a joint the 2D did not show (weight
#: below the threshold) is than the bin's shown joints, along x, y and z (a joint outside the image
#: is where the lift guesses it, across the image too: most along the image's vertical, where an
#: upright body leaves it).
UNOBSERVED_FACTOR: Final[NDArray[np.float64]] = np.array(
    [[1.00, 1.00, 1.00], [1.42, 1.45, 1.11], [2.12, 2.32, 1.25], [2.28, 2.47, 1.22]])
#: The scale of a track's fused joints' standard deviations averaged over ``pose-lifter lift``'s
#: window (:func:`pose_lifter.core.depth.smooth.smooth_fused`): the window averages the frames'
#: reading errors, so the smoothed joints err less than each frame's own deviations say.
SMOOTHED_STD_FACTOR: Final[float] = 0.920
#: The same of the lagged node's window (:func:`pose_lifter.core.depth.smooth.smooth_fused_at`:
#: the frames before a frame refined, those its lag holds after it as lifted).
LAGGED_STD_FACTOR: Final[float] = 0.871
#: The same without camera intrinsics (the body put at a default distance): nothing is known.
UNINFORMED_SCALE_STD: Final[float] = 0.5


def observed_bin(observed: NDArray[np.bool_]) -> NDArray[np.intp]:
    """The bin (n,) of :data:`OBSERVED_BINS` of each of ``n`` bodies whose 2D showed the joints
    ``observed`` (n, 12)."""
    count = np.asarray(observed).sum(axis=1)
    return np.asarray(np.searchsorted(-np.array(OBSERVED_BINS), -count, side="left"), dtype=np.intp)


def monocular_scale_std(observed: NDArray[np.bool_]) -> NDArray[np.float64]:
    """The monocular placement's relative scale uncertainty (n,) of ``n`` bodies
    (:data:`MONOCULAR_SCALE_STD` of their :func:`observed_bin`)."""
    return np.asarray(MONOCULAR_SCALE_STD[observed_bin(observed)])


def shape_std(observed: NDArray[np.bool_]) -> NDArray[np.float64]:
    """The shape's standard deviations (n, 12, 3; metres) of ``n`` bodies whose 2D showed the
    joints ``observed`` (n, 12): :data:`SHAPE_STD_M` (x and y across, z along the depth) times the
    body's :data:`SHAPE_FACTOR`, and times :data:`UNOBSERVED_FACTOR` where not observed."""
    seen = np.asarray(observed)
    b = observed_bin(seen)
    hidden = UNOBSERVED_FACTOR[b][:, None, :]  # (n, 1, 3)
    factor = np.where(seen[:, :, None], 1.0, hidden) * SHAPE_FACTOR[b][:, None, None]
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
    return np.asarray(np.hypot(shape, root))  # finite wherever the joints are (no square overflows)


def monocular_std(joints_m: NDArray[np.float64], weights: NDArray[np.float64],
                  intrinsics: CameraIntrinsics | None, confidence_threshold: float = 0.1
                  ) -> NDArray[np.float64]:
    """Per-axis standard deviations (n, 12, 3; metres) of ``n`` monocular lifts placed by
    :func:`pose_lifter.core.track.placement.place_results` (:func:`body_std` with
    :func:`monocular_scale_std`, or :data:`UNINFORMED_SCALE_STD` without ``intrinsics``).

    Parameters
    ----------
    joints_m : ndarray, shape (n, 12, 3)
    weights : ndarray, shape (n, 12)
        The joints' 2D weights; observed where at least ``confidence_threshold``.
    intrinsics : ((fx, fy), (cx, cy)) or None
    confidence_threshold : float
    """
    x = np.asarray(joints_m, dtype=np.float64)
    observed = np.asarray(weights) >= confidence_threshold
    s = monocular_scale_std(observed) if intrinsics is not None else np.full(len(x), UNINFORMED_SCALE_STD)
    return body_std(x, observed, s)
