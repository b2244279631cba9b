"""``ros2 run pose_lifter lifter_lifecycle``: the lifter as a managed (lifecycle) node.

The same node as ``lifter`` (:class:`pose_lifter.ros.node.LifterNode`, same name, parameters and
topics), driven by the standard ``rclpy.lifecycle`` transitions (``/pose_lifter/change_state``,
``ros2 lifecycle set /pose_lifter configure``, a lifecycle manager such as nav2's):

- **configure**: load the basis file, build the solver and compile or load its kernels, create
  the publishers and ``/diagnostics`` (a bad parameter or basis file fails the transition with
  the reason, and the node stays unconfigured);
- **activate**: subscribe to ``keypoints_2d`` and ``camera_info``: lifting starts;
- **deactivate**: unsubscribe (the solver stays loaded; activating again is immediate);
- **cleanup**: destroy the publishers; **shutdown**: as cleanup, from any state.

``ros2 run pose_lifter lifter`` (the plain node) does configure + activate in its constructor.
Both run in the one run loop (:func:`pose_lifter.ros.run.run_node`): SIGINT / SIGTERM exit with
code 0, at once during configure (loading, compiling), after the current callback otherwise.
"""

from __future__ import annotations

from contextlib import nullcontext
from typing import Any

from rclpy.lifecycle import LifecycleNode, LifecycleState, TransitionCallbackReturn

from pose_lifter.core import PoseLifterError
from pose_lifter.ros.node import NODE_NAME, LifterNode
from pose_lifter.ros.run import PhasedSignals, run_node

__all__ = ["LifecycleLifterNode", "main"]


class LifecycleLifterNode(LifterNode, LifecycleNode):
    """:class:`LifterNode` whose start is split into lifecycle transitions (see the module doc).

    Parameters
    ----------
    signals : PhasedSignals, optional
        The run loop's signal handling (configure is marked a start-up phase in it).
    **kwargs
        Passed to :class:`rclpy.node.Node`.
    """

    def __init__(self, signals: PhasedSignals | None = None, **kwargs: Any) -> None:
        self._signals = signals
        self._configured = False
        self._active = False
        super().__init__(**kwargs)

    def _deferred_start(self) -> bool:
        return True

    def on_configure(self, state: LifecycleState) -> TransitionCallbackReturn:
        try:
            # loading and compiling: a signal exits at once, as during the plain node's start
            with self._signals.starting() if self._signals is not None else nullcontext():
                self.configure_lifter()
        except (PoseLifterError, OSError, ValueError) as err:
            self.get_logger().error(f"configure failed: {err}")
            return TransitionCallbackReturn.FAILURE
        self._configured = True
        return TransitionCallbackReturn.SUCCESS

    def on_activate(self, state: LifecycleState) -> TransitionCallbackReturn:
        self.activate_lifter()
        self._active = True
        return super().on_activate(state)

    def on_deactivate(self, state: LifecycleState) -> TransitionCallbackReturn:
        self.deactivate_lifter()
        self._active = False
        self.get_logger().info("deactivated: not lifting")
        return super().on_deactivate(state)

    def on_cleanup(self, state: LifecycleState) -> TransitionCallbackReturn:
        self.cleanup_lifter()
        self._configured = False
        return TransitionCallbackReturn.SUCCESS

    def on_shutdown(self, state: LifecycleState) -> TransitionCallbackReturn:
        if self._active:
            self.deactivate_lifter()
            self._active = False
        if self._configured:
            self.cleanup_lifter()
            self._configured = False
        return TransitionCallbackReturn.SUCCESS


def main(args: list[str] | None = None) -> None:
    """Entry point of ``ros2 run pose_lifter lifter_lifecycle`` (exit codes as ``lifter``:
    :func:`pose_lifter.ros.run.run_node`)."""
    from pose_lifter.core.numeric.threads import one_blas_thread

    one_blas_thread()  # as the plain node: the solver's matrices are small

    def make(signals: PhasedSignals) -> LifecycleLifterNode:
        node = LifecycleLifterNode(signals)
        node.get_logger().info("unconfigured: waiting for the configure transition")
        return node

    run_node(make, NODE_NAME, args)


if __name__ == "__main__":
    main()
