"""Fixtures of the ROS graph tests: the installed ``lifter`` as a separate process, and an rclpy
client node (own Context) in the test process that publishes into the graph and listens.

Needs ``make ros`` (the colcon build of ros2_ws). Every run uses a random ROS_DOMAIN_ID and
localhost-only discovery, so parallel runs and other machines never see each other.
"""

from __future__ import annotations

import ctypes
import gc
import itertools
import os
import random
import signal
import subprocess
import sys
import time
from collections.abc import Callable, Iterator
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np
import pytest

REPO = Path(__file__).resolve().parents[2]
INSTALL = REPO / "ros2_ws" / "install"
LIFTER_EXE = INSTALL / "pose_lifter" / "lib" / "pose_lifter" / "lifter"
PARAMS_YAML = INSTALL / "pose_lifter" / "share" / "pose_lifter" / "config" / "lifter.yaml"
#: Seconds to wait for discovery, for one answer, and for a clean exit after SIGINT.
DISCOVERY_TIMEOUT = 120.0
ANSWER_TIMEOUT = 180.0
SHUTDOWN_TIMEOUT = 10.0
#: Seconds after which an idempotent service call is sent again. A server may drop its response
#: when it has not yet discovered the client's response reader (rmw_fastrtps: "failed to send
#: response (timeout): client will not receive response", ros2/ros2#1253); the client then waits
#: for ever, although ``service_is_ready()`` was true.
RESEND_AFTER = 5.0
#: frame_id of the empty frames of the start-up handshake (see GraphClient._handshake).
HANDSHAKE_FRAME = "pose_lifter_test_handshake"


def _require_build() -> None:
    if not LIFTER_EXE.is_file():
        pytest.fail(f"{LIFTER_EXE} is missing: run `make ros` first (make test does)")


def _load_workspace_messages(package: str = "pose_lifter_msgs") -> None:
    """Make ``pose_lifter_msgs`` importable in this (already running) test process.

    ``source install/setup.bash`` would do it, but it must happen before Python starts
    (LD_LIBRARY_PATH) and it would also put the installed copy of pose_lifter in front of the
    source tree for the offline tests. Instead: preload the message libraries (the typesupport
    extension then finds them by soname), extend LD_LIBRARY_PATH for the libraries rcl
    resolves at run time, and append the message package to sys.path.
    """
    import importlib

    try:
        importlib.import_module(f"{package}.msg")  # sourced workspace (or loaded already)
        return
    except ImportError:
        pass
    lib = INSTALL / package / "lib"
    os.environ["LD_LIBRARY_PATH"] = f"{lib}{os.pathsep}{os.environ.get('LD_LIBRARY_PATH', '')}"
    for kind in ("generator_c", "typesupport_fastrtps_c", "typesupport_introspection_c",
                 "typesupport_c", "generator_py"):
        ctypes.CDLL(str(lib / f"lib{package}__rosidl_{kind}.so"), mode=ctypes.RTLD_GLOBAL)
    site = lib / f"python{sys.version_info.major}.{sys.version_info.minor}" / "site-packages"
    if str(site) not in sys.path:
        sys.path.append(str(site))
    importlib.import_module(f"{package}.msg")


@pytest.fixture(scope="session")
def ros_domain_id() -> int:
    """A random domain id for this run (0..101 are valid with localhost discovery)."""
    return random.SystemRandom().randint(1, 101)


@pytest.fixture(scope="session")
def lifter_env(ros_domain_id: int) -> dict[str, str]:
    """The environment ``source install/setup.bash`` gives, plus the test graph's isolation."""
    _require_build()
    out = subprocess.run(
        ["bash", "-c", f"source '{INSTALL / 'setup.bash'}' && env -0"],
        check=True, capture_output=True, cwd=REPO,
    ).stdout
    env = dict(item.split("=", 1) for item in out.decode().split("\0") if "=" in item)
    env.update({
        "ROS_DOMAIN_ID": str(ros_domain_id),
        "ROS_AUTOMATIC_DISCOVERY_RANGE": "LOCALHOST",
        "PYTHONUNBUFFERED": "1",
        "RCUTILS_COLORIZED_OUTPUT": "0",
    })
    env.pop("ROS_LOCALHOST_ONLY", None)
    return env


@dataclass
class LifterProcess:
    """The installed ``lifter`` running as a child process; its log goes to ``log_path``."""

    proc: subprocess.Popen[bytes]
    log_path: Path

    def log(self) -> str:
        return self.log_path.read_text(errors="replace")

    def alive(self) -> bool:
        return self.proc.poll() is None

    def interrupt(self, timeout: float = SHUTDOWN_TIMEOUT) -> int:
        """SIGINT, as Ctrl-C in a terminal; returns the exit code (kills and fails on a hang)."""
        if self.proc.poll() is None:
            self.proc.send_signal(signal.SIGINT)
            try:
                self.proc.wait(timeout)
            except subprocess.TimeoutExpired:
                self.proc.kill()
                self.proc.wait()
                pytest.fail(f"lifter did not exit within {timeout} s of SIGINT; log:\n{self.log()}")
        return int(self.proc.returncode)


@pytest.fixture
def start_lifter(
    lifter_env: dict[str, str], tmp_path_factory: pytest.TempPathFactory
) -> Iterator[Callable[..., LifterProcess]]:
    """Factory: ``start_lifter(params={...}, params_file=PARAMS_YAML)`` -> :class:`LifterProcess`.

    Every process started is stopped with SIGINT at teardown, and must exit cleanly.
    """
    started: list[LifterProcess] = []

    def start(params: dict[str, Any] | None = None, params_file: Path | None = PARAMS_YAML,
              extra_ros_args: tuple[str, ...] = ()) -> LifterProcess:
        args = [str(LIFTER_EXE), "--ros-args"]
        if params_file is not None:
            args += ["--params-file", str(params_file)]
        for name, value in (params or {}).items():
            text = ("true" if value else "false") if isinstance(value, bool) else str(value)
            args += ["-p", f"{name}:={text}"]
        args += list(extra_ros_args)
        log_path = tmp_path_factory.mktemp("lifter") / "lifter.log"
        with open(log_path, "wb") as log:
            proc = subprocess.Popen(args, env=lifter_env, stdout=log, stderr=subprocess.STDOUT, cwd=REPO)
        handle = LifterProcess(proc, log_path)
        started.append(handle)
        return handle

    yield start
    failures = []
    for handle in started:
        was_alive = handle.alive()
        code = handle.interrupt()
        if was_alive and (code != 0 or "Traceback" in handle.log()):
            failures.append(f"exit code {code}; log:\n{handle.log()}")
    if failures:
        pytest.fail("lifter did not shut down cleanly on SIGINT: " + "\n".join(failures))


@pytest.fixture(scope="package")
def rclpy_context(ros_domain_id: int) -> Iterator[Any]:
    """A fresh rclpy Context for the test process, on the test graph's domain, shut down (its
    middleware threads with it) when the graph tests end rather than left to the tests after."""
    _require_build()
    _load_workspace_messages()
    os.environ["ROS_AUTOMATIC_DISCOVERY_RANGE"] = "LOCALHOST"
    os.environ.pop("ROS_LOCALHOST_ONLY", None)
    import rclpy
    from rclpy.context import Context
    from rclpy.signals import SignalHandlerOptions

    ctx = Context()
    # the test process keeps pytest's own Ctrl-C handling
    rclpy.init(context=ctx, domain_id=ros_domain_id, signal_handler_options=SignalHandlerOptions.NO)
    yield ctx
    gc.collect()
    rclpy.try_shutdown(context=ctx)


@dataclass
class Answer:
    """What the lifter published for one input frame."""

    skeletons: Any  # Skeleton3DArray
    markers: Any | None = None  # MarkerArray


@dataclass
class GraphClient:
    """The test's side of the graph: publishes keypoints/camera_info, collects the answers."""

    node: Any
    executor: Any
    types: Any
    lifter_name: str = "/pose_lifter"
    skeletons: list[Any] = field(default_factory=list)
    markers: list[Any] = field(default_factory=list)
    lifter: LifterProcess | None = None

    def __post_init__(self) -> None:
        from rclpy.qos import QoSProfile, ReliabilityPolicy

        reliable = QoSProfile(depth=100, reliability=ReliabilityPolicy.RELIABLE)
        t = self.types
        self.pub_keypoints = self.node.create_publisher(t.Skeleton2DArray, "keypoints_2d", reliable)
        self.pub_camera_info = self.node.create_publisher(t.CameraInfo, "camera_info", reliable)
        self.sub_skeletons = self.node.create_subscription(
            t.Skeleton3DArray, "skeletons_3d", self.skeletons.append, reliable)
        self.sub_markers = self.node.create_subscription(
            t.MarkerArray, "skeleton_markers", self.markers.append, reliable)
        from rcl_interfaces.srv import GetParameters, SetParameters

        self.set_client = self.node.create_client(SetParameters, f"{self.lifter_name}/set_parameters")
        self.get_client = self.node.create_client(GetParameters, f"{self.lifter_name}/get_parameters")

    def spin_until(self, condition: Callable[[], bool], timeout: float, what: str) -> None:
        deadline = time.monotonic() + timeout
        while not condition():
            if time.monotonic() > deadline:
                log = self.lifter.log()[-3000:] if self.lifter is not None else ""
                pytest.fail(f"timed out after {timeout} s waiting for {what}; lifter log tail:\n{log}")
            self.executor.spin_once(timeout_sec=0.05)

    def wait_for_lifter(self, process: LifterProcess) -> None:
        """Wait until the lifter process is matched on every topic and its services are up."""
        self.lifter = process
        def ready() -> bool:
            if not process.alive():
                pytest.fail(f"lifter exited early; log:\n{process.log()}")
            return (self.pub_keypoints.get_subscription_count() > 0
                    and self.pub_camera_info.get_subscription_count() > 0
                    and self.sub_skeletons.get_publisher_count() > 0
                    and self.sub_markers.get_publisher_count() > 0
                    and self.set_client.service_is_ready() and self.get_client.service_is_ready())
        self.spin_until(ready, DISCOVERY_TIMEOUT, "discovery of the lifter")
        self._handshake()

    def _handshake(self) -> None:
        """Publish empty frames until the lifter answers one: its best-effort reader has then
        matched this writer (the writer-side match that ``ready`` sees can come first, and a
        frame published in between is dropped by design). The handshake's answers are discarded.
        """
        from pose_lifter.messages.convert import make_header, stamp_to_ns

        deadline = time.monotonic() + DISCOVERY_TIMEOUT
        for i in itertools.count(1):
            self.pub_keypoints.publish(self.types.Skeleton2DArray(
                header=make_header(i, HANDSHAKE_FRAME, self.types), layout="coco17", skeletons=[]))
            wait_until = time.monotonic() + 1.0
            while time.monotonic() < wait_until:
                self.executor.spin_once(timeout_sec=0.05)
                # answers come in order: one to an earlier probe (late, not lost) comes before this one
                if any(a.header.frame_id == HANDSHAKE_FRAME and stamp_to_ns(a.header.stamp) == i
                       for a in self.skeletons):
                    break
            else:
                if time.monotonic() > deadline:
                    log = self.lifter.log()[-3000:] if self.lifter is not None else ""
                    pytest.fail(f"the lifter never answered a handshake frame; lifter log tail:\n{log}")
                continue
            break
        # each answer's MarkerArray follows it (when markers are on): let them arrive, then drop all
        end = time.monotonic() + 2.0
        while len(self.markers) < len(self.skeletons) and time.monotonic() < end:
            self.executor.spin_once(timeout_sec=0.05)
        if any(a.header.frame_id != HANDSHAKE_FRAME for a in self.skeletons):
            pytest.fail("an answer to a frame this test never sent arrived during the handshake")
        self.skeletons.clear()
        self.markers.clear()

    def send(self, frame: Any, expect_markers: bool = True, timeout: float = ANSWER_TIMEOUT) -> Answer:
        """Publish one Skeleton2DArray (message or CDR bytes) and wait for its answer.

        Frames are sent in lock step (the next only after the answer), as a detector at the
        lifter's rate would; the answer is matched by header stamp and frame id.
        """
        from pose_lifter.messages.convert import stamp_to_ns

        header = frame.header if not isinstance(frame, bytes) else None
        n_sk, n_mk = len(self.skeletons), len(self.markers)
        self.pub_keypoints.publish(frame)
        self.spin_until(
            lambda: len(self.skeletons) > n_sk and (not expect_markers or len(self.markers) > n_mk),
            timeout, "the lifter's answer")
        answer = Answer(self.skeletons[n_sk], self.markers[n_mk] if expect_markers else None)
        if len(self.skeletons) != n_sk + 1:
            pytest.fail(f"{len(self.skeletons) - n_sk} answers to one frame")
        if header is not None:
            assert stamp_to_ns(answer.skeletons.header.stamp) == stamp_to_ns(header.stamp)
            assert answer.skeletons.header.frame_id == header.frame_id
        return answer

    def set_parameters(self, **values: Any) -> list[Any]:
        """Call ``set_parameters``: one ``SetParametersResult`` per value."""
        from rcl_interfaces.srv import SetParameters
        from rclpy.parameter import Parameter

        req = SetParameters.Request(parameters=[Parameter(k, value=v).to_parameter_msg()
                                                for k, v in values.items()])
        return list(self.call(self.set_client, req).results)

    def get_parameters(self, *names: str) -> dict[str, Any]:
        from rcl_interfaces.srv import GetParameters
        from rclpy.parameter import parameter_value_to_python

        resp = self.call(self.get_client, GetParameters.Request(names=list(names)))
        return {n: parameter_value_to_python(v) for n, v in zip(names, resp.values, strict=True)}

    def call(self, client: Any, request: Any, *, idempotent: bool = True) -> Any:
        """The first answer to ``request``; idempotent requests are sent again every
        ``RESEND_AFTER`` s until one is answered (see ``RESEND_AFTER``)."""
        futures = [client.call_async(request)]
        deadline = time.monotonic() + ANSWER_TIMEOUT
        resend = time.monotonic() + RESEND_AFTER
        while not any(f.done() for f in futures):
            now = time.monotonic()
            if now > deadline:
                log = self.lifter.log()[-3000:] if self.lifter is not None else ""
                pytest.fail(f"timed out after {ANSWER_TIMEOUT} s waiting for service {client.srv_name} "
                            f"({len(futures)} requests sent); lifter log tail:\n{log}")
            if idempotent and now > resend:
                futures.append(client.call_async(request))
                resend = now + RESEND_AFTER
            self.executor.spin_once(timeout_sec=0.05)
        return next(f for f in futures if f.done()).result()


@pytest.fixture
def graph(rclpy_context: Any) -> Iterator[GraphClient]:
    """A client node in the test process (its own executor on the test Context)."""
    import rclpy
    from pose_lifter.messages.convert import rclpy_types
    from rclpy.executors import SingleThreadedExecutor

    node = rclpy.create_node(f"lifter_test_{os.getpid()}", context=rclpy_context)
    executor = SingleThreadedExecutor(context=rclpy_context)
    executor.add_node(node)
    client = GraphClient(node, executor, rclpy_types())
    yield client
    executor.remove_node(node)
    node.destroy_node()
    executor.shutdown()
    # rclpy objects left unreferenced in cycles are destroyed here, between tests, rather than by
    # whichever later collection runs (in another test, inside other code)
    gc.collect()


def all_finite(msg: Any) -> bool:
    """No NaN/inf anywhere in a Skeleton3DArray."""
    values: list[float] = []
    for s in msg.skeletons:
        values += [c for p in s.joints for c in (p.x, p.y, p.z)]
        cam = s.camera
        values += list(cam.projection) + list(cam.translation) + [cam.scale, cam.orientation.x,
                   cam.orientation.y, cam.orientation.z, cam.orientation.w]
        values += [s.objective, s.reprojection_error, s.solve_time]
    return bool(np.all(np.isfinite(np.asarray(values, dtype=np.float64))))
