"""Skeleton, layouts, metrics, bases file: small exact checks."""

from __future__ import annotations

import numpy as np
import pytest
import tolerances as tol
from pose_lifter.core import (
    BasisFileError,
    PoseBases,
    UnknownLayoutError,
    learn_pca_bases,
    mpjpe,
    normalise_pose,
    normalised_error,
    p_mpjpe,
    procrustes_align,
)
from pose_lifter.core.model.metrics import similarity_normalised_error
from pose_lifter.core.model.skeleton import LIMBS, body_frame, limb_lengths
from pose_lifter.core.options import LifterOptions
from pose_lifter.core.results import Camera, LiftResult, StartKind
from pose_lifter.core.solve.camera import camera_step, weighted_median
from pose_lifter.messages.layouts import get_layout, to_model_joints
from scipy.spatial.transform import Rotation


def _pose(seed: int = 0) -> np.ndarray:
    return normalise_pose(np.random.default_rng(seed).normal(size=(12, 3)))


def test_normalise_pose_is_centred_unit_leg_and_in_body_frame() -> None:
    raw = np.random.default_rng(1).normal(size=(12, 3)) * 3 + 7
    p = normalise_pose(raw)
    assert np.allclose(p.mean(0), 0)
    assert limb_lengths(p)[7] == pytest.approx(1.0)
    assert np.allclose(body_frame(p), np.eye(3), atol=tol.ROUND_OFF)
    # a rotated, shifted, scaled copy normalises to the same pose
    r = Rotation.from_euler("xyz", [10, 70, -20], degrees=True).as_matrix()
    assert np.allclose(normalise_pose(2.5 * raw @ r.T + 1.0), p, atol=tol.ROUND_OFF_LONG)
    assert len(LIMBS) == 8


def test_layouts_pick_the_paper_joints() -> None:
    coco = np.arange(34, dtype=float).reshape(17, 2)
    pts, conf = to_model_joints(coco, None, "coco17")
    assert pts[0].tolist() == coco[5].tolist() and pts[3].tolist() == coco[6].tolist()
    assert pts[11].tolist() == coco[16].tolist() and np.all(conf == 1)
    b25 = np.arange(50, dtype=float).reshape(25, 2)
    pts, _ = to_model_joints(b25, np.linspace(0, 1, 25), "body25")
    assert pts[0].tolist() == b25[5].tolist() and pts[9].tolist() == b25[9].tolist()
    assert get_layout("H36M17").model_indices[6] == 4
    with pytest.raises(UnknownLayoutError):
        get_layout("coco19")


def test_p_mpjpe_is_similarity_invariant_and_reflection_safe() -> None:
    g = _pose(2)
    r = Rotation.from_euler("xyz", [30, -50, 80], degrees=True).as_matrix()
    assert p_mpjpe(3.0 * g @ r.T + 5.0, g) == pytest.approx(0.0, abs=tol.ROUND_OFF_ACCUMULATED)
    mirrored = g * np.array([-1.0, 1.0, 1.0])
    # a mirror image is not a rotation: it must not align perfectly
    assert p_mpjpe(mirrored, g) > 0.05
    assert np.linalg.det(np.linalg.svd(procrustes_align(mirrored, g))[2]) != 0
    assert mpjpe(g + 1.0, g) == pytest.approx(0.0, abs=tol.ROUND_OFF)


def test_the_normalised_errors_share_one_reflection_safe_procrustes() -> None:
    g = _pose(3)
    r = Rotation.from_euler("xyz", [-40, 25, 110], degrees=True).as_matrix()
    noise = 0.05 * np.random.default_rng(3).normal(size=(12, 3))
    pred = 2.0 * (g + noise) @ r.T + 3.0
    # similarity-aligned, in the truth's leg units: blind to the scale, rotation and shift
    expected = np.linalg.norm(procrustes_align(g + noise, g) - g) / limb_lengths(g)[7]
    assert similarity_normalised_error(pred, g) == pytest.approx(expected, rel=tol.ROUND_OFF_ACCUMULATED)
    assert similarity_normalised_error(3.0 * pred, 2.0 * g) == pytest.approx(expected,
                                                                             rel=tol.ROUND_OFF_ACCUMULATED)
    # the paper's criterion (own leg = 1, rotation only) is blind to the rotation and shift too
    own = normalised_error(g + noise, g)
    assert normalised_error(pred, g) == pytest.approx(own, rel=tol.ROUND_OFF_ACCUMULATED)
    # neither aligns a mirror image
    mirrored = g * np.array([-1.0, 1.0, 1.0])
    assert similarity_normalised_error(mirrored, g) > 0.05 and normalised_error(mirrored, g) > 0.05
    # batched like the per-pose metrics
    batch = similarity_normalised_error(np.stack([pred, mirrored]), np.stack([g, g]))
    assert batch.shape == (2,) and batch[0] == pytest.approx(expected, rel=tol.ROUND_OFF_ACCUMULATED)


def test_weighted_median_minimises_weighted_l1() -> None:
    rng = np.random.default_rng(0)
    v, w = rng.normal(size=9), rng.uniform(0.1, 1, size=9)
    m = weighted_median(v, w)
    grid = np.linspace(-3, 3, 2001)
    best = grid[np.argmin([np.sum(w * np.abs(v - g)) for g in grid])]
    assert np.sum(w * np.abs(v - m)) <= np.sum(w * np.abs(v - best)) + tol.ROUND_OFF


def test_camera_step_recovers_a_camera_despite_two_outliers() -> None:
    rng = np.random.default_rng(5)
    y = rng.normal(size=(12, 3))
    rot = Rotation.random(random_state=4).as_matrix()
    cam = Camera(rot, 1.7, np.array([0.3, -0.2]))
    x = cam.project(y)
    x[[1, 8]] += rng.normal(scale=3.0, size=(2, 2))
    res = camera_step(x, y, np.ones(12), LifterOptions(camera_max_iter=500, camera_tol=1e-8, tau=1.0))
    assert res.converged
    assert np.allclose(res.camera.projection, cam.projection, atol=1e-4)
    assert np.allclose(res.camera.translation, cam.translation, atol=1e-4)


def test_bases_round_trip_and_bad_file(tmp_path) -> None:  # type: ignore[no-untyped-def]
    poses = np.stack([_pose(i) for i in range(60)])
    b = learn_pca_bases(poses, n_bases=10, n_starts=5, metadata={"data": "random"})
    f = tmp_path / "b.npz"
    b.save(f)
    c = PoseBases.load(f)
    assert np.array_equal(b.components, c.components) and c.method == "pca"
    assert c.metadata["data"] == "random" and c.start_alphas.shape == (5, 10)
    assert np.allclose(c.start_alphas[0], 0)
    with pytest.raises(BasisFileError):
        PoseBases.load(tmp_path / "missing.npz")
    (tmp_path / "bad.npz").write_bytes(b"not a zip")
    with pytest.raises(BasisFileError):
        PoseBases.load(tmp_path / "bad.npz")


def test_pca_bases_are_signed_by_their_convention_not_by_the_svd() -> None:
    # An SVD fixes each direction only up to its sign, and which sign LAPACK returns changes with
    # the BLAS kernel: the bases, and every problem and code built on them, must not.
    poses = np.stack([_pose(i) for i in range(60)])
    b = learn_pca_bases(poses, n_bases=10, n_starts=5)
    comps = b.components  # (36, 10)
    lead = comps[np.abs(comps).argmax(axis=0), np.arange(comps.shape[1])]
    assert np.all(lead > 0.0)  # each direction's entry of largest magnitude is positive
    x = poses.reshape(len(poses), -1)
    _, _, vt = np.linalg.svd(x - x.mean(axis=0), full_matrices=False)
    # the principal directions themselves, in order: only their signs are chosen
    np.testing.assert_allclose(np.abs(comps.T @ vt[:10].T), np.eye(10), atol=tol.ROUND_OFF_ACCUMULATED)


def test_packaged_bases_match_the_paper_setup() -> None:
    b = PoseBases.load()
    assert b.method == "sparse" and b.n_bases == 200
    assert b.limb_proportions[7] == pytest.approx(1.0)
    assert b.start_alphas.shape[0] == 30


def test_a_results_pose_replaced_shares_everything_else() -> None:
    """``LiftResult.with_pose`` (the per-frame copy of the smoothing and the measurement update)
    gives what ``dataclasses.replace`` gives, and leaves the original as it was; a camera's
    projection is its scaled first two rotation rows."""
    import dataclasses

    rot = Rotation.from_euler("xyz", [0.3, -0.2, 1.1]).as_matrix()
    cam = Camera(rot, 2.5, np.array([3.0, -1.0]))
    np.testing.assert_array_equal(cam.projection, 2.5 * rot[:2])
    assert cam.projection is cam.projection  # computed once
    rng = np.random.default_rng(1)
    pose, pose_camera, alpha = rng.normal(size=(12, 3)), rng.normal(size=(12, 3)), rng.normal(size=8)
    res = LiftResult(pose=pose, pose_camera=pose_camera, camera=cam, alpha=alpha, objective=1.5,
                     reprojection_error=0.2, limb_violation=0.0, n_iter=2, converged=True, n_starts=1,
                     start_index=-1, weights=np.ones(12), total_alternations=2, start=StartKind.PRIOR)
    new_pose, new_cam = rng.normal(size=(12, 3)), rng.normal(size=(12, 3))
    both = res.with_pose(new_pose, new_cam)
    assert both == dataclasses.replace(res, pose=new_pose, pose_camera=new_cam)
    assert both.pose is new_pose and both.pose_camera is new_cam and both.camera is cam
    assert res.pose is pose and res.pose_camera is pose_camera  # the original unchanged
    only = res.with_pose(pose_camera=new_cam)
    assert only.pose is pose and only.pose_camera is new_cam and only.alpha is alpha
    with pytest.raises(dataclasses.FrozenInstanceError):
        both.pose = pose  # type: ignore[misc]
    centred = new_cam - new_cam.mean(axis=0)
    derived = res.with_camera_pose(centred)  # pose_camera = (pose - mean) R^T, the centre kept
    assert derived.pose_camera is not None
    np.testing.assert_array_equal(derived.pose_camera, centred)
    np.testing.assert_allclose(derived.pose.mean(axis=0), pose.mean(axis=0), atol=1e-12)
    np.testing.assert_allclose((derived.pose - derived.pose.mean(axis=0)) @ rot.T, centred, atol=1e-12)
    assert derived.camera is cam and derived.alpha is alpha
