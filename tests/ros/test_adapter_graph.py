"""The installed ``adapter`` in front of the installed ``lifter``, on the real graph: yolo_ros'
``DetectionArray`` and REP-155 ``hri_msgs/Skeleton2D`` in, ``skeletons_3d`` out.

The message classes are the ones ``make ros`` builds from verbatim copies of the upstream
``.msg`` files (tests/ros/msgs/yolo_msgs, ros2_ws/vendor/hri_msgs).
"""

from __future__ import annotations

import subprocess
import time
from collections.abc import Callable, Iterator
from typing import Any

import numpy as np
import pytest
from detector_poses import coco17, coco17_to, model_xy
from pose_lifter.messages import convert as m
from pose_lifter.messages.adapters import TrackIds

from .conftest import DISCOVERY_TIMEOUT, INSTALL, REPO, GraphClient, LifterProcess, _load_workspace_messages

pytestmark = pytest.mark.ros

ADAPTER_EXE = INSTALL / "pose_lifter" / "lib" / "pose_lifter" / "adapter"


@pytest.fixture
def start_adapter(lifter_env: dict[str, str], tmp_path_factory: pytest.TempPathFactory
                  ) -> Iterator[Callable[..., LifterProcess]]:
    started: list[LifterProcess] = []

    def start(*ros_args: str) -> LifterProcess:
        log_path = tmp_path_factory.mktemp("adapter") / "adapter.log"
        with open(log_path, "wb") as log:
            proc = subprocess.Popen([str(ADAPTER_EXE), "--ros-args", *ros_args], env=lifter_env,
                                    stdout=log, stderr=subprocess.STDOUT, cwd=REPO)
        handle = LifterProcess(proc, log_path)
        started.append(handle)
        return handle

    yield start
    for handle in started:
        was_alive = handle.alive()
        code = handle.interrupt()
        assert not was_alive or (code == 0 and "Traceback" not in handle.log()), handle.log()


def answer_through(graph: GraphClient, publish: Callable[[int], None], frame_id: str,
                   adapter: LifterProcess) -> Any:
    """Publish (stamp i = 1, 2, ...) once a second until the lifter answers one; return it."""
    deadline = time.monotonic() + DISCOVERY_TIMEOUT
    i = 0
    while time.monotonic() < deadline:
        i += 1
        publish(i)
        until = time.monotonic() + 1.0
        while time.monotonic() < until:
            graph.executor.spin_once(timeout_sec=0.05)
            for a in graph.skeletons:
                if a.header.frame_id == frame_id and a.skeletons:
                    return a
        if not adapter.alive():
            pytest.fail(f"adapter exited; log:\n{adapter.log()}")
    pytest.fail(f"no answer through the adapter; adapter log:\n{adapter.log()}\n"
                f"lifter log:\n{graph.lifter.log() if graph.lifter else ''}")


def test_yolo_detection_array_in_skeletons_3d_out(graph: GraphClient, start_lifter: Any,
                                                  start_adapter: Any) -> None:
    _load_workspace_messages("yolo_msgs")
    from yolo_msgs.msg import Detection, DetectionArray, KeyPoint2D

    graph.wait_for_lifter(start_lifter())
    adapter = start_adapter("-p", "input_type:=yolo", "-r", "yolo/detections:=/yolo/detections")
    pub = graph.node.create_publisher(DetectionArray, "/yolo/detections", 10)
    xy = model_xy()
    kp, conf = coco17(xy)

    def publish(i: int) -> None:
        det = Detection(class_name="person", id="3", score=0.9)
        for k, ((x, y), c) in enumerate(zip(kp, conf, strict=True)):
            if c >= 0.5:  # yolo_node.py: keypoints above its threshold, id = index + 1
                p = KeyPoint2D(id=k + 1, score=float(c))
                p.point.x, p.point.y = float(x), float(y)
                det.keypoints.data.append(p)
        msg = DetectionArray(detections=[det, Detection(class_name="chair", id="")])
        msg.header = m.make_header(10**9 + i * 10**8, "yolo_cam", graph.types)
        pub.publish(msg)

    answer = answer_through(graph, publish, "yolo_cam", adapter)
    (skel,) = answer.skeletons
    assert skel.track_id == 3
    joints = np.array([[p.x, p.y, p.z] for p in skel.joints])
    assert np.all(np.isfinite(joints)) and np.all(joints[:, 2] > 0)  # in front of the camera
    assert skel.reprojection_error < 10.0  # pixels, on a 190-pixel-tall person


def test_hri_skeleton2d_in_skeletons_3d_out_with_frame_fallback(graph: GraphClient, start_lifter: Any,
                                                                start_adapter: Any) -> None:
    _load_workspace_messages("hri_msgs")
    from hri_msgs.msg import NormalizedPointOfInterest2D, Skeleton2D

    graph.wait_for_lifter(start_lifter())
    adapter = start_adapter("-p", "input_type:=hri", "-p", "image_width:=640", "-p", "image_height:=480",
                            "-p", "frame_id:=hri_fallback_frame")
    pub = graph.node.create_publisher(Skeleton2D, "/humans/bodies/b4f2a/skeleton2d", 10)
    xy = model_xy()
    k18, c18 = coco17_to("coco18", *coco17(xy))

    def publish(i: int) -> None:
        msg = Skeleton2D(skeleton=[NormalizedPointOfInterest2D(x=float(x / 640), y=float(y / 480), c=float(c))
                                   for (x, y), c in zip(k18, c18, strict=True)])
        msg.header = m.make_header(10**9 + i * 10**8, "", graph.types)  # empty frame_id
        pub.publish(msg)

    answer = answer_through(graph, publish, "hri_fallback_frame", adapter)
    (skel,) = answer.skeletons
    assert skel.track_id == TrackIds.FIRST_NAMED  # the first body id seen
    assert skel.reprojection_error < 10.0
    assert "body 'b4f2a'" in adapter.log()


def test_adapter_without_the_message_package_is_one_fatal_line(lifter_env: dict[str, str]) -> None:
    env = dict(lifter_env)
    env["AMENT_PREFIX_PATH"] = ":".join(p for p in env.get("AMENT_PREFIX_PATH", "").split(":")
                                        if "yolo_msgs" not in p)
    env["PYTHONPATH"] = ":".join(p for p in env.get("PYTHONPATH", "").split(":") if "yolo_msgs" not in p)
    out = subprocess.run([str(ADAPTER_EXE), "--ros-args", "-p", "input_type:=yolo"], env=env,
                         capture_output=True, text=True, timeout=60, cwd=REPO)
    assert out.returncode == 1, out.stderr
    assert "yolo_msgs/msg/DetectionArray is not available" in out.stderr + out.stdout
    assert "Traceback" not in out.stderr + out.stdout
    bad = subprocess.run([str(ADAPTER_EXE), "--ros-args", "-p", "input_type:=openpose"], env=lifter_env,
                         capture_output=True, text=True, timeout=60, cwd=REPO)
    assert bad.returncode == 1 and "input_type must be one of" in bad.stderr + bad.stdout


def test_hri_image_size_from_camera_info(graph: GraphClient, start_lifter: Any, start_adapter: Any) -> None:
    _load_workspace_messages("hri_msgs")
    from hri_msgs.msg import NormalizedPointOfInterest2D, Skeleton2D

    graph.wait_for_lifter(start_lifter())
    adapter = start_adapter("-p", "input_type:=hri", "-r", "camera_info:=/hri_cam/camera_info")
    pub = graph.node.create_publisher(Skeleton2D, "/humans/bodies/c1/skeleton2d", 10)
    info_pub = graph.node.create_publisher(graph.types.CameraInfo, "/hri_cam/camera_info", 10)
    xy = model_xy()
    k18, c18 = coco17_to("coco18", *coco17(xy))

    def publish(i: int) -> None:
        header = m.make_header(10**9 + i * 10**8, "hri_cam", graph.types)
        info_pub.publish(m.camera_info(header, 1280, 960, 800.0, 800.0, 640.0, 480.0, graph.types))
        msg = Skeleton2D(skeleton=[NormalizedPointOfInterest2D(x=float(x / 1280), y=float(y / 960),
                                                               c=float(c))
                                   for (x, y), c in zip(k18, c18, strict=True)])
        msg.header = header
        pub.publish(msg)

    answer = answer_through(graph, publish, "hri_cam", adapter)
    (skel,) = answer.skeletons
    assert skel.reprojection_error < 10.0
    # de-normalised with camera_info's 1280x960: the projection's origin sits on the person
    assert np.linalg.norm(np.asarray(skel.camera.translation) - xy.mean(axis=0)) < 25.0
