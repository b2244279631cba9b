"""The depth fusion (pose_lifter.core.depth) on small problems with a known answer: a body whose
joints are painted into a depth image as disks at their surface depth, at a scale the monocular
placement does not know."""

from __future__ import annotations

import numpy as np
import pytest
from numpy.typing import NDArray
from pose_lifter.core.depth import (
    SURFACE_OFFSET_M,
    DepthOptions,
    FusedPeople,
    fuse_depth,
    monocular_std,
    read_patches,
)
from pose_lifter.core.depth.fuse import _hidden
from pose_lifter.core.depth.reading import sensor_std
from pose_lifter.core.depth.uncertainty import RESIDUAL_SHAPE_LINE
from pose_lifter.core.track.placement import place_poses
from synthetic_poses import synthetic_poses
from tolerances import ROUND_OFF_ACCUMULATED

K = ((800.0, 800.0), (320.0, 240.0))
SIZE = (480, 640)
#: How far the fused joints may be from the truth when every reading is exact: metres. The fit's
#: stopping rule and the readings' 1 mm variance floor, and the prior on the scale (the monocular
#: placement's own error, a few per cent) that shrinks a 10 % scale error by ~1 % of itself.
EXACT_READING_M = 5e-3


def _project(x: NDArray[np.float64]) -> NDArray[np.float64]:
    (fx, fy), (cx, cy) = K
    return np.stack([fx * x[..., 0] / x[..., 2] + cx, fy * x[..., 1] / x[..., 2] + cy], axis=-1)


def _body(k: float = 1.1, seed: int = 3) -> tuple[NDArray[np.float64], NDArray[np.float64], float,
                                                   NDArray[np.float64]]:
    """A synthetic pose in the camera frame (leg units, centred), its camera scale and centre for a
    person about 4.5 m away (wholly in the image), and the true joints: the monocular placement
    scaled by ``k``."""
    pose = synthetic_poses(1, seed=seed)[0][0] * np.array([1.0, -1.0, -1.0])
    pose -= pose.mean(axis=0)
    scale, centre = 800.0 * 0.43 / 4.5, np.array([310.0, 235.0])
    x0 = place_poses(pose[None], np.array([scale]), centre[None], 0.43, K[0], K[1], 5.0)[0]
    return pose, centre, scale, k * x0


def _painted(joints: NDArray[np.float64], radius_px: float = 12.0, background: float = np.nan,
             shift: dict[int, float] | None = None) -> NDArray[np.float32]:
    """A depth image: each joint a disk at its surface depth (its depth minus its surface offset,
    plus ``shift``), nearer disks over farther ones."""
    img = np.full(SIZE, np.inf)
    v, u = np.mgrid[0:SIZE[0], 0:SIZE[1]]
    pix = _project(joints)
    for j in range(12):
        z = joints[j, 2] - SURFACE_OFFSET_M[j] + (shift or {}).get(j, 0.0)
        disk = (u - pix[j, 0]) ** 2 + (v - pix[j, 1]) ** 2 <= radius_px**2
        img[disk] = np.minimum(img[disk], z)
    img[np.isinf(img)] = background
    return img.astype(np.float32)


def _fuse(pose: NDArray[np.float64], centre: NDArray[np.float64], scale: float, truth: NDArray[np.float64],
          depth: NDArray[np.float32], weights: NDArray[np.float64] | None = None) -> FusedPeople:
    w = np.ones((1, 12)) if weights is None else weights[None]
    return fuse_depth(depth, K, _project(truth)[None], w, pose[None], np.array([scale]), centre[None])


def test_patch_reading_is_the_median_of_the_band() -> None:
    """Noisy readings of one surface: the reading is the median of the patch's in-band pixels
    (an independent reference: numpy's nanmedian of the same pixels)."""
    rng = np.random.default_rng(0)
    img = (2.5 + 0.01 * rng.standard_normal(SIZE)).astype(np.float32)
    img[rng.random(SIZE) < 0.3] = np.nan
    opt = DepthOptions(trim=1e9)  # no trimming: the plain median
    r = read_patches(img, np.array([[200.0, 100.0]]), np.array([4.0]), np.array([2.5]), opt)
    v, u = np.mgrid[0:SIZE[0], 0:SIZE[1]]
    patch = img[(u - 200) ** 2 + (v - 100) ** 2 <= 16].astype(np.float64)
    assert abs(float(r.surface[0]) - float(np.nanmedian(patch))) < ROUND_OFF_ACCUMULATED
    assert int(r.n_pixels[0]) == int(np.isfinite(patch).sum())


def test_patch_reading_drops_background_holes_and_mixed_pixels() -> None:
    img = np.full(SIZE, 6.0, dtype=np.float32)  # the wall
    img[100:200, 100:130] = 2.0  # a limb, 30 px wide
    img[100:200, 130] = 4.0  # mixed pixels at its silhouette
    img[150:153, 110:113] = np.nan  # a hole
    opt = DepthOptions()
    # on the limb, near its edge (the patch spills over the mixed pixels and the wall)
    r = read_patches(img, np.array([[126.0, 150.0], [115.0, 150.0]]), np.array([6.0, 6.0]),
                     np.array([2.1, 2.1]), opt)
    assert np.allclose(r.surface, 2.0, atol=ROUND_OFF_ACCUMULATED)
    # a flat surface: the median of the sensor's noise over the patch's independent draws (one a 3x3
    # window of the correlated noise: the patch's every pixel is sampled at this size)
    n_eff = r.n_pixels / opt.noise_window_px**2
    assert np.allclose(r.var, 0.5 * np.pi * sensor_std(np.array([2.0, 2.0]), opt) ** 2 / n_eff, rtol=1e-6)
    # off the limb (the wall only), outside the image, non-finite: no reading
    r = read_patches(img, np.array([[300.0, 300.0], [-50.0, 10.0], [np.nan, 5.0]]), np.full(3, 6.0),
                     np.full(3, 2.1), opt)
    assert np.isnan(r.surface).all() and (r.n_pixels == 0).all()


def test_exact_readings_give_the_metric_body() -> None:
    pose, centre, scale, truth = _body(k=1.1)
    fused = _fuse(pose, centre, scale, truth, _painted(truth))
    assert fused.from_depth.all() and fused.converged.all()
    assert abs(float(fused.leg_m[0]) - 0.43 * 1.1) < 1e-3
    assert np.abs(fused.joints_m[0] - truth).max() < EXACT_READING_M
    assert np.isfinite(fused.std_m).all() and (fused.std_m > 0).all()


def test_without_the_surface_offset_the_joints_sit_on_the_surface() -> None:
    """The offset is what moves a reading from the skin to the joint: painted without it (the
    reading at the joint's own depth), the fused joints come out in front by about the offsets."""
    pose, centre, scale, truth = _body(k=1.1)
    fused = _fuse(pose, centre, scale, truth, _painted(truth, shift=dict(enumerate(SURFACE_OFFSET_M))))
    err_z = fused.joints_m[0, :, 2] - truth[:, 2]
    assert (err_z > 0.5 * SURFACE_OFFSET_M).all()


def test_a_reading_off_the_body_is_dropped() -> None:
    pose, centre, scale, truth = _body(k=0.95)
    fused = _fuse(pose, centre, scale, truth, _painted(truth, shift={5: -0.6}))  # something before a wrist
    assert not fused.from_depth[0, 5] and fused.from_depth[0, np.arange(12) != 5].all()
    assert abs(float(fused.leg_m[0]) - 0.43 * 0.95) < 1e-3
    others = np.arange(12) != 5
    assert np.abs(fused.joints_m[0, others] - truth[others]).max() < EXACT_READING_M


def test_no_reading_keeps_the_monocular_placement() -> None:
    pose, centre, scale, truth = _body(k=1.2)
    fused = _fuse(pose, centre, scale, truth, np.full(SIZE, np.nan, dtype=np.float32))
    x0 = truth / 1.2
    assert not fused.from_depth.any() and fused.converged.all() and fused.n_iter[0] == 0
    assert np.allclose(fused.joints_m[0], x0, atol=ROUND_OFF_ACCUMULATED)
    assert np.allclose(fused.std_m, monocular_std(x0[None], np.ones((1, 12)), K),
                       atol=ROUND_OFF_ACCUMULATED)


def test_an_unobserved_joint_is_not_read() -> None:
    pose, centre, scale, truth = _body()
    w = np.ones(12)
    w[2] = 0.0
    fused = _fuse(pose, centre, scale, truth, _painted(truth), weights=w)
    assert not fused.from_depth[0, 2] and fused.from_depth[0, np.arange(12) != 2].all()
    assert (fused.std_m[0, 2] > fused.std_m[0, 1]).all()  # per axis: the wrist is less sure than its elbow


@pytest.mark.parametrize(("wrist_z", "hidden"), [(0.35, True), (-0.35, False)])
def test_a_wrist_behind_the_torso_is_hidden(wrist_z: float, hidden: bool) -> None:
    """A wrist on the torso's image is hidden when it is behind the torso, seen when in front."""
    body = np.array([[0.2, -0.5, 3.0], [0.3, -0.2, 3.0], [0.0, 0.0, 3.0], [-0.2, -0.5, 3.0],
                     [-0.3, -0.2, 3.0], [-0.4, 0.0, 3.0], [0.15, 0.1, 3.0], [0.15, 0.5, 3.0],
                     [0.15, 0.9, 3.0], [-0.15, 0.1, 3.0], [-0.15, 0.5, 3.0], [-0.15, 0.9, 3.0]])
    body[2, 2] += wrist_z
    got = _hidden(body[None], _project(body)[None], np.ones((1, 12), dtype=bool), K, 0.08)
    assert bool(got[0, 2]) is hidden
    assert not got[0, [0, 3, 6, 9]].any()  # the torso's own joints are never hidden by it


def test_seen_from_the_side_the_trunk_hides_the_far_shoulder_and_hip() -> None:
    """A body seen from its right side, its right arm and leg reaching forward (off the trunk's
    image): its left shoulder and hip lie behind the trunk on their pixels, no limb in front of
    them; the right ones are seen."""
    side = np.array([[0.0, -0.5, 3.2], [0.0, -0.2, 3.25], [0.0, 0.05, 3.25], [0.0, -0.5, 2.8],
                     [0.3, -0.45, 2.8], [0.6, -0.45, 2.8], [0.0, 0.1, 3.15], [0.0, 0.5, 3.15],
                     [0.0, 0.9, 3.15], [0.0, 0.1, 2.85], [0.35, 0.4, 2.85], [0.4, 0.8, 2.85]])
    got = _hidden(side[None], _project(side)[None], np.ones((1, 12), dtype=bool), K, 0.08)[0]
    assert got[[0, 6]].all()  # left shoulder, left hip: behind the trunk
    assert not got[[3, 4, 5, 9, 10, 11]].any()  # the right side: in front


@pytest.mark.parametrize("above_m", [0.15, 0.3])
def test_seen_from_the_side_the_neck_and_head_hide_the_far_shoulder(above_m: float) -> None:
    """The side view's far shoulder read above the trunk's top (its keypoint ``above_m`` higher,
    as a camera above the person sees it): the neck (0.15 m) or the head (0.3 m) in front of it
    hides it; the near shoulder read the same way lies in front of them and is seen."""
    side = np.array([[0.0, -0.5, 3.2], [0.0, -0.2, 3.25], [0.0, 0.05, 3.25], [0.0, -0.5, 2.8],
                     [0.3, -0.45, 2.8], [0.6, -0.45, 2.8], [0.0, 0.1, 3.15], [0.0, 0.5, 3.15],
                     [0.0, 0.9, 3.15], [0.0, 0.1, 2.85], [0.35, 0.4, 2.85], [0.4, 0.8, 2.85]])
    keypoints = side.copy()
    keypoints[[0, 3], 1] -= above_m
    got = _hidden(side[None], _project(keypoints)[None], np.ones((1, 12), dtype=bool), K, 0.08)[0]
    assert got[0] and not got[3]


def test_readings_fuse_a_later_pose_without_the_image() -> None:
    """A frame's readings fuse another pose of the same people (refined over later frames) as the
    image would: the readings do not depend on the pose beyond the occlusion test."""
    from pose_lifter.core.depth import fuse_readings, read_depth

    pose, centre, scale, truth = _body(k=1.05)
    img = _painted(truth)
    args = (K, _project(truth)[None], np.ones((1, 12)))
    readings = read_depth(img, *args, pose[None], np.array([scale]), centre[None])
    assert np.isfinite(readings.depth_m).all()
    other = pose + 0.02 * np.random.default_rng(1).standard_normal(pose.shape)
    later = fuse_readings(readings, *args, other[None], np.array([scale]), centre[None])
    direct = fuse_depth(img, *args, other[None], np.array([scale]), centre[None])
    assert np.allclose(later.joints_m, direct.joints_m, atol=ROUND_OFF_ACCUMULATED)
    assert np.allclose(later.std_m, direct.std_m, atol=ROUND_OFF_ACCUMULATED)


def test_the_conditioning_is_the_textbook_gaussian_one() -> None:
    """The kernels' ``condition`` against the conditional mean and covariance computed on the read
    joints alone, ``m + S[:, R] (S[R, R] + V)^-1 (d_R - m_R)``, for random priors and reading sets
    (an unread joint: the fusion's ``_UNREAD_VAR`` and no residual)."""
    from pose_lifter.core.depth.fuse import _UNREAD_VAR
    from pose_lifter.core.depth.kernels import condition
    from tolerances import DEPTH_CONDITIONING

    rng = np.random.default_rng(5)
    for _ in range(20):
        a = 0.05 * rng.standard_normal((12, 12))
        prior = a @ a.T + 1e-4 * np.eye(12)
        mean = 3.0 + 0.1 * rng.standard_normal(12)
        d = mean + 0.05 * rng.standard_normal(12)
        v = 1e-4 * (1.0 + rng.random(12))
        kept = rng.random(12) < 0.6
        r = np.flatnonzero(kept)
        gain = prior[:, r] @ np.linalg.inv(prior[np.ix_(r, r)] + np.diag(v[r]))
        want_z = mean + gain @ (d[r] - mean[r])
        want_sd = np.sqrt(np.diag(prior - gain @ prior[r, :]))
        shift, sd = np.empty(12), np.empty(12)
        condition(prior, np.where(kept, d - mean, 0.0), np.where(kept, v, _UNREAD_VAR), shift, sd)
        assert np.abs(mean + shift - want_z).max() < DEPTH_CONDITIONING
        assert np.abs(sd - want_sd).max() < DEPTH_CONDITIONING


def test_a_read_elbow_takes_its_unread_wrist_along() -> None:
    """The left elbow and wrist lie 8 cm deeper than the lift says (an arm leaning away), the
    wrist unseen by the 2D: the elbow's reading moves the wrist with it through the shape's
    correlation between them (a fusion of independent joints leaves it where the lift put it)."""
    pose, centre, scale, truth = _body(k=1.0)
    lifted = truth.copy()
    truth[[1, 2], 2] += 0.08
    w = np.ones(12)
    w[2] = 0.0
    fused = fuse_depth(_painted(truth), K, _project(truth)[None], w[None], pose[None], np.array([scale]),
                       centre[None])
    assert fused.from_depth[0, 1] and not fused.from_depth[0, 2]
    elbow, wrist = fused.joints_m[0, [1, 2], 2] - lifted[[1, 2], 2]
    assert 0.5 * 0.08 < elbow < 0.08 + 0.01  # the elbow: most of the way to its reading
    assert 0.5 * elbow < wrist < 0.08 + 0.01  # the wrist: along with it, not past the truth


def test_leave_one_out_is_the_conditioning_on_the_other_readings() -> None:
    """The kernels' ``leave_one_out`` against conditioning on the other kept readings one at a time
    (the textbook formula): each read joint's predicted residual and its variance."""
    from pose_lifter.core.depth.fuse import _UNREAD_VAR
    from pose_lifter.core.depth.kernels import leave_one_out
    from tolerances import DEPTH_CONDITIONING

    rng = np.random.default_rng(6)
    for _ in range(10):
        a = 0.05 * rng.standard_normal((12, 12))
        prior = a @ a.T + 1e-4 * np.eye(12)
        residual = 0.05 * rng.standard_normal(12)
        v = 1e-4 * (1.0 + rng.random(12))
        kept = rng.random(12) < 0.7
        got, got_var = np.empty(12), np.empty(12)
        leave_one_out(prior, np.where(kept, residual, 0.0), np.where(kept, v, _UNREAD_VAR), got, got_var)
        for j in np.flatnonzero(kept):
            r = np.flatnonzero(kept & (np.arange(12) != j))
            gain = prior[j, r] @ np.linalg.inv(prior[np.ix_(r, r)] + np.diag(v[r]))
            assert abs(got[j] - (residual[j] - gain @ residual[r])) < DEPTH_CONDITIONING
            assert abs(got_var[j] - (prior[j, j] - gain @ prior[r, j])) < DEPTH_CONDITIONING


def test_a_reading_its_neighbours_contradict_is_dropped() -> None:
    """A left wrist read 22 cm too near (a hand in front of it, unmodelled) while its elbow and
    the rest read true: what the other readings predict of the wrist rejects the reading, and
    the wrist stays near the truth (judged against the field alone, the reading is 2.9 of its
    standard deviations off and kept, pulling the wrist 15 cm)."""
    pose, centre, scale, truth = _body(k=1.0)
    fused = _fuse(pose, centre, scale, truth, _painted(truth, shift={2: -0.22}))
    assert not fused.from_depth[0, 2] and fused.from_depth[0, np.arange(12) != 2].all()
    assert abs(fused.joints_m[0, 2, 2] - truth[2, 2]) < 0.03


def test_the_shape_scale_is_the_fits_variance_factor_shrunk_towards_one() -> None:
    """``shape_scale`` against its formula written out per body: readings on the field give
    sqrt(nu0 / (nu0 + n)), residuals of s_j give 1, a residual past the gate counts as the gate,
    and a body without a reading keeps 1."""
    from pose_lifter.core.depth.fuse import SHAPE_SCALE_DOF, shape_scale

    rng = np.random.default_rng(7)
    n = 4
    g = np.concatenate([rng.uniform(2.5, 3.5, (n, 12, 1)), rng.normal(scale=0.3, size=(n, 12, 2))], axis=-1)
    theta = np.array([[1.05, 0.01, -0.02]] * n)
    v = rng.uniform(1e-4, 1e-3, (n, 12))
    shape_z = rng.uniform(0.03, 0.1, (n, 12))
    sd = np.sqrt(v + (theta[:, :1] * shape_z) ** 2)
    field = np.einsum("njc,nc->nj", g, theta)
    have = np.ones((n, 12), dtype=bool)
    have[1, :5] = False
    have[3] = False
    sign = rng.choice([-1.0, 1.0], (n, 12))
    d = field.copy()
    d[1] += sign[1] * sd[1]  # each residual one of its deviations
    d[2] += sign[2] * 2.0 * sd[2]
    d[2, 0] += 50.0 * sd[2, 0]  # past the gate
    got = shape_scale(d, v, g, have, theta, shape_z, 3.0)
    nu0 = SHAPE_SCALE_DOF
    want = [np.sqrt(nu0 / (nu0 + 12)), 1.0, np.sqrt((nu0 + 11 * 4.0 + 9.0) / (nu0 + 12)), 1.0]
    np.testing.assert_allclose(got, want, rtol=1e-9)


def test_readings_that_disagree_with_the_shape_widen_the_unread_joints() -> None:
    """The same body read twice, once true and once with its knees and ankles 25 cm deeper than
    its lifted shape (the readings kept): the unread wrists' depth deviations are wider the second
    time (equal without the shape scale)."""
    pose, centre, scale, truth = _body(k=1.0)
    w = np.ones(12)
    w[[2, 5]] = 0.0
    legs = {j: 0.25 for j in (7, 8, 10, 11)}
    agree = fuse_depth(_painted(truth), K, _project(truth)[None], w[None], pose[None], np.array([scale]),
                       centre[None])
    disagree = fuse_depth(_painted(truth, shift=legs), K, _project(truth)[None], w[None], pose[None],
                          np.array([scale]), centre[None])
    assert disagree.from_depth[0, [7, 8, 10, 11]].all()
    assert (disagree.std_m[0, [2, 5], 2] > 1.3 * agree.std_m[0, [2, 5], 2]).all()


def test_a_fit_far_from_its_2d_widens_the_joints_the_depth_does_not_fix() -> None:
    """The same body and readings fused for a fit whose 2D residual doubles the shape's deviations
    (its residual_factor 2 against 1): the unread wrists' deviations nearly double along the image,
    their depth ones widen; the read joints' depths, carried by their readings, widen far less
    (not exactly twice where read: the readings fix the body's distance, and the shape scale
    weighs the readings' residuals against the wider shape). Without a reading the fusion keeps
    the monocular deviations of the same residual."""
    pose, centre, scale, truth = _body(k=1.0)
    a, b = RESIDUAL_SHAPE_LINE
    one, two = (1.0 - a) / b, (2.0 - a) / b
    w = np.ones(12)
    w[[2, 5]] = 0.0
    args = (K, _project(truth)[None], w[None], pose[None], np.array([scale]), centre[None])
    typical = fuse_depth(_painted(truth), *args, residuals=np.array([one]))
    far = fuse_depth(_painted(truth), *args, residuals=np.array([two]))
    assert (far.std_m[0, [2, 5], :2] > 1.8 * typical.std_m[0, [2, 5], :2]).all()
    assert (far.std_m[0, [2, 5], 2] > 1.3 * typical.std_m[0, [2, 5], 2]).all()
    read = typical.from_depth[0] & far.from_depth[0]
    assert read.sum() >= 8 and (far.std_m[0, read, 2] < 1.3 * typical.std_m[0, read, 2]).all()
    blank = fuse_depth(np.full(SIZE, np.nan, dtype=np.float32), *args, residuals=np.array([two]))
    alone = monocular_std(blank.joints_m, w[None], K, residual=np.array([two]))
    np.testing.assert_allclose(blank.std_m, alone, rtol=1e-9)
