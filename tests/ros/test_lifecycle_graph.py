"""The installed ``lifter_lifecycle`` driven through its lifecycle transitions on the real graph:
nothing subscribed before activate, lifting while active, nothing after deactivate, a bad basis
file fails configure with the reason, a signal during configure exits at once with code 0, and
the plain ``lifter`` is unchanged (other tests)."""

from __future__ import annotations

import signal
import subprocess
import time
from collections.abc import Callable, Iterator
from typing import Any

import pytest

from .conftest import (
    ANSWER_TIMEOUT,
    DISCOVERY_TIMEOUT,
    INSTALL,
    REPO,
    RESEND_AFTER,
    SHUTDOWN_TIMEOUT,
    GraphClient,
    LifterProcess,
)
from .test_lifter_graph import CHEAP, good_frame

pytestmark = pytest.mark.ros

EXE = INSTALL / "pose_lifter" / "lib" / "pose_lifter" / "lifter_lifecycle"


@pytest.fixture
def managed(lifter_env: dict[str, str], tmp_path: Any) -> Iterator[Any]:
    started: list[LifterProcess] = []

    def start(*params: str) -> LifterProcess:
        args = [str(EXE), "--ros-args"]
        for p in (*[f"{k}:={v}" for k, v in CHEAP.items()], *params):
            args += ["-p", p]
        log = tmp_path / f"lifecycle{len(started)}.log"
        with open(log, "wb") as f:
            proc = subprocess.Popen(args, env=lifter_env, stdout=f, stderr=subprocess.STDOUT, cwd=REPO)
        started.append(LifterProcess(proc, log))
        return started[-1]

    yield start
    for handle in started:
        was_alive = handle.alive()
        code = handle.interrupt()
        assert not was_alive or (code == 0 and "Traceback" not in handle.log()), handle.log()


class Lifecycle:
    """Client of /pose_lifter/change_state and /pose_lifter/get_state."""

    def __init__(self, graph: GraphClient) -> None:
        from lifecycle_msgs.srv import ChangeState, GetState

        self.graph = graph
        self.change = graph.node.create_client(ChangeState, "/pose_lifter/change_state")
        self.get = graph.node.create_client(GetState, "/pose_lifter/get_state")
        graph.spin_until(lambda: self.change.service_is_ready() and self.get.service_is_ready(),
                         DISCOVERY_TIMEOUT, "the lifecycle services")

    def state(self) -> str:
        from lifecycle_msgs.srv import GetState

        return str(self.graph.call(self.get, GetState.Request()).current_state.label)

    def transition(self, label: str, failed: Callable[[], bool] | None = None) -> bool:
        """Request one transition; True when it succeeded.

        A transition is not sent twice. When its answer is late, the state is read instead: a
        server may drop an answer (see ``conftest.RESEND_AFTER``), and reaching the transition's
        goal state is its success; a transition expected to fail is judged by ``failed`` (e.g. the
        node logged its failure), since the state it stays in does not tell a failure from a
        transition not yet processed."""
        from lifecycle_msgs.msg import Transition
        from lifecycle_msgs.srv import ChangeState

        ids = {"configure": Transition.TRANSITION_CONFIGURE, "activate": Transition.TRANSITION_ACTIVATE,
               "deactivate": Transition.TRANSITION_DEACTIVATE, "cleanup": Transition.TRANSITION_CLEANUP,
               "shutdown": Transition.TRANSITION_INACTIVE_SHUTDOWN}
        goal = {"configure": "inactive", "activate": "active", "deactivate": "inactive",
                "cleanup": "unconfigured", "shutdown": "finalized"}
        req = ChangeState.Request()
        req.transition.id = ids[label]
        future = self.change.call_async(req)
        deadline = time.monotonic() + ANSWER_TIMEOUT
        while not future.done():
            if time.monotonic() > deadline:
                pytest.fail(f"no answer to the {label} transition after {ANSWER_TIMEOUT} s")
            settle(self.graph, RESEND_AFTER, until=future.done)
            if not future.done() and self.state() == goal[label]:
                return True
            if not future.done() and failed is not None and failed():
                return False
        return bool(future.result().success)


def settle(graph: GraphClient, seconds: float, until: Callable[[], bool] = lambda: False) -> None:
    end = time.monotonic() + seconds
    while time.monotonic() < end and not until():
        graph.executor.spin_once(timeout_sec=0.05)


def test_lifecycle_transitions(graph: GraphClient, managed: Any) -> None:
    proc = managed()
    lc = Lifecycle(graph)
    graph.lifter = proc
    assert lc.state() == "unconfigured"
    settle(graph, 1.0)
    assert graph.pub_keypoints.get_subscription_count() == 0
    assert graph.sub_skeletons.get_publisher_count() == 0

    assert lc.transition("configure")
    assert lc.state() == "inactive"
    graph.spin_until(lambda: graph.sub_skeletons.get_publisher_count() > 0, DISCOVERY_TIMEOUT, "publishers")
    settle(graph, 1.0)
    assert graph.pub_keypoints.get_subscription_count() == 0  # configured, not subscribed
    assert "solver ready in" in proc.log()

    assert lc.transition("activate")
    assert lc.state() == "active"
    graph.wait_for_lifter(proc)  # subscribed and answering
    answer = graph.send(good_frame(graph.types, 1))
    assert len(answer.skeletons.skeletons) == 1
    assert proc.log().count("solver ready in") == 1  # the work was configure's, not redone

    assert lc.transition("deactivate")
    assert lc.state() == "inactive"
    graph.spin_until(lambda: graph.pub_keypoints.get_subscription_count() == 0, 10.0, "unsubscribing")
    assert lc.transition("activate") and lc.state() == "active"
    graph.skeletons.clear()
    graph.markers.clear()
    graph.wait_for_lifter(proc)
    assert len(graph.send(good_frame(graph.types, 2)).skeletons.skeletons) == 1
    assert lc.transition("deactivate") and lc.transition("cleanup")
    assert lc.state() == "unconfigured"
    graph.spin_until(lambda: graph.sub_skeletons.get_publisher_count() == 0, 10.0, "publishers gone")
    assert lc.transition("configure") and lc.state() == "inactive"  # configure again after cleanup
    assert lc.transition("shutdown") and lc.state() == "finalized"
    assert proc.alive()


def test_configure_with_a_bad_basis_file_fails_with_the_reason(graph: GraphClient, managed: Any,
                                                               tmp_path: Any) -> None:
    bad = tmp_path / "bad.npz"
    bad.write_bytes(b"not a basis file")
    proc = managed(f"bases_file:={bad}")
    lc = Lifecycle(graph)
    assert not lc.transition("configure", failed=lambda: "configure failed:" in proc.log())
    assert lc.state() == "unconfigured" and proc.alive()
    assert "configure failed:" in proc.log()


@pytest.mark.parametrize("sig", [signal.SIGINT, signal.SIGTERM], ids=["SIGINT", "SIGTERM"])
def test_signal_during_configure_exits_0(graph: GraphClient, managed: Any, sig: int) -> None:
    from lifecycle_msgs.msg import Transition
    from lifecycle_msgs.srv import ChangeState

    proc = managed()
    lc = Lifecycle(graph)
    req = ChangeState.Request()
    req.transition.id = Transition.TRANSITION_CONFIGURE
    lc.change.call_async(req)  # not waited for: the node is loading the bases and the kernels
    settle(graph, 0.5)
    proc.proc.send_signal(sig)
    assert proc.proc.wait(SHUTDOWN_TIMEOUT) == 0, proc.log()  # exits 0 on its own, mid-configure or after
    assert "Traceback" not in proc.log()


def test_deactivation_publishes_the_answers_held_for_the_lag(graph: GraphClient, managed: Any) -> None:
    """With ``output_lag`` the answers held when the node is deactivated are published then, each
    once and in order (not lost with the input). Were deactivation to drop them, a deactivation
    sooner than the node's 0.5 s idle flush would leave them unanswered."""
    from pose_lifter.messages.convert import stamp_to_ns

    proc = managed("output_lag:=3", "max_waiting_frames:=100",
                   "qos_overrides./keypoints_2d.subscription.reliability:=reliable",
                   "qos_overrides./keypoints_2d.subscription.depth:=100")
    lc = Lifecycle(graph)
    graph.lifter = proc
    assert lc.transition("configure") and lc.transition("activate")
    graph.wait_for_lifter(proc)
    frames = [good_frame(graph.types, i) for i in range(5)]
    for f in frames:
        graph.pub_keypoints.publish(f)
    graph.spin_until(lambda: len(graph.skeletons) >= 2, ANSWER_TIMEOUT, "the first two answers")
    assert len(graph.skeletons) == 2  # frames 2-4 held for the lag
    assert lc.transition("deactivate")
    graph.spin_until(lambda: len(graph.skeletons) >= 5, 10.0, "the held answers")
    settle(graph, 0.5)
    assert [stamp_to_ns(a.header.stamp) for a in graph.skeletons] == [
        stamp_to_ns(f.header.stamp) for f in frames]
    assert all(len(a.skeletons) == 1 for a in graph.skeletons)


def test_an_option_of_the_paper_mode_is_refused_in_the_hybrid_mode(graph: GraphClient, managed: Any) -> None:
    """The parameter callback validates through the core's options: an option only the paper
    mode reads (n_starts) is refused, with the reason, while the node runs the hybrid mode; with
    the paper mode it is taken, and another mode is then refused while it is set."""
    proc = managed()
    lc = Lifecycle(graph)
    graph.lifter = proc
    assert lc.transition("configure") and lc.transition("activate")
    graph.wait_for_lifter(proc)
    (r,) = graph.set_parameters(n_starts=3)
    assert not r.successful and "n_starts = 3 is read only in paper mode, not in 'hybrid' mode" in r.reason
    assert graph.get_parameters("n_starts", "mode") == {"n_starts": 30, "mode": "hybrid"}
    assert [r.successful for r in graph.set_parameters(mode="paper", n_starts=3)] == [True, True]
    (r,) = graph.set_parameters(mode="learned")
    assert not r.successful and "n_starts = 3 is read only in paper mode" in r.reason
    assert graph.get_parameters("n_starts", "mode") == {"n_starts": 3, "mode": "paper"}
    assert len(graph.send(good_frame(graph.types, 1)).skeletons.skeletons) == 1  # lifting, in paper mode


def test_configure_with_an_option_of_another_mode_fails_with_the_reason(graph: GraphClient, managed: Any
                                                                        ) -> None:
    proc = managed("n_starts:=3")  # the hybrid mode (the default) does not read it
    lc = Lifecycle(graph)
    assert not lc.transition("configure", failed=lambda: "configure failed:" in proc.log())
    assert lc.state() == "unconfigured" and proc.alive()
    assert "n_starts = 3 is read only in paper mode" in proc.log()
