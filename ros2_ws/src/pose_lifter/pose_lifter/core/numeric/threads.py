"""The process's threads: one BLAS thread, and the solver's own pool.

One BLAS thread for this process: the solver's matrices are small (at most the prior's 512 x
512 layers), so BLAS threads only contend with each other and with the rest of the machine (a
detector beside the node, the offline lift's worker processes). Measured on a 2-core machine
under load with an earlier 2 x 768 prior: one prior pose 913 us with OpenBLAS's 2 threads, 300 us
with one.

The node and the ``pose-lifter`` CLI call :func:`one_blas_thread` at start-up; a library user
embedding :class:`pose_lifter.core.Lifter` decides for their own process (``OMP_NUM_THREADS=1``
or ``threadpoolctl``).

The compiled kernels that release the GIL (a round's runs, the prior's rows) are split over the
threads of :func:`thread_pool` when a lifter has more than one (``Lifter.threads``, the node's
``solver_threads``).
"""

from __future__ import annotations

import os
from concurrent.futures import ThreadPoolExecutor

__all__ = ["one_blas_thread", "thread_pool"]

_POOLS: dict[tuple[int, int], ThreadPoolExecutor] = {}


def thread_pool(threads: int) -> ThreadPoolExecutor:
    """This process's pool of ``threads`` threads, made on first use (a forked child makes its
    own: the parent's threads do not exist in it)."""
    key = (os.getpid(), threads)
    pool = _POOLS.get(key)
    if pool is None:
        pool = _POOLS[key] = ThreadPoolExecutor(threads, thread_name_prefix="pose_lifter_solver")
    return pool


def one_blas_thread() -> bool:
    """Limit the BLAS libraries loaded in this process to one thread (through ``threadpoolctl``,
    a scikit-learn dependency). Returns False when ``threadpoolctl`` is not installed."""
    try:
        from threadpoolctl import threadpool_limits
    except ImportError:  # pragma: no cover - scikit-learn brings it
        return False
    threadpool_limits(limits=1, user_api="blas")
    return True
