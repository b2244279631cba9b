"""Pose augmentations of mocap frames for the learned prior's training: new poses that keep
each person's bone lengths.

* :func:`mirror_poses`: the mirror image of a person (world x negated) with its left and right
  joints swapped, so the result is again a person seen the right way round (a plain reflection
  would be a left-handed body, which no camera films);
* :func:`transplant_limbs`: arms or legs of another frame, taken torso-relative (in the donor's
  :func:`~pose_lifter.core.model.skeleton.body_frame`, put into the receiver's) and re-built with the
  receiver's bone lengths (compositional augmentation: poses no trial has);
* :func:`turn_limbs` / :func:`random_turns`: each limb turned about its root (shoulder or hip)
  and its end (wrist or ankle) about its middle joint (elbow or knee); rotations, so the bone
  lengths are kept.

Poses are arrays of shape (..., 12, 3) in the joint order of
:data:`pose_lifter.core.model.skeleton.JOINT_NAMES`, any length unit.
"""

from __future__ import annotations

from typing import Final

import numpy as np
from numpy.typing import NDArray
from scipy.spatial.transform import Rotation

from pose_lifter.core.model.skeleton import COUNTERPART, LIMBS, body_frame

__all__ = ["CHAINS", "MIRROR_INDEX", "mirror_poses", "random_turns", "transplant_limbs", "turn_limbs"]

#: The four limbs as (root, middle, end) joints: left arm, right arm, left leg, right leg.
CHAINS: Final[tuple[tuple[int, int, int], ...]] = tuple(
    (LIMBS[2 * i][0], LIMBS[2 * i][1], LIMBS[2 * i + 1][1]) for i in range(len(LIMBS) // 2))
#: Joint order of the mirrored person: each joint's left/right counterpart.
MIRROR_INDEX: Final[tuple[int, ...]] = COUNTERPART


def mirror_poses(poses: NDArray[np.float64]) -> NDArray[np.float64]:
    """The mirror image about the world's y-z plane (x negated) with left and right joints swapped.

    A proper person again (the handedness of its body frame is kept), its left limbs the
    original's right ones; an involution. Shape (..., 12, 3) -> same.
    """
    p = np.asarray(poses, dtype=np.float64)
    out = p[..., list(MIRROR_INDEX), :].copy()
    out[..., 0] *= -1.0
    return out


def transplant_limbs(poses: NDArray[np.float64], donors: NDArray[np.float64],
                     limbs: NDArray[np.bool_]) -> NDArray[np.float64]:
    """Limbs of ``donors`` on ``poses``, torso-relative, with the receiver's bone lengths.

    For each selected limb (root ``r``, middle ``m``, end ``e``) the donor's bone directions
    ``m - r`` and ``e - m`` are expressed in the donor's body frame, turned into the receiver's
    body frame and scaled to the receiver's bone lengths; the root stays where it is.

    Parameters
    ----------
    poses, donors : ndarray, shape (N, 12, 3)
    limbs : ndarray of bool, shape (N, 4)
        Which limbs (:data:`CHAINS` order) to take from the donor.

    Returns
    -------
    ndarray, shape (N, 12, 3)
    """
    p = np.array(poses, dtype=np.float64, copy=True)
    d = np.asarray(donors, dtype=np.float64)
    sel = np.asarray(limbs, dtype=bool)
    if d.shape != p.shape or sel.shape != (p.shape[0], len(CHAINS)):
        raise ValueError(f"poses {p.shape}, donors {d.shape} and limbs {sel.shape} do not match")
    # donor world -> donor body -> receiver world: v @ R_d.T @ R_p
    turn = np.einsum("nba,nbc->nac", body_frame(d), body_frame(p))
    for k, (r, m, e) in enumerate(CHAINS):
        rows = np.flatnonzero(sel[:, k])
        if len(rows) == 0:
            continue
        len1 = np.linalg.norm(p[rows, m] - p[rows, r], axis=-1, keepdims=True)
        len2 = np.linalg.norm(p[rows, e] - p[rows, m], axis=-1, keepdims=True)
        v1 = np.einsum("na,nab->nb", d[rows, m] - d[rows, r], turn[rows])
        v2 = np.einsum("na,nab->nb", d[rows, e] - d[rows, m], turn[rows])
        v1 /= np.linalg.norm(v1, axis=-1, keepdims=True)
        v2 /= np.linalg.norm(v2, axis=-1, keepdims=True)
        p[rows, m] = p[rows, r] + len1 * v1
        p[rows, e] = p[rows, m] + len2 * v2
    return p


def turn_limbs(poses: NDArray[np.float64], root_turns: NDArray[np.float64],
               end_turns: NDArray[np.float64]) -> NDArray[np.float64]:
    """Turn each limb about its root, then its end about its middle joint.

    Parameters
    ----------
    poses : ndarray, shape (N, 12, 3)
    root_turns, end_turns : ndarray, shape (N, 4, 3)
        Rotation vectors (axis times angle, radians; 0 = unchanged) per limb of :data:`CHAINS`:
        ``root_turns`` moves the middle and end joints about the root, ``end_turns`` then
        moves the end joint about the middle one.

    Returns
    -------
    ndarray, shape (N, 12, 3)
        Same bone lengths (rotations about the bones' own joints).
    """
    p = np.array(poses, dtype=np.float64, copy=True)
    n = p.shape[0]
    rt = np.asarray(root_turns, dtype=np.float64)
    et = np.asarray(end_turns, dtype=np.float64)
    if rt.shape != (n, len(CHAINS), 3) or et.shape != rt.shape:
        raise ValueError(f"turns must be ({n}, {len(CHAINS)}, 3), got {rt.shape} and {et.shape}")
    r_root = Rotation.from_rotvec(rt.reshape(-1, 3)).as_matrix().reshape(n, len(CHAINS), 3, 3)
    r_end = Rotation.from_rotvec(et.reshape(-1, 3)).as_matrix().reshape(n, len(CHAINS), 3, 3)
    for k, (r, m, e) in enumerate(CHAINS):
        root = p[:, r]
        mid = root + np.einsum("nab,nb->na", r_root[:, k], p[:, m] - root)
        end = root + np.einsum("nab,nb->na", r_root[:, k], p[:, e] - root)
        end = mid + np.einsum("nab,nb->na", r_end[:, k], end - mid)
        p[:, m], p[:, e] = mid, end
    return p


def random_turns(n: int, max_root_deg: float, max_end_deg: float, p_limb: float,
                 rng: np.random.Generator) -> tuple[NDArray[np.float64], NDArray[np.float64]]:
    """Random rotation vectors for :func:`turn_limbs`: per limb (with probability ``p_limb``,
    else none) a uniform axis on the sphere and an angle uniform in [0, max] degrees.

    Returns
    -------
    root_turns, end_turns : ndarray, shape (n, 4, 3)
    """
    out = []
    for max_deg in (max_root_deg, max_end_deg):
        axis = rng.normal(size=(n, len(CHAINS), 3))
        axis /= np.maximum(np.linalg.norm(axis, axis=-1, keepdims=True), 1e-12)
        angle = np.radians(rng.uniform(0.0, max_deg, size=(n, len(CHAINS))))
        angle *= rng.random((n, len(CHAINS))) < p_limb
        out.append(axis * angle[..., None])
    return out[0], out[1]
