"""The learned prior's compiled layer pass for a few rows
(:meth:`pose_lifter.core.model.prior.PosePrior._forward_small`)."""

from __future__ import annotations

import numpy as np
from numpy.typing import NDArray

from ..numeric.jit import njit_nogil

__all__ = ["affine_rows"]


@njit_nogil
def affine_rows(h: NDArray[np.float32], w: NDArray[np.float32], b: NDArray[np.float32], relu: bool
                 ) -> NDArray[np.float32]:
    """``h @ w + b`` (then ``max(., 0)`` with ``relu``) for a few rows ``h`` (n, d), ``w`` (d, m),
    ``b`` (m,), in float32: each output is ``b[j]`` plus the products ``h[r, i] * w[i, j]`` added
    one at a time in the order of ``i`` (each product and each sum rounded; no fused multiply-add),
    so a row's output does not depend on the other rows. The weight rows are taken eight at a
    time: an output row is read and written once per eight products instead of once per product
    (the pass was bound by those loads and stores), and each block of weights is read once for all
    rows of ``h``; a weight row that only zeros of ``h`` (a ReLU's) multiply is not read at all
    (one row of a hidden layer reads half the weights), and a zero among the others adds a
    signed zero, which leaves a sum unchanged.
    It releases the GIL: threads may run parts of the rows (:meth:`PosePrior.forward_rows`)."""
    n, d = h.shape
    m = w.shape[1]
    out = np.empty((n, m), dtype=np.float32)
    for r in range(n):
        out[r, :] = b
    # the inputs some row needs (a weight row that multiplies only zeros is not read)
    active = np.empty(d, dtype=np.int64)
    k = 0
    for i in range(d):
        for r in range(n):
            if h[r, i] != 0.0:
                active[k] = i
                k += 1
                break
    k8 = k - k % 8
    for a in range(0, k8, 8):
        i0, i1, i2, i3 = active[a], active[a + 1], active[a + 2], active[a + 3]
        i4, i5, i6, i7 = active[a + 4], active[a + 5], active[a + 6], active[a + 7]
        w0, w1, w2, w3, w4, w5, w6, w7 = w[i0], w[i1], w[i2], w[i3], w[i4], w[i5], w[i6], w[i7]
        for r in range(n):
            h0, h1, h2, h3 = h[r, i0], h[r, i1], h[r, i2], h[r, i3]
            h4, h5, h6, h7 = h[r, i4], h[r, i5], h[r, i6], h[r, i7]
            o = out[r]
            for j in range(m):
                o[j] = (o[j] + h0 * w0[j] + h1 * w1[j] + h2 * w2[j] + h3 * w3[j]
                        + h4 * w4[j] + h5 * w5[j] + h6 * w6[j] + h7 * w7[j])
    for a in range(k8, k):
        wi = w[active[a]]
        for r in range(n):
            hi = h[r, active[a]]
            o = out[r]
            for j in range(m):
                o[j] += hi * wi[j]
    if relu:
        for r in range(n):
            for j in range(m):
                if out[r, j] < 0.0:
                    out[r, j] = 0.0
    return out
