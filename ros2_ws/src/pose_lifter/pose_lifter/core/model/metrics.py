"""Error metrics, named after the protocols they implement.

All take poses of shape ``(..., J, 3)`` and return per-pose values of shape ``(...)``
(or per-joint ``(..., J)``) in the units of the inputs.
"""

from __future__ import annotations

import numpy as np
from numpy.typing import NDArray

from ..errors import InvalidInputError
from .skeleton import RIGHT_LOWER_LEG, limb_lengths

__all__ = [
    "mpjpe",
    "normalised_error",
    "p_mpjpe",
    "per_joint_error",
    "procrustes_align",
    "similarity_normalised_error",
]


def per_joint_error(pred: NDArray[np.float64], gt: NDArray[np.float64]) -> NDArray[np.float64]:
    """Euclidean error of every joint, shape ``(..., J)``."""
    return np.asarray(np.linalg.norm(np.asarray(pred) - np.asarray(gt), axis=-1))


def mpjpe(pred: NDArray[np.float64], gt: NDArray[np.float64]) -> NDArray[np.float64]:
    """Mean per-joint position error (Protocol #1), after removing each pose's centroid.

    Parameters
    ----------
    pred, gt : ndarray, shape (..., J, 3)

    Returns
    -------
    ndarray, shape (...)
    """
    p = np.asarray(pred, dtype=np.float64)
    g = np.asarray(gt, dtype=np.float64)
    p = p - p.mean(axis=-2, keepdims=True)
    g = g - g.mean(axis=-2, keepdims=True)
    return np.asarray(per_joint_error(p, g).mean(axis=-1))


def _procrustes_rotation(p0: NDArray[np.float64], g0: NDArray[np.float64]
                         ) -> tuple[NDArray[np.float64], NDArray[np.float64]]:
    """The proper rotation ``R`` minimising ``||p0 R - g0||_F`` for centred poses ``(..., J, 3)``
    (Kabsch; reflection-safe: the smallest singular direction is flipped when ``det < 0``), and
    the singular values of ``p0^T g0`` with that flip applied (their sum is ``tr(R^T p0^T g0)``)."""
    h = np.swapaxes(p0, -1, -2) @ g0  # (..., 3, 3)
    u, s, vt = np.linalg.svd(h)
    d = np.sign(np.linalg.det(u @ vt))
    d = np.where(d == 0, 1.0, d)
    s = s.copy()
    s[..., -1] *= d
    u = u.copy()
    u[..., :, -1] *= d[..., None]
    return u @ vt, s


def procrustes_align(pred: NDArray[np.float64], gt: NDArray[np.float64]) -> NDArray[np.float64]:
    """Similarity transform (rotation, scale, translation) of ``pred`` onto ``gt``.

    Minimises ``||s R p + t - g||_F`` with ``R`` a proper rotation (reflection-safe: the
    sign of the smallest singular direction is flipped when ``det < 0``).

    Parameters
    ----------
    pred, gt : ndarray, shape (..., J, 3)

    Returns
    -------
    ndarray, shape (..., J, 3)
        The aligned prediction.
    """
    p = np.asarray(pred, dtype=np.float64)
    g = np.asarray(gt, dtype=np.float64)
    mu_p = p.mean(axis=-2, keepdims=True)
    mu_g = g.mean(axis=-2, keepdims=True)
    p0 = p - mu_p
    g0 = g - mu_g
    rot, s = _procrustes_rotation(p0, g0)  # p0 @ rot ~ g0
    norm_p = np.sum(p0**2, axis=(-2, -1))
    scale = np.sum(s, axis=-1) / np.where(norm_p > 0, norm_p, 1.0)
    return np.asarray(scale[..., None, None] * (p0 @ rot) + mu_g)


def p_mpjpe(pred: NDArray[np.float64], gt: NDArray[np.float64]) -> NDArray[np.float64]:
    """MPJPE after similarity (Procrustes) alignment, "Protocol #2"; shape ``(...)``."""
    return np.asarray(per_joint_error(procrustes_align(pred, gt), gt).mean(axis=-1))


def normalised_error(pred: NDArray[np.float64], gt: NDArray[np.float64]) -> NDArray[np.float64]:
    """The paper's criterion ``||y - y_hat||_2`` in units of the right lower leg.

    Both poses are centred and scaled to a unit right lower leg, and ``pred`` is aligned to
    ``gt`` by a rotation (the weak-perspective camera leaves global rotation and depth sign
    to the estimate; Procrustes without scale). Returns the 2-norm of the stacked 3n-vector
    difference, shape ``(...)``. Raises ``InvalidInputError`` (a ``ValueError``) when an
    estimate's right lower leg has zero length (e.g. a flat floor whose knee and ankle are both
    missing).
    """
    p = np.asarray(pred, dtype=np.float64)
    g = np.asarray(gt, dtype=np.float64)
    p = p - p.mean(axis=-2, keepdims=True)
    g = g - g.mean(axis=-2, keepdims=True)
    leg = limb_lengths(p)[..., RIGHT_LOWER_LEG]
    if np.any(~(leg > 1e-12 * np.maximum(1.0, np.abs(p).max(axis=(-2, -1))))):
        raise InvalidInputError("an estimate has a zero-length right lower leg: the paper's criterion "
                         "(estimate scaled by its own leg) is undefined for it")
    p = p / leg[..., None, None]
    g = g / limb_lengths(g)[..., RIGHT_LOWER_LEG][..., None, None]
    aligned = p @ _procrustes_rotation(p, g)[0]
    return _stacked_norm(aligned - g)


def similarity_normalised_error(pred: NDArray[np.float64], gt: NDArray[np.float64]) -> NDArray[np.float64]:
    """``||procrustes_align(pred, gt) - gt||_2`` over the stacked 3n-vector, in units of the
    truth's right lower leg, shape ``(...)``: the paper's criterion for estimates whose own leg
    means nothing (the floors of :func:`pose_lifter.offline.evaluate.evaluate_bag`: flat 2D, mean pose)."""
    g = np.asarray(gt, dtype=np.float64)
    leg = limb_lengths(g)[..., RIGHT_LOWER_LEG]
    return np.asarray(_stacked_norm(procrustes_align(pred, g) - g) / leg)


def _stacked_norm(diff: NDArray[np.float64]) -> NDArray[np.float64]:
    """2-norm of each pose's stacked ``(J * 3)``-vector, shape ``(...)``."""
    return np.asarray(np.linalg.norm(diff.reshape(*diff.shape[:-2], -1), axis=-1))
