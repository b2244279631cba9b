"""core.numeric.fast: the per-frame helpers give what their numpy counterparts give, to round-off."""

from __future__ import annotations

import numpy as np
import tolerances as tol
from pose_lifter.core.numeric.fast import mean_rows, row_norms
from pose_lifter.core.solve.pose_step import PriorRows


def test_mean_rows_and_row_norms_are_the_mean_and_the_norms() -> None:
    rng = np.random.default_rng(0)
    for n in range(1, 40):
        for shape in ((n, 2), (n, 3), (4, n, 3)):
            a = rng.normal(size=shape) * 10.0 ** rng.uniform(-3, 3)
            scale = np.abs(a).max()
            np.testing.assert_allclose(row_norms(a), np.linalg.norm(a, axis=-1), rtol=tol.ROUND_OFF)
            if len(shape) == 2:
                np.testing.assert_allclose(mean_rows(a), a.mean(axis=0), rtol=0, atol=tol.ROUND_OFF * scale)
    assert mean_rows(np.array([[1.0, 2.0], [3.0, -2.0]])).tolist() == [2.0, 0.0]
    assert row_norms(np.array([[3.0, 4.0], [0.0, 0.0]])).tolist() == [5.0, 0.0]


def test_depth_row_is_the_scaled_cross_product() -> None:
    rng = np.random.default_rng(1)
    for _ in range(100):
        m = rng.normal(size=(2, 3))
        expected = np.cross(m[0], m[1]) / np.linalg.norm(m[0])
        assert np.abs(PriorRows.depth_row(m) - expected).max() <= tol.ROUND_OFF * np.abs(expected).max()
