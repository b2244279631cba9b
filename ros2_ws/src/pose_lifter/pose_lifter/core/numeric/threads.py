"""One BLAS thread for this process: the solver's matrices are small (at most the prior's 512 x
512 layers), so BLAS threads only contend with each other and with the rest of the machine (a
detector beside the node, the offline lift's worker processes). Measured on a 2-core machine
under load with an earlier 2 x 768 prior: one prior pose 913 us with OpenBLAS's 2 threads, 300 us
with one.

The node and the ``pose-lifter`` CLI call :func:`one_blas_thread` at start-up; a library user
embedding :class:`pose_lifter.core.Lifter` decides for their own process (``OMP_NUM_THREADS=1``
or ``threadpoolctl``).
"""

from __future__ import annotations

__all__ = ["one_blas_thread"]


def one_blas_thread() -> bool:
    """Limit the BLAS libraries loaded in this process to one thread (through ``threadpoolctl``,
    a scikit-learn dependency). Returns False when ``threadpoolctl`` is not installed."""
    try:
        from threadpoolctl import threadpool_limits
    except ImportError:  # pragma: no cover - scikit-learn brings it
        return False
    threadpool_limits(limits=1, user_api="blas")
    return True
