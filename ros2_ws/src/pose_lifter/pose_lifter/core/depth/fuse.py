"""Depth fused with the monocular lift: the body's metric place from the depth camera, each joint
from its depth reading where that reading is the joint's, and from the lifted shape where not.

The monocular lift fixes the body's shape and its image (the weak-perspective fit of the 2D); its
distance comes from an assumed leg length, a few per cent off, and its depths from the limbs'
foreshortening, often leaning the whole body towards or away from the camera. Moving a joint along
its ray keeps its image, so the depth is fitted as a field of three numbers along the rays: the
placed depths scaled (the body's size and distance together) and tilted across the image:

1. **Place** each body as the monocular lift does (:func:`~pose_lifter.core.track.placement.place_poses`,
   leg 0.43 m): joints ``X0`` (12, 3).
2. **Read** a patch of the depth image at each observed keypoint
   (:func:`~pose_lifter.core.depth.reading.read_patches`) and add the joint's surface offset:
   readings ``d_j`` with variances ``v_j``.
3. **Occlusion**: a reading at a joint that another body part hides on the image (a limb or a torso
   of the placed bodies, any person's, in front of it by a margin) is the occluder's, not the joint's.
4. **Depth field**: ``theta = (k, a, b)`` minimises
   ``sum_j rho((d_j - g_j . theta) / sigma_j) + (theta - (1, 0, 0))^T P (theta - (1, 0, 0)) / 2``,
   ``g_j = (z0_j, y_j, x_j)`` the joint's placed depth and its offsets across the image from the
   body's centroid (metres), ``rho`` Tukey's biweight (c = 4.685),
   ``sigma_j^2 = v_j + (k sigma_shape,j)^2`` (the reading's variance and the shape's error in depth),
   ``P`` the prior's precisions (on ``k`` the monocular placement's own scale error,
   :func:`~pose_lifter.core.depth.uncertainty.monocular_scale_std`, and on ``sigma_shape`` the
   shape's, both scaled by the lift's 2D residual,
   :func:`~pose_lifter.core.depth.uncertainty.residual_factor`; on ``a`` and ``b``
   :attr:`~pose_lifter.core.depth.reading.DepthOptions.tilt_std`), by iteratively reweighted least
   squares from ``k`` the median of ``d_j / z0_j``, until no parameter moves by more than ``tol`` or
   ``max_iter``. Readings beyond ``gate`` standard deviations of the field are dropped.
5. **Fuse**: the true depths are Gaussian about the field's, ``z ~ N(g . theta, S)``, ``S`` the
   shape's covariance (per joint :func:`~pose_lifter.core.depth.uncertainty.shape_std`, scaled per
   body by how far its readings sit from the field, :func:`shape_scale`; correlated between joints
   by :data:`~pose_lifter.core.depth.uncertainty.SHAPE_CORR_Z`) plus the field's
   (from the fit's covariance); each kept reading is ``d_j = z_j + e_j``, ``e_j ~ N(0, v_j / p_j)``,
   ``p_j`` the probability that the reading is the joint's (a Gaussian against a stray surface
   uniform over the depth band, :attr:`~pose_lifter.core.depth.reading.DepthOptions.outlier_share`:
   first about the field alone, then about what the other readings predict of the joint through
   ``S``, leaving the reading out; below 1/2 the reading is dropped: a wrist read 22 cm before an
   elbow read true is another surface, though within three of the field's own deviations). The
   depths are the conditional mean given the readings, their standard deviations the conditional
   ones where read and the marginal ones elsewhere (the correlations hold less on motion the prior
   never saw): a reading moves its own joint, and through the correlations the joints
   the depth does not read (an elbow read farther than the field takes its hidden wrist along).
   Each joint moves along its ray to its depth: the lift's image of the joint, which the prior has
   denoised, is kept (the 2D keypoint's own ray is noisier: on the training split it costs ~10 mm
   of P-MPJPE at 3 m). A body without a kept reading keeps the monocular placement and its
   uncertainty.

:func:`read_depth` takes steps 1-3 (it needs the image), :func:`fuse_readings` steps 4-5 (it needs
the readings only: a pose refined over later frames is fused with its frame's readings without
keeping the image); :func:`fuse_depth` both, and :func:`read_and_fuse` both with the readings.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Final

import numpy as np
from numpy.typing import NDArray

from pose_lifter.core.depth.kernels import (
    depth_fit_kernel,
    field_kernel,
    fuse_kernel,
    hidden_kernel,
    masked_median,
)
from pose_lifter.core.depth.reading import (
    LIMB_RADIUS_M,
    SURFACE_OFFSET_M,
    DepthArray,
    DepthOptions,
    joint_radius_px,
    read_people,
)
from pose_lifter.core.depth.uncertainty import (
    RESIDUAL_SCALE_LINE,
    RESIDUAL_SHAPE_LINE,
    SHAPE_CORR_Z,
    SHAPE_STD_M,
    body_std,
    lean_factor,
    monocular_scale_std,
    residual_factor,
    shape_std,
)
from pose_lifter.core.errors import InvalidInputError
from pose_lifter.core.model.skeleton import JOINT_NAMES, LIMBS, N_JOINTS, body_frame
from pose_lifter.core.track.placement import (
    DEFAULT_DISTANCE_M,
    DEFAULT_LEG_LENGTH_M,
    CameraIntrinsics,
    place_poses,
)

__all__ = ["SHAPE_SCALE_DOF", "DepthReadings", "FusedPeople", "compile_kernels", "fuse_depth",
           "fuse_readings", "read_and_fuse", "read_depth", "shape_scale"]

#: Radius of each limb of :data:`~pose_lifter.core.model.skeleton.LIMBS` as an occluder, metres.
_LIMB_RADIUS: Final[NDArray[np.float64]] = np.array(
    [0.5 * (LIMB_RADIUS_M[a] + LIMB_RADIUS_M[b]) for a, b in LIMBS])
#: The trunk as an occluder: an elliptic cylinder along the spine, from below the hips' midpoint to
#: above the shoulders', its half axes across the hips and front to back (an adult torso about
#: 0.33 m wide and 0.2 m deep: ANSUR 1988 chest breadth and depth), metres.
_TORSO_HALF_WIDTH: Final[float] = 0.165
_TORSO_HALF_DEPTH: Final[float] = 0.1
_TORSO_BELOW_HIPS: Final[float] = 0.06
_TORSO_ABOVE_SHOULDERS: Final[float] = 0.04
_L_SHOULDER, _R_SHOULDER, _L_HIP, _R_HIP = (JOINT_NAMES.index(f"{s}_{j}") for j in ("shoulder", "hip")
                                              for s in ("left", "right"))
#: The shape's depth errors per joint (the field fit's), and with the joints' correlations before
#: them (12, 13), as :func:`~pose_lifter.core.depth.kernels.fuse_kernel` takes them.
_SHAPE_Z: Final[NDArray[np.float64]] = np.ascontiguousarray(SHAPE_STD_M[:, 1])
_SHAPE_MODEL: Final[NDArray[np.float64]] = np.column_stack([SHAPE_CORR_Z, _SHAPE_Z])
#: The prior degrees of freedom of :func:`shape_scale`: a body read at as many joints has its
#: shape's deviations scaled half way to what its residuals say.
SHAPE_SCALE_DOF: Final[float] = 8.0
#: A joint without a reading enters the conditioning with this variance (m^2): no weight.
_UNREAD_VAR: Final[float] = 1e6
#: The least inlier probability by which a reading's variance is divided in the leave-one-out
#: predictions (a doubtful reading weighs little in the others' predictions, never nothing).
_MIN_INLIER: Final[float] = 0.05
#: The neck and the head as occluders, along the spine from the shoulders' midpoint (adult values,
#: metres): the neck a capsule to :data:`_NECK_LENGTH` of radius :data:`_NECK_RADIUS`, the head a
#: sphere of :data:`_HEAD_RADIUS` at :data:`_HEAD_ABOVE_SHOULDERS` (seen from above they cover the
#: shoulders' pixels; the 12 joints do not place them otherwise).
_NECK_LENGTH: Final[float] = 0.12
_NECK_RADIUS: Final[float] = 0.055
_HEAD_ABOVE_SHOULDERS: Final[float] = 0.25
_HEAD_RADIUS: Final[float] = 0.10
#: The occluders' segments: the limbs, then the neck and the head (a segment of zero length),
#: between the 12 joints and the three points :func:`_occluder_points` appends; their radii.
_LIMB_ARRAY: Final[NDArray[np.int64]] = np.array(
    [*LIMBS, (N_JOINTS, N_JOINTS + 1), (N_JOINTS + 2, N_JOINTS + 2)], dtype=np.int64)
_OCCLUDER_RADIUS: Final[NDArray[np.float64]] = np.concatenate([_LIMB_RADIUS, [_NECK_RADIUS, _HEAD_RADIUS]])


@dataclass(frozen=True)
class FusedPeople:
    """The people of one frame placed with a depth image.

    Attributes
    ----------
    joints_m : ndarray, shape (n, 12, 3)
        Metres, camera optical frame.
    std_m : ndarray, shape (n, 12, 3)
        Standard deviation of each joint along x, y, z, metres.
    from_depth : ndarray of bool, shape (n, 12)
        The joints whose depth reading was kept.
    leg_m : ndarray, shape (n,)
        The right lower leg's length the depth gives each body (0.43 m times its scale ``k``).
    converged : ndarray of bool, shape (n,)
        The depth fit met its stopping rule (a body with no reading: True, at the prior).
    n_iter : ndarray of int, shape (n,)
    objective : ndarray, shape (n,)
        The depth fit's objective at its end.
    """

    joints_m: NDArray[np.float64]
    std_m: NDArray[np.float64]
    from_depth: NDArray[np.bool_]
    leg_m: NDArray[np.float64]
    converged: NDArray[np.bool_]
    n_iter: NDArray[np.int64]
    objective: NDArray[np.float64]


def _trunks(joints: NDArray[np.float64]) -> tuple[NDArray[np.float64], NDArray[np.float64],
                                                  NDArray[np.float64]]:
    """Each body's trunk (``joints`` (n, 12, 3)): its axes (n, 3, 3) as rows (the body frame of
    :func:`~pose_lifter.core.model.skeleton.body_frame`: right hip to left hip, up the spine, the
    facing direction; the camera's axes for a body without one, whose trunk is then empty), the
    hips' midpoint in those axes (n, 3) and the trunk's ends along the spine from it (n, 2)."""
    hips = 0.5 * (joints[:, _L_HIP] + joints[:, _R_HIP])
    up = 0.5 * (joints[:, _L_SHOULDER] + joints[:, _R_SHOULDER]) - hips
    with np.errstate(invalid="ignore", divide="ignore"):
        axes = body_frame(joints)
    framed = np.asarray(np.isfinite(axes).all(axis=(1, 2)))
    axes = np.where(framed[:, None, None], axes, np.eye(3))
    extent = np.stack([np.full(len(hips), -_TORSO_BELOW_HIPS),
                       np.sum(up * axes[:, 1], axis=-1) + _TORSO_ABOVE_SHOULDERS], axis=-1)
    return axes, np.einsum("nij,nj->ni", axes, hips), extent


def _occluder_points(joints: NDArray[np.float64], up: NDArray[np.float64]) -> NDArray[np.float64]:
    """The 12 joints (n, 12, 3) and the ends of the neck and the head (:data:`_LIMB_ARRAY`) along
    each body's spine direction ``up`` (n, 3): (n, 15, 3)."""
    base = 0.5 * (joints[:, _L_SHOULDER] + joints[:, _R_SHOULDER])
    extra = base[:, None] + np.array([0.0, _NECK_LENGTH, _HEAD_ABOVE_SHOULDERS])[None, :, None] * up[:, None]
    return np.concatenate([joints, extra], axis=1)


def _hidden(joints: NDArray[np.float64], pixels: NDArray[np.float64], candidates: NDArray[np.bool_],
            intrinsics: CameraIntrinsics, margin: float) -> NDArray[np.bool_]:
    """Which ``candidates`` (n, 12) joints of the placed bodies ``joints`` (n, 12, 3) another body
    part hides at their keypoints ``pixels`` (n, 12, 2): a limb (a capsule of
    :data:`_LIMB_RADIUS`), the neck or the head (:data:`_NECK_LENGTH`) of any body, not one of the
    joint's own limbs, or a trunk (an elliptic cylinder, :data:`_TORSO_HALF_WIDTH`) of any body,
    the joint's own too (seen from the side it hides the far shoulder, hip and arm), whose surface
    on the joint's pixel is nearer than the joint's surface by more than ``margin`` metres."""
    (fx, fy), (cx, cy) = intrinsics
    axes, centre, extent = _trunks(joints)
    points = _occluder_points(joints, axes[:, 1])
    z = np.maximum(points[..., 2], 1e-3)
    proj = np.stack([fx * points[..., 0] / z + cx, fy * points[..., 1] / z + cy], axis=-1)
    hidden = np.zeros(candidates.shape, dtype=bool)
    hidden_kernel(np.ascontiguousarray(proj), np.ascontiguousarray(z), np.ascontiguousarray(candidates),
                  np.ascontiguousarray(pixels, dtype=np.float64), joints[..., 2] - SURFACE_OFFSET_M[None],
                  _LIMB_ARRAY, _OCCLUDER_RADIUS, np.ascontiguousarray(centre), np.ascontiguousarray(axes),
                  np.ascontiguousarray(extent), _TORSO_HALF_WIDTH, _TORSO_HALF_DEPTH,
                  np.array([fx, fy, cx, cy], dtype=np.float64), margin, hidden)
    return hidden


@dataclass(frozen=True)
class DepthReadings:
    """The depth readings of the joints of ``n`` people of one frame, kept after the occlusion
    test (:func:`read_depth`): all a later fusion of the frame needs (:func:`fuse_readings`, e.g.
    of a pose refined over the next frames), without the image.

    Attributes
    ----------
    depth_m : ndarray, shape (n, 12)
        Each joint's depth (its surface reading plus its surface offset), metres; NaN where the
        joint was not read, or the reading is another body part's.
    var : ndarray, shape (n, 12)
        Their variances, m^2 (NaN where no reading).
    """

    depth_m: NDArray[np.float64]
    var: NDArray[np.float64]


class _Placed:
    """The monocular placement (step 1) of ``n`` lifts, and what the steps after it read."""

    def __init__(self, intrinsics: CameraIntrinsics, points: NDArray[np.float64],
                 weights: NDArray[np.float64], poses: NDArray[np.float64], scales: NDArray[np.float64],
                 centres: NDArray[np.float64], opt: DepthOptions,
                 residuals: NDArray[np.float64] | None = None) -> None:
        pose = np.asarray(poses, dtype=np.float64)
        n = len(pose)
        #: each lift's scales of its shape's and its placement's deviations (its fit's 2D residual;
        #: the placement's also its body's lean, :func:`~pose_lifter.core.depth.uncertainty.lean_factor`)
        self.shape_factor, residual_scale = (
            np.broadcast_to(np.asarray(residual_factor(residuals, line), dtype=np.float64), (n,))
            for line in (RESIDUAL_SHAPE_LINE, RESIDUAL_SCALE_LINE))
        self.px = np.asarray(points, dtype=np.float64).reshape(n, N_JOINTS, 2)
        self.scales = np.asarray(scales, dtype=np.float64).reshape(n)
        (fx, fy), (cx, cy) = intrinsics
        self.x0 = place_poses(pose, self.scales, np.asarray(centres, dtype=np.float64).reshape(n, 2),
                              DEFAULT_LEG_LENGTH_M, (float(fx), float(fy)), (float(cx), float(cy)),
                              DEFAULT_DISTANCE_M)
        self.scale_factor = residual_scale * lean_factor(self.x0)
        wt = np.asarray(weights, dtype=np.float64).reshape(n, N_JOINTS)
        self.observed = (wt >= opt.confidence_threshold) & np.isfinite(self.px).all(axis=-1)


def _masked_median(values: NDArray[np.float64], mask: NDArray[np.bool_], empty: float) -> NDArray[np.float64]:
    """Each row's median of ``values`` (n, 12) where ``mask``; ``empty`` for a row without any
    (compiled: :func:`~pose_lifter.core.depth.kernels.masked_median`)."""
    out = np.empty(len(values))
    masked_median(np.ascontiguousarray(values, dtype=np.float64), np.ascontiguousarray(mask, dtype=bool),
                  float(empty), out)
    return out


def read_depth(depth: DepthArray, intrinsics: CameraIntrinsics, points: NDArray[np.float64],
               weights: NDArray[np.float64], poses: NDArray[np.float64], scales: NDArray[np.float64],
               centres: NDArray[np.float64], options: DepthOptions | None = None) -> DepthReadings:
    """Steps 1-3 of the fusion (module docstring): the readings of the observed joints of ``n``
    people, those another body part hides dropped (arguments as :func:`fuse_depth`)."""
    opt = options if options is not None else DepthOptions()
    _check_image(depth)
    return _read(depth, intrinsics, _Placed(intrinsics, points, weights, poses, scales, centres, opt), opt)


def _check_image(depth: DepthArray) -> None:
    """:class:`InvalidInputError` unless ``depth`` is a non-empty (H, W) image."""
    img = np.asarray(depth)
    if img.ndim != 2 or img.size == 0:
        raise InvalidInputError(f"a depth image must be (H, W), got shape {img.shape}")


def _read(depth: DepthArray, intrinsics: CameraIntrinsics, placed: _Placed, opt: DepthOptions
          ) -> DepthReadings:
    """Steps 2-3 of :func:`read_depth` for the people ``placed``."""
    x0, px = placed.x0, placed.px
    z0 = x0[..., 2]
    (fx, fy), _ = intrinsics
    radius = joint_radius_px(0.5 * (float(fx) + float(fy)) / np.maximum(z0.mean(axis=1), 1e-3), opt)
    # each band about the person's depth as the image shows it (read_people)
    surface, var = read_people(depth, px, radius, z0, placed.observed, opt)
    d = surface + SURFACE_OFFSET_M[None]
    v = var + opt.offset_std_m**2
    have = placed.observed & np.isfinite(d) & (z0 > 0)
    # a first scale (the median of d_j / z0_j) places the bodies for the occlusion test
    k = _masked_median(d / np.where(z0 > 0, z0, 1.0), have, 1.0)
    have &= ~_hidden(k[:, None, None] * x0, px, have, intrinsics, opt.occlusion_margin_m)
    return DepthReadings(np.where(have, d, np.nan), np.where(have, v, np.nan))


def fuse_depth(depth: DepthArray, intrinsics: CameraIntrinsics, points: NDArray[np.float64],
               weights: NDArray[np.float64], poses: NDArray[np.float64], scales: NDArray[np.float64],
               centres: NDArray[np.float64], options: DepthOptions | None = None,
               residuals: NDArray[np.float64] | None = None) -> FusedPeople:
    """The ``n`` people of one frame placed with the frame's registered depth image (module
    docstring: steps and the objective of the scale fit): :func:`fuse_readings` of
    :func:`read_depth`.

    Parameters
    ----------
    depth : ndarray of float32 or uint16, shape (H, W)
        Metres along the optical axis, NaN where there is no reading (or uint16 millimetres, 0
        where there is none: :data:`~pose_lifter.core.depth.reading.DepthArray`); registered to
        the camera of ``intrinsics``.
    intrinsics : ((fx, fy), (cx, cy))
        Pixels.
    points : ndarray, shape (n, 12, 2)
        The keypoints the lifts read, pixels.
    weights : ndarray, shape (n, 12)
        Their weights (confidences); joints below ``options.confidence_threshold`` are not read.
    poses : ndarray, shape (n, 12, 3)
        Each lift's ``pose_camera`` (camera frame, centred, leg units).
    scales : ndarray, shape (n,)
        Each lift's camera scale (pixels per leg unit).
    centres : ndarray, shape (n, 2)
        Each lift's camera translation (the image of its centroid, pixels).
    options : DepthOptions, optional
    residuals : ndarray, shape (n,), optional
        Each lift's fit's 2D residual
        (:func:`~pose_lifter.core.depth.uncertainty.fit_residual`): the shape's and the
        monocular placement's deviations scaled by its
        :func:`~pose_lifter.core.depth.uncertainty.residual_factor` (each its line); None: unscaled.

    Returns
    -------
    FusedPeople
        Finite joints and standard deviations for every person (a person the depth cannot place
        keeps the monocular placement and its uncertainty).

    Raises
    ------
    InvalidInputError
        ``depth`` is not a 2-D image.
    """
    return read_and_fuse(depth, intrinsics, points, weights, poses, scales, centres, options, residuals)[1]


def read_and_fuse(depth: DepthArray, intrinsics: CameraIntrinsics, points: NDArray[np.float64],
                  weights: NDArray[np.float64], poses: NDArray[np.float64], scales: NDArray[np.float64],
                  centres: NDArray[np.float64], options: DepthOptions | None = None,
                  residuals: NDArray[np.float64] | None = None) -> tuple[DepthReadings, FusedPeople]:
    """:func:`read_depth` and :func:`fuse_readings` of its readings, the people placed once
    (arguments as :func:`fuse_depth`): the readings (for a later fusion of the frame) and the
    people placed."""
    opt = options if options is not None else DepthOptions()
    _check_image(depth)
    placed = _Placed(intrinsics, points, weights, poses, scales, centres, opt, residuals)
    readings = _read(depth, intrinsics, placed, opt)
    return readings, _fuse(readings, placed, opt)


def fuse_readings(readings: DepthReadings, intrinsics: CameraIntrinsics, points: NDArray[np.float64],
                  weights: NDArray[np.float64], poses: NDArray[np.float64], scales: NDArray[np.float64],
                  centres: NDArray[np.float64], options: DepthOptions | None = None,
                  residuals: NDArray[np.float64] | None = None) -> FusedPeople:
    """Steps 4-5 of the fusion (module docstring) of the ``n`` people of :func:`read_depth`'s
    ``readings``: the same people, possibly with other poses (a pose refined over later frames);
    arguments as :func:`fuse_depth`."""
    opt = options if options is not None else DepthOptions()
    return _fuse(readings, _Placed(intrinsics, points, weights, poses, scales, centres, opt, residuals), opt)


def _fuse(readings: DepthReadings, placed: _Placed, opt: DepthOptions) -> FusedPeople:
    """Steps 4-5 of :func:`fuse_readings` for the people ``placed``."""
    x0, observed = placed.x0, placed.observed
    n = len(x0)
    # 4b. the robust fit of the depth field (IRLS): the placed depth scaled, plus a tilt across
    # the image (a depth that grows linearly across the body: the monocular lift's commonest error
    # in depth, a body leaning towards or away from the camera, moves no joint on the image), from
    # the median of d_j / z0_j (:func:`~pose_lifter.core.depth.kernels.field_kernel`)
    have = np.empty((n, N_JOINTS), dtype=bool)
    d, v = np.empty((n, N_JOINTS)), np.empty((n, N_JOINTS))
    g = np.empty((n, N_JOINTS, 3))  # (z0_j, y_j, x_j)
    theta0 = np.empty((n, 3))
    field_kernel(x0, observed, np.ascontiguousarray(readings.depth_m, dtype=np.float64).reshape(n, N_JOINTS),
                 np.ascontiguousarray(readings.var, dtype=np.float64).reshape(n, N_JOINTS), have, d, v, g,
                 theta0)
    # the prior on k: the monocular placement's own error (scaled, as the shape's, by the fit's residual)
    mono_scale = monocular_scale_std(observed) * placed.scale_factor
    precision = np.empty((n, 3))
    precision[:, 0] = mono_scale**-2
    precision[:, 1:] = opt.tilt_std**-2
    theta = np.empty((n, 3))
    cov = np.empty((n, 3, 3))
    objective = np.empty(n)
    n_iter = np.empty(n, dtype=np.int64)
    converged = np.empty(n, dtype=bool)
    depth_fit_kernel(d, v, g, have, _SHAPE_Z, precision, np.array([1.0, 0.0, 0.0]), theta0, int(opt.max_iter),
                     opt.tol, theta, cov, objective, n_iter, converged)
    # 4c-5. readings beyond the gate dropped; the joints: the body moved along its rays to the
    # fitted depths, a kept reading's depth fused with its joint's along the joint's ray (the
    # lift's image of the joint: the 2D denoised by the prior), each reading first judged by its
    # residual from the field, then by what the other readings predict of its joint (leave one
    # out); a joint without its own reading keeps its marginal deviation (the correlations,
    # measured on motion the prior knows, hold less on motion it does not: on the cross-action
    # folds the conditional one covered 83 % of such joints at 2 sigma, the marginal 86 %).
    # Compiled, one person at a time: :func:`~pose_lifter.core.depth.kernels.fuse_kernel`; the
    # shape's deviations scaled by what the field's residuals say of this body (shape_scale)
    shape = shape_std(observed) * placed.shape_factor[:, None, None]
    shape *= shape_scale(d, v, g, have, theta, shape[..., 2], opt.gate)[:, None, None]
    joints = np.empty((n, N_JOINTS, 3))
    std = np.empty((n, N_JOINTS, 3))
    kept = np.empty((n, N_JOINTS), dtype=bool)
    placeable = np.empty(n, dtype=bool)
    settings = np.array([opt.gate, opt.band_m, opt.band_fraction, opt.outlier_share, _MIN_INLIER,
                         _UNREAD_VAR])
    fuse_kernel(x0, g, d, v, have, theta, cov, shape, _SHAPE_MODEL, mono_scale, settings, joints, std, kept,
                placeable)
    bad = ~(np.isfinite(joints).all(axis=(1, 2)) & np.isfinite(std).all(axis=(1, 2)))
    if bad.any():  # never NaN: such a person keeps the monocular placement
        joints[bad] = x0[bad]
        std[bad] = body_std(x0[bad], observed[bad], mono_scale[bad], placed.shape_factor[bad])
        kept[bad] = False
    k = np.where(placeable, theta[:, 0], 1.0)
    return FusedPeople(joints, std, kept, DEFAULT_LEG_LENGTH_M * k, converged, n_iter, objective)


def shape_scale(d: NDArray[np.float64], v: NDArray[np.float64], g: NDArray[np.float64],
                have: NDArray[np.bool_], theta: NDArray[np.float64], shape_z: NDArray[np.float64],
                gate: float) -> NDArray[np.float64]:
    """Per body, the scale of its shape's deviations that its depth readings' residuals from the
    fitted field give: the fit's a-posteriori variance factor, shrunk towards 1.

    ``sqrt((nu0 + sum_j min(r_j^2 / s_j^2, gate^2)) / (nu0 + n))`` over the body's ``n``
    readings, ``r_j = d_j - g_j . theta`` and ``s_j^2 = v_j + (k shape_z_j)^2`` (the reading's
    variance and the shape's in depth, ``k = theta[0]``), ``nu0`` :data:`SHAPE_SCALE_DOF`; a
    residual beyond the gate counts as the gate (such a reading is another surface's). The shape
    constants (:mod:`~pose_lifter.core.depth.uncertainty`) are averages measured on known motion:
    a body whose readings sit closer to its lifted shape than they say has its deviations
    narrowed, and one they disagree with (a motion the prior never saw, whose shape errs more)
    widened. 1 for a body without a reading.

    Parameters
    ----------
    d, v : ndarray, shape (n, 12)
        The readings' depths and variances (m, m^2; read where ``have``).
    g : ndarray, shape (n, 12, 3)
        The field's regressors.
    have : ndarray of bool, shape (n, 12)
    theta : ndarray, shape (n, 3)
        The fitted field.
    shape_z : ndarray, shape (n, 12)
        The shape's standard deviations in depth (m).
    gate : float

    Returns
    -------
    ndarray, shape (n,)
    """
    field = np.einsum("njc,nc->nj", np.where(have[..., None], g, 0.0), theta)
    r = np.where(have, d, 0.0) - np.where(have, field, 0.0)
    s2 = np.where(have, v, 1.0) + np.where(have, theta[:, :1] * shape_z, 0.0) ** 2
    z2 = np.where(have, np.minimum(r * r / s2, gate * gate), 0.0)
    return np.asarray(np.sqrt((SHAPE_SCALE_DOF + z2.sum(axis=1)) / (SHAPE_SCALE_DOF + have.sum(axis=1))))


def compile_kernels() -> None:
    """Compile the fusion's kernels (numba, see ``core.numeric.jit``) into their cache, or load
    them from it: one fusion of a small synthetic frame in metres and in millimetres (writable, and
    read-only as a view of a message's bytes), so that no frame pays for it."""
    grid = np.linspace(-0.5, 0.5, N_JOINTS)
    pose = np.stack([grid, grid[::-1], 0.2 * grid], axis=-1)[None]
    points = 32.0 + 10.0 * pose[..., :2]
    read_only = np.full((64, 64), 3000, dtype=np.uint16)
    read_only.flags.writeable = False  # a view of a message's bytes (numba compiles it apart)
    for depth in (np.full((64, 64), 3.0, dtype=np.float32), np.full((64, 64), 3000, dtype=np.uint16),
                  read_only):
        fuse_depth(depth, ((50.0, 50.0), (32.0, 32.0)), points, np.ones((1, N_JOINTS)), pose,
                   np.array([20.0]), np.array([[32.0, 32.0]]))
