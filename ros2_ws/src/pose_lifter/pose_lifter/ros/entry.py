"""Entry point of ``ros2 run pose_lifter lifter``: signals are handled from the first instruction.

Importing the node (rclpy, numpy, numba: ~1 s) happens after SIGINT / SIGTERM handlers are in
place, so a signal during the import exits quietly with code 0 instead of a traceback.
:func:`pose_lifter.ros.node.main` then takes over the handlers for the start-up and running phases.
"""

from __future__ import annotations

import signal
import sys
from types import FrameType


def _interrupt(signum: int, frame: FrameType | None) -> None:
    raise KeyboardInterrupt


def lifter() -> None:
    """Install the handlers, import the node, run it (see :func:`pose_lifter.ros.node.main`)."""
    signal.signal(signal.SIGINT, _interrupt)
    signal.signal(signal.SIGTERM, _interrupt)
    try:
        from pose_lifter.ros.node import main
    except KeyboardInterrupt:
        sys.exit(0)
    main()
