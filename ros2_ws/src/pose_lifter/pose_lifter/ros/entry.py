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
import sys
from types import FrameType

__all__ = ["action_recognition", "adapter", "lifter", "lifter_lifecycle"]


_signalled = False  # a signal arrived during the import


def _interrupt(signum: int, frame: FrameType | None) -> None:
    global _signalled
    _signalled = True
    raise KeyboardInterrupt


def _run(module: str) -> None:
    """Install the handlers, import ``module``, call its ``main()``. A signal during the import
    exits 0 whatever it interrupted: inside a C extension's initialisation (rclpy's) the
    KeyboardInterrupt comes out as an ImportError ("initialization failed")."""
    signal.signal(signal.SIGINT, _interrupt)
    signal.signal(signal.SIGTERM, _interrupt)
    try:
        main = importlib.import_module(module).main
    except BaseException:
        if _signalled:
            sys.exit(0)
        raise
    main()


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
