"""Baseline: Ramakrishna, Kanade & Sheikh, "Reconstructing 3D Human Pose from 2D Image
Landmarks" (ECCV 2012), as the paper compares against it.

The model is the same linear one as the main method, ``y = mu + B alpha`` (class-wise PCA
bases, :func:`pose_lifter.core.model.bases.learn_classwise_pca_bases`), but it is fitted with an
L2 reprojection loss by *projected matching pursuit*:

1. start from the mean pose; fit the camera;
2. project every unused basis through the current camera and add the one whose 2D image is
   most correlated with the 2D residual (``|<r, P b_i>| / ||P b_i||``, weighted);
3. re-estimate the coefficients of the chosen bases (L2 loss, subject to the limb-length
   constraint) and the camera, alternately, until they settle;
4. repeat until the reprojection error stops decreasing, or ``max_bases`` bases are used.
   The state with the lowest error is returned.

Limb-length constraint (a departure to note). Ramakrishna et al. enforce one necessary
condition on the limbs instead of one per limb: their paper fixes the *sum of squared*
limb lengths (solvable in closed form there); Wang et al. (Sec. 2) describe it as a
constraint on the *sum of limb lengths*. Both are offered (``limb_constraint="sum"``, the
default, ``sum_i ||C_i y|| = sum_i L_i``; or ``"sum_squared"``, ``sum_i ||C_i y||^2 =
sum_i L_i^2``). The coefficient step, least squares under this one constraint, is solved
globally for the sum of squares (one quadratic equality: a generalised trust-region
subproblem, a 1-D secular equation); for the plain sum by fixed-point reweighting of the
same solver (``sum ||v_i|| = sum ||v_i||^2 / ||v_i||``), see :func:`_constrained_ls`.
The constraint is feasible whenever the mean pose's
sum is at most the target (true by convexity for the training mean and the training
limb proportions), because the sum grows without bound along any basis direction.

Camera: scaled orthographic, ``x_j = s R[:2] y_j + t``, fitted by weighted least squares:
the translation in closed form; ``(s, R[:2])`` from the nearest scaled-orthographic matrix
to the affine least-squares solution (SVD), a few majorisation steps, then
Levenberg-Marquardt on (rotation vector, log s) (see :func:`_fit_camera_ls`). Independent
of ``core/solve/camera.py``.

Input 2D is normalised (weighted centroid, RMS radius) before solving; the returned
camera is in input units. The input is treated as generic image coordinates: if image y
points down, ``pose_camera`` is in a frame with x right, y down, z = x cross y (forward).
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass
from typing import Final, Literal, NamedTuple

import numpy as np
from numpy.typing import NDArray

from ..errors import InvalidInputError, OptionsError, TooFewJointsError
from ..model.bases import PoseBases
from ..model.skeleton import N_JOINTS, LimbVectors, limb_lengths
from ..results import Camera, LiftResult, WarmStart
from ..validation import check_keypoint_sequence, check_keypoints

__all__ = ["RamakrishnaLifter", "RamakrishnaOptions", "limb_sum_residual", "ramakrishna_lift"]

_CAMERA_MAJORISATION_STEPS: Final[int] = 10


@dataclass(frozen=True)
class RamakrishnaOptions:
    """Settings of :func:`ramakrishna_lift`.

    Attributes
    ----------
    max_bases : int
        Cap on the number of bases the pursuit may add.
    limb_constraint : {"sum", "sum_squared"}
        Which single limb-length condition to enforce (module docstring).
    max_alternations : int
        Coefficient/camera alternations after each added basis.
    alternation_tol : float
        Stop alternating when the relative change of the error is below this.
    pursuit_tol : float
        Stop the pursuit when adding a basis lowers the error by less than this fraction,
        or when the error (normalised units) is below it.
    confidence_threshold : float
        Joints with confidence below this are missing (weight 0).
    min_visible_joints : int
    """

    max_bases: int = 10
    limb_constraint: Literal["sum", "sum_squared"] = "sum"
    max_alternations: int = 10
    alternation_tol: float = 1e-6
    pursuit_tol: float = 1e-6
    confidence_threshold: float = 0.1
    min_visible_joints: int = 6

    def __post_init__(self) -> None:
        if not isinstance(self.max_bases, int) or self.max_bases < 1:
            raise OptionsError(f"max_bases must be a positive integer, got {self.max_bases!r}")
        if self.limb_constraint not in ("sum", "sum_squared"):
            raise OptionsError(
                f"limb_constraint must be 'sum' or 'sum_squared', got {self.limb_constraint!r}")
        if not 3 <= int(self.min_visible_joints) <= N_JOINTS:
            raise OptionsError("min_visible_joints must be in [3, 12]")


def _fit_camera_ls(
    x: NDArray[np.float64], y: NDArray[np.float64], w: NDArray[np.float64],
    rot_init: NDArray[np.float64] | None = None,
) -> tuple[NDArray[np.float64], float, NDArray[np.float64]]:
    """Weighted LS scaled-orthographic camera: ``min sum_j w_j ||x_j - s R2 y_j - t||^2``.

    ``t`` is eliminated by weighted centring. For fixed ``s`` the problem in ``R2`` (2x3,
    orthonormal rows) has no closed form (unbalanced Procrustes). Start: ``rot_init``, or
    the nearest scaled-orthographic matrix (SVD) to the affine LS solution, improved by a
    few monotone majorisation steps (``S = Y^T W Y``, ``H = Y^T W X``, ``lam >=
    lambda_max(S)``: ``R2 <- polar(s H + s^2 (lam I - S) R2^T)^T``, ``s <- tr(R2 H) /
    tr(R2 S R2^T)``, Kiers 1990); then Levenberg-Marquardt (scipy ``least_squares``) on a
    rotation vector and ``log s``.

    Returns (rotation (3, 3), scale, translation (2,)).
    """
    from scipy.optimize import least_squares
    from scipy.spatial.transform import Rotation

    wsum = float(w.sum())
    xbar = (w[:, None] * x).sum(axis=0) / wsum
    ybar = (w[:, None] * y).sum(axis=0) / wsum
    xc, yc = x - xbar, y - ybar
    s_mat = yc.T @ (w[:, None] * yc)  # (3, 3)
    h_mat = yc.T @ (w[:, None] * xc)  # (3, 2)

    def best_scale(r2: NDArray[np.float64]) -> float:
        den = float(np.trace(r2 @ s_mat @ r2.T))
        return max(float(np.trace(r2 @ h_mat)) / den, 1e-12) if den > 0 else 1e-12

    if rot_init is not None:
        r0 = Rotation.from_matrix(np.asarray(rot_init, dtype=np.float64)).as_matrix()
    else:
        m_aff = np.linalg.lstsq(s_mat, h_mat, rcond=None)[0].T  # (2, 3): x ~ M y
        u, _, vt = np.linalg.svd(m_aff, full_matrices=False)
        r2 = u @ vt
        lam = float(np.linalg.eigvalsh(s_mat)[-1])
        for _ in range(_CAMERA_MAJORISATION_STEPS):
            sc = best_scale(r2)
            u, _, vt = np.linalg.svd(sc * h_mat + sc * sc * (lam * np.eye(3) - s_mat) @ r2.T,
                                     full_matrices=False)
            r2 = (u @ vt).T
        r0 = np.vstack([r2, np.cross(r2[0], r2[1])])
    sw = np.sqrt(w)[:, None]

    def resid(p: NDArray[np.float64]) -> NDArray[np.float64]:
        rot = Rotation.from_rotvec(p[:3]).as_matrix() @ r0
        return np.asarray((sw * (xc - np.exp(p[3]) * yc @ rot[:2].T)).reshape(-1))

    p0 = np.array([0.0, 0.0, 0.0, np.log(best_scale(r0[:2]))])
    sol = least_squares(resid, p0, method="lm", xtol=1e-12, ftol=1e-12, gtol=1e-12)
    rot = Rotation.from_rotvec(sol.x[:3]).as_matrix() @ r0
    s = float(np.exp(sol.x[3]))
    return rot, s, xbar - s * (rot[:2] @ ybar)


def limb_sum_residual(
    pose: NDArray[np.float64], target_lengths: NDArray[np.float64],
    limb_constraint: Literal["sum", "sum_squared"] = "sum",
) -> float:
    """Residual of the single limb condition: ``sum ||C_i y|| - sum L_i`` (or squared)."""
    ll = limb_lengths(pose)
    tl = np.asarray(target_lengths, dtype=np.float64)
    if limb_constraint == "sum":
        return float(ll.sum() - tl.sum())
    return float((ll**2).sum() - (tl**2).sum())


def _gtrs(
    h: NDArray[np.float64], c: NDArray[np.float64], e_mat: NDArray[np.float64], e_vec: NDArray[np.float64],
    eps: float,
) -> NDArray[np.float64]:
    """Global minimiser of ``a^T H a - 2 c^T a`` s.t. ``a^T E a + 2 e^T a + eps = 0``.

    One quadratic equality constraint (a generalised trust-region subproblem), H PSD, E PSD.
    With ``H V = E' V diag(sigma)``, ``V^T E' V = I`` (``E' = E + 1e-12 tr(E)/q I``) the
    stationary points are ``u_i = (ct_i - lam et_i) / (sigma_i + lam)`` and the global one
    has ``lam > -sigma_min``, where the constraint reads
    ``phi(lam) = sum_i (ct_i + sigma_i et_i)^2 / (sigma_i + lam)^2 - |et|^2 + eps = 0``,
    decreasing in ``lam``: a bracketed 1-D root (brentq). The "hard case" (no root above
    ``-sigma_min``) puts the free component along the bottom eigenvector. When the
    constraint cannot be met (``eps > |et|^2``) the minimiser of the constraint function
    is returned.
    """
    from scipy.linalg import eigh
    from scipy.optimize import brentq

    q = c.shape[0]
    ridge = 1e-12 * max(float(np.trace(e_mat)) / q, 1e-300)
    sig, v = eigh(h, e_mat + ridge * np.eye(q))
    ct, et = v.T @ c, v.T @ e_vec
    g = ct + sig * et
    base = eps - float(et @ et)
    if base >= 0:  # infeasible target: closest point (minimum of the constraint function)
        return np.asarray(-(v @ et))

    def phi(lam: float) -> float:
        r = g / (sig + lam)
        return float(r @ r) + base

    s_min = float(sig[0])
    gap = 1e-12 * (1.0 + abs(s_min))
    lo = -s_min + gap
    if phi(lo) > 0:
        hi = max(1.0, abs(lo))
        while phi(hi) > 0:
            hi *= 2.0
        lam = brentq(phi, lo, hi, xtol=1e-14 * (1.0 + abs(hi)), rtol=1e-15, maxiter=500)
        u = (ct - lam * et) / (sig + lam)
        return np.asarray(v @ u)
    # hard case: lam = -sigma_min, the bottom component is free
    lam = -s_min
    u = np.zeros(q)
    rest = np.abs(sig - s_min) > gap
    u[rest] = (ct[rest] - lam * et[rest]) / (sig[rest] + lam)
    free = int(np.flatnonzero(~rest)[0])
    # constraint in u-coordinates: sum (u_i + et_i)^2 - |et|^2 + eps = 0
    need = -(float(np.sum((u[rest] + et[rest]) ** 2)) + base)
    root = float(np.sqrt(max(need, 0.0)))
    cands = [root - et[free], -root - et[free]]
    obj = [sig[free] * z * z - 2.0 * ct[free] * z for z in cands]
    u[free] = cands[int(np.argmin(obj))]
    return np.asarray(v @ u)


def _constrained_ls(
    a_mat: NDArray[np.float64], b_vec: NDArray[np.float64], cb: NDArray[np.float64],
    cm: NDArray[np.float64], target_lengths: NDArray[np.float64], squared: bool,
    a_prev: NDArray[np.float64] | None, max_rounds: int = 200,
) -> tuple[NDArray[np.float64], bool]:
    """``min ||A a - b||^2`` s.t. the single limb condition; returns (a, constraint met).

    ``sum_squared``: ``sum_i ||cm_i + cb_i a||^2 = sum_i L_i^2`` is one quadratic
    constraint, solved globally by :func:`_gtrs`. ``sum``: ``sum_i ||v_i|| = sum_i L_i`` is
    solved by fixed-point reweighting: with the current lengths ``l_i``, the quadratic
    constraint ``sum_i ||v_i||^2 / l_i = sum_i L_i`` (equal to the original one at a fixed
    point ``l_i = ||v_i||``) is solved by :func:`_gtrs`, and ``l`` updated, until the
    lengths settle (at most ``max_rounds`` rounds).
    """
    h = a_mat.T @ a_mat
    c = a_mat.T @ b_vec
    dd = np.einsum("ijk,ijl->ikl", cb, cb)  # (8, q, q)
    de = np.einsum("ijk,ij->ik", cb, cm)  # (8, q)
    d0 = np.einsum("ij,ij->i", cm, cm)  # (8,)

    def lengths(a: NDArray[np.float64]) -> NDArray[np.float64]:
        return np.asarray(np.linalg.norm(cm + cb @ a, axis=1))

    if squared:
        target = float((target_lengths**2).sum())
        a = _gtrs(h, c, dd.sum(axis=0), de.sum(axis=0), float(d0.sum()) - target)
        return a, abs(float((lengths(a) ** 2).sum()) - target) <= 1e-8 * (1.0 + target)
    target = float(target_lengths.sum())
    ell = lengths(a_prev) if a_prev is not None else np.asarray(target_lengths, dtype=np.float64)
    a = np.zeros(c.shape[0])
    for _ in range(max_rounds):
        om = 1.0 / np.maximum(ell, 1e-9)
        a = _gtrs(h, c, np.einsum("i,ikl->kl", om, dd), om @ de, float(om @ d0) - target)
        new = lengths(a)
        done = float(np.max(np.abs(new - ell))) <= 1e-11 * (1.0 + float(new.max()))
        ell = new
        if done:
            break
    return a, abs(float(ell.sum()) - target) <= 1e-8 * (1.0 + target)


@dataclass(frozen=True)
class _Problem:
    """The normalised fitting problem of one skeleton.

    Attributes
    ----------
    x : ndarray, shape (12, 2)
        Normalised image coordinates (missing joints at 0).
    w : ndarray, shape (12,)
        Joint weights, 1 visible, 0 missing.
    sw : ndarray, shape (24,)
        Square roots of the weights, one per image coordinate.
    mu : ndarray, shape (36,)
        Mean pose.
    comps : ndarray, shape (36, k)
        Basis poses.
    cb_all : ndarray, shape (8, 3, k)
        Limb vectors of the basis poses.
    cm : ndarray, shape (8, 3)
        Limb vectors of the mean pose.
    tl : ndarray, shape (8,)
        Target limb lengths.
    squared : bool
        Whether the limb condition is on the sum of squared lengths.
    """

    x: NDArray[np.float64]
    w: NDArray[np.float64]
    sw: NDArray[np.float64]
    mu: NDArray[np.float64]
    comps: NDArray[np.float64]
    cb_all: NDArray[np.float64]
    cm: NDArray[np.float64]
    tl: NDArray[np.float64]
    squared: bool

    def error(
        self, rot: NDArray[np.float64], s: float, t: NDArray[np.float64], y: NDArray[np.float64],
    ) -> float:
        """Weighted squared reprojection error of pose ``y`` (12, 3) through camera ``rot`` (3, 3),
        ``s``, ``t`` (2,)."""
        r = self.x - (s * y @ rot[:2].T + t)
        return float(np.sum(self.w * (r * r).sum(axis=1)))

    def coefficients(
        self, chosen: list[int], rot: NDArray[np.float64], s: float,
        t: NDArray[np.float64], a_prev: NDArray[np.float64], rounds: int,
    ) -> tuple[NDArray[np.float64], bool]:
        """Constrained LS coefficients (len(chosen),) of the ``chosen`` bases for a fixed camera
        ``rot`` (3, 3), ``s``, ``t`` (2,), warm-started at ``a_prev``; see :func:`_constrained_ls`."""
        big_m = np.kron(np.eye(N_JOINTS), s * rot[:2])
        a_mat = self.sw[:, None] * (big_m @ self.comps[:, chosen])
        b_vec = self.sw * ((self.x - t).reshape(-1) - big_m @ self.mu)
        return _constrained_ls(a_mat, b_vec, self.cb_all[:, :, chosen], self.cm, self.tl, self.squared,
                               a_prev, rounds)


class _Normalisation(NamedTuple):
    """The 2D input in normalised units, ``x`` (12, 2) ``= (x_in - centre) / radius``: ``centre``
    (2,) is the weighted centroid of the visible joints, ``radius`` their RMS distance from it."""

    x: NDArray[np.float64]
    centre: NDArray[np.float64]
    radius: float


class _State(NamedTuple):
    """One state of the pursuit: the weighted squared reprojection ``error`` (normalised units),
    the indices of the bases in use (``chosen``), their coefficients ``alpha`` (len(chosen),), the
    camera ``rot`` (3, 3), ``s``, ``t`` (2,) in normalised units, and whether the alternation
    settled and the limb condition holds (``ok``)."""

    error: float
    chosen: list[int]
    alpha: NDArray[np.float64]
    rot: NDArray[np.float64]
    s: float
    t: NDArray[np.float64]
    ok: bool


def _checked_input(
    points_2d: NDArray[np.float64], confidence: NDArray[np.float64] | None, bases: PoseBases,
    target_lengths: NDArray[np.float64] | None, opts: RamakrishnaOptions,
) -> tuple[NDArray[np.float64], NDArray[np.float64], NDArray[np.float64]]:
    """Validate the input of :func:`ramakrishna_lift`.

    Returns
    -------
    x_in : ndarray, shape (12, 2)
        The 2D joints, missing ones at 0.
    w : ndarray, shape (12,)
        Joint weights, 1 visible, 0 missing.
    tl : ndarray, shape (8,)
        Target limb lengths.
    """
    x_in, conf = check_keypoints(points_2d, confidence)
    w = (conf >= opts.confidence_threshold).astype(np.float64)
    if not np.all(np.isfinite(x_in[w > 0])):
        raise InvalidInputError("points_2d has non-finite values at visible joints")
    if int(w.sum()) < opts.min_visible_joints:
        raise TooFewJointsError(f"{int(w.sum())} visible joints, need {opts.min_visible_joints}")
    x_in = np.where(w[:, None] > 0, x_in, 0.0)
    tl = np.asarray(bases.limb_proportions if target_lengths is None else target_lengths, dtype=np.float64)
    if tl.shape != (8,) or not np.all(np.isfinite(tl)) or np.any(tl <= 0):
        raise InvalidInputError("target_lengths must be 8 positive numbers")
    return x_in, w, tl


def _normalise(x_in: NDArray[np.float64], w: NDArray[np.float64]) -> _Normalisation:
    """Centre the joints ``x_in`` (12, 2) on their ``w``-weighted (12,) centroid and scale them to
    unit RMS radius."""
    centre = (w[:, None] * x_in).sum(axis=0) / w.sum()
    radius = float(np.sqrt((w * ((x_in - centre) ** 2).sum(axis=1)).sum() / w.sum()))
    if not radius > 0:
        raise InvalidInputError("the visible joints are all at one point")
    return _Normalisation((x_in - centre) / radius, centre, radius)


def _problem(x: NDArray[np.float64], w: NDArray[np.float64], bases: PoseBases, tl: NDArray[np.float64],
             squared: bool) -> _Problem:
    """The fitting problem of the normalised joints ``x`` (12, 2) with weights ``w`` (12,) and
    target limb lengths ``tl`` (8,)."""
    mu, comps = bases.mean, bases.components
    limbs = LimbVectors.of(mu, comps)
    sw = np.sqrt(np.repeat(w, 2))
    return _Problem(x, w, sw, mu, comps, limbs.of_components, limbs.of_mean, tl, squared)


def _most_correlated_basis(
    pb: _Problem, chosen: list[int], rot: NDArray[np.float64], s: float, t: NDArray[np.float64],
    y: NDArray[np.float64],
) -> int | None:
    """Step 2: the unused basis whose image through the camera ``rot`` (3, 3), ``s``, ``t`` (2,)
    is most correlated with the residual of the pose ``y`` (12, 3); None when none is usable."""
    big_m = np.kron(np.eye(N_JOINTS), s * rot[:2])  # (24, 36)
    proj = pb.sw[:, None] * (big_m @ pb.comps)  # (24, k)
    resid = pb.sw * (pb.x - (s * y @ rot[:2].T + t)).reshape(-1)
    norms = np.linalg.norm(proj, axis=0)
    usable = norms > 1e-9 * max(float(norms.max()), 1e-300)
    score = np.where(usable, np.abs(proj.T @ resid) / np.maximum(norms, 1e-300), -1.0)
    score[chosen] = -1.0
    i_new = int(np.argmax(score))
    if score[i_new] < 0:
        return None
    return i_new


def _fit_chosen(
    pb: _Problem, chosen: list[int], alpha_s: NDArray[np.float64], rot: NDArray[np.float64], s: float,
    t: NDArray[np.float64], opts: RamakrishnaOptions,
) -> tuple[_State, NDArray[np.float64]]:
    """Step 3: alternate constrained LS coefficients and LS camera for the ``chosen`` bases.

    For "sum", a few reweighting rounds per alternation, warm-started; an exact solve at the end.
    ``alpha_s`` (len(chosen),) and the camera ``rot`` (3, 3), ``s``, ``t`` (2,) are the start.

    Returns
    -------
    state : _State
        The fitted state (``chosen`` is the caller's list, not a copy).
    y : ndarray, shape (12, 3)
        Its pose.
    """
    settled, prev = False, np.inf
    b_sel = pb.comps[:, chosen]
    for _ in range(opts.max_alternations):
        alpha_s, _ = pb.coefficients(chosen, rot, s, t, alpha_s, 3)
        y = (pb.mu + b_sel @ alpha_s).reshape(N_JOINTS, 3)
        rot, s, t = _fit_camera_ls(pb.x, y, pb.w, rot_init=rot)
        e = pb.error(rot, s, t, y)
        if abs(prev - e) <= opts.alternation_tol * (1.0 + e):
            settled = True
            break
        prev = e
    alpha_s, feasible = pb.coefficients(chosen, rot, s, t, alpha_s, 200)
    y = (pb.mu + b_sel @ alpha_s).reshape(N_JOINTS, 3)
    rot, s, t = _fit_camera_ls(pb.x, y, pb.w, rot_init=rot)
    e = pb.error(rot, s, t, y)
    return _State(e, chosen, alpha_s, rot, s, t, feasible and settled), y


def _pursue(pb: _Problem, cap: int, opts: RamakrishnaOptions) -> tuple[_State, int]:
    """Steps 1-4: the projected matching pursuit from the mean pose.

    Returns
    -------
    best : _State
        The kept state (always with >= 1 basis when one was added: the mean pose alone need
        not meet the constraint).
    n_added : int
        The number of bases added.
    """
    y = pb.mu.reshape(N_JOINTS, 3)
    rot, s, t = _fit_camera_ls(pb.x, y, pb.w)
    best = _State(np.inf, [], np.zeros(0), rot, s, t, False)
    chosen: list[int] = []
    alpha_s = np.zeros(0)
    n_added, stale = 0, 0
    for _ in range(min(cap, pb.comps.shape[1])):
        i_new = _most_correlated_basis(pb, chosen, rot, s, t, y)
        if i_new is None:
            break
        chosen.append(i_new)
        alpha_s = np.append(alpha_s, 0.0)
        n_added += 1
        fit, y = _fit_chosen(pb, chosen, alpha_s, rot, s, t, opts)
        alpha_s, rot, s, t = fit.alpha, fit.rot, fit.s, fit.t
        # 4: keep the best state; stop when the error is ~0 or has not improved twice running
        if fit.error < best.error * (1.0 - opts.pursuit_tol) or not best.chosen:
            best = fit._replace(chosen=list(chosen), alpha=alpha_s.copy())
            stale = 0
        else:
            stale += 1
        if fit.error <= opts.pursuit_tol or stale >= 2:
            break
    return best, n_added


def _lift_result(
    best: _State, n_added: int, pb: _Problem, norm: _Normalisation, x_in: NDArray[np.float64],
    opts: RamakrishnaOptions,
) -> LiftResult:
    """The :class:`LiftResult` of the kept state ``best``, its camera in the units of the input
    joints ``x_in`` (12, 2)."""
    e, sel, a_sel, rot, s, t, ok = best
    alpha = np.zeros(pb.comps.shape[1])
    alpha[sel] = a_sel
    pose = (pb.mu + pb.comps @ alpha).reshape(N_JOINTS, 3)
    camera = Camera(rot, s * norm.radius, t * norm.radius + norm.centre)
    proj2d = camera.project(pose)
    vis = pb.w > 0
    reproj = float(np.linalg.norm(proj2d[vis] - x_in[vis], axis=1).mean())
    centred = pose - pose.mean(axis=0)
    if sel:
        target = float((pb.tl**2).sum() if pb.squared else pb.tl.sum())
        ok = ok and abs(limb_sum_residual(pose, pb.tl, opts.limb_constraint)) <= 1e-6 * (1.0 + target)
    return LiftResult(
        pose=pose,
        pose_camera=centred @ rot.T,
        camera=camera,
        alpha=alpha,
        objective=float(e),
        reprojection_error=reproj,
        limb_violation=float(np.max(np.abs(limb_lengths(pose) - pb.tl))),
        n_iter=n_added,
        converged=bool(ok),
        n_starts=1,
        start_index=0,
        weights=pb.w,
    )


def ramakrishna_lift(
    points_2d: NDArray[np.float64],
    confidence: NDArray[np.float64] | None,
    bases: PoseBases,
    max_bases: int | None = None,
    target_lengths: NDArray[np.float64] | None = None,
    options: RamakrishnaOptions | None = None,
) -> LiftResult:
    """Lift one skeleton by projected matching pursuit (Ramakrishna et al. 2012).

    Parameters
    ----------
    points_2d : ndarray, shape (12, 2)
        Image coordinates of the 12 model joints (any consistent unit).
    confidence : ndarray, shape (12,), optional
        Below ``options.confidence_threshold`` = missing. None = all visible.
    bases : PoseBases
        Normally class-wise PCA bases.
    max_bases : int, optional
        Overrides ``options.max_bases``.
    target_lengths : ndarray, shape (8,), optional
        Limb lengths (model units) whose sum (or sum of squares) the pose must match;
        default ``bases.limb_proportions``.
    options : RamakrishnaOptions, optional

    Returns
    -------
    LiftResult
        ``objective`` is the weighted squared reprojection error in normalised 2D units;
        ``limb_violation`` the largest per-limb deviation ``| ||C_i y|| - L_i |`` (this
        method constrains only the sum, so it is not ~0); ``n_iter`` the number of bases
        added; ``converged`` whether the kept state's alternation settled and its
        constraint holds; ``n_starts`` = 1, ``start_index`` = 0.
    """
    opts = options if options is not None else RamakrishnaOptions()
    cap = int(max_bases) if max_bases is not None else opts.max_bases
    if cap < 1:
        raise OptionsError("max_bases must be >= 1")
    x_in, w, tl = _checked_input(points_2d, confidence, bases, target_lengths, opts)
    norm = _normalise(x_in, w)
    pb = _problem(norm.x, w, bases, tl, opts.limb_constraint == "sum_squared")
    best, n_added = _pursue(pb, cap, opts)
    return _lift_result(best, n_added, pb, norm, x_in, opts)


class RamakrishnaLifter:
    """The baseline behind the same call shape as :class:`pose_lifter.core.lift.lifter.Lifter`.

    Parameters
    ----------
    bases : PoseBases
        Normally class-wise PCA bases (:func:`pose_lifter.core.model.bases.learn_classwise_pca_bases`).
    options : RamakrishnaOptions, optional
    target_lengths : ndarray, shape (8,), optional
        See :func:`ramakrishna_lift`.
    """

    def __init__(self, bases: PoseBases, options: RamakrishnaOptions | None = None,
                 target_lengths: NDArray[np.float64] | None = None) -> None:
        self.bases = bases
        self.options = options if options is not None else RamakrishnaOptions()
        self.target_lengths = target_lengths

    def lift(self, points_2d: NDArray[np.float64], confidence: NDArray[np.float64] | None = None,
             warm: WarmStart | None = None) -> LiftResult:
        """Lift one skeleton (12, 2); ``warm`` is accepted and ignored (the method has none)."""
        return ramakrishna_lift(points_2d, confidence, self.bases, target_lengths=self.target_lengths,
                                options=self.options)

    def lift_many(self, points_2d: NDArray[np.float64], confidence: NDArray[np.float64] | None = None,
                  warm_start: bool = True) -> Sequence[LiftResult]:
        """Lift frames (T, 12, 2) independently (``warm_start`` is ignored)."""
        pts, conf = check_keypoint_sequence(points_2d, confidence)
        return [self.lift(pts[i], None if conf is None else conf[i]) for i in range(pts.shape[0])]
