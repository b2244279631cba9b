"""The learned prior's poses computed ahead, for several people in one pass of its network.

The weights of a prior (4 MB) are no longer in the cache when the next pose needs them, so the
network of one pose costs the reading of its weights from memory. The node's frame of several
people, and the offline lift's chains lifted in step, compute the poses they expect in one pass
(:class:`PosesAhead`); :meth:`pose_lifter.core.hybrid.PriorFit.predict` takes a pose from it,
bit for bit the pose computed alone.
"""

from __future__ import annotations

import numpy as np
from numpy.typing import NDArray

from ._jit import HAVE_NUMBA
from .errors import InvalidInputError
from .prior import PosePrior, flip_rows
from .skeleton import N_JOINTS

__all__ = ["PosesAhead"]


class PosesAhead:
    """Poses of priors computed ahead, their networks in one pass, for the inputs expected next.

    In a lift, a pose and its mirror image cost ~0.5 ms of network (the weights read from
    memory; ~0.15 ms with them in cache); computed ahead for the 6-8 people of a step, ~0.2 ms
    a pose (many36.mcap, one process). The caller expects an input per person
    (:meth:`PriorFit.prior_input <pose_lifter.core.hybrid.PriorFit.prior_input>`) and computes
    their poses in one pass over each prior's weights (:meth:`compute`); :meth:`predict` returns
    the pose held for its input (the prior, and the input's bytes, are the key) and computes it
    otherwise (an outlier pass, a joint the track gated or filled in). The rows run through the
    compiled pass of a single pose (:meth:`PosePrior._forward_small
    <pose_lifter.core.prior.PosePrior._forward_small>`), whose rows do not mix: a pose is the one
    :meth:`PosePrior.predict <pose_lifter.core.prior.PosePrior.predict>` gives alone, bit for
    bit. Without numba nothing is computed ahead (numpy's matrix product of many rows rounds
    otherwise than of two).

    Parameters
    ----------
    flip : bool
        The priors' test-time flip averaging (``LifterOptions.prior_flip``).
    """

    def __init__(self, flip: bool) -> None:
        self.flip = flip
        self._poses: dict[tuple[int, bytes], tuple[PosePrior, NDArray[np.float64]]] = {}
        #: poses answered from here and computed on demand since the last :meth:`clear`
        self.hits = 0
        self.misses = 0

    def __len__(self) -> int:
        return len(self._poses)

    def clear(self) -> None:
        """Forget every pose computed ahead (the counters too)."""
        self._poses.clear()
        self.hits = self.misses = 0

    @staticmethod
    def _key(prior: PosePrior, points: NDArray[np.float64], visible: NDArray[np.bool_]) -> tuple[int, bytes]:
        return id(prior), np.ascontiguousarray(points, dtype=np.float64).tobytes() + \
            np.ascontiguousarray(visible, dtype=np.bool_).tobytes()

    def compute(self, expected: list[tuple[PosePrior, NDArray[np.float64], NDArray[np.bool_]]]) -> None:
        """Replace the poses held by those of the ``expected`` inputs ``(prior, points, visible)``
        (a frame (12, 2), (12,) or a window (W, 12, 2), (W, 12)), each prior's network in one
        compiled pass; an input the prior refuses is left out."""
        self._poses.clear()
        if not HAVE_NUMBA:
            return
        by_prior: dict[int, tuple[PosePrior, list[tuple[tuple[int, bytes], NDArray[np.float64],
                                                        NDArray[np.float64], NDArray[np.float64]]]]] = {}
        for prior, points, visible in expected:
            key = self._key(prior, points, visible)
            try:
                feats, centre, radius = prior.features(points, visible)
            except InvalidInputError:
                continue
            by_prior.setdefault(id(prior), (prior, []))[1].append((key, feats, centre, radius))
        for prior, inputs in by_prior.values():
            # the inputs stacked: the rows and the poses formed once for all of them (element-wise:
            # what PosePrior.input_rows and .poses give each alone)
            rows = flip_rows(np.stack([f for _, f, _, _ in inputs]), self.flip)  # (n, [2,] d)
            h = np.ascontiguousarray(rows.reshape(-1, rows.shape[-1]), dtype=np.float32)
            y = prior._forward_small(h).reshape(*rows.shape[:-1], N_JOINTS, 3)
            poses = prior.poses(y, np.stack([c for _, _, c, _ in inputs]),
                                np.stack([r for _, _, _, r in inputs]), self.flip)  # (n, 12, 3)
            for (key, _, _, _), pose in zip(inputs, poses, strict=True):
                self._poses[key] = (prior, pose)

    def predict(self, prior: PosePrior, points: NDArray[np.float64], visible: NDArray[np.bool_]
                ) -> NDArray[np.float64]:
        """``prior.predict(points, visible, flip)``: the pose held for this input (computed by
        ``prior``), else computed now."""
        held = self._poses.get(self._key(prior, points, visible))
        if held is not None and held[0] is prior:
            self.hits += 1
            return held[1].copy()
        self.misses += 1
        return prior.predict(points, visible, self.flip)
