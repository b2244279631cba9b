"""Entry points of the package's executables (``ros2 run pose_lifter <name>``): signals are
handled from the first instruction.

Importing a node (rclpy, numpy, numba: ~1 s) happens after SIGINT / SIGTERM handlers are in
place, so a signal during the import exits quietly with code 0 instead of a traceback. The
node's ``main`` then runs it in the one run loop (:func:`pose_lifter.ros.run.run_node`), which
takes over the handlers for the start-up and running phases.
"""

from __future__ import annotations

import importlib
import signal
from types import FrameType

from pose_lifter.ros.run import exit_now

__all__ = ["action_recognition", "adapter", "lifter", "lifter_lifecycle"]


def _interrupt(signum: int, frame: FrameType | None) -> None:
    """A signal while the node's modules are imported: nothing runs yet, so exit at once with
    code 0, outputs flushed. (A KeyboardInterrupt is not enough: raised inside a callback of the
    import machinery, e.g. a module lock's weakref callback, it is printed as "Exception ignored"
    and the start-up goes on; inside a C extension's initialisation it comes out as an
    ImportError.)"""
    exit_now()


def _run(module: str) -> None:
    """Install the handlers, import ``module``, call its ``main()`` (whose run loop takes the
    handlers over, :class:`pose_lifter.ros.run.PhasedSignals`)."""
    signal.signal(signal.SIGINT, _interrupt)
    signal.signal(signal.SIGTERM, _interrupt)
    importlib.import_module(module).main()


def lifter() -> None:
    """``lifter``: :func:`pose_lifter.ros.node.main`."""
    _run("pose_lifter.ros.node")


def lifter_lifecycle() -> None:
    """``lifter_lifecycle``: :func:`pose_lifter.ros.lifecycle.main`."""
    _run("pose_lifter.ros.lifecycle")


def adapter() -> None:
    """``adapter``: :func:`pose_lifter.ros.adapter_node.main`."""
    _run("pose_lifter.ros.adapter_node")


def action_recognition() -> None:
    """``action_recognition``: :func:`pose_lifter.ros.action_recognition.main`."""
    _run("pose_lifter.ros.action_recognition")
