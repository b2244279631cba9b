"""The monocular uncertainty model (pose_lifter.core.depth.uncertainty)."""

from __future__ import annotations

import numpy as np
from pose_lifter.core.depth.uncertainty import (
    LEAN_SCALE_LINE,
    MONOCULAR_SCALE_STD,
    OBSERVED_BINS,
    RESIDUAL_FACTOR_MIN,
    RESIDUAL_SCALE_LINE,
    RESIDUAL_SHAPE_LINE,
    SHAPE_STD_M,
    body_std,
    fit_residual,
    lean_factor,
    monocular_std,
    observed_bin,
    residual_factor,
    spine_lean,
)
from pose_lifter.core.results import Camera, LiftResult

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


def _result(reprojection_px: float, scale: float, prior: bool) -> LiftResult:
    pose = np.zeros((12, 3))
    camera = Camera(np.eye(3), scale, np.zeros(2))
    return LiftResult(pose, pose, camera, np.zeros(3), 1.0, reprojection_px, 0.0, 2, True, 1, -1, np.ones(12),
                      prior_pose=pose if prior else None)


def test_the_fit_s_residual_is_its_reprojection_error_in_leg_units() -> None:
    """The hybrid fit's mean reprojection error over its camera scale; none (NaN) for a paper-mode
    fit (no prior's pose), whose close fit of its 2D says nothing of its error."""
    r = fit_residual([_result(6.0, 120.0, True), _result(6.0, 60.0, True), _result(6.0, 120.0, False)])
    np.testing.assert_allclose(r[:2], [0.05, 0.1])
    assert np.isnan(r[2])


def test_the_residual_scales_the_deviations_along_its_lines() -> None:
    """``a + b r`` above its floor, the floor below it, 1 without a residual; the monocular
    deviations' shape part scales by the shape's line, the slide along the rays by the scale's."""
    a, b = RESIDUAL_SHAPE_LINE
    r = np.array([0.0, 0.05, 0.2, np.nan])
    f = np.asarray(residual_factor(r, RESIDUAL_SHAPE_LINE))
    np.testing.assert_allclose(f[1:3], a + b * r[1:3])
    assert f[0] == max(a, RESIDUAL_FACTOR_MIN) and f[3] == 1.0
    assert residual_factor(None, RESIDUAL_SHAPE_LINE) == 1.0
    x = np.zeros((2, 12, 3))
    x[..., 2] = 4.0
    residual = np.array([0.05, 0.2])  # above both floors
    shape = np.asarray(residual_factor(residual, RESIDUAL_SHAPE_LINE))
    scale = np.asarray(residual_factor(residual, RESIDUAL_SCALE_LINE))
    assert (shape > RESIDUAL_FACTOR_MIN).all() and (scale > RESIDUAL_FACTOR_MIN).all()
    std = monocular_std(x, np.ones((2, 12)), K, residual=residual)
    for i in range(2):  # a whole body on the optical axis: x, y the shape's, z both
        np.testing.assert_allclose(std[i, :, 0], shape[i] * SHAPE_STD_M[:, 0])
        np.testing.assert_allclose(std[i, :, 2], np.hypot(shape[i] * SHAPE_STD_M[:, 1],
                                                          scale[i] * MONOCULAR_SCALE_STD[0] * 4.0))


def _upright(elevation_deg: float, distance: float = 4.0) -> np.ndarray:
    """A body standing upright (hips at y 0, shoulders 0.5 m above, the camera's y down) seen from
    ``elevation_deg`` above: its spine turned by that angle about the camera's x axis."""
    body = np.zeros((12, 3))
    body[[0, 3], 1] = -0.5  # shoulders
    body[[0, 6], 0], body[[3, 9], 0] = -0.2, 0.2  # left and right
    e = np.radians(elevation_deg)
    turn = np.array([[1.0, 0.0, 0.0], [0.0, np.cos(e), -np.sin(e)], [0.0, np.sin(e), np.cos(e)]])
    return body @ turn.T + [0.0, 0.0, distance]


def test_the_spine_s_lean_widens_the_slide_along_its_line() -> None:
    """The lean is the spine's angle out of the image plane, whichever way; the monocular slide's
    deviation scales by the lean's line (a body seen level less, one seen from above more), the
    shape's not; a degenerate spine (all joints at one point) keeps the unscaled slide."""
    bodies = np.array([_upright(0.0), _upright(30.0), _upright(-30.0)])
    np.testing.assert_allclose(spine_lean(bodies), np.radians([0.0, 30.0, 30.0]), atol=1e-12)
    a, b = LEAN_SCALE_LINE
    factor = lean_factor(bodies)
    np.testing.assert_allclose(factor, [a, a + b * np.radians(30.0), a + b * np.radians(30.0)])
    assert factor[0] < 1.0 < factor[1]
    std = monocular_std(bodies, np.ones((3, 12)), K)
    shape = SHAPE_STD_M[:, [0, 0, 1]]
    for i in range(3):  # sqrt(shape^2 + (s |x|)^2): the slide's share grows by the factor
        slide = np.sqrt(np.maximum(std[i] ** 2 - shape**2, 0.0))
        np.testing.assert_allclose(slide, factor[i] * MONOCULAR_SCALE_STD[0] * np.abs(bodies[i]), atol=1e-12)
    point = np.zeros((1, 12, 3))
    point[..., 2] = 4.0
    assert np.isnan(spine_lean(point)[0]) and lean_factor(point)[0] == 1.0
