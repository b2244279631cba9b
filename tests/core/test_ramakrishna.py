"""The Ramakrishna et al. (2012) baseline: projected matching pursuit with one limb condition."""

from __future__ import annotations

import numpy as np
import pytest
import tolerances as tol
from numpy.typing import NDArray
from pose_lifter.core.baselines import ramakrishna as rk
from pose_lifter.core.errors import InvalidInputError, OptionsError, TooFewJointsError
from pose_lifter.core.model.bases import PoseBases, learn_classwise_pca_bases
from pose_lifter.core.model.metrics import p_mpjpe
from pose_lifter.core.model.skeleton import limb_lengths
from pose_lifter.core.results import Camera
from scipy.optimize import minimize
from scipy.spatial.transform import Rotation
from synthetic_poses import synthetic_poses


@pytest.fixture(scope="module")
def bases() -> PoseBases:
    poses, labels = synthetic_poses(400, seed=1)
    return learn_classwise_pca_bases(poses, labels, n_per_class=4, n_starts=3)


def _camera(seed: int) -> Camera:
    return Camera(Rotation.random(random_state=seed).as_matrix(), 100.0, np.array([320.0, 240.0]))


def test_single_basis_poses_recovered_from_noise_free_2d(bases: PoseBases) -> None:
    # y = mu + b_i: the pursuit should pick b_i first and reproduce the pose exactly.
    # Measured: 13 of 15 exact (P-MPJPE < 1e-4); 2 fall into a wrong camera basin from the
    # mean-pose initialisation (P-MPJPE ~0.15, still below the mean-pose floor ~0.2).
    errs, floors = [], []
    for i in range(bases.n_bases):
        alpha = np.zeros(bases.n_bases)
        alpha[i] = 1.0
        truth = bases.pose(alpha)
        res = rk.ramakrishna_lift(_camera(i).project(truth), None, bases, max_bases=4,
                                  target_lengths=limb_lengths(truth))
        errs.append(float(p_mpjpe(res.pose, truth)))
        floors.append(float(p_mpjpe(bases.mean_pose, truth)))
    errs_a, floors_a = np.array(errs), np.array(floors)
    assert np.sum(errs_a < 1e-3) >= 12
    assert np.all(errs_a < floors_a)


def test_sparse_poses_in_span_beat_mean_pose(bases: PoseBases) -> None:
    rng = np.random.default_rng(0)
    errs, floors = [], []
    for i in range(6):
        idx = [5 * (i % 3) + j for j in range(3)]  # class offset + 2 of its components
        alpha = np.zeros(bases.n_bases)
        alpha[idx] = rng.normal(size=3) * np.array([1.0, 0.5, 0.3])
        truth = bases.pose(alpha)
        res = rk.ramakrishna_lift(_camera(i).project(truth), None, bases, max_bases=8,
                                  target_lengths=limb_lengths(truth))
        errs.append(float(p_mpjpe(res.pose, truth)))
        floors.append(float(p_mpjpe(bases.mean_pose, truth)))
    # measured: 5 of 6 below 0.04 (right lower leg = 1), one camera-basin failure
    assert np.median(errs) < 0.04
    assert np.sum(np.array(errs) < 0.05) >= 5


@pytest.mark.parametrize("mode", ["sum", "sum_squared"])
def test_limb_condition_holds_and_result_is_consistent(bases: PoseBases, mode: str) -> None:
    rng = np.random.default_rng(3)
    poses, _ = synthetic_poses(3, seed=7)
    opts = rk.RamakrishnaOptions(limb_constraint=mode)  # type: ignore[arg-type]
    for j, truth in enumerate(poses):
        cam = _camera(10 + j)
        x = cam.project(truth) + rng.normal(scale=2.0, size=(12, 2))
        conf = np.ones(12)
        conf[[2, 8]] = 0.0  # two missing joints
        x[[2, 8]] = 1e6  # garbage there must not matter
        res = rk.ramakrishna_lift(x, conf, bases, options=opts)
        tl = bases.limb_proportions
        assert abs(rk.limb_sum_residual(res.pose, tl, mode)) <= tol.LIFT_LIMB_VIOLATION
        model = bases.mean + bases.components @ res.alpha
        np.testing.assert_allclose(res.pose.reshape(-1), model, atol=tol.ROUND_OFF)
        assert 1 <= np.count_nonzero(res.alpha) <= opts.max_bases
        np.testing.assert_array_equal(res.weights, conf)
        vis = conf > 0
        reproj = np.linalg.norm(res.camera.project(res.pose)[vis] - x[vis], axis=1).mean()
        assert res.reprojection_error == pytest.approx(reproj)
        rot = res.camera.rotation
        np.testing.assert_allclose(rot @ rot.T, np.eye(3), atol=tol.ROUND_OFF_LONG)
        assert np.linalg.det(rot) == pytest.approx(1.0)
        np.testing.assert_allclose(res.pose_camera, (res.pose - res.pose.mean(axis=0)) @ rot.T,
                                   atol=tol.ROUND_OFF)
        assert res.limb_violation == pytest.approx(np.max(np.abs(limb_lengths(res.pose) - tl)))
        # only the sum is constrained: individual limbs are generally off
        assert res.limb_violation > tol.LIFT_LIMB_VIOLATION


def test_deterministic(bases: PoseBases) -> None:
    poses, _ = synthetic_poses(1, seed=11)
    x = _camera(5).project(poses[0]) + np.random.default_rng(1).normal(size=(12, 2))
    a = rk.ramakrishna_lift(x, None, bases)
    b = rk.ramakrishna_lift(x, None, bases)
    np.testing.assert_array_equal(a.pose, b.pose)
    np.testing.assert_array_equal(a.alpha, b.alpha)
    assert a.objective == b.objective


def test_max_bases_caps_the_pursuit(bases: PoseBases) -> None:
    poses, _ = synthetic_poses(1, seed=12)
    x = _camera(6).project(poses[0])
    for cap in (1, 2, 5):
        res = rk.ramakrishna_lift(x, None, bases, max_bases=cap)
        assert np.count_nonzero(res.alpha) <= cap
        assert res.n_iter <= cap


def test_bad_input(bases: PoseBases) -> None:
    x = np.zeros((12, 2))
    with pytest.raises(InvalidInputError):
        rk.ramakrishna_lift(np.zeros((11, 2)), None, bases)
    with pytest.raises(TooFewJointsError):
        rk.ramakrishna_lift(x, np.r_[np.ones(4), np.zeros(8)], bases)
    with pytest.raises(InvalidInputError):
        rk.ramakrishna_lift(x, None, bases)  # all joints at one point
    with pytest.raises(InvalidInputError):
        rk.ramakrishna_lift(np.full((12, 2), np.nan), None, bases)
    with pytest.raises(OptionsError):
        rk.RamakrishnaOptions(limb_constraint="each")  # type: ignore[arg-type]


def test_camera_fit_recovers_camera() -> None:
    rng = np.random.default_rng(4)
    for seed in range(3):
        cam = Camera(Rotation.random(random_state=seed).as_matrix(), 2.0, rng.normal(size=2))
        y = rng.normal(size=(12, 3))
        w = np.ones(12)
        w[0] = 0.0
        rot, s, t = rk._fit_camera_ls(cam.project(y) + np.eye(12, 2)[:, :1] * 5.0 * (1 - w[:, None]), y, w)
        np.testing.assert_allclose(rot[:2], cam.rotation[:2], atol=1e-8)
        assert s == pytest.approx(2.0, abs=1e-8)
        np.testing.assert_allclose(t, cam.translation, atol=1e-8)


def _quad_problem(seed: int, q: int) -> tuple[NDArray[np.float64], ...]:
    rng = np.random.default_rng(seed)
    a = rng.normal(size=(10, q))
    d = rng.normal(size=(6, q))
    return a.T @ a, a.T @ rng.normal(size=10), d.T @ d, d.T @ rng.normal(size=6), rng


@pytest.mark.parametrize("seed", range(6))
def test_gtrs_is_global_against_multistart_slsqp(seed: int) -> None:
    h, c, e_mat, e_vec, rng = _quad_problem(seed, 4)
    eps = -float(rng.uniform(1.0, 20.0))
    a = rk._gtrs(h, c, e_mat, e_vec, eps)

    def con(z: NDArray[np.float64]) -> float:
        return float(z @ e_mat @ z + 2 * e_vec @ z + eps)

    def obj(z: NDArray[np.float64]) -> float:
        return float(z @ h @ z - 2 * c @ z)

    assert abs(con(a)) <= 1e-8
    for _ in range(8):
        res = minimize(obj, rng.normal(size=4) * 3, method="SLSQP",
                       constraints=[{"type": "eq", "fun": con}], options={"ftol": 1e-12, "maxiter": 500})
        if res.success and abs(con(res.x)) < 1e-7:
            assert obj(a) <= res.fun + 1e-7 * (1 + abs(res.fun))


def test_gtrs_hard_case_uses_null_direction() -> None:
    # H singular with c in its range: the best point is on the LS solution set, moved
    # along H's null space onto the constraint (zero extra cost).
    h = np.diag([2.0, 1.0, 0.0])
    c = np.array([2.0, 1.0, 0.0])  # LS solution (1, 1, z) for any z
    a = rk._gtrs(h, c, np.eye(3), np.zeros(3), -11.0)  # ||a||^2 = 11
    np.testing.assert_allclose(a[:2], [1.0, 1.0], atol=tol.ROUND_OFF_ACCUMULATED)
    assert abs(a[2]) == pytest.approx(3.0, abs=tol.ROUND_OFF_ACCUMULATED)


def test_lifter_wrapper_matches_function(bases: PoseBases) -> None:
    poses, _ = synthetic_poses(2, seed=13)
    x = np.stack([_camera(7 + i).project(p) for i, p in enumerate(poses)])
    lifter = rk.RamakrishnaLifter(bases, rk.RamakrishnaOptions(max_bases=3))
    many = lifter.lift_many(x)
    assert len(many) == 2
    one = rk.ramakrishna_lift(x[1], None, bases, options=rk.RamakrishnaOptions(max_bases=3))
    np.testing.assert_array_equal(many[1].pose, one.pose)
    with pytest.raises(InvalidInputError):
        lifter.lift_many(x[0])
