"""The monocular uncertainty model (pose_lifter.core.depth.uncertainty)."""

from __future__ import annotations

import numpy as np
from pose_lifter.core.depth.uncertainty import (
    MONOCULAR_SCALE_STD,
    OBSERVED_BINS,
    SHAPE_STD_M,
    body_std,
    monocular_std,
    observed_bin,
)

K = ((800.0, 800.0), (320.0, 240.0))


def test_observed_bins_count_the_joints_shown() -> None:
    seen = np.ones((5, 12), dtype=bool)
    for i, n in enumerate([12, 11, 10, 8, 3]):
        seen[i, n:] = False
    assert observed_bin(seen).tolist() == [0, 1, 1, 2, 3]
    assert OBSERVED_BINS[observed_bin(seen)[2]] <= 10 < OBSERVED_BINS[observed_bin(seen)[2] - 1]


def test_std_is_the_shape_and_the_slide_along_the_rays() -> None:
    """A whole body at (0, 0, 4): x and y are the shape's spread (the slide moves a joint on the
    optical axis only in z), z adds the scale's share of the distance."""
    x = np.zeros((1, 12, 3))
    x[..., 2] = 4.0
    std = monocular_std(x, np.ones((1, 12)), K)
    np.testing.assert_allclose(std[0, :, 0], SHAPE_STD_M[:, 0])
    np.testing.assert_allclose(std[0, :, 2], np.hypot(SHAPE_STD_M[:, 1], MONOCULAR_SCALE_STD[0] * 4.0))


def test_std_stays_finite_for_absurd_but_finite_placements() -> None:
    """A body placed at 1e200 m (coordinates of 1e9 px, a focal length of 1e300): finite std, not
    an overflow that the message writer would refuse."""
    x = np.full((1, 12, 3), 1e200)
    std = body_std(x, np.ones((1, 12), dtype=bool), np.array([0.5]))
    assert np.isfinite(std).all() and (std > 1e199).all()
