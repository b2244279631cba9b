"""Outputs of the learned prior's network computed ahead, for several people in one pass.

The weights of a prior (4 MB) are no longer in the cache when the next pose needs them, so the
network of one pose costs the reading of its weights from memory. The node's frame of several
people, and the offline lift's chains lifted in step, compute the rows they expect in one pass
(:class:`OutputsAhead`); :meth:`pose_lifter.core.hybrid.PriorFit.predict` takes a row's output
from it, bit for bit the output of the pose alone.
"""

from __future__ import annotations

import numpy as np
from numpy.typing import NDArray

from ._jit import HAVE_NUMBA
from .prior import FRAME_DIM, PosePrior
from .skeleton import N_JOINTS

__all__ = ["OutputsAhead"]


class OutputsAhead:
    """Outputs of priors' networks computed ahead, in one pass, for the input rows expected next.

    In a lift, a pose and its mirror image cost ~0.5 ms of network (the weights read from
    memory; ~0.15 ms with them in cache); computed ahead for the 6 people of a step, ~0.2 ms a
    pose (many36.mcap, one process). The caller expects a row per person
    (:meth:`PriorFit.expected_rows <pose_lifter.core.hybrid.PriorFit.expected_rows>`) and
    computes them in one pass over the weights (:meth:`compute`); :meth:`PriorFit.predict
    <pose_lifter.core.hybrid.PriorFit.predict>` takes a row's output from here when the row is
    the expected one (the row's float32 bytes are the key) and computes it otherwise (an outlier
    pass, a joint the track gated). Rows run through the compiled pass of a single pose
    (:meth:`PosePrior._forward_small <pose_lifter.core.prior.PosePrior._forward_small>`), whose
    rows do not mix: the outputs are those of the pose alone, bit for bit. Without numba nothing
    is computed ahead (numpy's matrix product of many rows rounds otherwise than of two).
    """

    def __init__(self) -> None:
        self._outputs: dict[bytes, tuple[PosePrior, NDArray[np.float64]]] = {}
        #: rows answered from here and rows computed on demand since the last :meth:`clear`
        self.hits = 0
        self.misses = 0

    def __len__(self) -> int:
        return len(self._outputs)

    def clear(self) -> None:
        """Forget every output computed ahead (the counters too)."""
        self._outputs.clear()
        self.hits = self.misses = 0

    def compute(self, expected: list[tuple[PosePrior, NDArray[np.float64]]]) -> None:
        """Replace the outputs held by those of ``expected`` (per prior, its rows (k, 36 window)
        or (36 window,)), each prior's rows in one compiled pass."""
        self._outputs.clear()
        if not HAVE_NUMBA:
            return
        by_prior: dict[int, tuple[PosePrior, list[NDArray[np.float32]]]] = {}
        for prior, rows in expected:
            r32 = np.asarray(rows, dtype=np.float32).reshape(-1, FRAME_DIM * prior.window)
            by_prior.setdefault(id(prior), (prior, []))[1].extend(r32)
        for prior, rows32 in by_prior.values():
            unique = {r.tobytes(): r for r in rows32}
            if not unique:
                continue
            h = np.ascontiguousarray(np.stack(list(unique.values())))
            y = prior._forward_small(h)
            for key, out in zip(unique, y, strict=True):
                self._outputs[key] = (prior, out)

    def forward(self, prior: PosePrior, rows: NDArray[np.float64]) -> NDArray[np.float64]:
        """``prior.forward(rows)`` (rows (..., 36 window)), from the outputs held when every row
        is there (computed by ``prior``), else computed now."""
        r32 = np.asarray(rows, dtype=np.float32)
        flat = r32.reshape(-1, r32.shape[-1])
        outs = []
        for r in flat:
            held = self._outputs.get(r.tobytes())
            if held is None or held[0] is not prior:
                self.misses += len(flat)
                return prior.forward(rows)
            outs.append(held[1])
        self.hits += len(flat)
        return np.stack(outs).reshape(*r32.shape[:-1], N_JOINTS, 3)
