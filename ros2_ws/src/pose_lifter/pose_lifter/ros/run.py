"""The one run loop of the package's nodes (``lifter``, ``lifter_lifecycle``, ``adapter``,
``action_recognition``): start-up, spin, Ctrl-C / SIGTERM, fatal start-up errors.

Every executable behaves the same way:

- SIGINT / SIGTERM exit with code 0, whatever the phase. During start-up (building the node:
  loading the basis file, the first kernel compile, ~25 s after an install; and a lifecycle
  node's configure transition) they exit at once, outputs flushed: nothing runs yet that could
  be lost. While the node runs they end the spin loop after the current callback, so a frame in
  progress is finished and published and nothing is torn down under a running solve.
- A node that cannot be built (bad parameter, basis file, missing message package, bad ROS
  arguments) is one ``[FATAL] ... cannot start: <reason>`` line and exit code 1.

rclpy's own signal handlers are off (they would shut the context down under a running callback);
:mod:`pose_lifter.ros.entry` installs quiet handlers before the node's modules are imported.
"""

from __future__ import annotations

import os
import signal
import sys
from collections.abc import Callable, Iterator
from contextlib import contextmanager
from types import FrameType
from typing import Any, NoReturn

__all__ = ["PhasedSignals", "exit_now", "fatal", "one_line", "run_node"]


def one_line(err: BaseException) -> str:
    """An exception as one log line: its text (or type), whitespace collapsed, at most 1000 chars."""
    text = " ".join(str(err).split()) or type(err).__name__
    return text[:1000]


class PhasedSignals:
    """SIGINT / SIGTERM by phase: while starting (``running`` false) they exit at once with code
    0; while running they set ``stop``, which ends the spin loop after the current callback.

    Installing the handlers is part of construction; :meth:`starting` marks a start-up phase
    inside the running loop (a lifecycle node's configure transition).
    """

    def __init__(self) -> None:
        self.running = False
        self.stop = False
        for sig in (signal.SIGINT, signal.SIGTERM):
            signal.signal(sig, self._handle)

    @contextmanager
    def starting(self) -> Iterator[None]:
        """Within the block a signal exits at once (no frame is in progress: the executor runs
        one callback at a time, and this one is loading or compiling)."""
        running, self.running = self.running, False
        try:
            yield
        finally:
            self.running = running

    def _handle(self, signum: int, frame: FrameType | None) -> None:
        self.stop = True
        if not self.running:
            # Nothing runs yet, so nothing is lost: exit at once with code 0. (A KeyboardInterrupt
            # is not enough: numba's first compile runs ctypes callbacks that swallow it, or
            # leave llvmlite half torn down with tracebacks; numba writes cache files atomically.)
            exit_now()


def exit_now() -> NoReturn:
    """Exit with code 0 at once, outputs flushed: a signal while nothing runs yet (start-up)."""
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


def run_node(make: Callable[[PhasedSignals], Any], name: str, args: list[str] | None = None) -> None:
    """Run one node until SIGINT / SIGTERM (see the module doc for the exit codes).

    Parameters
    ----------
    make : callable
        Builds the node; given the process's :class:`PhasedSignals` (a lifecycle node marks its
        configure transition with :meth:`PhasedSignals.starting`).
    name : str
        Logger name of the ``[FATAL]`` line when the node cannot be built.
    args : list of str, optional
        Command-line arguments for ``rclpy.init`` (``None``: ``sys.argv``).
    """
    signals = PhasedSignals()
    import rclpy
    from rclpy.executors import ExternalShutdownException, SingleThreadedExecutor
    from rclpy.signals import SignalHandlerOptions
    from rclpy.utilities import ok, try_shutdown

    node: Any = None
    executor: Any = None
    try:
        try:
            rclpy.init(args=args, signal_handler_options=SignalHandlerOptions.NO)
            node = make(signals)
        except (KeyboardInterrupt, ExternalShutdownException):
            return
        except Exception as err:  # bad start-up parameters, basis file or message package: say why
            fatal(name, f"cannot start: {one_line(err)}")
        signals.running = True
        executor = SingleThreadedExecutor()
        executor.add_node(node)
        while not signals.stop and ok():
            executor.spin_once(timeout_sec=0.1)
    except (KeyboardInterrupt, ExternalShutdownException):
        pass
    finally:
        if executor is not None:  # its guard conditions go before the context they belong to
            executor.shutdown()
        if node is not None:
            node.destroy_node()
        try_shutdown()
