"""The worker processes of the offline commands (a bag's tracks, a collection's bags, a depth
topic's first pass): forked from the command, stopped by it at once, and ended with it however it
ends, so that none is left waiting for its pool's next task."""

from __future__ import annotations

import os
import signal
import sys
import time
from typing import Any, Final

__all__ = ["STOP_TIMEOUT", "die_with_parent", "quiet_worker", "stop_workers"]


def quiet_worker(parent: int) -> None:
    """A forked worker's signals: Ctrl-C and SIGTERM end it at once (SIG_DFL; its parent reports
    them), and so does its parent's end (:func:`die_with_parent`); ``parent``: the parent's id,
    read before the fork. A pool initialiser (a bag's tracks' workers, the first pass's reader)."""
    signal.signal(signal.SIGINT, signal.SIG_DFL)
    signal.signal(signal.SIGTERM, signal.SIG_DFL)
    die_with_parent(parent)


def die_with_parent(parent: int) -> None:
    """This forked worker gets SIGTERM when the process that forked it ends, however it ends
    (killed, crashed): Linux's ``PR_SET_PDEATHSIG``, a no-op elsewhere. A worker left behind would
    wait for its pool's next task for ever. ``parent``: that process's id, read before the fork
    (it may have ended before this runs: then the signal is sent at once)."""
    if sys.platform.startswith("linux"):
        import ctypes

        ctypes.CDLL(None, use_errno=True).prctl(_PR_SET_PDEATHSIG, int(signal.SIGTERM), 0, 0, 0)
    if os.getppid() != parent:
        os.kill(os.getpid(), signal.SIGTERM)


_PR_SET_PDEATHSIG: Final[int] = 1  #: prctl's option (linux/prctl.h)


#: Seconds a worker has to exit after SIGTERM (a collection's worker discards the bag it was
#: writing first) before :func:`stop_workers` kills it.
STOP_TIMEOUT: Final[float] = 10.0


def stop_workers(ex: Any) -> None:
    """Stop a ProcessPoolExecutor (forked workers) now: its queued work dropped, each worker sent
    SIGTERM and killed if it has not exited within STOP_TIMEOUT; on return every worker has been
    reaped.

    The executor is not shut down with ``wait=True``: a worker whose task turned SIGTERM into an
    exception is kept alive by the executor's worker loop, which returns that exception as the
    task's result and waits for the next task, so that could wait forever. Its manager thread,
    which reaps the workers of a broken pool itself, is joined once they are gone and before they
    are joined here: two threads waiting for the same child race (the loser's wait finds no child
    and leaves the process marked alive).
    """
    import multiprocessing.connection

    processes = list((getattr(ex, "_processes", None) or {}).values())  # no public accessor
    manager = getattr(ex, "_executor_manager_thread", None)  # (shutdown forgets both)
    ex.shutdown(wait=False, cancel_futures=True)
    for proc in processes:
        proc.terminate()
    deadline = time.monotonic() + STOP_TIMEOUT
    running = {proc.sentinel: proc for proc in processes}  # ready once its process has exited
    while running and (left := deadline - time.monotonic()) > 0:
        for sentinel in multiprocessing.connection.wait(list(running), left):
            del running[sentinel]
    for proc in running.values():
        proc.kill()
    if manager is not None:
        manager.join(STOP_TIMEOUT)
    for proc in processes:
        proc.join()
