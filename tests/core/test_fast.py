"""core._fast: the per-frame helpers return exactly what their numpy originals do."""

from __future__ import annotations

import numpy as np
import tolerances as tol
from pose_lifter.core._fast import median_rows, pairwise_sum
from pose_lifter.core.pose_step import PriorRows


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


def test_pairwise_sum_is_numpys_sum_to_the_bit() -> None:
    """numpy sums 8 or more elements in 8 interleaved partial sums: a left-to-right sum differs
    in the last bits (it did on about half of these arrays)."""
    rng = np.random.default_rng(2)
    left_to_right = 0
    for n in range(0, 129):
        for _ in range(20):
            a = rng.normal(size=n) * 10.0 ** rng.uniform(-3, 3, size=n)
            assert pairwise_sum(a) == np.add.reduce(a) == np.sum(a.reshape(-1, 1)), n
            left_to_right += float(sum(a.tolist(), 0.0)) != np.sum(a)
    assert left_to_right > 500
    assert str(pairwise_sum(np.array([-0.0]))) == str(np.sum(np.array([-0.0]))) == "0.0"
