"""Test-time flip averaging of the learned prior (``LifterOptions.prior_flip``): the mirror maps
are involutions that swap left and right, and the averaged prediction is mirror-equivariant."""

from __future__ import annotations

import numpy as np
import pytest
from pose_lifter.core.model.prior import PosePrior, mirror_features, mirror_pose, prior_features
from pose_lifter.core.model.skeleton import JOINTS_LEFT, JOINTS_RIGHT

#: float32 inference: two batches of the same two rows in another order agree to rounding.
FLOAT32_REL = 1e-5


@pytest.fixture(scope="module")
def detection() -> tuple[np.ndarray, np.ndarray]:
    rng = np.random.default_rng(3)
    pts = rng.uniform(100, 500, size=(12, 2))
    vis = np.ones(12, dtype=bool)
    vis[[1, 10]] = False  # one left and one right joint missing
    return pts, vis


def _mirror_image(pts: np.ndarray, vis: np.ndarray, width: float = 640.0) -> tuple[np.ndarray, np.ndarray]:
    """The detection of the left-right flipped image: x -> width - x, a left joint becomes the right."""
    swap = np.arange(12)
    swap[list(JOINTS_LEFT)], swap[list(JOINTS_RIGHT)] = JOINTS_RIGHT, JOINTS_LEFT
    out = pts[swap].copy()
    out[:, 0] = width - out[:, 0]
    return out, vis[swap]


def test_mirroring_is_an_involution_that_swaps_sides(detection: tuple[np.ndarray, np.ndarray]) -> None:
    pts, vis = detection
    feats, _, _ = prior_features(pts, vis)
    np.testing.assert_array_equal(mirror_features(mirror_features(feats)), feats)
    # the features of the mirrored image are the mirrored features (normalisation commutes)
    mpts, mvis = _mirror_image(pts, vis)
    np.testing.assert_allclose(mirror_features(feats), prior_features(mpts, mvis)[0], atol=1e-12)
    pose = np.random.default_rng(4).normal(size=(12, 3))
    back = mirror_pose(mirror_pose(pose))
    np.testing.assert_array_equal(back, pose)
    m = mirror_pose(pose)
    np.testing.assert_array_equal(m[JOINTS_LEFT[0]], pose[JOINTS_RIGHT[0]] * [-1, 1, 1])
    # windows: every frame mirrored on its own
    win = np.concatenate([feats, feats[::-1]])
    np.testing.assert_array_equal(mirror_features(win)[:36], mirror_features(feats))


def test_flip_averaged_prediction_is_mirror_equivariant(detection: tuple[np.ndarray, np.ndarray]) -> None:
    prior = PosePrior.load()
    pts, vis = detection
    mpts, mvis = _mirror_image(pts, vis)
    a = prior.predict(pts, vis, flip=True)
    b = prior.predict(mpts, mvis, flip=True)
    # the mirrored image's pose is the pose mirrored (x about the image's mirror line)
    expect = mirror_pose(a)
    expect[:, 0] += 640.0
    scale = np.abs(a).max()
    np.testing.assert_allclose(b, expect, atol=FLOAT32_REL * scale)
    # without averaging the network is not equivariant: the test can tell the two apart
    c = prior.predict(mpts, mvis)
    plain = mirror_pose(prior.predict(pts, vis))
    plain[:, 0] += 640.0
    assert np.abs(c - plain).max() > 100 * FLOAT32_REL * scale
