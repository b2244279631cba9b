"""Optional numba compilation of the solver kernels.

``njit(f)`` is ``numba.njit(cache=True)(f)`` when numba is importable and ``f`` unchanged
otherwise: the same kernel runs compiled (fast) or as plain Python (same results up to round-off,
slower; see ``core/solve/pose_step.py``).
Compiled kernels are cached in ``__pycache__`` (or numba's user cache dir when that is not
writable); the first compilation of all kernels takes ~25 s of CPU, a cached load ~0.5 s.
"""

from __future__ import annotations

import importlib
from collections.abc import Callable
from typing import Any, TypeVar, cast

try:  # numba has no type stubs: imported by name, typed as Any
    _numba_njit: Any = importlib.import_module("numba").njit
except ImportError:  # pragma: no cover
    _numba_njit = None

#: Whether the kernels are compiled (numba importable).
HAVE_NUMBA: bool = _numba_njit is not None

_F = TypeVar("_F", bound=Callable[..., Any])


def njit(f: _F) -> _F:
    """``numba.njit(cache=True)(f)`` when numba is importable, else ``f`` unchanged."""
    return f if _numba_njit is None else cast(_F, _numba_njit(cache=True)(f))


def njit_nogil(f: _F) -> _F:
    """``numba.njit(cache=True, nogil=True)(f)`` when numba is importable, else ``f`` unchanged:
    a kernel that releases the GIL while it runs, so that threads run it in parallel."""
    return f if _numba_njit is None else cast(_F, _numba_njit(cache=True, nogil=True)(f))
