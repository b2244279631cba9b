"""``fma(a, b, c) = a * b + c`` rounded once, callable inside the compiled kernels.

The BLAS numpy calls on small vectors (``ddot``, ``dgemv``) contracts products and sums into fused
multiply-adds; a kernel that must give numpy's result to the bit (the fused run of
:mod:`pose_lifter.core.run_kernel` against the Python loop it replaces) repeats them with this.
Compiled: LLVM's ``llvm.fma.f64`` (exact also where the CPU has no FMA unit); without numba:
the same value through exact rational arithmetic.
"""

from __future__ import annotations

import importlib
import math
from collections.abc import Callable
from fractions import Fraction
from typing import Any

from ._jit import HAVE_NUMBA, njit

__all__ = ["fma"]


def _fma_exact(a: float, b: float, c: float) -> float:
    """``a * b + c`` with one rounding (exact rationals; non-finite operands: the plain formula)."""
    if not (math.isfinite(a) and math.isfinite(b) and math.isfinite(c)):
        return a * b + c
    return float(Fraction(a) * Fraction(b) + Fraction(c))


def _fma_typer(typingctx: Any, a: Any, b: Any, c: Any) -> Any:
    """The numba intrinsic's typing and code: ``llvm.fma.f64(a, b, c)``."""
    types: Any = importlib.import_module("numba.core.types")
    ir: Any = importlib.import_module("llvmlite.ir")

    def codegen(context: Any, builder: Any, signature: Any, args: Any) -> Any:
        f64 = ir.DoubleType()
        fn = builder.module.declare_intrinsic("llvm.fma", [f64], ir.FunctionType(f64, [f64, f64, f64]))
        return builder.call(fn, args)

    return types.float64(types.float64, types.float64, types.float64), codegen


_llvm_fma: Any = (importlib.import_module("numba.extending").intrinsic(_fma_typer) if HAVE_NUMBA
                  else _fma_exact)


@njit
def _fma_jit(a: float, b: float, c: float) -> float:
    """``a * b + c`` rounded once: the intrinsic, compiled (the exact fallback without numba)."""
    return float(_llvm_fma(a, b, c))


#: ``a * b + c`` rounded once (float64).
fma: Callable[[float, float, float], float] = _fma_jit
