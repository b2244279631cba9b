"""Small dense linear algebra for the compiled kernels: a written-out Cholesky factorisation and
solve (each also into the caller's buffers, for the solver's inner loops), and a reduction-free
``A^T x``."""

from __future__ import annotations

import math

import numpy as np
from numpy.typing import NDArray

from .jit import njit


@njit
def _cholesky_into(a: NDArray[np.float64], lo: NDArray[np.float64]) -> bool:
    """The lower Cholesky factor of the symmetric ``a`` (n, n) (lower triangle read) written into
    the lower triangle of ``lo`` (n, n; its upper triangle is not written). Returns True, or False
    with a partial factor when ``a`` is not (numerically) positive definite."""
    n = a.shape[0]
    for j in range(n):
        d = a[j, j]
        for k in range(j):
            d -= lo[j, k] * lo[j, k]
        if not d > 1e-14 * abs(a[j, j]) or not d > 0.0:
            return False
        d = math.sqrt(d)
        lo[j, j] = d
        for i in range(j + 1, n):
            e = a[i, j]
            for k in range(j):
                e -= lo[i, k] * lo[j, k]
            lo[i, j] = e / d
    return True


@njit
def _cholesky(a: NDArray[np.float64]) -> tuple[NDArray[np.float64], bool]:
    """The lower Cholesky factor (n, n) of the symmetric ``a`` (n, n) (lower triangle read) and
    True, or a partial factor and False when ``a`` is not (numerically) positive definite
    (:func:`_cholesky_into` into a new zeroed array)."""
    lo = np.zeros(a.shape)
    ok = _cholesky_into(a, lo)
    return lo, ok


@njit
def _cholesky_apply_into(lo: NDArray[np.float64], b: NDArray[np.float64], y: NDArray[np.float64],
                         x: NDArray[np.float64]) -> None:
    """``x = (L L^T)^-1 b`` (n,) for the lower Cholesky factor ``lo`` (n, n) of
    :func:`_cholesky_into` (lower triangle read): a forward substitution into ``y`` (n,) and a back
    substitution into ``x`` (n,) (neither may be ``b``)."""
    n = lo.shape[0]
    for i in range(n):
        e = b[i]
        for k in range(i):
            e -= lo[i, k] * y[k]
        y[i] = e / lo[i, i]
    for i in range(n - 1, -1, -1):
        e = y[i]
        for k in range(i + 1, n):
            e -= lo[k, i] * x[k]
        x[i] = e / lo[i, i]


@njit
def _cholesky_apply(lo: NDArray[np.float64], b: NDArray[np.float64]) -> NDArray[np.float64]:
    """``(L L^T)^-1 b`` (n,) for the lower Cholesky factor ``lo`` (n, n) of :func:`_cholesky`
    (:func:`_cholesky_apply_into` into new arrays)."""
    x = np.empty(b.size)
    _cholesky_apply_into(lo, b, np.empty(b.size), x)
    return x


@njit
def _axpy_rows(at: NDArray[np.float64], x: NDArray[np.float64], out: NDArray[np.float64]) -> None:
    """``out += at.T @ x`` as a sum of the rows of ``at`` (n, m) (C-contiguous): each step is a
    vectorisable axpy over m, with no floating-point reduction chain (which LLVM may not
    reorder, so a dot-product loop runs at one add per ~4 cycles)."""
    for p in range(at.shape[0]):
        xp = x[p]
        for q in range(at.shape[1]):
            out[q] += at[p, q] * xp


