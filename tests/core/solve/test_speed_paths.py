"""Agreement checks of the fast-path implementation details (no timing assertions)."""

from __future__ import annotations

import numpy as np
import tolerances as tol
from numpy.typing import NDArray
from pose_lifter.core.solve.camera import project_scaled_orthographic

Arr = NDArray[np.float64]


def _svd_projection(n: Arr) -> Arr:
    u, s, vt = np.linalg.svd(n, full_matrices=False)
    return np.asarray(s.mean() * (u @ vt))


def test_closed_form_scaled_orthographic_projection_equals_the_svd() -> None:
    rng = np.random.default_rng(0)
    for i in range(500):
        n = rng.normal(size=(2, 3)) * 10.0 ** rng.uniform(-3, 3)
        if i % 5 == 0:  # nearly rank 1
            n[1] = n[0] * rng.normal() + 1e-7 * rng.normal(size=3)
        got = project_scaled_orthographic(n)
        ref = _svd_projection(n)
        # the nearest point is unique unless n is exactly rank 1; compare distances then too
        assert (np.linalg.norm(got - n)
                <= np.linalg.norm(ref - n) * (1 + tol.ROUND_OFF_ACCUMULATED) + tol.ROUND_OFF)
        if np.linalg.svd(n, compute_uv=False)[1] > 1e-6 * np.linalg.norm(n):
            np.testing.assert_allclose(got, ref, rtol=0, atol=1e-6 * np.abs(ref).max())
        # always a scaled orthographic matrix
        g = got @ got.T
        np.testing.assert_allclose(g, g[0, 0] * np.eye(2), atol=1e-6 * max(1.0, g[0, 0]))


def test_weighted_median_minimises_weighted_l1_with_ties_and_zero_weights() -> None:
    from pose_lifter.core.solve.camera import weighted_median

    rng = np.random.default_rng(1)
    for i in range(3000):
        n = int(rng.integers(1, 14))
        v = rng.normal(size=n)
        if i % 3 == 0:
            v = np.round(v, 1)  # ties
        w = np.ones(n) if i % 5 == 0 else rng.integers(0, 3, size=n).astype(float)
        m = weighted_median(v, w)
        if w.sum() == 0:
            assert m == np.median(v)
            continue
        # the weighted-L1 objective is piecewise linear with kinks at the values: its minimum is
        # attained at one of them
        best = min(float(np.sum(w * np.abs(v - c))) for c in v)
        assert float(np.sum(w * np.abs(v - m))) <= best + tol.ROUND_OFF


def test_cholesky_into_solves_or_refuses() -> None:
    """The written-out Cholesky factorisation and solve of the Newton step, into the caller's
    buffers: it solves a positive definite system and refuses an indefinite one."""
    from pose_lifter.core.numeric.linalg import _cholesky_apply_into, _cholesky_into

    rng = np.random.default_rng(2)
    lo, y, x = np.empty((16, 16)), np.empty(16), np.empty(16)
    for _ in range(200):
        a = rng.normal(size=(16, 16))
        spd = a @ a.T + 1e-3 * np.eye(16)
        b = rng.normal(size=16)
        assert _cholesky_into(spd, lo)
        _cholesky_apply_into(lo, b, y, x)
        np.testing.assert_allclose(spd @ x, b, atol=1e-8 * np.abs(b).max() * np.linalg.cond(spd))
        sym = 0.5 * (a + a.T)  # indefinite (almost surely)
        if np.linalg.eigvalsh(sym)[0] < -1e-8:
            assert not _cholesky_into(sym, lo)


def test_mirrored_start_kernel_equals_normalise_pose() -> None:
    # the compiled single-pose normalise_pose_flat (in the lifter's mirrored warm start) must stay
    # the same computation as the vectorised normalise_pose
    from pose_lifter.core.lift.lifter import Lifter
    from pose_lifter.core.lift.runs import PINV_RCOND, _mirror_kernel
    from pose_lifter.core.model.skeleton import normalise_pose, normalise_pose_flat
    from scipy.spatial.transform import Rotation

    m = Lifter().model
    rng = np.random.default_rng(3)
    for i in range(50):
        pose = m.pose(0.3 * rng.normal(size=m.n_bases))
        rot = Rotation.random(random_state=i).as_matrix()
        got, ok = _mirror_kernel(np.ascontiguousarray(pose), rot, m.mean, m.u, m.sig, m.v)
        cam = pose @ rot.T
        cam[:, 2] *= -1.0
        flat, ok_flat = normalise_pose_flat(np.ascontiguousarray(cam))
        assert ok and ok_flat
        np.testing.assert_allclose(flat, normalise_pose(cam).reshape(-1), atol=tol.ROUND_OFF)
        keep = m.sig > PINV_RCOND * m.sig[0]  # the pseudo-inverse's cut-off
        proj = m.u.T @ (normalise_pose(cam).reshape(-1) - m.mean)
        coef = np.where(keep, proj, 0.0) / np.where(keep, m.sig, 1.0)
        want = m.v @ coef
        # 1/sig reaches ~40 for the smallest kept singular value: compare in pose space too
        np.testing.assert_allclose(m.pose(got), m.pose(want), atol=tol.ROUND_OFF_ACCUMULATED)
        np.testing.assert_allclose(got, want, atol=1e-6 * np.abs(want).max())
    flat = np.zeros((12, 3))  # degenerate: no body frame, no leg
    assert not _mirror_kernel(flat, np.eye(3), m.mean, m.u, m.sig, m.v)[1]
    assert not normalise_pose_flat(flat)[1]
