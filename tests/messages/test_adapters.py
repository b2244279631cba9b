"""Detector inputs: the layouts, the core converters (pose_lifter.messages.detectors) and the ROS
message adapters (pose_lifter.messages.adapters) on messages of the real yolo_msgs / hri_msgs
definitions (tests/ros/msgs/yolo_msgs and ros2_ws/vendor/hri_msgs, registered with rosbags from
their text and written to a bag)."""

from __future__ import annotations

from pathlib import Path
from types import SimpleNamespace
from typing import Any

import numpy as np
import pytest
import tolerances as tol
from detector_poses import coco17, coco17_to, model_xy
from pose_lifter.core import Lifter, PoseBases
from pose_lifter.core.errors import InvalidInputError, UnknownLayoutError
from pose_lifter.core.model.skeleton import N_JOINTS
from pose_lifter.messages import adapters, typestore
from pose_lifter.messages import convert as m
from pose_lifter.messages.detectors import (
    Person2D,
    batch_to_model,
    dense_to_model,
    from_mediapipe,
    from_mmpose,
    from_openpose_json,
    from_ultralytics,
    guess_layout,
    sparse_to_model,
)
from pose_lifter.messages.layouts import ALIASES, LAYOUTS, get_layout, to_model_joints
from pose_lifter.offline import bags

REPO = Path(__file__).resolve().parents[2]
THIRD_PARTY = REPO / "tests" / "ros" / "msgs"

# --------------------------------------------------------------------------- layouts


@pytest.mark.parametrize("name", ["coco18", "halpe26", "mediapipe33", "coco_wholebody133", "body25"])
def test_every_layout_gives_the_same_model_joints_as_coco17(name: str) -> None:
    xy = model_xy()
    kp, conf = coco17(xy)
    ref_pts, ref_conf = to_model_joints(kp, conf, "coco17")
    np.testing.assert_allclose(ref_pts, xy)
    other, other_conf = coco17_to(name, kp, conf)
    pts, c = to_model_joints(other, other_conf, name)
    np.testing.assert_allclose(pts, ref_pts)
    np.testing.assert_allclose(c, ref_conf)


def test_layout_table_is_consistent() -> None:
    for name, lay in LAYOUTS.items():
        assert lay.name == name
        assert len(lay.model_indices) == N_JOINTS
        assert len(set(lay.model_indices)) == N_JOINTS
        assert all(0 <= i < lay.n_keypoints for i in lay.model_indices)
    for alias, target in ALIASES.items():
        assert get_layout(alias) is LAYOUTS[target]
        assert get_layout(f" {alias.upper()} ") is LAYOUTS[target]
    with pytest.raises(UnknownLayoutError, match="coco_wholebody133"):
        get_layout("coco19")


# --------------------------------------------------------------------------- core converters


def test_dense_with_confidence_column_and_normalised_coordinates() -> None:
    xy = model_xy()
    kp, conf = coco17(xy)
    pts, c = dense_to_model(np.column_stack([kp / [640.0, 480.0], conf]), image_size=(640, 480))
    np.testing.assert_allclose(pts, xy)
    np.testing.assert_allclose(c, to_model_joints(kp, conf, "coco17")[1])
    with pytest.raises(InvalidInputError, match="image_size"):
        dense_to_model(kp, conf, "coco17", image_size=(0, 480))
    with pytest.raises(InvalidInputError, match="no known layout has 19"):
        dense_to_model(np.zeros((19, 2)))


def test_dense_missing_nan_keypoints_become_zero_visible_nan_refused() -> None:
    kp, conf = coco17(model_xy())
    kp[9] = np.nan  # left wrist
    conf[9] = 0.0
    pts, c = dense_to_model(kp, conf, "coco17")
    assert c[2] == 0.0 and np.all(pts[2] == 0.0) and np.all(np.isfinite(pts))
    conf[9] = 0.7
    with pytest.raises(InvalidInputError, match="left_wrist"):
        dense_to_model(kp, conf, "coco17")


def test_sparse_one_based_ids_missing_joints_and_bad_ids() -> None:
    xy = model_xy()
    kp, conf = coco17(xy)
    keep = [i for i in range(17) if i != 10]  # the right wrist below the detector's threshold
    pts, c = sparse_to_model([i + 1 for i in keep], kp[keep], conf[keep], "coco17", id_base=1)
    ref, ref_c = to_model_joints(kp, conf, "coco17")
    assert c[5] == 0.0  # right wrist missing
    mask = np.arange(12) != 5
    np.testing.assert_allclose(pts[mask], ref[mask])
    np.testing.assert_allclose(c[mask], ref_c[mask])
    with pytest.raises(InvalidInputError, match=r"\[18\]"):
        sparse_to_model([18], [[1.0, 2.0]], [0.9], "coco17", id_base=1)
    with pytest.raises(InvalidInputError, match="twice"):
        sparse_to_model([3, 3], [[1.0, 2.0], [1.0, 2.0]], [0.9, 0.9], "coco17", id_base=1)
    with pytest.raises(InvalidInputError, match="lengths differ"):
        sparse_to_model([3, 4], [[1.0, 2.0]], [0.9, 0.9], "coco17")


def test_batch_guesses_layout_and_keeps_track_ids() -> None:
    kp, conf = coco17(model_xy())
    people = batch_to_model(np.stack([kp, kp + 100]), np.stack([conf, conf]), track_ids=[4, 9])
    assert [p.track_id for p in people] == [4, 9]
    np.testing.assert_allclose(people[1].points - people[0].points, 100.0)
    assert guess_layout(17).name == "coco17" and guess_layout(133).name == "coco_wholebody133"
    assert batch_to_model(np.zeros((0, 17, 3))) == []
    with pytest.raises(InvalidInputError, match="3 track ids for 2"):
        batch_to_model(np.stack([kp, kp]), track_ids=[1, 2, 3])


class FakeTensor:
    """What ultralytics hands out: a torch tensor (.cpu().numpy())."""

    def __init__(self, a: np.ndarray) -> None:
        self._a = np.asarray(a, dtype=np.float32)

    def cpu(self) -> FakeTensor:
        return self

    def numpy(self) -> np.ndarray:
        return self._a


def test_ultralytics_result_with_tracker_ids() -> None:
    # ultralytics.engine.results.Results: .keypoints.xy (N,17,2), .keypoints.conf (N,17), .boxes.id
    kp, conf = coco17(model_xy())
    result = SimpleNamespace(
        keypoints=SimpleNamespace(xy=FakeTensor(np.stack([kp, kp + 5])),
                                  conf=FakeTensor(np.stack([conf, conf]))),
        boxes=SimpleNamespace(id=FakeTensor(np.array([7.0, 2.0]))))
    people = from_ultralytics(result)
    assert [p.track_id for p in people] == [7, 2]
    np.testing.assert_allclose(people[0].points, model_xy(), atol=1e-4)
    untracked = from_ultralytics(SimpleNamespace(
        keypoints=SimpleNamespace(xy=FakeTensor(kp[None]), conf=None), boxes=SimpleNamespace(id=None)))
    assert untracked[0].track_id == -1 and np.all(untracked[0].confidence == 1.0)


def test_mediapipe_tasks_and_legacy_results() -> None:
    xy = model_xy()
    kp, conf = coco17(xy)
    mp_xy, mp_conf = coco17_to("mediapipe33", kp, conf)
    lms = [SimpleNamespace(x=x / 640.0, y=y / 480.0, z=0.0, visibility=v, presence=1.0)
           for (x, y), v in zip(mp_xy, mp_conf, strict=True)]
    tasks = from_mediapipe(SimpleNamespace(pose_landmarks=[lms, lms]), (640, 480))  # PoseLandmarkerResult
    legacy = from_mediapipe(SimpleNamespace(pose_landmarks=SimpleNamespace(landmark=lms)), (640, 480))
    assert len(tasks) == 2 and len(legacy) == 1
    for p in (*tasks, *legacy):
        np.testing.assert_allclose(p.points, xy, atol=tol.ROUND_OFF_ACCUMULATED)
    assert from_mediapipe(SimpleNamespace(pose_landmarks=None), (640, 480)) == []


def test_mmpose_and_openpose_outputs() -> None:
    xy = model_xy()
    kp, conf = coco17(xy)
    h, hc = coco17_to("halpe26", kp, conf)
    instance = {"keypoints": h.tolist(), "keypoint_scores": hc.tolist(), "bbox": [[0, 0, 1, 1]]}
    inferencer = {"predictions": [[instance]]}
    sample = SimpleNamespace(pred_instances=SimpleNamespace(keypoints=h[None], keypoint_scores=hc[None]))
    for people in (from_mmpose(inferencer), from_mmpose(sample)):
        np.testing.assert_allclose(people[0].points, xy)
    k25, c25 = coco17_to("body25", kp, conf)
    op = {"people": [{"person_id": [-1], "pose_keypoints_2d": np.column_stack([k25, c25]).ravel().tolist()}]}
    np.testing.assert_allclose(from_openpose_json(op)[0].points, xy)
    with pytest.raises(InvalidInputError, match="multiple of 3"):
        from_openpose_json({"people": [{"pose_keypoints_2d": [1.0, 2.0]}]})


# --------------------------------------------------------------------------- ROS messages


@pytest.fixture(scope="module")
def store() -> Any:
    """A fresh Jazzy typestore with ours + the upstream yolo_msgs and hri_msgs from their text."""
    from rosbags.typesys import Stores, get_typestore

    st = get_typestore(Stores.ROS2_JAZZY)
    for pkg in ("pose_lifter_msgs",):
        typestore.register_msg_package(st, pkg, typestore.msg_dir())
    names = typestore.register_msg_package(st, "yolo_msgs", THIRD_PARTY / "yolo_msgs" / "msg")
    assert "yolo_msgs/msg/DetectionArray" in names
    typestore.register_msg_package(st, "hri_msgs", REPO / "ros2_ws" / "vendor" / "hri_msgs" / "msg")
    return st


def yolo_array(store: Any, people: list[tuple[str, np.ndarray, np.ndarray]], stamp_ns: int = 10**9,
               threshold: float = 0.5) -> Any:
    """A DetectionArray as yolo_node.py builds it: keypoints above threshold, ids kp_id + 1."""
    f = {n: typestore.message_factory(f"yolo_msgs/msg/{n}", store)
         for n in ("DetectionArray", "Detection", "KeyPoint2D", "KeyPoint2DArray", "Point2D")}
    header = typestore.message_factory("std_msgs/msg/Header", store)
    time = typestore.message_factory("builtin_interfaces/msg/Time", store)
    dets = []
    for tid, kp, conf in people:
        data = [f["KeyPoint2D"](id=i + 1, point=f["Point2D"](x=float(x), y=float(y)), score=float(c))
                for i, ((x, y), c) in enumerate(zip(kp, conf, strict=True)) if c >= threshold]
        dets.append(f["Detection"](class_id=0, class_name="person", score=0.9, id=tid,
                                   keypoints=f["KeyPoint2DArray"](data=data)))
    dets.append(f["Detection"](class_id=56, class_name="chair", score=0.8, id="",
                               keypoints=f["KeyPoint2DArray"](data=[])))
    return f["DetectionArray"](header=header(stamp=time(sec=stamp_ns // 10**9, nanosec=stamp_ns % 10**9),
                                              frame_id="camera_color_optical_frame"), detections=dets)


def hri_skeleton(store: Any, kp18: np.ndarray, c18: np.ndarray, size: tuple[int, int]) -> Any:
    poi = typestore.message_factory("hri_msgs/msg/NormalizedPointOfInterest2D", store)
    make = typestore.message_factory("hri_msgs/msg/Skeleton2D", store)
    return make(skeleton=[poi(x=float(x / size[0]), y=float(y / size[1]), c=float(c))
                          for (x, y), c in zip(kp18, c18, strict=True)])


def test_yolo_detection_array_through_a_bag_to_a_lift(store: Any, tmp_path: Path) -> None:
    xy = model_xy()
    kp, conf = coco17(xy)
    msg = yolo_array(store, [("3", kp, conf), ("person_b", kp + 50, conf)])
    path = tmp_path / "yolo.mcap"
    from rosbags.rosbag2 import StoragePlugin, Writer

    with Writer(tmp_path / "yolo", version=9, storage_plugin=StoragePlugin.MCAP) as w:
        conn = w.add_connection("/yolo/detections", "yolo_msgs/msg/DetectionArray", typestore=store)
        w.write(conn, 10**9, store.serialize_cdr(msg, "yolo_msgs/msg/DetectionArray"))
    path = next((tmp_path / "yolo").glob("*.mcap"))
    (read,) = list(bags.read_messages(path))  # AnyReader uses the bag's embedded definitions
    assert read.msgtype == "yolo_msgs/msg/DetectionArray"
    ids = adapters.TrackIds()
    people, problems = adapters.yolo_detections_to_people(read.msg, ids)
    assert problems == [] and len(people) == 2  # the chair is not a person
    assert people[0].track_id == 3 and people[1].track_id == adapters.TrackIds.FIRST_NAMED
    assert ids("person_b") == people[1].track_id and ids("") == -1
    keep = conf >= 0.5
    np.testing.assert_allclose(people[0].points[to_model_joints(kp, keep.astype(float), "coco17")[1] > 0],
                               xy[to_model_joints(kp, keep.astype(float), "coco17")[1] > 0])
    assert np.all(people[0].confidence[to_model_joints(kp, keep.astype(float), "coco17")[1] == 0] == 0)

    types = m.rosbags_types(store)
    array = adapters.people_to_skeleton2d_array(read.msg.header, people, types)
    assert array.layout == "wang12" and array.header.frame_id == "camera_color_optical_frame"
    raw = store.serialize_cdr(array, "pose_lifter_msgs/msg/Skeleton2DArray")
    back = store.deserialize_cdr(raw, "pose_lifter_msgs/msg/Skeleton2DArray")
    pts, c = m.skeleton2d_to_arrays(back.skeletons[0], back.layout)
    result = Lifter(PoseBases.load()).lift(pts, c)
    assert result.reprojection_error < tol.ADAPTED_REPROJECTION_PX


def test_yolo_bad_keypoint_id_is_reported_not_raised(store: Any) -> None:
    kp, conf = coco17(model_xy())
    msg = yolo_array(store, [("1", kp, conf)])
    msg.detections[0].keypoints.data[0].id = 40
    people, problems = adapters.yolo_detections_to_people(msg, adapters.TrackIds())
    assert people == [] and "outside layout 'coco17'" in problems[0]


def test_hri_skeleton2d_normalised_to_pixels(store: Any) -> None:
    xy = model_xy()
    kp, conf = coco17(xy)
    k18, c18 = coco17_to("coco18", kp, conf)
    msg = hri_skeleton(store, k18, c18, (640, 480))
    raw = store.serialize_cdr(msg, "hri_msgs/msg/Skeleton2D")
    back = store.deserialize_cdr(raw, "hri_msgs/msg/Skeleton2D")
    person = adapters.hri_skeleton_to_person(back, (640, 480), 12)
    assert isinstance(person, Person2D) and person.track_id == 12
    np.testing.assert_allclose(person.points, xy, atol=1e-3)  # float32 coordinates
    assert adapters.hri_body_id("/humans/bodies/b4f2a/skeleton2d") == "b4f2a"
    assert adapters.hri_body_id("/humans/bodies/b4f2a/roi") is None
    with pytest.raises(InvalidInputError, match="coco18"):
        adapters.hri_skeleton_to_person(SimpleNamespace(skeleton=back.skeleton[:17]), (640, 480), 1)
