"""Virtual views of mocap poses: cameras at an azimuth / elevation / roll, weak-perspective or
perspective projection, per-person limb-length changes. Shared by the prior's training
(:mod:`pose_lifter.mocap.prior_training`) and the accuracy evaluation (:mod:`pose_lifter.mocap.evaluation`)
so both film people the same way; :func:`pose_lifter.mocap.scenes.corrupt_2d` adds detector-like errors.

Units: poses in metres, world Y-up; 2D in "focal units" (focal length 1, principal point 0),
which any pixel camera reaches by an affine map that the lifter's normalisation removes.
"""

from __future__ import annotations

import numpy as np
from numpy.typing import NDArray

from pose_lifter.core.model.skeleton import LIMB_GROUPS, LIMBS, N_JOINTS, RIGHT_LOWER_LEG
from pose_lifter.mocap.scenes import look_at

__all__ = ["film", "limb_scale_factors", "scale_limbs", "view_rotation", "view_rotations"]


def view_rotation(azimuth_deg: float, elevation_deg: float, roll_deg: float = 0.0
                  ) -> NDArray[np.float64]:
    """World (Y-up) -> camera optical frame (x right, y down, z forward) of a camera on a sphere
    around the origin at ``azimuth`` (about +Y, from +Z towards +X) and ``elevation`` (positive:
    above, looking down), rolled about its optical axis. A proper rotation, shape (3, 3)."""
    az, el, ro = np.radians([azimuth_deg, elevation_deg, roll_deg])
    cam = np.array([np.sin(az) * np.cos(el), np.sin(el), np.cos(az) * np.cos(el)])
    rot = look_at(cam, np.zeros(3))
    c, s = np.cos(ro), np.sin(ro)
    return np.array([[c, -s, 0.0], [s, c, 0.0], [0.0, 0.0, 1.0]]) @ rot


def view_rotations(azimuth_deg: NDArray[np.float64], elevation_deg: NDArray[np.float64],
                   roll_deg: NDArray[np.float64]) -> NDArray[np.float64]:
    """:func:`view_rotation` of many cameras at once (arrays of shape (N,)): shape (N, 3, 3), the
    same rotations to rounding (elevations within (-90, 90) degrees)."""
    az, el, ro = (np.radians(np.asarray(a, dtype=np.float64)) for a in (azimuth_deg, elevation_deg, roll_deg))
    z = -np.stack([np.sin(az) * np.cos(el), np.sin(el), np.cos(az) * np.cos(el)], axis=-1)
    z /= np.linalg.norm(z, axis=-1, keepdims=True)
    up = np.array([0.0, 1.0, 0.0])
    y = -(up - z[:, 1:2] * z)
    y /= np.linalg.norm(y, axis=-1, keepdims=True)
    x = np.cross(y, z)
    rot = np.stack([x, y, z], axis=-2)
    c, s = np.cos(ro), np.sin(ro)
    roll = np.zeros((len(az), 3, 3))
    roll[:, 0, 0], roll[:, 0, 1], roll[:, 1, 0], roll[:, 1, 1], roll[:, 2, 2] = c, -s, s, c, 1.0
    out: NDArray[np.float64] = np.einsum("nab,nbc->nac", roll, rot)
    return out


def film(poses: NDArray[np.float64], rotations: NDArray[np.float64], distance: NDArray[np.float64],
         perspective: NDArray[np.bool_]
         ) -> tuple[NDArray[np.float64], NDArray[np.float64], NDArray[np.float64]]:
    """Project poses through per-pose cameras.

    Parameters
    ----------
    poses : ndarray, shape (N, 12, 3)
        Metres, world frame; each is centred on its joints' centroid first.
    rotations : ndarray, shape (N, 3, 3)
        World -> optical rotations (:func:`view_rotation`).
    distance : ndarray, shape (N,)
        Camera to centroid, metres.
    perspective : ndarray of bool, shape (N,)
        Pinhole projection; False: weak perspective at the same distance.

    Returns
    -------
    points : ndarray, shape (N, 12, 2)
        Focal units.
    camera_pose : ndarray, shape (N, 12, 3)
        The centred pose in the camera's optical frame, metres.
    leg : ndarray, shape (N,)
        The right lower leg's length in focal units at the centroid's depth (the unit of the
        evaluation's noise and outlier magnitudes).
    """
    p = np.asarray(poses, dtype=np.float64)
    centred = p - p.mean(axis=1, keepdims=True)
    cam = np.einsum("nab,njb->nja", rotations, centred)
    d = np.asarray(distance, dtype=np.float64)[:, None]
    depth = np.where(np.asarray(perspective)[:, None], cam[..., 2] + d, d)
    if np.any(depth <= 0.05):
        raise ValueError("a joint is behind (or at) the camera")
    pts = cam[..., :2] / depth[..., None]
    knee, ankle = LIMBS[RIGHT_LOWER_LEG]
    leg = np.linalg.norm(p[:, knee] - p[:, ankle], axis=-1) / d[:, 0]
    return pts, cam, leg


#: Bone groups scaled together (both sides): upper arm, forearm, thigh, shin -> LIMBS rows.
_GROUPS = LIMB_GROUPS


def limb_scale_factors(n: int, spread: float, rng: np.random.Generator) -> NDArray[np.float64]:
    """Per-person factors for the 8 limbs, shape (n, 8): one factor per bone group (upper arm,
    forearm, thigh, shin; both sides alike) uniform in ``[1 - spread, 1 + spread]``."""
    g = rng.uniform(1.0 - spread, 1.0 + spread, size=(n, len(_GROUPS)))
    out = np.ones((n, len(LIMBS)))
    for k, rows in enumerate(_GROUPS):
        for r in rows:
            out[:, r] = g[:, k]
    return out


def scale_limbs(poses: NDArray[np.float64], factors: NDArray[np.float64]) -> NDArray[np.float64]:
    """Change limb lengths along the kinematic chain: each limb's child joint (and the joints
    below it) moves so that the limb is ``factor`` times as long. Shapes (N, 12, 3), (N, 8) or (8,)."""
    out = np.array(poses, dtype=np.float64, copy=True)
    f = np.broadcast_to(np.asarray(factors, dtype=np.float64), (out.shape[0], len(LIMBS)))
    # LIMBS are (parent, child) pairs, parents first along each chain
    children: dict[int, list[int]] = {j: [] for j in range(N_JOINTS)}
    for a, b in LIMBS:
        children[a].append(b)

    def below(j: int) -> list[int]:
        return [j] + [k for c in children[j] for k in below(c)]

    for i, (a, b) in enumerate(LIMBS):
        delta = (f[:, i, None] - 1.0) * (out[:, b] - out[:, a])
        for j in below(b):
            out[:, j] += delta
    return out
