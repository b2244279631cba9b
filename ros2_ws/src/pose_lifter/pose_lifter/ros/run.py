"""Running one node until Ctrl-C / SIGTERM: the shared ``main`` of the executables, and the
lifter's phased signal handling and one-line fatal errors (:func:`pose_lifter.ros.node.main`)."""

from __future__ import annotations

import os
import signal
import sys
from collections.abc import Callable
from types import FrameType
from typing import Any, NoReturn

__all__ = ["PhasedSignals", "fatal", "one_line", "run_node"]


def one_line(err: BaseException) -> str:
    """An exception as one log line: its text (or type), whitespace collapsed, at most 1000 chars."""
    text = " ".join(str(err).split()) or type(err).__name__
    return text[:1000]


class PhasedSignals:
    """SIGINT / SIGTERM: during start-up (loading, the first kernel compile: ~25 s) they exit at
    once; while running (``running`` set) they set ``stop``, so the spin loop ends after the
    current callback and a frame in progress is finished and published (nothing is torn down
    under a running solve)."""

    def __init__(self) -> None:
        self.running = False
        self.stop = False
        for sig in (signal.SIGINT, signal.SIGTERM):
            signal.signal(sig, self._handle)

    def _handle(self, signum: int, frame: FrameType | None) -> None:
        self.stop = True
        if not self.running:
            # Nothing runs yet, so nothing is lost: exit at once with code 0. (A KeyboardInterrupt
            # is not enough: numba's first compile runs ctypes callbacks that swallow it, or
            # leave llvmlite half torn down with tracebacks; numba writes cache files atomically.)
            sys.stdout.flush()
            sys.stderr.flush()
            os._exit(0)


def fatal(name: str, text: str) -> NoReturn:
    """One ``[FATAL]`` line from the logger ``name``, then exit code 1."""
    try:
        import rclpy

        rclpy.logging.get_logger(name).fatal(text)
    except Exception:  # logging not initialised (rclpy.init itself failed)
        print(f"[FATAL] [{name}]: {text}", file=sys.stderr, flush=True)
    raise SystemExit(1)


def run_node(make: Callable[[], Any], name: str, args: list[str] | None = None) -> None:
    """``rclpy.init``, build the node with ``make()``, spin it, shut down cleanly.

    A :class:`~pose_lifter.core.PoseLifterError` while building it (bad parameters, a missing
    message package) is one ``[FATAL]`` line and exit code 1; Ctrl-C / SIGTERM in any phase ends
    it quietly (a signal during start-up makes the pending rcl calls fail: not an error then).
    """
    import rclpy
    from rclpy.executors import ExternalShutdownException

    from pose_lifter.core import PoseLifterError

    rclpy.init(args=args)
    node: Any = None
    try:
        node = make()
        rclpy.spin(node)
    except (KeyboardInterrupt, ExternalShutdownException):
        pass
    except PoseLifterError as err:
        rclpy.logging.get_logger(name).fatal(f"cannot start: {err}")
        raise SystemExit(1) from None
    except Exception:
        if rclpy.ok():
            raise
        # a signal arrived while the node was still starting: rcl calls fail, exit quietly
    finally:
        if node is not None:
            node.destroy_node()
        rclpy.try_shutdown()
