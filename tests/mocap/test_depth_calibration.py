"""The uncertainty constants' estimates (pose_lifter.mocap.depth_calibration.spread_factors) on
Gaussian errors of known spreads."""

from __future__ import annotations

import numpy as np
from numpy.typing import NDArray
from pose_lifter.core.model.skeleton import COUNTERPART, N_JOINTS
from pose_lifter.mocap.depth_calibration import residual_line, shape_correlation, spread_factors

#: Relative error of a 68th percentile of ~40,000 Gaussian samples (its standard error is ~0.6 %).
QUANTILE_RTOL = 0.03


def test_spread_factors_recover_the_spreads_they_were_drawn_with() -> None:
    rng = np.random.default_rng(0)
    across = np.array([0.02 + 0.002 * min(j, COUNTERPART[j]) for j in range(N_JOINTS)])  # same left and right
    along = 3.0 * across
    bin_factor = [1.0, 1.5]
    hidden_factor = np.array([2.0, 5.0, 1.5])  # x, y, z: a joint outside an upright body's image
    n = 20_000

    def draw(b: int, factor: NDArray[np.float64]) -> list[list[list[float]]]:
        sd = np.stack([across, across, along]) * bin_factor[b] * factor[:, None]  # (3, 12)
        return [[list(rng.standard_normal(n) * sd[a, j]) for j in range(N_JOINTS)] for a in range(3)]

    ones = np.ones(3)
    shown = [draw(0, ones), draw(1, ones)]
    hidden = [[[[] for _ in range(N_JOINTS)] for _ in range(3)], draw(1, hidden_factor)]
    shape, factor, unobserved = spread_factors(shown, hidden)
    np.testing.assert_allclose(shape, np.stack([across, along], axis=1), rtol=QUANTILE_RTOL)
    np.testing.assert_allclose(factor, bin_factor, rtol=QUANTILE_RTOL)
    np.testing.assert_allclose(unobserved, [ones, hidden_factor], rtol=QUANTILE_RTOL)



def test_shape_correlation_recovers_a_known_one_seen_in_a_mirror() -> None:
    """Gaussian errors of a known correlation that is the same for left and right: recovered
    (to the sampling error of 20000 samples), and exactly unchanged by swapping left and right."""
    swap = list(COUNTERPART)
    rng = np.random.default_rng(2)
    a = rng.standard_normal((12, 12))
    cov = a @ a.T + 12.0 * np.eye(12)
    cov = 0.5 * (cov + cov[np.ix_(swap, swap)])
    sd = np.sqrt(np.diag(cov))
    want = cov / np.outer(sd, sd)
    got = shape_correlation(rng.multivariate_normal(np.zeros(12), cov, size=20000))
    assert np.abs(got - want).max() < 0.03
    np.testing.assert_allclose(got, got[np.ix_(swap, swap)], atol=1e-12)
    np.testing.assert_allclose(np.diag(got), 1.0, atol=1e-12)


def test_residual_line_recovers_the_spread_s_growth_with_the_residual() -> None:
    """Errors drawn with a standard deviation of 0.4 + 8 r (r uniform on 0.02-0.2) over unit
    deviations: the line through the deciles' 68th percentiles is (0.4, 8) to the sampling's error
    (its level: the errors over it are unit Gaussians); a non-finite residual is left out."""
    rng = np.random.default_rng(3)
    r = rng.uniform(0.02, 0.2, 20000)
    z = np.abs(rng.standard_normal((20000, N_JOINTS, 3))) * (0.4 + 8.0 * r)[:, None, None]
    a, b = residual_line(np.append(r, np.nan), np.concatenate([z, np.full((1, N_JOINTS, 3), 9.0)]))
    np.testing.assert_allclose([a, b], [0.4, 8.0], rtol=0.03)
