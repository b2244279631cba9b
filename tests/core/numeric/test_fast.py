"""core.numeric.fast: the per-frame helpers return what their numpy originals do."""

from __future__ import annotations

import numpy as np
import tolerances as tol
from pose_lifter.core.numeric.fast import median_rows, pairwise_sum
from pose_lifter.core.solve.pose_step import PriorRows


def test_median_rows_is_numpys_median_along_the_first_axis() -> None:
    rng = np.random.default_rng(0)
    for n in range(1, 40):
        for shape in ((n,), (n, 2), (n, 8)):
            a = rng.normal(size=shape)
            assert np.array_equal(median_rows(a), np.median(a, axis=0)), shape
    ties = np.array([[1.0, 2.0], [1.0, 2.0], [3.0, -1.0], [3.0, 5.0]])
    assert np.array_equal(median_rows(ties), [2.0, 2.0])


def test_depth_row_is_the_scaled_cross_product() -> None:
    rng = np.random.default_rng(1)
    for _ in range(100):
        m = rng.normal(size=(2, 3))
        expected = np.cross(m[0], m[1]) / np.linalg.norm(m[0])
        assert np.abs(PriorRows.depth_row(m) - expected).max() <= tol.ROUND_OFF * np.abs(expected).max()


def test_pairwise_sum_is_numpys_sum() -> None:
    """numpy's pairwise order (8 interleaved partial sums from 8 elements on), compiled: numpy's sum
    to round-off on any CPU, and a left-to-right sum's counterpart only to round-off too."""
    rng = np.random.default_rng(2)
    for n in range(0, 129):
        for _ in range(20):
            a = rng.normal(size=n) * 10.0 ** rng.uniform(-3, 3, size=n)
            scale = float(np.sum(np.abs(a)))
            assert abs(pairwise_sum(a) - float(np.add.reduce(a))) <= tol.ROUND_OFF * scale, n
    assert str(pairwise_sum(np.array([-0.0]))) == "0.0"
