"""Small dense linear algebra for the compiled kernels: LAPACK solves and Cholesky tests, a
written-out Cholesky solve and a reduction-free ``A^T x``."""

from __future__ import annotations

import math

import numpy as np
from numpy.typing import NDArray
from scipy.linalg.lapack import dgesv as _dgesv
from scipy.linalg.lapack import dpotrf as _dpotrf

from .jit import HAVE_NUMBA, njit

_EYE8 = 1e-14 * np.eye(8)


def _solve_lapack(a: NDArray[np.float64], b: NDArray[np.float64]) -> NDArray[np.float64]:
    """``a^-1 b`` by LAPACK gesv called directly (numpy's wrapper costs more than the solve
    at these sizes); least squares if ``a`` is singular."""
    _, _, x, info = _dgesv(a, b)
    if info != 0:
        return np.asarray(np.linalg.lstsq(a, b, rcond=None)[0])
    return np.asarray(x)


def _pos_def_lapack(a: NDArray[np.float64]) -> bool:
    """Whether the Cholesky factorisation (LAPACK potrf, lower triangle) of ``a`` succeeds."""
    return bool(_dpotrf(a, lower=1, clean=0)[1] == 0)


@njit
def _solve_jit(a: NDArray[np.float64], b: NDArray[np.float64]) -> NDArray[np.float64]:
    """:func:`_solve_lapack` inside the compiled kernels: numba's ``solve`` is the same LAPACK
    gesv (scipy's), raising on a singular ``a``; least squares then (numpy's default rcond)."""
    try:
        return np.asarray(np.linalg.solve(a, b), dtype=np.float64)
    except Exception:  # singular, or non-finite values (gesv propagates them; numba raises)
        pass
    if not (np.all(np.isfinite(a)) and np.all(np.isfinite(b))):
        return np.full(b.shape[0], np.nan)
    return np.asarray(np.linalg.lstsq(a, b, rcond=2.220446049250313e-16 * max(a.shape[0], a.shape[1]))[0],
                      dtype=np.float64)


@njit
def _pos_def_jit(a: NDArray[np.float64]) -> bool:
    """:func:`_pos_def_lapack` inside the compiled kernels (numba's ``cholesky``: the same
    potrf on the lower triangle, raising where the matrix is not positive definite)."""
    try:
        np.linalg.cholesky(a)
    except Exception:
        return False
    return True


# the compiled kernels call LAPACK through numba; without numba they run as plain Python and call
# scipy's LAPACK directly
_solve = _solve_jit if HAVE_NUMBA else _solve_lapack
_pos_def = _pos_def_jit if HAVE_NUMBA else _pos_def_lapack



@njit
def _cholesky_solve(a: NDArray[np.float64], b: NDArray[np.float64]) -> tuple[NDArray[np.float64], bool]:
    """``a^-1 b`` by a Cholesky factorisation of the symmetric ``a`` (n, n) (lower triangle read);
    ``(x, True)``, or ``(b, False)`` when ``a`` is not (numerically) positive definite. Written
    out: at n = 16 a LAPACK call costs more than the arithmetic."""
    n = a.shape[0]
    lo = np.zeros((n, n))
    for j in range(n):
        d = a[j, j]
        for k in range(j):
            d -= lo[j, k] * lo[j, k]
        if not d > 1e-14 * abs(a[j, j]) or not d > 0.0:
            return b, False
        d = math.sqrt(d)
        lo[j, j] = d
        for i in range(j + 1, n):
            e = a[i, j]
            for k in range(j):
                e -= lo[i, k] * lo[j, k]
            lo[i, j] = e / d
    y = np.empty(n)
    for i in range(n):
        e = b[i]
        for k in range(i):
            e -= lo[i, k] * y[k]
        y[i] = e / lo[i, i]
    x = np.empty(n)
    for i in range(n - 1, -1, -1):
        e = y[i]
        for k in range(i + 1, n):
            e -= lo[k, i] * x[k]
        x[i] = e / lo[i, i]
    return x, True




@njit
def _axpy_rows(at: NDArray[np.float64], x: NDArray[np.float64], out: NDArray[np.float64]) -> None:
    """``out += at.T @ x`` as a sum of the rows of ``at`` (n, m) (C-contiguous): each step is a
    vectorisable axpy over m, with no floating-point reduction chain (which LLVM may not
    reorder, so a dot-product loop runs at one add per ~4 cycles)."""
    for p in range(at.shape[0]):
        xp = x[p]
        for q in range(at.shape[1]):
            out[q] += at[p, q] * xp


