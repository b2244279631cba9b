"""The alpha-step protocol of the pose ADM, the coordinates it is solved in, and the step of its
Python loop: the paper's inner ADM in the lifting."""

from __future__ import annotations

from typing import Protocol

import numpy as np
from numpy.typing import NDArray

from ...model.pose_model import LiftedConstraints
from .lifted_admm import QStepFn, lifted_alpha_admm, lifted_quadratic, restore_feasibility


class AlphaStep(Protocol):
    """One alpha-step of the pose ADM: ``argmin_alpha ||A alpha - d1||^2 + ||alpha - d2||^2`` (under
    the limb constraints when the variant has them) from the current iterate ``alpha`` (k,).
    Returns the new ``alpha`` (k,) and the solver's iterations."""

    def __call__(self, d1: NDArray[np.float64], d2: NDArray[np.float64], alpha: NDArray[np.float64]
                 ) -> tuple[NDArray[np.float64], int]: ...


class Coordinates:
    """Where an alpha-step is solved: the reduced ``s = V^T alpha`` (``A = M U S`` (m, r), ``V``
    (k, r); the part of ``alpha`` in the null space of ``B`` is set to its optimum in closed form).
    The step's objective is ``s^T G s - 2 lin^T s + const`` with ``G = A^T A + I``."""

    def __init__(self, a: NDArray[np.float64], v: NDArray[np.float64]) -> None:
        self.a, self.v = a, v
        self.g = a.T @ a + np.eye(a.shape[1])

    def quadratic(self, d1: NDArray[np.float64], d2: NDArray[np.float64]
                  ) -> tuple[NDArray[np.float64], float, NDArray[np.float64]]:
        """``(lin, const, V^T d2)`` of the step for ``d1`` (m,), ``d2`` (k,)."""
        vtd2 = self.v.T @ d2
        return self.a.T @ d1 + vtd2, float(d1 @ d1 + vtd2 @ vtd2), vtd2

    def start(self, alpha: NDArray[np.float64]) -> NDArray[np.float64]:
        return np.asarray(self.v.T @ alpha)

    def alpha(self, s: NDArray[np.float64], d2: NDArray[np.float64], vtd2: NDArray[np.float64]
              ) -> NDArray[np.float64]:
        return np.asarray(d2 - self.v @ vtd2 + self.v @ s)


class LiftedStep:
    """The alpha-step in the rank-1 lifting ``z = [s; 1]``: the paper's inner (Q, P) ADM followed by
    the Gauss-Newton projection onto the limb constraints."""

    def __init__(self, coords: Coordinates, cons: LiftedConstraints, delta: float, max_iter: int, tol: float,
                 qstep_fn: QStepFn | None) -> None:
        self._c, self._cons = coords, cons
        self._delta, self._max_iter, self._tol, self._qstep_fn = delta, max_iter, tol, qstep_fn

    def __call__(self, d1: NDArray[np.float64], d2: NDArray[np.float64], alpha: NDArray[np.float64]
                 ) -> tuple[NDArray[np.float64], int]:
        lin, const, vtd2 = self._c.quadratic(d1, d2)
        wmat = lifted_quadratic(self._c.g, lin, const)
        z0 = np.append(self._c.start(alpha), 1.0)
        res = lifted_alpha_admm(wmat, self._cons, z0, self._delta, self._max_iter, self._tol, self._qstep_fn)
        z = restore_feasibility(self._cons, res.x)
        return self._c.alpha(z[:-1], d2, vtd2), res.n_iter


__all__ = ["AlphaStep", "Coordinates", "LiftedStep"]
