"""References for the pose step (``core/solve/pose_step.py``): the basis coefficients ``alpha`` of
``y = mu + B alpha`` for a fixed camera, minimising
``sum_j w_j loss(x_j - (M0 y_j + t)) + theta ||alpha||_1`` (:func:`pose_objective`).

Without the limb constraints the problem is convex (an LP for L1, a QP for L2; Clarabel,
:func:`reference_pose_convex`); with them it is not, and :func:`reference_pose_limbs_local` is
a local SLSQP reference.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any, NamedTuple

import numpy as np
from numpy.typing import NDArray

from ..errors import InvalidInputError
from ..model.skeleton import LimbVectors, limb_selectors
from ..results import Camera
from ._common import (
    array,
    check_loss,
    clarabel_kwargs,
    cvxpy,
    local_minimize,
    loss_value,
    status_ok,
    weights_array,
)

__all__ = ["pose_objective", "reference_pose_convex", "reference_pose_limbs_local"]


def pose_objective(
    points: NDArray[np.float64], camera: Camera, mean: NDArray[np.float64],
    components: NDArray[np.float64], weights: NDArray[np.float64], theta: float,
    loss: str, alpha: NDArray[np.float64],
) -> float:
    """The pose problem's objective ``sum_j w_j loss(x_j - M0 y_j - t) + theta ||alpha||_1``.

    Parameters
    ----------
    points, camera, mean, components, weights, theta, loss
        As in :func:`reference_pose_convex`.
    alpha : ndarray, shape (k,)
    """
    x, mu, b, w = _pose_data(points, mean, components, weights)
    a = array(alpha, (b.shape[1],), "alpha")
    y = (mu + b @ a).reshape(x.shape[0], 3)
    return loss_value(x - camera.project(y), w, check_loss(loss)) + float(theta) * float(np.abs(a).sum())


def _pose_data(
    points: Any, mean: Any, components: Any, weights: Any,
) -> tuple[NDArray[np.float64], NDArray[np.float64], NDArray[np.float64], NDArray[np.float64]]:
    """The pose problem's data, checked: points (n, 2), mean (3n,), components (3n, k) and
    weights (n,), finite (weights >= 0)."""
    x = array(points, (None, 2), "points")
    n = x.shape[0]
    mu = array(mean, (3 * n,), "mean")
    b = array(components, (3 * n, None), "components")
    return x, mu, b, weights_array(weights, n)


class _Residual(NamedTuple):
    """The pose step's weighted residual ``r(alpha) = b - A alpha`` (stacked x1, y1, x2, ...)."""

    a_mat: NDArray[np.float64]  #: (2n, k)
    b_vec: NDArray[np.float64]  #: (2n,)
    w2: NDArray[np.float64]  #: (2n,) per-entry weights

    def at(self, alpha: NDArray[np.float64]) -> NDArray[np.float64]:
        """``r(alpha)``, shape (2n,), of ``alpha`` (k,)."""
        return np.asarray(self.b_vec - self.a_mat @ alpha)


def _pose_linear_map(
    x: NDArray[np.float64], camera: Camera, mu: NDArray[np.float64], bm: NDArray[np.float64],
    w: NDArray[np.float64],
) -> _Residual:
    """The weighted residual of checked data (:func:`_pose_data`)."""
    n = x.shape[0]
    big_m = np.kron(np.eye(n), camera.projection)  # (2n, 3n)
    a_mat = big_m @ bm
    b_vec = x.reshape(-1) - big_m @ mu - np.tile(camera.translation, n)
    return _Residual(a_mat, b_vec, np.repeat(w, 2))


def reference_pose_convex(
    points: NDArray[np.float64], camera: Camera, mean: NDArray[np.float64],
    components: NDArray[np.float64], weights: NDArray[np.float64], theta: float, loss: str,
) -> tuple[NDArray[np.float64], float]:
    """Pose step without limb constraints (L1NAWS, L1NANS, L2NAWS, L2NANS); Clarabel.

    Minimises ``sum_j w_j loss(x_j - (M0 y_j + t)) + theta ||alpha||_1`` with
    ``y = (mu + B alpha).reshape(n, 3)``, ``M0 = camera.projection``, ``t =
    camera.translation`` (an LP for L1, a QP for L2).

    Parameters
    ----------
    points : ndarray, shape (n, 2)
    camera : Camera
    mean : ndarray, shape (3n,)
    components : ndarray, shape (3n, k)
    weights : ndarray, shape (n,)
    theta : float
        >= 0 (0 for the "NS" variants).
    loss : {"l1", "l2"}

    Returns
    -------
    alpha : ndarray, shape (k,)
    objective : float
        Re-evaluated in numpy at ``alpha``.
    """
    cp = cvxpy()

    lo = check_loss(loss)
    x, mu, bm, w = _pose_data(points, mean, components, weights)
    a_mat, b_vec, w2 = _pose_linear_map(x, camera, mu, bm, w)
    if not theta >= 0:
        raise InvalidInputError("theta must be >= 0")
    alpha = cp.Variable(a_mat.shape[1])
    resid = b_vec - a_mat @ alpha
    data = cp.sum(cp.multiply(w2, cp.abs(resid))) if lo == "l1" else cp.sum(cp.multiply(w2, cp.square(resid)))
    prob = cp.Problem(cp.Minimize(data + float(theta) * cp.norm1(alpha)))
    prob.solve(**clarabel_kwargs())
    status_ok(prob, "reference_pose_convex")
    a = np.asarray(alpha.value, dtype=np.float64).reshape(-1)
    return a, pose_objective(x, camera, mu, bm, w, theta, lo, a)


@dataclass(frozen=True)
class _SmoothPose:
    """The pose problem with limb constraints in the smooth form of
    :func:`reference_pose_limbs_local`, over ``u = (a_plus, a_minus[, e])``.

    Attributes
    ----------
    residual : _Residual
        ``r = b - A alpha`` and its per-entry weights (:func:`_pose_linear_map`).
    limbs : LimbVectors
        Limb vectors of the components and of the mean.
    lsq : ndarray, shape (8,)
        Squared target lengths.
    th : float
        ``theta``.
    l1 : bool
        L1 loss, with the slacks ``e`` (shape (2n,)) at the end of ``u``.
    """

    residual: _Residual
    limbs: LimbVectors
    lsq: NDArray[np.float64]
    th: float
    l1: bool

    @property
    def k(self) -> int:
        """The number of components."""
        return int(self.residual.a_mat.shape[1])

    @property
    def nvar(self) -> int:
        """The length of ``u``."""
        return 2 * self.k + (self.residual.a_mat.shape[0] if self.l1 else 0)

    def alpha_of(self, u: NDArray[np.float64]) -> NDArray[np.float64]:
        """``alpha = a_plus - a_minus``, shape (k,), of ``u`` (nvar,)."""
        k = self.k
        return np.asarray(u[:k] - u[k : 2 * k])

    def fun(self, u: NDArray[np.float64]) -> float:
        """The smooth objective at ``u`` (nvar,)."""
        k = self.k
        reg = self.th * float(u[: 2 * k].sum())
        if self.l1:
            return float(self.residual.w2 @ u[2 * k :]) + reg
        r = self.residual.at(self.alpha_of(u))
        return float(self.residual.w2 @ (r * r)) + reg

    def jac(self, u: NDArray[np.float64]) -> NDArray[np.float64]:
        """The gradient (nvar,) of :meth:`fun` at ``u`` (nvar,)."""
        k = self.k
        g = np.zeros(self.nvar)
        g[: 2 * k] = self.th
        if self.l1:
            g[2 * k :] = self.residual.w2
        else:
            r = self.residual.at(self.alpha_of(u))
            ga = -2.0 * self.residual.a_mat.T @ (self.residual.w2 * r)
            g[:k] += ga
            g[k : 2 * k] -= ga
        return g

    def limb_fun(self, u: NDArray[np.float64]) -> NDArray[np.float64]:
        """The limb constraints ``||C_i y||^2 - L_i``, shape (8,), at ``u`` (nvar,)."""
        v = self.limbs.of_mean + self.limbs.of_components @ self.alpha_of(u)  # (8, 3)
        return np.asarray((v * v).sum(axis=1) - self.lsq)

    def limb_jac(self, u: NDArray[np.float64]) -> NDArray[np.float64]:
        """The Jacobian (8, nvar) of :meth:`limb_fun` at ``u`` (nvar,)."""
        k = self.k
        v = self.limbs.of_mean + self.limbs.of_components @ self.alpha_of(u)
        ga = 2.0 * np.einsum("ij,ijk->ik", v, self.limbs.of_components)  # (8, k)
        out = np.zeros((len(v), self.nvar))
        out[:, :k] = ga
        out[:, k : 2 * k] = -ga
        return out

    def slack_ineq(self, u: NDArray[np.float64]) -> NDArray[np.float64]:
        """L1 only: ``e - r >= 0`` and ``e + r >= 0``, shape (4n,), at ``u`` (nvar,)."""
        r = self.residual.at(self.alpha_of(u))
        e = u[2 * self.k :]
        return np.concatenate([e - r, e + r])


def _smooth_constraints(
    sp: _SmoothPose, a0: NDArray[np.float64],
) -> tuple[list[dict[str, Any]], list[tuple[float | None, float | None]], NDArray[np.float64]]:
    """The constraints, the bounds and the start of :func:`local_minimize` for ``sp``.

    Parameters
    ----------
    sp : _SmoothPose
    a0 : ndarray, shape (k,)
        The start ``alpha``; the slacks of L1 start at ``|r(a0)|``.

    Returns
    -------
    constraints : list of dict
    bounds : list of (float or None, float or None), length nvar
    u0 : ndarray, shape (nvar,)
    """
    k = sp.k
    cons: list[dict[str, Any]] = [{"type": "eq", "fun": sp.limb_fun, "jac": sp.limb_jac}]
    bounds: list[tuple[float | None, float | None]] = [(0.0, None)] * (2 * k)
    u0 = np.concatenate([np.maximum(a0, 0.0), np.maximum(-a0, 0.0)])
    if sp.l1:
        # e - r >= 0 and e + r >= 0 with r = b - A alpha
        a_mat = sp.residual.a_mat
        r_dim = a_mat.shape[0]
        jr = np.hstack([-a_mat, a_mat])  # d r / d (a+, a-)
        ineq_jac = np.vstack([np.hstack([-jr, np.eye(r_dim)]), np.hstack([jr, np.eye(r_dim)])])
        cons.append({"type": "ineq", "fun": sp.slack_ineq, "jac": lambda u: ineq_jac})
        bounds += [(0.0, None)] * r_dim
        u0 = np.concatenate([u0, np.abs(sp.residual.b_vec - a_mat @ a0)])
    return cons, bounds, u0


def reference_pose_limbs_local(
    points: NDArray[np.float64], camera: Camera, mean: NDArray[np.float64],
    components: NDArray[np.float64], weights: NDArray[np.float64], theta: float, loss: str,
    limb_sq_lengths: NDArray[np.float64], alpha0: NDArray[np.float64],
) -> tuple[NDArray[np.float64], float]:
    """Full (nonconvex) pose step with the 8 limb constraints: a local SLSQP reference.

    Minimises ``sum_j w_j loss(x_j - (M0 y_j + t)) + theta ||alpha||_1`` subject to
    ``||C_i y||^2 = L_i`` (``C`` from :func:`pose_lifter.core.model.skeleton.limb_selectors`), in a
    smooth form: ``alpha = a_plus - a_minus`` with ``a_plus, a_minus >= 0`` and
    ``||alpha||_1 -> sum(a_plus + a_minus)``; for L1 the absolute residuals become slacks
    ``e >= |r|`` (two linear inequalities per coordinate) minimising ``sum w e``. Analytic
    gradients throughout; same SLSQP / trust-constr fallback as
    :func:`reference_alpha_local`. Local: the result depends on ``alpha0``.

    Parameters
    ----------
    points : ndarray, shape (12, 2)
    camera : Camera
    mean : ndarray, shape (36,)
    components : ndarray, shape (36, k)
    weights : ndarray, shape (12,)
    theta : float
    loss : {"l1", "l2"}
    limb_sq_lengths : ndarray, shape (8,)
        ``L_i``, squared target lengths.
    alpha0 : ndarray, shape (k,)

    Returns
    -------
    alpha : ndarray, shape (k,)
    objective : float
        The original (non-smooth) objective at ``alpha``.
    """
    lo = check_loss(loss)
    x, mu, bm, w = _pose_data(points, mean, components, weights)
    residual = _pose_linear_map(x, camera, mu, bm, w)
    a0 = array(alpha0, (bm.shape[1],), "alpha0")
    c = limb_selectors()
    lsq = array(limb_sq_lengths, (c.shape[0],), "limb_sq_lengths")
    sp = _SmoothPose(residual, LimbVectors.of(mu, bm), lsq, float(theta), lo == "l1")
    cons, bounds, u0 = _smooth_constraints(sp, a0)
    u = local_minimize(sp.fun, u0, sp.jac, cons, bounds, sp.limb_fun, "reference_pose_limbs_local")
    alpha = sp.alpha_of(u)
    return alpha, pose_objective(x, camera, mu, bm, w, sp.th, lo, alpha)
