"""The paper's 12-joint skeleton, its 8 limbs and the limb-length proportions.

A 3D pose is an array of shape ``(12, 3)`` (joint-major); the paper's vector
``y in R^{3n}`` is ``pose.reshape(-1)`` (x1, y1, z1, x2, ...), so that
``M = I_n kron M0`` acts as ``pose @ M0.T``.
"""

from __future__ import annotations

import math
from typing import Final, NamedTuple

import numpy as np
from numpy.typing import NDArray

from ..errors import InvalidInputError
from ..numeric.fast import row_norms
from ..numeric.jit import njit

__all__ = [
    "ANTHROPOMETRIC_PROPORTIONS",
    "BONES_FOR_DRAWING",
    "COUNTERPART",
    "HIPS",
    "JOINTS_LEFT",
    "JOINTS_RIGHT",
    "JOINT_NAMES",
    "LEFT_LIMBS",
    "LIMBS",
    "LIMB_GROUPS",
    "LIMB_GROUP_OF",
    "LIMB_NAMES",
    "N_JOINTS",
    "RIGHT_LIMBS",
    "RIGHT_LOWER_LEG",
    "SHOULDERS",
    "LimbVectors",
    "body_frame",
    "limb_lengths",
    "limb_selectors",
    "normalise_pose",
    "normalise_pose_flat",
]

JOINT_NAMES: Final[tuple[str, ...]] = (
    "left_shoulder",
    "left_elbow",
    "left_wrist",
    "right_shoulder",
    "right_elbow",
    "right_wrist",
    "left_hip",
    "left_knee",
    "left_ankle",
    "right_hip",
    "right_knee",
    "right_ankle",
)
N_JOINTS: Final[int] = len(JOINT_NAMES)
JOINTS_LEFT: Final[tuple[int, ...]] = (0, 1, 2, 6, 7, 8)
JOINTS_RIGHT: Final[tuple[int, ...]] = (3, 4, 5, 9, 10, 11)
#: The spine's ends: the shoulders and the hips, (left, right) each.
SHOULDERS: Final[tuple[int, int]] = (0, 3)
HIPS: Final[tuple[int, int]] = (6, 9)
#: Each joint's counterpart on the other side (left and right exchanged): the joint order of a
#: mirror image, and of a detection whose left and right labels are swapped.
COUNTERPART: Final[tuple[int, ...]] = tuple(
    {**dict(zip(JOINTS_LEFT, JOINTS_RIGHT, strict=True)),
     **dict(zip(JOINTS_RIGHT, JOINTS_LEFT, strict=True))}[j] for j in range(N_JOINTS))

#: The paper's eight limbs as (joint, joint) index pairs, in this order.
LIMBS: Final[tuple[tuple[int, int], ...]] = (
    (0, 1),  # left upper arm
    (1, 2),  # left lower arm
    (3, 4),  # right upper arm
    (4, 5),  # right lower arm
    (6, 7),  # left upper leg
    (7, 8),  # left lower leg
    (9, 10),  # right upper leg
    (10, 11),  # right lower leg
)
#: The 8 limbs as 4 bone groups (upper arm, forearm, thigh, shin), each its (left, right) indices
#: into LIMBS; LEFT_LIMBS / RIGHT_LIMBS their columns and LIMB_GROUP_OF[i] the group of limb i.
LIMB_GROUPS: Final[tuple[tuple[int, int], ...]] = ((0, 2), (1, 3), (4, 6), (5, 7))
LEFT_LIMBS: Final[tuple[int, ...]] = tuple(left for left, _ in LIMB_GROUPS)
RIGHT_LIMBS: Final[tuple[int, ...]] = tuple(right for _, right in LIMB_GROUPS)
LIMB_GROUP_OF: Final[tuple[int, ...]] = tuple(
    next(k for k, g in enumerate(LIMB_GROUPS) if i in g) for i in range(len(LIMBS)))
LIMB_NAMES: Final[tuple[str, ...]] = (
    "left_upper_arm",
    "left_lower_arm",
    "right_upper_arm",
    "right_lower_arm",
    "left_upper_leg",
    "left_lower_leg",
    "right_upper_leg",
    "right_lower_leg",
)
#: Index (into LIMBS) of the right lower leg, the unit of length.
RIGHT_LOWER_LEG: Final[int] = 7

#: Limb lengths relative to the lower leg (knee-ankle = 1), from the segment-length
#: proportions of Drillis & Contini (1966) as tabulated by Winter, "Biomechanics and Motor
#: Control of Human Movement" (fractions of stature H: shoulder 0.818, elbow 0.630,
#: wrist 0.485, hip 0.530, knee 0.285, ankle 0.039). Lee & Chen (1985), the paper's [c14],
#: use anthropometric proportions of this kind; their exact table was not available to us.
#: upper arm = 0.188 H, lower arm = 0.145 H, upper leg = 0.245 H, lower leg = 0.246 H.
ANTHROPOMETRIC_PROPORTIONS: Final[NDArray[np.float64]] = np.array(
    [0.188, 0.145, 0.188, 0.145, 0.245, 0.246, 0.245, 0.246]
) / 0.246

#: Segments to draw (limbs plus shoulder line, hip line and the two torso sides).
BONES_FOR_DRAWING: Final[tuple[tuple[int, int], ...]] = (*LIMBS, (0, 3), (6, 9), (0, 6), (3, 9))


#: The limbs' first and second joints (:func:`limb_lengths`).
_LIMB_A = np.array([a for a, _ in LIMBS])
_LIMB_B = np.array([b for _, b in LIMBS])


def _check_pose(pose: NDArray[np.float64]) -> NDArray[np.float64]:
    arr = np.asarray(pose, dtype=np.float64)
    if arr.shape[-2:] != (N_JOINTS, 3):
        raise InvalidInputError(f"expected a pose of shape (..., {N_JOINTS}, 3), got {arr.shape}")
    return arr


def limb_lengths(pose: NDArray[np.float64]) -> NDArray[np.float64]:
    """Lengths of the 8 limbs.

    Parameters
    ----------
    pose : ndarray, shape (..., 12, 3)

    Returns
    -------
    ndarray, shape (..., 8)
    """
    arr = _check_pose(pose)
    d = arr[..., _LIMB_A, :] - arr[..., _LIMB_B, :]
    return row_norms(d)


def limb_selectors() -> NDArray[np.float64]:
    """The paper's selection matrices ``C_i = E_{i1} - E_{i2}``.

    Returns
    -------
    ndarray, shape (8, 3, 36)
        ``C[i] @ pose.reshape(-1)`` is the vector along limb ``i``. The same read-only array on
        every call (built once).
    """
    return _LIMB_SELECTORS


def _build_limb_selectors() -> NDArray[np.float64]:
    c = np.zeros((len(LIMBS), 3, 3 * N_JOINTS))
    for i, (j1, j2) in enumerate(LIMBS):
        c[i, :, 3 * j1 : 3 * j1 + 3] += np.eye(3)
        c[i, :, 3 * j2 : 3 * j2 + 3] -= np.eye(3)
    c.flags.writeable = False
    return c


_LIMB_SELECTORS = _build_limb_selectors()


class LimbVectors(NamedTuple):
    """The limb vectors ``C_i y`` (:func:`limb_selectors`) of a linear pose model ``y = mean +
    components @ alpha``: ``of_mean + of_components @ alpha`` (8, 3)."""

    of_components: NDArray[np.float64]  #: (8, 3, k)
    of_mean: NDArray[np.float64]  #: (8, 3)

    @classmethod
    def of(cls, mean: NDArray[np.float64], components: NDArray[np.float64]) -> LimbVectors:
        """The limb vectors of ``mean`` (36,) and ``components`` (36, k)."""
        c = limb_selectors()
        return cls(np.einsum("ija,ak->ijk", c, components), c @ mean)


#: The joints that define the body frame (:func:`body_frame`, :func:`normalise_pose_flat`).
(_LEFT_SHOULDER, _RIGHT_SHOULDER), (_LEFT_HIP, _RIGHT_HIP) = SHOULDERS, HIPS


def body_frame(pose: NDArray[np.float64]) -> NDArray[np.float64]:
    """Rotation whose rows are the body axes of a pose (paper, Sec. 4.3.3).

    x runs from the right hip to the left hip, y along the spine (hip centre to shoulder
    centre, made orthogonal to x), z = x cross y (the direction the body faces).

    Parameters
    ----------
    pose : ndarray, shape (..., 12, 3)

    Returns
    -------
    ndarray, shape (..., 3, 3)
        ``R`` with ``pose @ R.T`` expressed in body coordinates.
    """
    arr = _check_pose(pose)
    x = arr[..., _LEFT_HIP, :] - arr[..., _RIGHT_HIP, :]
    hips = 0.5 * (arr[..., _LEFT_HIP, :] + arr[..., _RIGHT_HIP, :])
    shoulders = 0.5 * (arr[..., _LEFT_SHOULDER, :] + arr[..., _RIGHT_SHOULDER, :])
    up = shoulders - hips
    x = x / np.linalg.norm(x, axis=-1, keepdims=True)
    y = up - np.sum(up * x, axis=-1, keepdims=True) * x
    y = y / np.linalg.norm(y, axis=-1, keepdims=True)
    # x cross y written out: numpy's cross costs ~50 us a call on the node's few rows
    z = np.stack([x[..., 1] * y[..., 2] - x[..., 2] * y[..., 1],
                  x[..., 2] * y[..., 0] - x[..., 0] * y[..., 2],
                  x[..., 0] * y[..., 1] - x[..., 1] * y[..., 0]], axis=-1)
    return np.stack([x, y, z], axis=-2)


def normalise_pose(pose: NDArray[np.float64], rotate: bool = True) -> NDArray[np.float64]:
    """Put poses in the model frame of the bases.

    Centred on the centroid of the 12 joints, scaled so the right lower leg has length 1
    and (with ``rotate``) expressed in the body frame of :func:`body_frame`.

    Parameters
    ----------
    pose : ndarray, shape (..., 12, 3)
    rotate : bool

    Returns
    -------
    ndarray, shape (..., 12, 3)
    """
    arr = _check_pose(pose)
    centred = arr - arr.mean(axis=-2, keepdims=True)
    if rotate:
        rot = body_frame(centred)
        centred = np.einsum("...jk,...lk->...jl", centred, rot)
    leg = limb_lengths(centred)[..., RIGHT_LOWER_LEG]
    if np.any(~np.isfinite(leg)) or np.any(leg <= 0):
        raise InvalidInputError("a pose has a degenerate right lower leg")
    return np.asarray(centred / leg[..., None, None])


@njit
def normalise_pose_flat(pose: NDArray[np.float64]) -> tuple[NDArray[np.float64], bool]:
    """:func:`normalise_pose` of one pose (12, 3), flattened to (36,), as a compiled kernel (the
    lifter calls it on every warm frame; the vectorised version costs ~60 us in numpy calls).
    Returns ``(pose, ok)``; ``ok`` is False for a degenerate right lower leg or body frame (where
    :func:`normalise_pose` raises). Kept equal to :func:`normalise_pose` by a test."""
    n = pose.shape[0]
    cp = np.empty((n, 3))
    for a in range(3):
        c = 0.0
        for j in range(n):
            c += pose[j, a]
        c /= n
        for j in range(n):
            cp[j, a] = pose[j, a] - c
    x = cp[_LEFT_HIP] - cp[_RIGHT_HIP]
    x = x / math.sqrt(x[0] ** 2 + x[1] ** 2 + x[2] ** 2)
    up = 0.5 * (cp[_LEFT_SHOULDER] + cp[_RIGHT_SHOULDER]) - 0.5 * (cp[_LEFT_HIP] + cp[_RIGHT_HIP])
    y = up - (up[0] * x[0] + up[1] * x[1] + up[2] * x[2]) * x
    y = y / math.sqrt(y[0] ** 2 + y[1] ** 2 + y[2] ** 2)
    z = np.array([x[1] * y[2] - x[2] * y[1], x[2] * y[0] - x[0] * y[2], x[0] * y[1] - x[1] * y[0]])
    body = np.empty(3 * n)
    for j in range(n):
        body[3 * j] = cp[j, 0] * x[0] + cp[j, 1] * x[1] + cp[j, 2] * x[2]
        body[3 * j + 1] = cp[j, 0] * y[0] + cp[j, 1] * y[1] + cp[j, 2] * y[2]
        body[3 * j + 2] = cp[j, 0] * z[0] + cp[j, 1] * z[1] + cp[j, 2] * z[2]
    knee, ankle = LIMBS[RIGHT_LOWER_LEG]
    leg = math.sqrt((body[3 * knee] - body[3 * ankle]) ** 2 + (body[3 * knee + 1] - body[3 * ankle + 1]) ** 2
                    + (body[3 * knee + 2] - body[3 * ankle + 2]) ** 2)
    if not (math.isfinite(leg) and leg > 0.0):
        return body, False
    return body / leg, True
