"""Random lifts of one frame for the tests of the Skeleton3DArray writer (no solver run)."""

from __future__ import annotations

import numpy as np
from pose_lifter.core.results import Camera, LiftResult
from scipy.spatial.transform import Rotation


def random_result(rng: np.random.Generator, rotation: np.ndarray) -> LiftResult:
    """A LiftResult of random numbers (its camera's rotation ``rotation``), some joints unobserved."""
    weights = rng.uniform(0.0, 1.0, 12) * (rng.uniform(size=12) > 0.2)
    return LiftResult(rng.normal(size=(12, 3)), rng.normal(size=(12, 3)),
                      Camera(rotation, float(rng.uniform(50, 200)), rng.normal(300, 50, size=2)),
                      np.zeros(4), float(rng.uniform()), float(rng.uniform()), 0.0, 3,
                      bool(rng.uniform() > 0.3), 1, -1, weights, total_alternations=int(rng.integers(0, 40)))


def random_frame(rng: np.random.Generator, n: int, depth: float = 5.0
                 ) -> tuple[list[LiftResult], list[np.ndarray], list[float], list[bool]]:
    """``n`` skeletons' lifts, metric joints (about ``depth`` m ahead), solve times and warm flags."""
    results = [random_result(rng, r) for r in Rotation.random(n, random_state=rng).as_matrix()]
    joints = [rng.normal(size=(12, 3)) + np.array([0.0, 0.0, depth]) for _ in range(n)]
    times = list(rng.uniform(0, 0.01, n))
    warm = [bool(w) for w in rng.uniform(size=n) > 0.5]
    return results, joints, times, warm
