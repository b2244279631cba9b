"""Synthetic 12-joint poses for core tests (no mocap data needed).

A crude forward-kinematics body: a rigid torso and 8 limbs of the anthropometric lengths,
each limb pointing in a random direction around a class-specific mean direction. Poses
are returned normalised (:func:`pose_lifter.core.model.skeleton.normalise_pose`).
"""

from __future__ import annotations

import numpy as np
from numpy.typing import NDArray
from pose_lifter.core.model.bases import PoseBases, learn_pca_bases
from pose_lifter.core.model.skeleton import ANTHROPOMETRIC_PROPORTIONS, normalise_pose

# torso joints (left sho, right sho, left hip, right hip), x to the subject's left, y up
_TORSO = {0: (0.75, 2.4, 0.0), 3: (-0.75, 2.4, 0.0), 6: (0.4, 0.0, 0.0), 9: (-0.4, 0.0, 0.0)}
# limb chains: (root, mid, end, upper limb index, lower limb index)
_CHAINS = ((0, 1, 2, 0, 1), (3, 4, 5, 2, 3), (6, 7, 8, 4, 5), (9, 10, 11, 6, 7))
# mean limb directions per class: arms down / legs down; arms forward; one leg raised
_CLASS_DIRECTIONS = (
    ((0.1, -1, 0.1), (0, -1, 0.2), (-0.1, -1, 0.1), (0, -1, 0.2),
     (0, -1, 0), (0, -1, -0.1), (0, -1, 0), (0, -1, -0.1)),
    ((0.2, -0.3, 1), (0, 0, 1), (-0.2, -0.3, 1), (0, 0, 1),
     (0, -1, 0.1), (0, -1, -0.1), (0, -1, 0.1), (0, -1, -0.1)),
    ((0.6, -0.8, 0.2), (0.5, 0.5, 0.5), (-0.6, -0.8, 0.2), (-0.5, 0.5, 0.5),
     (0, -0.3, 1), (0, -1, 0), (0, -1, 0), (0, -1, 0.1)),
)


def synthetic_poses(
    n: int, seed: int = 0, spread: float = 0.35, n_classes: int = 3,
) -> tuple[NDArray[np.float64], NDArray[np.int64]]:
    """``n`` normalised poses (n, 12, 3) with exact anthropometric limb lengths, and labels."""
    rng = np.random.default_rng(seed)
    poses = np.zeros((n, 12, 3))
    labels = rng.integers(0, n_classes, size=n)
    lengths = ANTHROPOMETRIC_PROPORTIONS
    for p in range(n):
        dirs = np.asarray(_CLASS_DIRECTIONS[labels[p] % len(_CLASS_DIRECTIONS)], dtype=np.float64)
        for j, xyz in _TORSO.items():
            poses[p, j] = xyz
        for root, mid, end, up, low in _CHAINS:
            for a, b, limb in ((root, mid, up), (mid, end, low)):
                d = dirs[limb] / np.linalg.norm(dirs[limb]) + spread * rng.normal(size=3)
                poses[p, b] = poses[p, a] + lengths[limb] * d / np.linalg.norm(d)
        # a small random torso lean so the body frame varies a little
        poses[p] += 0.05 * rng.normal(size=(1, 3))
    return normalise_pose(poses), labels.astype(np.int64)


def small_pca_bases() -> PoseBases:
    """12 PCA bases of 300 synthetic poses: fewer than the 24 directions the limb map needs to be
    onto, so a pose step on them runs the Python loop with the paper's inner ADM."""
    poses, _ = synthetic_poses(300, seed=1)
    return learn_pca_bases(poses, n_bases=12, n_starts=3, seed=0)
