"""The one placement of lifted people in the camera frame, with or without a depth image.

:func:`place_people` places the ``n`` lifts of one camera: with a registered depth image (or the
readings an earlier placement of the same frame took of it), fused with it
(:func:`~pose_lifter.core.depth.fuse.read_and_fuse`, :func:`~pose_lifter.core.depth.fuse.fuse_readings`);
without, at the distance their image scale gives for the assumed leg length
(:func:`~pose_lifter.core.track.placement.place_results`). Either way each joint gets its standard
deviation (:func:`~pose_lifter.core.depth.uncertainty.monocular_std` without depth), scaled by
what its fit's 2D residual says of it (:func:`~pose_lifter.core.depth.uncertainty.residual_factor`).
The node, the lagged node and the offline lift place with it, and place a pose refined over later
frames again with the readings of its own frame.
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np
from numpy.typing import NDArray

from pose_lifter.core.depth.fuse import DepthReadings, fuse_readings, read_and_fuse
from pose_lifter.core.depth.reading import DepthArray
from pose_lifter.core.depth.uncertainty import fit_residual, monocular_std
from pose_lifter.core.results import LiftResult
from pose_lifter.core.track.placement import CameraIntrinsics, place_results

__all__ = ["Placed", "place_people"]


@dataclass(frozen=True)
class Placed:
    """``n`` people placed in the camera frame.

    Attributes
    ----------
    joints_m : ndarray, shape (n, 12, 3)
        Metres, camera optical frame.
    std_m : ndarray, shape (n, 12, 3)
        Each joint's standard deviation along x, y, z, metres.
    readings : DepthReadings or None
        The depth readings the placement used ((n, 12) arrays), None without depth.
    from_depth : ndarray of bool, shape (n, 12), or None
        The joints whose depth reading was kept (None without depth).
    """

    joints_m: NDArray[np.float64]
    std_m: NDArray[np.float64]
    readings: DepthReadings | None
    from_depth: NDArray[np.bool_] | None = None


def place_people(results: Sequence[LiftResult], points: NDArray[np.float64],
                 intrinsics: CameraIntrinsics | None, leg_length_m: float, default_distance_m: float, *,
                 poses: NDArray[np.float64] | None = None,
                 depth: DepthArray | None = None, readings: DepthReadings | None = None) -> Placed:
    """The ``n`` lifts ``results`` of one camera placed (module docstring).

    Parameters
    ----------
    results : sequence of LiftResult
        Their camera scale and translation, and the joints' weights in the fit (``weights``: a
        joint with weight 0, missing or dropped as an outlier, is not read from depth).
    points : ndarray, shape (n, 12, 2)
        The 2D the lifts read, labelled as their joints (pixels).
    intrinsics : ((fx, fy), (cx, cy)) or None
        None: the monocular placement at ``default_distance_m``, whatever the depth.
    leg_length_m, default_distance_m : float
        The monocular placement's (:func:`~pose_lifter.core.track.placement.place_poses`).
    poses : ndarray, shape (n, 12, 3), optional
        The poses to place (camera frame, centred, leg units); default each result's
        ``pose_camera``.
    depth : ndarray of float32 or uint16, shape (H, W), optional
        The frame's registered depth image (metres, NaN where no reading; or millimetres, 0 where
        none: :data:`~pose_lifter.core.depth.reading.DepthArray`).
    readings : DepthReadings, optional
        The readings of an earlier placement of the same frame and people (instead of ``depth``).

    Returns
    -------
    Placed

    Raises
    ------
    InvalidInputError
        As the monocular placement (a camera scale not > 0) or the fusion (a depth image not 2-D).
    """
    pose = (np.array([r.pose_camera for r in results], dtype=np.float64) if poses is None
            else np.asarray(poses, dtype=np.float64))
    weights = np.array([r.weights for r in results], dtype=np.float64)
    residuals = fit_residual(results)
    if intrinsics is None or (depth is None and readings is None):
        joints = place_results(pose, results, leg_length_m, intrinsics, default_distance_m)
        return Placed(joints, monocular_std(joints, (weights > 0).astype(np.float64), intrinsics,
                                            residual=residuals), None)
    scales = np.array([float(r.camera.scale) for r in results], dtype=np.float64)
    centres = np.array([r.camera.translation for r in results], dtype=np.float64).reshape(-1, 2)
    args = (intrinsics, np.asarray(points, dtype=np.float64), weights, pose, scales, centres)
    if readings is None:
        assert depth is not None
        readings, fused = read_and_fuse(depth, *args, residuals=residuals)
    else:
        fused = fuse_readings(readings, *args, residuals=residuals)
    return Placed(fused.joints_m, fused.std_m, readings, fused.from_depth)
