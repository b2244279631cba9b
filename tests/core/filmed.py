"""Synthetic people filmed weak-perspective, for the prior and hybrid tests."""

from __future__ import annotations

import numpy as np
from pose_lifter.core.model.synthetic import synthetic_poses
from pose_lifter.mocap.views import film, view_rotation


def filmed_views(n: int, seed: int = 0, azimuth: float = 60.0) -> tuple[np.ndarray, np.ndarray]:
    """Synthetic people filmed weak-perspective: (pixels (n, 12, 2), camera-frame truth (n, 12, 3))."""
    poses = synthetic_poses(n, seed=seed)
    rots = np.repeat(view_rotation(azimuth, 10.0)[None], n, axis=0)
    pts, cam, _ = film(poses, rots, np.full(n, 4.0), np.zeros(n, dtype=bool))
    return 800.0 * pts + 320.0, cam - cam.mean(axis=1, keepdims=True)
