"""Running one node until Ctrl-C / SIGTERM: the shared ``main`` of the executables."""

from __future__ import annotations

from collections.abc import Callable
from typing import Any

__all__ = ["run_node"]


def run_node(make: Callable[[], Any], name: str, args: list[str] | None = None) -> None:
    """``rclpy.init``, build the node with ``make()``, spin it, shut down cleanly.

    A :class:`~pose_lifter.core.PoseLifterError` while building it (bad parameters, a missing
    message package) is one ``[FATAL]`` line and exit code 1; Ctrl-C / SIGTERM in any phase ends
    it quietly (a signal during start-up makes the pending rcl calls fail: not an error then).
    """
    import rclpy
    from rclpy.executors import ExternalShutdownException

    from .core import PoseLifterError

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
