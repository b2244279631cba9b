"""Small numpy helpers for the per-frame path, without numpy's per-call argument handling (which
costs more than the arithmetic on arrays of 12 joints). Each returns what its numpy original does.

:func:`pairwise_sum` is numpy's sum for the compiled kernels, in numpy's pairwise order, so a
kernel that uses it sums as the numpy code it replaces does (``tests/core/numeric/test_fast.py`` checks
it to round-off: nothing may depend on the last bit, which differs between CPUs anyway)."""

from __future__ import annotations

import numpy as np
from numpy.typing import NDArray

from .jit import njit

__all__ = ["mean_rows", "median_rows", "pairwise_sum", "row_norms"]

#: numpy's block size of its pairwise summation (``PW_BLOCKSIZE``).
_PW_BLOCKSIZE = 128


def mean_rows(a: NDArray[np.float64]) -> NDArray[np.float64]:
    """``a.mean(axis=0)`` of a small float (n, d) array, n >= 1 (~1 us less a call): the same
    reduction (row by row) divided by ``n``."""
    return np.asarray(np.add.reduce(a, axis=0) / a.shape[0])


def row_norms(a: NDArray[np.float64]) -> NDArray[np.float64]:
    """``np.linalg.norm(a, axis=-1)`` of a small real (..., d) array, e.g. (n, d) -> (n,) or (m, n,
    d) -> (m, n) (~1 us less a call): numpy's own special case, ``sqrt`` of the row sums of
    ``a * a``."""
    return np.asarray(np.sqrt(np.add.reduce(a * a, axis=-1)))


def median_rows(a: NDArray[np.float64]) -> NDArray[np.float64]:
    """``np.median(a, axis=0)`` of a small (n,) or (n, d) array, n >= 1 (~30 us less a call): the
    same values, the middle row of the sorted columns or the mean of the two middle ones."""
    s = a.copy()
    s.sort(axis=0)  # np.sort(a, axis=0) without its wrapper
    m = len(s) // 2
    return np.asarray(s[m] if len(s) % 2 else (s[m - 1] + s[m]) / 2.0)


@njit
def pairwise_sum(a: NDArray[np.float64]) -> float:
    """``np.add.reduce(a)`` of a contiguous 1-D float64 array of at most 128 elements (``np.sum`` of
    any such array flattened): its identity 0 plus numpy's pairwise sum, which below 8 elements
    adds them one by one and up to 128 keeps 8 interleaved partial sums, added as a tree, then
    adds the rest one by one. (Above 128 numpy sums halves recursively: not needed here.)"""
    n = a.size
    res = 0.0
    if n > _PW_BLOCKSIZE:
        raise ValueError("pairwise_sum: at most 128 elements")
    if n < 8:
        for i in range(n):
            res += float(a[i])
        return 0.0 + res
    r0, r1, r2, r3 = float(a[0]), float(a[1]), float(a[2]), float(a[3])
    r4, r5, r6, r7 = float(a[4]), float(a[5]), float(a[6]), float(a[7])
    i = 8
    while i < n - n % 8:
        r0 += a[i]
        r1 += a[i + 1]
        r2 += a[i + 2]
        r3 += a[i + 3]
        r4 += a[i + 4]
        r5 += a[i + 5]
        r6 += a[i + 6]
        r7 += a[i + 7]
        i += 8
    res = ((r0 + r1) + (r2 + r3)) + ((r4 + r5) + (r6 + r7))
    while i < n:
        res += a[i]
        i += 1
    return 0.0 + res
