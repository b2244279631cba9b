"""Synthetic poses and cameras for tests and examples (no mocap data needed).

Poses come from a small kinematic model driven by a few latent "actions" (so that they lie
near a low-dimensional set, like real motion), in metres, Y up, body facing +z.
"""

from __future__ import annotations

import numpy as np
from numpy.typing import NDArray
from scipy.spatial.transform import Rotation

from .skeleton import N_JOINTS

__all__ = ["project_weak", "random_cameras", "synthetic_poses"]

_SEG = {"upper_arm": 0.28, "lower_arm": 0.22, "upper_leg": 0.42, "lower_leg": 0.42}


def _limb(origin: NDArray[np.float64], a1: NDArray[np.float64], a2: NDArray[np.float64],
          l1: float, l2: float, bend_axis: NDArray[np.float64]
          ) -> tuple[NDArray[np.float64], NDArray[np.float64]]:
    down = np.array([0.0, -1.0, 0.0])
    r1 = Rotation.from_rotvec(a1)
    mid = origin + r1.apply(down) * l1
    r2 = r1 * Rotation.from_rotvec(bend_axis * a2)
    end = mid + r2.apply(down) * l2
    return mid, end


def synthetic_poses(n: int, seed: int = 0, n_actions: int = 4) -> NDArray[np.float64]:
    """``n`` poses of shape (n, 12, 3) in metres from ``n_actions`` cyclic latent motions."""
    rng = np.random.default_rng(seed)
    protos = rng.normal(scale=0.6, size=(n_actions, 2, 12))
    out = np.zeros((n, N_JOINTS, 3))
    for i in range(n):
        a = i % n_actions
        ph = rng.uniform(0, 2 * np.pi)
        p = protos[a, 0] * np.sin(ph) + protos[a, 1] * np.cos(ph) + rng.normal(scale=0.05, size=12)
        ls, rs = np.array([0.18, 1.40, 0.0]), np.array([-0.18, 1.40, 0.0])
        lh, rh = np.array([0.10, 0.90, 0.0]), np.array([-0.10, 0.90, 0.0])
        le, lw = _limb(ls, np.array([p[0], 0.0, 0.3 + 0.3 * p[1]]), abs(p[2]), _SEG["upper_arm"],
                       _SEG["lower_arm"], np.array([1.0, 0.0, 0.0]))
        re, rw = _limb(rs, np.array([p[3], 0.0, -0.3 - 0.3 * p[4]]), abs(p[5]), _SEG["upper_arm"],
                       _SEG["lower_arm"], np.array([1.0, 0.0, 0.0]))
        lk, la = _limb(lh, np.array([p[6], 0.0, 0.1 * p[7]]), -abs(p[8]), _SEG["upper_leg"],
                       _SEG["lower_leg"], np.array([1.0, 0.0, 0.0]))
        rk, ra = _limb(rh, np.array([p[9], 0.0, 0.1 * p[10]]), -abs(p[11]), _SEG["upper_leg"],
                       _SEG["lower_leg"], np.array([1.0, 0.0, 0.0]))
        out[i] = np.stack([ls, le, lw, rs, re, rw, lh, lk, la, rh, rk, ra])
    return out


def random_cameras(n: int, seed: int = 0) -> list[NDArray[np.float64]]:
    """``n`` random rotations (3, 3), uniformly distributed."""
    return [Rotation.random(random_state=seed + i).as_matrix() for i in range(n)]


def project_weak(pose: NDArray[np.float64], rotation: NDArray[np.float64], scale: float,
                 translation: NDArray[np.float64]) -> NDArray[np.float64]:
    """Scaled-orthographic projection (12, 3) -> (12, 2)."""
    return np.asarray(scale * pose @ rotation[:2].T + translation)
