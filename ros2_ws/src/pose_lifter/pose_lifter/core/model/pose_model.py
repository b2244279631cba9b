"""The pose model: the bases, their SVD and the limb constraints in the coordinates the
pose step solves in (built once per basis file)."""

from __future__ import annotations

import functools
from dataclasses import dataclass

import numpy as np
from numpy.typing import NDArray

from ..errors import InvalidInputError
from ..numeric.records import ModelArrays, model_record
from .bases import PoseBases
from .skeleton import N_JOINTS, limb_selectors


@dataclass(frozen=True)
class LiftedConstraints:
    """The limb constraints of a lifted problem, with what the Q-step needs precomputed.

    Attributes
    ----------
    omegas : ndarray, shape (8, d, d)
        Symmetric ``Omega_i``; ``z^T Omega_i z = ||C_i y||^2 - L_i``.
    affine : ndarray, shape (9, d*d)
        Rows ``vec(Omega_i)`` and ``vec(e e^T)`` (the constraint ``Q[-1,-1] = 1``).
    affine_rhs : ndarray, shape (9,)
    gram_pinv : ndarray, shape (9, 9)
        Pseudo-inverse of the Gram matrix ``affine @ affine.T``.
    """

    omegas: NDArray[np.float64]
    affine: NDArray[np.float64]
    affine_rhs: NDArray[np.float64]
    gram_pinv: NDArray[np.float64]

    @property
    def dim(self) -> int:
        """Size ``d`` of the lifted matrix."""
        return int(self.omegas.shape[1])

    @staticmethod
    def build(omegas: NDArray[np.float64]) -> LiftedConstraints:
        """Precompute the affine projection data for ``omegas`` (8, d, d)."""
        om = 0.5 * (omegas + np.swapaxes(omegas, 1, 2))
        d = om.shape[1]
        e = np.zeros((d, d))
        e[-1, -1] = 1.0
        affine = np.vstack([om.reshape(om.shape[0], -1), e.reshape(1, -1)])
        rhs = np.zeros(affine.shape[0])
        rhs[-1] = 1.0
        gram_pinv = np.asarray(np.linalg.pinv(affine @ affine.T, rcond=1e-12), dtype=np.float64)
        return LiftedConstraints(om, affine, rhs, gram_pinv)

    def violation(self, z: NDArray[np.float64]) -> NDArray[np.float64]:
        """``z^T Omega_i z`` for every constraint, shape (8,)."""
        return np.asarray(np.einsum("i,kij,j->k", z, self.omegas, z))


def _lifted_omegas(basis: NDArray[np.float64], mu: NDArray[np.float64], limb_sq: NDArray[np.float64]
                   ) -> NDArray[np.float64]:
    """``Omega_i`` (8, m + 1, m + 1) of the lifting ``z = [coefficients; 1]`` for ``y = mu + basis
    coefficients`` (basis (36, m)): ``z^T Omega_i z = ||C_i y||^2 - L_i``."""
    c = limb_selectors()
    ctc = np.einsum("iak,ial->ikl", c, c)  # (8, 36, 36)
    m = basis.shape[1]
    out = np.zeros((8, m + 1, m + 1))
    out[:, :m, :m] = np.einsum("ka,iab,bl->ikl", basis.T, ctc, basis)
    cross = np.einsum("ka,iab,b->ik", basis.T, ctc, mu)
    out[:, :m, m] = cross
    out[:, m, :m] = cross
    out[:, m, m] = np.einsum("a,iab,b->i", mu, ctc, mu) - limb_sq
    return out


@dataclass(frozen=True)
class PoseModel:
    """Everything of the pose step that depends only on the bases and limb targets.

    Built once per basis file; never per frame.

    Attributes
    ----------
    mean : ndarray, shape (36,)
    components : ndarray, shape (36, k)
    limb_sq : ndarray, shape (8,)
        Target squared limb lengths ``L_i`` (right lower leg = 1).
    u, sig, v : ndarrays, shapes (36, r), (r,), (k, r)
        Thin SVD of the components.
    reduced : LiftedConstraints
        Constraints in the reduced lifting (``d = r + 1``, coordinates ``s = V^T alpha``).
    limb_cu, limb_cmu : ndarrays, shapes (8, 3, r), (8, 3)
        ``C_i U S`` and ``C_i mu``: the limb vectors in the reduced coordinates (the Riemannian
        alpha-step's limb coordinates).
    """

    mean: NDArray[np.float64]
    components: NDArray[np.float64]
    limb_sq: NDArray[np.float64]
    u: NDArray[np.float64]
    sig: NDArray[np.float64]
    v: NDArray[np.float64]
    reduced: LiftedConstraints
    limb_cu: NDArray[np.float64]
    limb_cmu: NDArray[np.float64]

    @functools.cached_property
    def kernel_limbs(self) -> tuple[NDArray[np.float64], NDArray[np.float64]]:
        """``C_i U S`` (24, r) and ``C_i mu`` (24,) as C-contiguous arrays for the compiled
        Riemannian alpha-step (made once per model)."""
        r = self.sig.size
        return (np.ascontiguousarray(self.limb_cu.reshape(24, r)),
                np.ascontiguousarray(self.limb_cmu.reshape(24)))

    @functools.cached_property
    def limb_coordinates(self) -> tuple[NDArray[np.float64], NDArray[np.float64], NDArray[np.float64],
                                        NDArray[np.float64]] | None:
        """The reduced coordinates ``s`` split as ``s = s0 + Z l + N t``, where ``l`` (24,) are the
        8 limb vectors ``C_i (mu + U S s)`` and ``t`` is free: ``(Z (r, 24), N (r, r - 24), s0 (r,),
        limb lengths (8,))``. The limb constraints are then ``||l_i|| = sqrt(L_i)``, a product of
        spheres (the ``"riemannian"`` alpha-solver). None when the limb map ``C U S`` (24, r) does
        not have full row rank (fewer than 24 independent basis directions, e.g. a small PCA)."""
        cu24 = self.kernel_limbs[0]
        if cu24.shape[1] < 24:
            return None
        uu, sv, vt = np.linalg.svd(cu24)
        if sv[-1] <= 1e-8 * sv[0]:
            return None
        z = vt[:24].T @ ((uu.T) / sv[:, None])  # (r, 24): cu24 @ z = I
        n = np.ascontiguousarray(vt[24:].T)  # (r, r - 24): cu24 @ n = 0
        s0 = -z @ self.kernel_limbs[1]
        return np.ascontiguousarray(z), n, s0, np.sqrt(self.limb_sq)

    @property
    def n_bases(self) -> int:
        return int(self.components.shape[1])

    @staticmethod
    def build(bases: PoseBases, limb_proportions: NDArray[np.float64]) -> PoseModel:
        """Precompute the SVD and the reduced lifting's constraint data.

        Parameters
        ----------
        bases : PoseBases
        limb_proportions : ndarray, shape (8,)
            Limb lengths (not squared), right lower leg = 1.
        """
        props = np.asarray(limb_proportions, dtype=np.float64)
        if props.shape != (8,) or not np.all(np.isfinite(props)) or np.any(props <= 0):
            raise InvalidInputError("limb_proportions must be 8 positive lengths")
        mu = bases.mean
        b = bases.components
        u, s, vt = np.linalg.svd(b, full_matrices=False)
        r = int(np.sum(s > s[0] * 1e-10))
        u, s, v = u[:, :r], s[:r], vt[:r].T
        c = limb_selectors()  # (8, 3, 36)
        limb_sq = props**2
        us = u * s
        cu = np.einsum("iak,kr->iar", c, us)
        return PoseModel(
            mean=mu, components=b, limb_sq=limb_sq, u=u, sig=s, v=v,
            reduced=LiftedConstraints.build(_lifted_omegas(us, mu, limb_sq)),
            limb_cu=cu,
            limb_cmu=np.einsum("iak,k->ia", c, mu),
        )

    def pose(self, alpha: NDArray[np.float64]) -> NDArray[np.float64]:
        """``(mu + B alpha)`` as (12, 3)."""
        return np.asarray((self.mean + self.components @ alpha).reshape(N_JOINTS, 3))

    def limb_violation(self, alpha: NDArray[np.float64], radii: NDArray[np.float64] | None = None) -> float:
        """``max_i | ||C_i y|| - r_i |`` for ``y = mu + B alpha``, with the limb lengths ``r`` (8,)
        in use (default the model's, ``sqrt(L_i)``; a prior's per-person ``limb_radii``)."""
        lv = (self._limb_matrix @ (self.mean + self.components @ alpha)).reshape(8, 3)
        r = np.sqrt(self.limb_sq) if radii is None else radii
        return float(np.max(np.abs(np.sqrt(np.sum(lv * lv, axis=1)) - r)))

    @functools.cached_property
    def riemannian_arrays(self) -> tuple[NDArray[np.float64], NDArray[np.float64], NDArray[np.float64]]:
        """``V`` (k, r), ``V^T`` (r, k) and ``(C U S)^T`` (r, 24), C-contiguous: the Riemannian pose
        kernel's operands that depend only on the bases (made once per model)."""
        return (np.ascontiguousarray(self.v), np.ascontiguousarray(self.v.T),
                np.ascontiguousarray(self.kernel_limbs[0].T))

    @functools.cached_property
    def limb_radii(self) -> NDArray[np.float64]:
        """The limb lengths ``sqrt(L_i)`` (8,), C-contiguous."""
        return np.ascontiguousarray(np.sqrt(self.limb_sq))

    @functools.cached_property
    def kernel_arrays(self) -> ModelArrays:
        """The model as the compiled pose step and run read it (:func:`model_record`; made once per
        model). Without an onto limb map (:attr:`limb_coordinates` None) its limb-coordinate
        arrays are zeros: only the rows and the limb matrix are read then."""
        r = self.sig.size
        vc, vt, cu24_t = self.riemannian_arrays
        coords = self.limb_coordinates
        z, n, s0 = (np.zeros((r, 24)), np.zeros((r, 0)), np.zeros(r)) if coords is None else coords[:3]
        return model_record(ModelArrays(mean=self.mean, u=self.u, sig=self.sig, vc=vc, vt=vt,
                                        comps=self.components, limb_matrix=self._limb_matrix, z=z, n=n, s0=s0,
                                        cu24_t=cu24_t, cmu24=self.kernel_limbs[1]))

    @functools.cached_property
    def _limb_matrix(self) -> NDArray[np.float64]:
        """The 8 ``C_i`` stacked, (24, 36)."""
        return np.ascontiguousarray(limb_selectors().reshape(24, 3 * N_JOINTS))


