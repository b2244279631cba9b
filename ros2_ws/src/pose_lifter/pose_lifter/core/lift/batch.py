"""A batch of lifts: the rows a caller hands the lifter (:class:`LiftRow`), a row once its input
is checked (:class:`Person`), and the prior stage's pass of the learned prior's network over every
row that needs a pose (:func:`prior_calls`).

The lifter (:meth:`pose_lifter.core.lift.lifter.Lifter.lift_people`) runs its stages in order over
a batch's rows: the input checks, the prior, the runs, the mirrored hypotheses, the outlier passes;
each stage is one call of the compiled kernels (:func:`~pose_lifter.core.solve.run_kernel.run_calls`)
or of the network (:func:`prior_calls`) over all the rows it concerns, and the Python around them
is per-row bookkeeping. A run's or a pose's result does not depend on what else is in its batch
(the kernel solves each run on its own operands, the network's rows do not mix), so a person
lifted with others gets what they get alone, bit for bit (``tests/core/lift/test_batch.py``).
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Final

import numpy as np
from numpy.typing import NDArray

from ..errors import InvalidInputError
from ..model.prior import PosePrior, flip_rows
from ..model.skeleton import N_JOINTS
from ..numeric.jit import HAVE_NUMBA
from ..results import Camera, Failure, Normalisation, TrackContext, WarmStart

__all__ = ["LiftRow", "Person", "PriorCall", "prior_calls"]


@dataclass(frozen=True, eq=False)
class LiftRow:
    """One person's frame handed to a lifter: :meth:`~pose_lifter.core.lift.lifter.Lifter.lift`'s
    arguments, lifted with the other rows of its batch
    (:meth:`~pose_lifter.core.lift.lifter.Lifter.lift_people`)."""

    points: NDArray[np.float64]  #: (12, 2)
    confidence: NDArray[np.float64] | None = None  #: (12,)
    warm: WarmStart | None = None
    track: TrackContext | None = None


@dataclass(frozen=True)
class Person:
    """One row of a batch after the input checks, normalised.

    Attributes
    ----------
    x : ndarray, shape (12, 2)
        The 2D in input units (a missing joint at the weighted centroid of the others:
        :func:`~pose_lifter.core.validation.joint_weights`).
    xn : ndarray, shape (12, 2)
        The same normalised by ``norm``.
    w : ndarray, shape (12,)
        The 2D term's weights.
    norm : Normalisation
    warm : WarmStart or None
    cam0 : Camera or None
        The warm start's camera in the normalised units.
    track : TrackContext
        As the modes read it (``temporal_weight`` an array (12,)).
    """

    x: NDArray[np.float64]
    xn: NDArray[np.float64]
    w: NDArray[np.float64]
    norm: Normalisation
    warm: WarmStart | None
    cam0: Camera | None
    track: TrackContext


@dataclass(frozen=True, eq=False)
class PriorCall:
    """One pose asked of a learned prior: ``prior.predict(points, visible, flip)``, computed with
    the other poses of its stage (:func:`prior_calls`).

    Attributes
    ----------
    prior : PosePrior
    points : ndarray, shape (12, 2) or (W, 12, 2)
        A frame, or a window of frames for a prior with ``window`` W.
    visible : ndarray of bool, shape (12,) or (W, 12)
    flip : bool
        Test-time flip averaging (``LifterOptions.prior_flip``).
    """

    prior: PosePrior
    points: NDArray[np.float64]
    visible: NDArray[np.bool_]
    flip: bool


def prior_calls(calls: list[PriorCall], threads: int = 1) -> list[NDArray[np.float64] | Failure]:
    """The poses (12, 3) of ``calls``, in order, each prior's network in one pass over its
    weights for all of its calls (its rows split over ``threads`` threads,
    :meth:`PosePrior.forward_rows`).

    A prior's weights (4 MB) are no longer in the cache when the next person needs them, so one
    pose alone costs the reading of the weights from memory; the poses of a frame's people read
    them once. The rows go through the compiled layer pass (:meth:`PosePrior._forward_small`),
    whose rows do not mix: each pose is the one :meth:`PosePrior.predict` gives alone, bit for
    bit. Without numba each pose is computed alone (numpy's matrix product of many rows rounds
    otherwise than of two). An input the prior refuses gets its :class:`Failure` in its place.
    """
    if not HAVE_NUMBA:
        out: list[NDArray[np.float64] | Failure] = []
        for c in calls:
            try:
                out.append(c.prior.predict(c.points, c.visible, c.flip))
            except InvalidInputError as err:
                out.append(Failure.of(err))
        return out
    refused: dict[int, Failure] = {}
    posed: dict[int, NDArray[np.float64]] = {}
    groups: dict[tuple[int, bool], list[tuple[int, NDArray[np.float64], NDArray[np.float64],
                                              NDArray[np.float64]]]] = {}
    for i, c in enumerate(calls):
        try:
            feats, centre, radius = c.prior.features(c.points, c.visible)
        except InvalidInputError as err:
            refused[i] = Failure.of(err)
            continue
        groups.setdefault((id(c.prior), c.flip), []).append((i, feats, centre, radius))
    for (_, flip), members in groups.items():
        prior = calls[members[0][0]].prior
        # stacked: the rows and the poses formed once for all of them (element-wise: what
        # PosePrior.input_rows and .poses give each alone)
        rows = flip_rows(np.stack([f for _, f, _, _ in members]), flip)  # (n, [2,] d)
        h = np.ascontiguousarray(rows.reshape(-1, rows.shape[-1]), dtype=np.float32)
        y = prior.forward_rows(h, threads).reshape(*rows.shape[:-1], N_JOINTS, 3)
        poses = prior.poses(y, np.stack([c for _, _, c, _ in members]),
                            np.stack([r for _, _, _, r in members]), flip)  # (n, 12, 3)
        for (i, _, _, _), pose in zip(members, poses, strict=True):
            posed[i] = pose
    return [posed[i] if i in posed else refused[i] for i in range(len(calls))]


#: The track context of a row given none.
NO_TRACK: Final[TrackContext] = TrackContext()
