"""The pose step: the compiled Riemannian step against the Python ADM loop around the same
alpha-step (its reference), the solver results' common shape, and the lifter's per-alternation
history."""

from __future__ import annotations

import numpy as np
import pytest
import tolerances as tol
from numpy.typing import NDArray
from pose_lifter.core.lift.lifter import Lifter
from pose_lifter.core.model.bases import PoseBases, default_bases_path
from pose_lifter.core.model.pose_model import PoseModel
from pose_lifter.core.numeric.records import StepSettings, settings_record
from pose_lifter.core.options import LifterOptions
from pose_lifter.core.results import Duals, PoseResult, SolveInfo
from pose_lifter.core.solve.alpha.base import Coordinates
from pose_lifter.core.solve.alpha.sphere_newton import (
    RIEMANNIAN_MAX_ITER,
    SphereStep,
    _riemannian_alpha_kernel,
    _sphere_setup,
    newton_work,
)
from pose_lifter.core.solve.pose_kernel import _pose_rows
from pose_lifter.core.solve.pose_step import PriorRows, _adm, _alpha_step, pose_step, prior_operands
from scipy.spatial.transform import Rotation
from synthetic_poses import small_pca_bases

Arr = NDArray[np.float64]


@pytest.fixture(scope="module")
def model() -> PoseModel:
    bases = PoseBases.load(default_bases_path("hybrid"))
    return PoseModel.build(bases, bases.limb_proportions)


def _problem(model: PoseModel, seed: int) -> tuple[Arr, Arr, Arr, Arr, Arr]:
    """2D of a random in-model pose seen by a random camera, with noise and two missing joints:
    (points (12, 2), projection (2, 3), translation (2,), weights (12,), the true pose (12, 3))."""
    rng = np.random.default_rng(seed)
    alpha = np.zeros(model.n_bases)
    alpha[rng.choice(model.n_bases, 6, replace=False)] = rng.normal(0.0, 0.3, 6)
    pose = model.pose(alpha)
    rot = Rotation.from_euler("yx", [rng.uniform(-np.pi, np.pi), rng.uniform(-0.3, 0.3)]).as_matrix()
    m0 = 1.3 * rot[:2]
    t = rng.normal(0.0, 0.2, 2)
    x = pose @ m0.T + t + rng.normal(0.0, 0.02, (12, 2))
    w = np.ones(12)
    w[rng.choice(12, 2, replace=False)] = 0.0
    return x, m0, t, w, pose


def _prior_rows(model: PoseModel, seed: int, pose: Arr, m0: Arr, t: Arr) -> PriorRows:
    """Prior rows for a :func:`_problem`: its true pose's image positions and depths with noise,
    a joint without image-position rows, another without a depth row, and a person's own limb
    lengths (the model's within +-10 %)."""
    rng = np.random.default_rng(100 + seed)
    target = np.column_stack([pose @ m0.T + t, (pose - pose.mean(0)) @ PriorRows.depth_row(m0)])
    target += rng.normal(0.0, 0.05, target.shape)
    weights = np.column_stack([np.full(12, 0.6), np.full(12, 0.4)])
    weights[3, 0] = 0.0
    weights[7, 1] = 0.0
    return PriorRows(target, weights, np.sqrt(model.limb_sq) * rng.uniform(0.9, 1.1, 8))


class _RiemannianStep:
    """The alpha-step protocol around the compiled Riemannian alpha-step
    (:func:`pose_lifter.core.solve.alpha.sphere_newton._riemannian_alpha_kernel`), for the Python ADM loop
    ``_adm``: the compiled pose step's ADM written as that loop, its reference. It carries
    ``s = V^T alpha`` from call to call as the kernel does."""

    def __init__(self, model: PoseModel, mus: Arr, radii: Arr, alpha0: Arr, opts: LifterOptions) -> None:
        coords = model.limb_coordinates
        assert coords is not None
        z, n, s0, _ = coords
        # one Newton step per alpha-step, the method's (RIEMANNIAN_MAX_ITER), whatever the product's
        # settings say; only the alpha-step's fields are read
        self._km = model.kernel_arrays
        self._st = settings_record(StepSettings(
            th=0.0, l1=True, limbs=True, eta=1.0, eta_growth=1.0, eta_max=1.0, pose_tol=0.0,
            alpha_max_iter=RIEMANNIAN_MAX_ITER, alpha_tol=opts.newton_tol, prox=opts.alpha_prox,
            cam_tol=0.0, tau=0.0, alt_tol=0.0))
        mus = np.ascontiguousarray(mus)
        g = mus.T @ mus + (1.0 + opts.alpha_prox) * np.eye(model.sig.size)
        q, rmat, s1, s2 = _sphere_setup(g, z, n)
        c64 = np.ascontiguousarray
        geom = (g @ s0, q, c64(rmat.T), c64(s1.T), c64(s2.T))
        self._step = SphereStep(mus, geom, np.ascontiguousarray(radii, dtype=np.float64),
                                newton_work(mus.shape[1]))
        self._sk = model.v.T @ alpha0

    def __call__(self, d1: Arr, d2: Arr, alpha: Arr) -> tuple[Arr, int]:
        out = np.empty(alpha.size)
        it = _riemannian_alpha_kernel(np.ascontiguousarray(d1), np.ascontiguousarray(d2), self._sk,
                                      self._step, self._km, self._st, out)
        return out, int(it)


class _LinearStep:
    """The alpha-step without limbs written out in numpy, for the Python ADM loop ``_adm``: the
    reference of the compiled linear alpha-step. ``argmin ||A alpha - d1||^2 + ||alpha - d2||^2``
    in the reduced coordinates by ``numpy.linalg.solve`` (LAPACK), the compiled step by its own
    Cholesky factor."""

    def __init__(self, model: PoseModel, mus: Arr) -> None:
        self._c = Coordinates(mus, model.v)

    def __call__(self, d1: Arr, d2: Arr, alpha: Arr) -> tuple[Arr, int]:
        lin, _, vtd2 = self._c.quadratic(d1, d2)
        return self._c.alpha(np.linalg.solve(self._c.g, lin), d2, vtd2), 1


def _loop(x: Arr, m0: Arr, t: Arr, w: Arr, model: PoseModel, alpha0: Arr, opts: LifterOptions, max_iter: int,
          prior: PriorRows | None, duals: Duals | None) -> PoseResult:
    """The pose step with the Riemannian alpha-step through the Python ADM loop (the reference)."""
    xp, pw, rad = prior_operands(model, prior)
    rows = _pose_rows(x, m0, t, w, model.kernel_arrays, xp, pw)
    step = (_RiemannianStep(model, rows.mus, rad, alpha0, opts) if opts.method.limbs
            else _LinearStep(model, rows.mus))
    return _adm(rows, model, alpha0.copy(), step, max_iter, opts, duals)


@pytest.mark.parametrize("seed", range(4))
@pytest.mark.parametrize("with_prior", [False, True])
def test_compiled_pose_step_is_the_python_loop(model: PoseModel, seed: int, with_prior: bool) -> None:
    x, m0, t, w, pose = _problem(model, seed)
    prior = _prior_rows(model, seed, pose, m0, t) if with_prior else None
    opts = LifterOptions(theta=0.1, pose_tol=1e-12)
    if prior is not None:
        # the loop checks feasibility against its model's limb lengths: the person's, here; the
        # compiled step takes them from the prior rows or the model alike
        assert prior.limb_radii is not None
        person = PoseModel.build(PoseBases.load(default_bases_path("hybrid")), prior.limb_radii)
        a = pose_step(x, m0, t, w, model, np.zeros(model.n_bases), opts, max_iter=15, prior=prior)
        prior = PriorRows(prior.target, prior.weights)
        b = pose_step(x, m0, t, w, person, np.zeros(model.n_bases), opts, max_iter=15, prior=prior)
        assert b.objective == pytest.approx(a.objective, rel=tol.FUSED_VS_LOOP_REL)
        assert np.abs(b.pose - a.pose).max() <= tol.FUSED_VS_LOOP_REL * np.abs(a.pose).max()
        model = person
    args = (x, m0, t, w, model, np.zeros(model.n_bases), opts)
    # one ADM iteration at a time, both ways from the same input: the start, then the loop's own
    # iterate and multipliers after k iterations
    state = None
    for k in range(15):
        if k:
            state = _loop(*args, max_iter=k, prior=prior, duals=None)
        a0 = np.zeros(model.n_bases) if state is None else state.alpha
        duals = None if state is None else state.duals
        compiled = pose_step(*args[:5], a0, opts, max_iter=1, prior=prior, duals=duals)
        loop = _loop(*args[:5], a0, opts, max_iter=1, prior=prior, duals=duals)
        assert (compiled.n_iter, compiled.alpha_iter) == (loop.n_iter, loop.alpha_iter)
        assert loop.objective == pytest.approx(compiled.objective, rel=tol.FUSED_STEP_REL)
        assert np.abs(loop.alpha - compiled.alpha).max() <= tol.FUSED_STEP_REL * np.abs(compiled.alpha).max()
        assert compiled.duals is not None and loop.duals is not None
        n_rows = 24 + (2 * 11 + 11 if with_prior else 0)
        assert compiled.duals.data.shape == loop.duals.data.shape == (n_rows,)
        dual_scale = np.abs(compiled.duals.data).max()
        assert np.abs(loop.duals.data - compiled.duals.data).max() <= tol.FUSED_STEP_REL * dual_scale
    # the whole step, 15 iterations and not converged: what a user sees (objective, pose)
    compiled = pose_step(*args, max_iter=15, prior=prior)
    loop = _loop(*args, max_iter=15, prior=prior, duals=None)
    assert compiled.n_iter == loop.n_iter == 15 and not compiled.converged and not loop.converged
    assert compiled.alpha_iter == loop.alpha_iter > 0
    assert loop.objective == pytest.approx(compiled.objective, rel=tol.FUSED_VS_LOOP_REL)
    assert np.abs(loop.pose - compiled.pose).max() <= tol.FUSED_VS_LOOP_REL * np.abs(compiled.pose).max()
    assert abs(loop.limb_violation - compiled.limb_violation) <= tol.FUSED_VS_LOOP_REL
    # the loop is not the kernel by accident: the paper's inner ADM as its alpha-step ends elsewhere
    if not with_prior:
        xp, pw, _ = prior_operands(model, None)
        rows = _pose_rows(x, m0, t, w, model.kernel_arrays, xp, pw)
        other = _adm(rows, model, np.zeros(model.n_bases), _alpha_step(model, rows.mus, opts, None), 15, opts,
                     None)
        assert abs(other.objective - compiled.objective) > 1e-6 * compiled.objective


@pytest.mark.parametrize("seed", range(3))
@pytest.mark.parametrize("variant", ["L1NAWS", "L1NANS", "L2NAWS"])
def test_compiled_pose_step_without_limbs_is_the_python_loop(model: PoseModel, seed: int, variant: str
                                                             ) -> None:
    """Without limbs the compiled step's linear alpha-step (a Cholesky factor per step) and the
    loop's (numpy's solve) take the same iterates, one ADM iteration at a time and over a whole
    step, on the shipped bases and on 12 PCA bases whose limb map is not onto."""
    x, m0, t, w, _ = _problem(model, seed)
    opts = LifterOptions(theta=0.1, pose_tol=1e-12, variant=variant)
    small = PoseModel.build(small_pca_bases(), np.sqrt(model.limb_sq))
    for m in (model, small):
        args = (x, m0, t, w, m)
        state = None
        for k in range(6):
            if k:
                state = _loop(*args, np.zeros(m.n_bases), opts, k, None, None)
            a0 = np.zeros(m.n_bases) if state is None else state.alpha
            duals = None if state is None else state.duals
            compiled = pose_step(*args, a0, opts, max_iter=1, duals=duals)
            loop = _loop(*args, a0, opts, 1, None, duals)
            assert (compiled.n_iter, compiled.alpha_iter) == (loop.n_iter, loop.alpha_iter) == (1, 1)
            assert loop.objective == pytest.approx(compiled.objective, rel=tol.FUSED_STEP_REL)
            scale = np.abs(compiled.alpha).max()
            assert np.abs(loop.alpha - compiled.alpha).max() <= tol.FUSED_STEP_REL * scale
        compiled = pose_step(*args, np.zeros(m.n_bases), opts, max_iter=30)
        loop = _loop(*args, np.zeros(m.n_bases), opts, 30, None, None)
        assert compiled.n_iter == loop.n_iter and compiled.converged == loop.converged
        assert loop.objective == pytest.approx(compiled.objective, rel=tol.FUSED_VS_LOOP_REL)
        assert np.abs(loop.pose - compiled.pose).max() <= tol.FUSED_VS_LOOP_REL * np.abs(compiled.pose).max()
        assert compiled.limb_violation == loop.limb_violation == 0.0
        # not the limb-constrained step by accident: with limbs the same problem ends elsewhere
        if m is model:
            limbed = pose_step(*args, np.zeros(m.n_bases), opts.replace(variant="full"), max_iter=30)
            assert abs(limbed.objective - compiled.objective) > 1e-6 * compiled.objective


def test_every_solver_result_reports_convergence_alike(model: PoseModel) -> None:
    x, m0, t, w, _ = _problem(model, 7)
    # the Riemannian step on the shipped bases, the paper's inner ADM on 12 PCA bases (no onto limb
    # map), the linear solve without limbs
    small = PoseModel.build(small_pca_bases(), np.sqrt(model.limb_sq))
    for m, opts in ((model, LifterOptions(pose_tol=1e-5)), (small, LifterOptions(pose_tol=1e-5)),
                    (model, LifterOptions(pose_tol=1e-5, variant="L1NAWS"))):
        res = pose_step(x, m0, t, w, m, np.zeros(m.n_bases), opts, max_iter=200)
        assert isinstance(res, SolveInfo) and res.n_iter <= 200 and res.alpha_iter >= res.n_iter
        assert res.converged == (res.n_iter < 200), (m.n_bases, opts.variant)


def test_lift_result_carries_the_alternations(model: PoseModel) -> None:
    x, _, _, _, _ = _problem(model, 3)
    for mode in ("paper", "hybrid"):
        options = LifterOptions(mode="paper", n_starts=3) if mode == "paper" else LifterOptions(mode=mode)
        lifter = Lifter(None, options)
        res = lifter.lift(100.0 * x + 300.0)
        assert len(res.history) == res.n_iter >= 1, mode
        objectives = [a.objective for a in res.history]
        assert res.objective == pytest.approx(min(objectives), rel=1e-12)
        for a in res.history:
            assert isinstance(a.camera, SolveInfo) and isinstance(a.pose, SolveInfo)
            assert a.camera.n_iter >= 1 and a.pose.n_iter >= 1
        # the run stops when an alternation no longer lowers the objective enough, or at the cap
        cap = lifter.options.max_alternations if mode == "paper" else lifter.options.hybrid_alternations
        assert res.converged or res.n_iter == cap
