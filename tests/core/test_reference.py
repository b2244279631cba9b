"""The reference solvers of pose_lifter.core.reference, each checked on its own."""

from __future__ import annotations

import cvxpy  # noqa: F401  (required: in the lock; a broken install fails here)
import numpy as np
import pytest
import tolerances as tol
from numpy.typing import NDArray
from pose_lifter.core import reference as ref
from pose_lifter.core.errors import InvalidInputError
from pose_lifter.core.model.bases import PoseBases, learn_pca_bases
from pose_lifter.core.model.skeleton import limb_lengths, limb_selectors
from pose_lifter.core.reference import camera as ref_camera
from pose_lifter.core.reference import pose as ref_pose
from pose_lifter.core.results import Camera
from scipy.spatial.transform import Rotation
from synthetic_poses import synthetic_poses


@pytest.fixture(scope="module")
def bases() -> PoseBases:
    poses, _ = synthetic_poses(300, seed=1)
    return learn_pca_bases(poses, n_bases=10, n_starts=3, seed=0)


def _random_camera(rng: np.random.Generator) -> Camera:
    rot = Rotation.random(random_state=int(rng.integers(1 << 30))).as_matrix()
    return Camera(rot, float(rng.uniform(0.5, 3.0)), rng.normal(size=2))


Arr = NDArray[np.float64]


def _pose_in_span(bases: PoseBases, rng: np.random.Generator) -> tuple[Arr, Arr]:
    """A pose mean + B alpha (alpha = a random training-like code) and its alpha."""
    poses, _ = synthetic_poses(1, seed=int(rng.integers(1 << 30)))
    alpha = bases.components.T @ (poses[0].reshape(-1) - bases.mean)
    return bases.pose(alpha), alpha


def _rot_dist(a: NDArray[np.float64], b: NDArray[np.float64]) -> float:
    return float(np.linalg.norm(a[:2] - b[:2]))


# ------------------------------------------------------------------------------ camera


@pytest.mark.parametrize("loss", ["l1", "l2"])
def test_camera_given_rotation_matches_exact_inner(loss: str) -> None:
    # Clarabel's LP/QP and the closed-form / breakpoint-enumeration inner solvers are
    # independent codes for the same convex problem: equal optimal values.
    rng = np.random.default_rng(0)
    for _ in range(5):
        x, y = rng.normal(size=(12, 2)), rng.normal(size=(12, 3))
        w = rng.uniform(0.0, 1.0, size=12)
        w[rng.integers(12)] = 0.0
        rot = Rotation.random(random_state=int(rng.integers(1 << 30))).as_matrix()
        s, t, f = ref.reference_camera_given_rotation(x, y, w, rot, loss)
        inner = ref_camera._inner_l1_exact if loss == "l1" else ref_camera._inner_l2_exact
        _, _, f2 = inner(x, y @ rot[:2].T, w)
        assert s >= 0
        assert abs(f - f2) <= 1e-7 * (1 + f2)
        assert f == pytest.approx(ref.camera_objective(x, y, w, Camera(rot, s, t), loss), abs=tol.ROUND_OFF)


@pytest.mark.parametrize("loss", ["l1", "l2"])
def test_camera_recovered_from_noise_free_data(loss: str) -> None:
    rng = np.random.default_rng(1)
    for _ in range(2):
        cam = _random_camera(rng)
        y = rng.normal(size=(12, 3))
        x = cam.project(y)
        w = np.ones(12)
        w[[2, 7]] = 0.0  # missing joints: free to be anything
        x[[2, 7]] += 50.0
        est, f = ref.reference_camera(x, y, w, loss, n_restarts=6, seed=3)
        assert f <= tol.RECOVERY
        assert _rot_dist(est.rotation, cam.rotation) <= tol.RECOVERY
        assert est.scale == pytest.approx(cam.scale, abs=tol.RECOVERY)
        np.testing.assert_allclose(est.translation, cam.translation, atol=tol.RECOVERY)
        np.testing.assert_allclose(est.rotation @ est.rotation.T, np.eye(3), atol=tol.ROUND_OFF)
        assert np.linalg.det(est.rotation) == pytest.approx(1.0, abs=tol.ROUND_OFF)


def test_camera_l1_with_outliers_not_worse_than_truth_and_close_to_it() -> None:
    rng = np.random.default_rng(2)
    cam = _random_camera(rng)
    y = rng.normal(size=(12, 3))
    x = cam.project(y) + 0.01 * rng.normal(size=(12, 2))
    x[[4, 9]] += np.array([[3.0, -2.0], [-2.5, 4.0]])  # gross outliers on 2 of 12 joints
    w = np.ones(12)
    est, f = ref.reference_camera(x, y, w, "l1", n_restarts=6, seed=0)
    assert f <= ref.camera_objective(x, y, w, cam, "l1") + tol.CAMERA_OBJECTIVE_ABS
    # L1 is robust: the outliers hardly move the estimate; L2 is pulled away
    assert _rot_dist(est.rotation, cam.rotation) < 0.05
    est2, _ = ref.reference_camera(x, y, w, "l2", n_restarts=6, seed=0)
    assert _rot_dist(est2.rotation, cam.rotation) > 2 * _rot_dist(est.rotation, cam.rotation)


def test_camera_rejects_bad_input() -> None:
    x, y = np.zeros((12, 2)), np.zeros((12, 3))
    with pytest.raises(InvalidInputError):
        ref.reference_camera(x, y, np.ones(12), "l3")
    with pytest.raises(InvalidInputError):
        ref.reference_camera(x, y, np.r_[np.ones(2), np.zeros(10)], "l1")
    with pytest.raises(InvalidInputError):
        ref.reference_camera(x[:5], y, np.ones(12), "l1")


# ------------------------------------------------------------------------------ Q-step


def _sym(a: NDArray[np.float64]) -> NDArray[np.float64]:
    return 0.5 * (a + a.T)


@pytest.mark.parametrize("delta", [0.3, 1.0, 10.0])
def test_qstep_kkt(bases: PoseBases, delta: float) -> None:
    # KKT of the equality-constrained QP over symmetric Q: feasibility, and the gradient
    # sym(W) + sym(G) + delta (Q - sym(P)) lies in span{sym(Omega_i), E_mm}.
    rng = np.random.default_rng(3)
    y, _ = _pose_in_span(bases, rng)
    omegas = ref.limb_omegas(bases.mean, bases.components, limb_lengths(y) ** 2)
    m1 = omegas.shape[1]
    w_mat, p_mat, g_mat = (rng.normal(size=(m1, m1)) for _ in range(3))  # deliberately non-symmetric
    q = ref.reference_qstep(w_mat, omegas, p_mat, g_mat, delta)
    np.testing.assert_allclose(q, q.T, atol=tol.ROUND_OFF)
    scale = 1.0 + float(np.abs(omegas).max())
    assert abs(q[-1, -1] - 1.0) <= tol.KKT
    assert np.max(np.abs(np.einsum("cij,ij->c", omegas, q))) <= tol.KKT * scale * (1 + np.abs(q).max())
    grad = _sym(w_mat) + _sym(g_mat) + delta * (q - _sym(p_mat))
    e = np.zeros((m1, m1))
    e[-1, -1] = 1.0
    basis = np.stack([*(_sym(o).reshape(-1) for o in omegas), e.reshape(-1)], axis=1)
    coef, *_ = np.linalg.lstsq(basis, -grad.reshape(-1), rcond=None)
    resid = grad.reshape(-1) + basis @ coef
    assert np.linalg.norm(resid) <= tol.KKT * (1 + np.linalg.norm(grad))
    # and it beats feasible perturbations (directions in the null space of the constraints)
    def obj(qq: Arr) -> float:
        d = qq - p_mat
        return float(np.sum(w_mat * qq) + np.sum(g_mat * d) + 0.5 * delta * np.sum(d**2))

    _, _, vt = np.linalg.svd(basis.T)
    null = vt[basis.shape[1]:]
    for _ in range(5):
        d = (null.T @ rng.normal(size=null.shape[0])).reshape(m1, m1)
        d = _sym(d)
        assert obj(q + 1e-3 * d) >= obj(q) - tol.ROUND_OFF_ACCUMULATED


# ----------------------------------------------------------------------------- alpha-step


def _alpha_problem(bases: PoseBases, seed: int) -> tuple[Arr, Arr, Arr]:
    """The paper's W (non-symmetric) and Omegas for a problem with a feasible z*."""
    rng = np.random.default_rng(seed)
    y, alpha = _pose_in_span(bases, rng)
    omegas = ref.limb_omegas(bases.mean, bases.components, limb_lengths(y) ** 2)
    cam = _random_camera(rng)
    mb = np.kron(np.eye(12), cam.projection) @ bases.components
    k = bases.n_bases
    w_mat = np.zeros((k + 1, k + 1))
    w_mat[:k, :k] = mb.T @ mb + np.eye(k)
    w_mat[k, :k] = 2.0 * (rng.normal(size=24) @ mb - rng.normal(size=k))
    return w_mat, omegas, np.append(alpha, 1.0)


def test_omegas_encode_limb_lengths(bases: PoseBases) -> None:
    rng = np.random.default_rng(4)
    y, alpha = _pose_in_span(bases, rng)
    target = rng.uniform(0.5, 1.5, size=8)
    om = ref.limb_omegas(bases.mean, bases.components, target)
    z = np.append(alpha, 1.0)
    c = limb_selectors()
    direct = np.sum((c @ y.reshape(-1)) ** 2, axis=1) - target
    np.testing.assert_allclose(np.einsum("i,cij,j->c", z, om, z), direct, atol=tol.ROUND_OFF_LONG)


@pytest.mark.parametrize("seed", [5, 6])
def test_alpha_sdp_is_lower_bound_of_local_solutions(bases: PoseBases, seed: int) -> None:
    w_mat, omegas, z_feasible = _alpha_problem(bases, seed)
    q, lb = ref.reference_alpha_sdp(w_mat, omegas)
    assert np.linalg.eigvalsh(q).min() >= -tol.SCS_ACCURACY * np.abs(q).max()
    assert q[-1, -1] == pytest.approx(1.0, abs=tol.SCS_ACCURACY)
    share = ref.top_eigenvalue_share(q)
    assert 0.0 < share <= 1.0
    rng = np.random.default_rng(seed)
    starts = [z_feasible]
    # starts within 0.3 of the feasible point: from 0.5 SLSQP stalls on one of seed 5's starts at a
    # stationary point of the violation (4e-2), trust-constr at 6e-3 (no local solver then applies)
    starts += [np.append(z_feasible[:-1] + 0.3 * rng.normal(size=bases.n_bases), 1.0) for _ in range(3)]
    for z0 in starts:
        z, f = ref.reference_alpha_local(w_mat, omegas, z0)
        assert z[-1] == 1.0
        assert np.max(np.abs(np.einsum("i,cij,j->c", z, omegas, z))) <= tol.FEASIBILITY
        assert f == pytest.approx(float(z @ w_mat @ z), rel=tol.ROUND_OFF)
        assert lb <= f + tol.SDP_BOUND_REL * (1 + abs(f))
        # local optimality: not worse than the feasible start
        assert z0 is not z_feasible or f <= float(z0 @ w_mat @ z0) + tol.ROUND_OFF_ACCUMULATED


def test_top_eigenvalue_share() -> None:
    v = np.array([1.0, 2.0, 3.0])
    assert ref.top_eigenvalue_share(np.outer(v, v)) == pytest.approx(1.0)
    assert ref.top_eigenvalue_share(np.eye(4)) == pytest.approx(0.25)


# ------------------------------------------------------------------------------- pose step


@pytest.mark.parametrize("loss", ["l1", "l2"])
@pytest.mark.parametrize("theta", [0.0, 0.05])
def test_pose_convex_optimal(bases: PoseBases, loss: str, theta: float) -> None:
    rng = np.random.default_rng(7)
    y, alpha_true = _pose_in_span(bases, rng)
    cam = _random_camera(rng)
    x = cam.project(y) + 0.05 * rng.normal(size=(12, 2))
    w = rng.uniform(0.2, 1.0, size=12)
    w[3] = 0.0
    alpha, f = ref.reference_pose_convex(x, cam, bases.mean, bases.components, w, theta, loss)
    assert f == pytest.approx(ref.pose_objective(x, cam, bases.mean, bases.components, w, theta, loss, alpha))
    others = [alpha + s * rng.normal(size=alpha.shape) for s in (1e-3, 0.1, 1.0)]
    for a in [alpha_true, np.zeros_like(alpha), *others]:
        assert f <= ref.pose_objective(x, cam, bases.mean, bases.components, w, theta, loss, a) + 1e-8


def test_pose_convex_l2_subgradient_condition(bases: PoseBases) -> None:
    # 0 in 2 A^T W (A alpha - b) + theta d||alpha||_1 at the L2 (LASSO) optimum
    rng = np.random.default_rng(8)
    y, _ = _pose_in_span(bases, rng)
    cam = _random_camera(rng)
    x = cam.project(y) + 0.05 * rng.normal(size=(12, 2))
    w, theta = np.ones(12), 0.3
    alpha, _ = ref.reference_pose_convex(x, cam, bases.mean, bases.components, w, theta, "l2")
    a_mat, b_vec, w2 = ref_pose._pose_linear_map(x, cam, bases.mean, bases.components, w)
    g = 2.0 * a_mat.T @ (w2 * (a_mat @ alpha - b_vec))
    active = np.abs(alpha) > 1e-7
    assert np.any(~active)  # theta large enough to zero some coefficients
    np.testing.assert_allclose(g[active], -theta * np.sign(alpha[active]), atol=1e-6)
    assert np.all(np.abs(g[~active]) <= theta + 1e-6)


@pytest.mark.parametrize("loss", ["l1", "l2"])
def test_pose_convex_recovers_noise_free_pose(bases: PoseBases, loss: str) -> None:
    rng = np.random.default_rng(9)
    y, alpha_true = _pose_in_span(bases, rng)
    cam = _random_camera(rng)
    x = cam.project(y)
    alpha, f = ref.reference_pose_convex(x, cam, bases.mean, bases.components, np.ones(12), 0.0, loss)
    assert f <= tol.RECOVERY
    np.testing.assert_allclose(alpha, alpha_true, atol=1e-5)


@pytest.mark.parametrize("loss", ["l1", "l2"])
def test_pose_limbs_local_feasible_and_not_worse_than_truth(bases: PoseBases, loss: str) -> None:
    rng = np.random.default_rng(10)
    y, alpha_true = _pose_in_span(bases, rng)
    lsq = limb_lengths(y) ** 2
    cam = _random_camera(rng)
    x = cam.project(y) + 0.02 * rng.normal(size=(12, 2))
    w, theta = np.ones(12), 0.05
    f_true = ref.pose_objective(x, cam, bases.mean, bases.components, w, theta, loss, alpha_true)
    c = limb_selectors()
    for alpha0 in (alpha_true, alpha_true + 0.3 * rng.normal(size=alpha_true.shape)):
        alpha, f = ref.reference_pose_limbs_local(
            x, cam, bases.mean, bases.components, w, theta, loss, lsq, alpha0)
        yy = bases.mean + bases.components @ alpha
        viol = np.max(np.abs(np.sum((c @ yy) ** 2, axis=1) - lsq))
        assert viol <= tol.FEASIBILITY
        if alpha0 is alpha_true:  # a feasible start: the local solver can only improve it
            assert f <= f_true + tol.ROUND_OFF_ACCUMULATED
        # and the result is close to the truth (data nearly noise-free)
        assert np.max(np.abs(yy - y.reshape(-1))) < 0.1
