"""Per-joint uncertainty of a placed lift: the standard deviation of each joint along x, y, z.

A placed monocular lift errs two ways. Its shape: each joint's position relative to the body,
a few centimetres across the image and more along the depth (the depths come from the limbs'
foreshortening), more for a joint the 2D did not show (:data:`SHAPE_STD_M`,
:data:`UNOBSERVED_FACTOR`). Its place: the body's distance comes from an assumed leg length, so the
whole body slides along the rays by a relative error (:data:`MONOCULAR_SCALE_STD`), which moves a
joint by that fraction of its own position. Both grow when the 2D shows less of the body
(:data:`OBSERVED_BINS`, :data:`SHAPE_FACTOR`): a person close to the camera, cut by the image's
border, is lifted from a part of the body. The two are independent; :func:`body_std` adds them.
Both also grow with the lift's own residual (:func:`fit_residual`, :func:`residual_factor`): a fit
that cannot reach its 2D (a motion the prior knows badly, a 2D it misread) errs more, one that
reaches it closely less. The slide grows as well with the body's lean out of the image plane
(:func:`spine_lean`, :func:`lean_factor`): seen from above or below, its distance errs more.
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

from pose_lifter.core.model.skeleton import HIPS, SHOULDERS

if TYPE_CHECKING:
    from collections.abc import Sequence

    from pose_lifter.core.results import LiftResult
    from pose_lifter.core.track.placement import CameraIntrinsics

__all__ = ["LAGGED_STD_FACTOR", "LEAN_SCALE_LINE", "MONOCULAR_SCALE_STD", "OBSERVED_BINS",
           "RESIDUAL_FACTOR_MIN", "RESIDUAL_SCALE_LINE", "RESIDUAL_SHAPE_LINE", "SHAPE_CORR_Z",
           "SHAPE_FACTOR", "SHAPE_STD_M", "SMOOTHED_STD_FACTOR", "UNINFORMED_SCALE_STD", "UNOBSERVED_FACTOR",
           "body_std", "fit_residual", "lean_factor", "monocular_scale_std", "monocular_std", "observed_bin",
           "residual_factor", "shape_std", "spine_lean"]

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
SMOOTHED_STD_FACTOR: Final[float] = 0.914
#: The same of the lagged node's window (:func:`pose_lifter.core.depth.smooth.smooth_fused_at`:
#: the frames before a frame refined, those its lag holds after it as lifted).
LAGGED_STD_FACTOR: Final[float] = 0.868
#: The same without camera intrinsics (the body put at a default distance): nothing is known.
UNINFORMED_SCALE_STD: Final[float] = 0.5
#: ``(a, b)``: a lift's shape deviations are scaled by ``a + b r``, ``r`` its fit's 2D residual
#: (:func:`fit_residual`, leg units): per decile of ``r`` the 68th percentile of the shape's errors
#: over its deviations, a line fitted through them, at the level that makes the errors over the
#: scaled deviations' 68th percentile 1 (:func:`pose_lifter.mocap.depth_calibration.residual_line`).
#: Unscaled, the errors' spread over the shape's deviations runs from 0.8 in the decile of least
#: residual (median r 0.035) to 1.8 in the decile of most (0.15), past 1 only above r ~0.07.
RESIDUAL_SHAPE_LINE: Final[tuple[float, float]] = (0.423, 9.01)
#: The same of the monocular placement's scale (its relative distance error,
#: :data:`MONOCULAR_SCALE_STD`): from 0.74 to 2.4 over the same deciles.
RESIDUAL_SCALE_LINE: Final[tuple[float, float]] = (0.082, 14.60)
#: ``(a, b)``: a monocular placement's scale deviation is also scaled by ``a + b lean``, ``lean`` the
#: placed body's spine's angle out of the image plane (:func:`spine_lean`, radians): a camera above
#: or below the person (or a person leaning towards or away from it) shows the legs foreshortened,
#: and the distance from their image length errs more. Measured as :data:`RESIDUAL_SCALE_LINE`,
#: per decile of the lean, on the scale's errors over their residual-scaled deviations: unscaled,
#: from 0.84 in the deciles of least lean (level views, median lean 0-5 degrees) to 1.1 in those of
#: most (views from 30 degrees above, 23-42 degrees).
LEAN_SCALE_LINE: Final[tuple[float, float]] = (0.880, 0.404)
#: The least scale :func:`residual_factor` and :func:`lean_factor` give (a fit that meets its 2D
#: exactly still errs).
RESIDUAL_FACTOR_MIN: Final[float] = 0.5


def fit_residual(results: Sequence[LiftResult]) -> NDArray[np.float64]:
    """Each lift's 2D residual (n,): its mean reprojection error over its camera's scale (the
    body's image size), in leg units; NaN for a lift without the learned prior's pose (the paper
    mode fits its 2D closely whatever its error: its residual says nothing of it)."""
    return np.array([r.reprojection_error / r.camera.scale if r.prior_pose is not None and r.camera.scale > 0
                     else np.nan for r in results], dtype=np.float64)


def residual_factor(residual: NDArray[np.float64] | None, line: tuple[float, float]
                    ) -> NDArray[np.float64] | float:
    """The scale (n,) of a deviation of lifts whose fits left ``residual`` (n,; :func:`fit_residual`)
    along ``line`` (:data:`RESIDUAL_SHAPE_LINE`, :data:`RESIDUAL_SCALE_LINE`):
    ``max(a + b r, RESIDUAL_FACTOR_MIN)``; 1 where ``r`` is not finite, and 1.0 for ``residual``
    None."""
    if residual is None:
        return 1.0
    r = np.asarray(residual, dtype=np.float64)
    known = np.isfinite(r)
    a, b = line
    return np.where(known, np.maximum(a + b * np.where(known, r, 0.0), RESIDUAL_FACTOR_MIN), 1.0)


def spine_lean(joints_m: NDArray[np.float64]) -> NDArray[np.float64]:
    """The angle (n,; radians, 0 to pi/2) of each of ``n`` bodies' spines (``joints_m`` (n, 12, 3),
    camera optical frame: the hips' centre to the shoulders' centre) out of the image plane: 0 for
    an upright body seen level, ~0.5 seen from 30 degrees above; NaN for a degenerate spine."""
    x = np.asarray(joints_m, dtype=np.float64)
    spine = x[:, list(SHOULDERS)].mean(axis=1) - x[:, list(HIPS)].mean(axis=1)
    norm = np.linalg.norm(spine, axis=1)
    ok = np.isfinite(norm) & (norm > 0)
    sine = np.abs(spine[:, 2]) / np.where(ok, norm, 1.0)
    return np.where(ok, np.arcsin(np.clip(sine, 0.0, 1.0)), np.nan)


def lean_factor(joints_m: NDArray[np.float64]) -> NDArray[np.float64]:
    """The scale (n,) of ``n`` monocular placements' scale deviations (joints (n, 12, 3)) along
    :data:`LEAN_SCALE_LINE` of their :func:`spine_lean`, at least :data:`RESIDUAL_FACTOR_MIN`; 1
    where the lean is unknown (a degenerate spine)."""
    return np.asarray(residual_factor(spine_lean(joints_m), LEAN_SCALE_LINE))


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


def body_std(joints_m: NDArray[np.float64], observed: NDArray[np.bool_], scale_std: NDArray[np.float64],
             shape_factor: NDArray[np.float64] | float = 1.0) -> NDArray[np.float64]:
    """Per-axis standard deviations (n, 12, 3; metres) of ``n`` placed bodies.

    Parameters
    ----------
    joints_m : ndarray, shape (n, 12, 3)
        The joints, camera optical frame, metres.
    observed : ndarray of bool, shape (n, 12)
        The joints the 2D showed.
    scale_std : ndarray, shape (n,)
        Relative standard deviation of each body's distance (its scale about the camera centre).
    shape_factor : ndarray, shape (n,), or float
        Each body's scale of its shape's spread (:func:`residual_factor`).

    Returns
    -------
    ndarray, shape (n, 12, 3)
        ``sqrt(shape^2 + (scale_std * |x|)^2)`` per axis: the shape's spread
        (:data:`SHAPE_STD_M`, times :data:`UNOBSERVED_FACTOR` where not observed, times
        ``shape_factor``) and the body's slide along the rays.
    """
    x = np.asarray(joints_m, dtype=np.float64)
    shape = shape_std(observed) * np.reshape(np.asarray(shape_factor, dtype=np.float64), (-1, 1, 1))
    root = np.asarray(scale_std, dtype=np.float64)[:, None, None] * np.abs(x)
    return np.asarray(np.hypot(shape, root))  # finite wherever the joints are (no square overflows)


def monocular_std(joints_m: NDArray[np.float64], weights: NDArray[np.float64],
                  intrinsics: CameraIntrinsics | None, confidence_threshold: float = 0.1,
                  residual: NDArray[np.float64] | None = None) -> NDArray[np.float64]:
    """Per-axis standard deviations (n, 12, 3; metres) of ``n`` monocular lifts placed by
    :func:`pose_lifter.core.track.placement.place_results` (:func:`body_std` with
    :func:`monocular_scale_std`, or :data:`UNINFORMED_SCALE_STD` without ``intrinsics``), the
    shape's and the placement's scaled by the fits' :func:`residual_factor` (each its line), the
    placement's also by the body's :func:`lean_factor`.

    Parameters
    ----------
    joints_m : ndarray, shape (n, 12, 3)
    weights : ndarray, shape (n, 12)
        The joints' 2D weights; observed where at least ``confidence_threshold``.
    intrinsics : ((fx, fy), (cx, cy)) or None
    confidence_threshold : float
    residual : ndarray, shape (n,), optional
        Each fit's 2D residual (:func:`fit_residual`); None: unscaled.
    """
    x = np.asarray(joints_m, dtype=np.float64)
    observed = np.asarray(weights) >= confidence_threshold
    if intrinsics is None:
        s = np.full(len(x), UNINFORMED_SCALE_STD)
    else:
        s = monocular_scale_std(observed) * residual_factor(residual, RESIDUAL_SCALE_LINE) * lean_factor(x)
    return body_std(x, observed, s, residual_factor(residual, RESIDUAL_SHAPE_LINE))
