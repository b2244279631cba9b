"""The offline lift's depth input (pose_lifter.offline.depth): which topic, each message's partner
by header stamp within the tolerance, the images read one at a time, and ``pose-lifter lift
--depth-topic`` end to end (a missing topic is an error naming the bag's image topics; no depth
topic is the monocular lift, joint for joint)."""

from __future__ import annotations

import dataclasses
import io
import struct
from pathlib import Path
from typing import Any

import numpy as np
import pytest
from PIL import Image
from pose_lifter import cli
from pose_lifter.messages import typestore
from pose_lifter.messages.convert import skeleton3d_to_joints, skeleton3d_to_std, stamp_to_ns
from pose_lifter.messages.depth import DepthFault, PairFault
from pose_lifter.messages.names import COMPRESSED_IMAGE, IMAGE, TOPIC_DEPTH, TOPIC_DEPTH_COMPRESSED
from pose_lifter.offline import bags
from pose_lifter.offline.depth import depth_topic_of, pair_depth

REPO = Path(__file__).resolve().parents[2]
WALK = REPO / "bags" / "walk_clean.mcap"  # 640 x 480 camera_info, keypoints stamped as recorded
N = 12  # keypoints messages lifted
#: The depth images' wall, millimetres: the monocular lift places walk_clean's walker ~5.1 m away.
WALL_MM = 4500
#: The fused joints lie behind the wall's surface by the joints' surface offsets (at most ~0.12 m,
#: pose_lifter.core.depth.SURFACE_OFFSET_M) and their spread along the ray: within this of it.
NEAR_WALL_M = 0.2


def _depth_image(stamp_ns: int, mm: int, size: tuple[int, int] = (640, 480), encoding: str = "16UC1") -> Any:
    w, h = size
    sec, nsec = divmod(stamp_ns, 10**9)
    msg = typestore.message_factory(IMAGE)(height=h, width=w, encoding=encoding, step=2 * w,
                                          data=np.full(h * w, mm, dtype="<u2").view(np.uint8))
    msg.header.stamp.sec, msg.header.stamp.nanosec = sec, nsec
    return msg


def _compressed_image(stamp_ns: int, mm: int) -> Any:
    out = io.BytesIO()
    Image.fromarray(np.full((480, 640), mm, dtype=np.uint16)).save(out, format="PNG")
    msg = typestore.message_factory(COMPRESSED_IMAGE)(
        format="16UC1; compressedDepth png",
        data=np.frombuffer(struct.pack("<iff", 0, 0.0, 0.0) + out.getvalue(), dtype=np.uint8))
    msg.header.stamp.sec, msg.header.stamp.nanosec = divmod(stamp_ns, 10**9)
    return msg


def rgbd_bag(path: Path, offset_ns: int = 3_000_000, topic: str = TOPIC_DEPTH, compressed: bool = False,
             size: tuple[int, int] = (640, 480), encoding: str = "16UC1", source: Path = WALK) -> Path:
    """``source``'s first N frames with a depth image per frame, stamped ``offset_ns`` after the
    keypoints' header stamp and recorded before them (a wall at WALL_MM + 1 mm per frame)."""
    kind = COMPRESSED_IMAGE if compressed else IMAGE
    with bags.BagWriter(path, compress=False) as w:
        n = 0
        for raw in bags.read_raw(source):
            if raw.topic == "/keypoints_2d":
                if n == N:
                    break
                header = typestore.pose_lifter_typestore().deserialize_cdr(raw.data, raw.msgtype).header
                stamp = stamp_to_ns(header.stamp) + offset_ns
                image = (_compressed_image(stamp, WALL_MM + n) if compressed
                         else _depth_image(stamp, WALL_MM + n, size, encoding))
                w.write(topic, raw.stamp_ns, image, kind)
                n += 1
            w.write_raw(raw)
    return path


def lift(*args: str) -> int:
    return cli.main(["lift", *args, "--quiet", "--workers", "1", "--max-messages", str(N)])


# ------------------------------------------------------------------ the topic


def test_depth_topic_of() -> None:
    topics = {"/keypoints_2d": "x", "/camera/color/image_raw": IMAGE, TOPIC_DEPTH: IMAGE,
              "/camera_info": "sensor_msgs/msg/CameraInfo"}
    assert depth_topic_of(topics, "", "b") == TOPIC_DEPTH  # the one image topic named depth
    assert depth_topic_of(topics, "none", "b") is None
    assert depth_topic_of(topics, "/camera/color/image_raw", "b") == "/camera/color/image_raw"
    assert depth_topic_of({**topics, TOPIC_DEPTH_COMPRESSED: COMPRESSED_IMAGE}, "", "b") is None  # two
    assert depth_topic_of({"/keypoints_2d": "x"}, "", "b") is None  # none: the monocular lift
    with pytest.raises(bags.BagError, match=r"no depth topic '/nope'.*'/camera/color/image_raw'"):
        depth_topic_of(topics, "/nope", "b")
    with pytest.raises(bags.BagError, match="not sensor_msgs/msg/Image"):
        depth_topic_of(topics, "/camera_info", "b")


# ------------------------------------------------------------------ pairing and reading


def _frame_stamps() -> list[int]:
    out = []
    for x in bags.read_messages(WALK, ["/keypoints_2d"]):
        out.append(stamp_to_ns(x.msg.header.stamp) or x.stamp_ns)
        if len(out) == N:
            return out
    return out


def test_pairs_by_header_stamp_within_the_tolerance(tmp_path: Path) -> None:
    bag = rgbd_bag(tmp_path / "rgbd.mcap", offset_ns=3_000_000)
    stamps = _frame_stamps()
    sizes = [(640.0, 480.0)] * N
    depth = pair_depth(bag, TOPIC_DEPTH, IMAGE, stamps, sizes, 0.02)
    assert depth.partners == tuple(range(N)) and depth.paired == N and not depth.unpaired
    tight = pair_depth(bag, TOPIC_DEPTH, IMAGE, stamps, sizes, 0.002)  # 3 ms off: never paired
    assert tight.partners == (None,) * N and tight.unpaired == {str(PairFault.GAP): N - 1,
                                                                  str(PairFault.TOO_NEW): 1}
    with depth.frames() as frames:
        for i in (0, 1, 5, 2):  # forward, then back (the topic read again from its start)
            image = frames.image(i)
            assert image is not None and image.shape == (480, 640)
            assert image.dtype == np.uint16 and (image == WALL_MM + i).all()  # 16UC1: kept in millimetres
        assert not frames.refused


def test_refused_images_leave_their_frames_to_the_2d(tmp_path: Path) -> None:
    stamps = _frame_stamps()
    small = rgbd_bag(tmp_path / "small.mcap", size=(320, 240))
    with pair_depth(small, TOPIC_DEPTH, IMAGE, stamps, [(640.0, 480.0)] * N, 0.02).frames() as frames:
        assert frames.image(0) is None and frames.refused == {str(DepthFault.SIZE): 1}
    mono8 = rgbd_bag(tmp_path / "mono8.mcap", encoding="8UC1")
    with pair_depth(mono8, TOPIC_DEPTH, IMAGE, stamps, [None] * N, 0.02).frames() as frames:
        assert frames.image(3) is None and frames.image(3) is None
        assert frames.refused == {str(DepthFault.ENCODING): 1}  # once per image
        assert "'8UC1'" in frames.reasons[str(DepthFault.ENCODING)]


def test_lift_says_once_why_the_depth_images_are_refused(tmp_path: Path,
                                                         capsys: pytest.CaptureFixture[str]) -> None:
    bag = rgbd_bag(tmp_path / "small.mcap", size=(320, 240))  # not registered to the 640 x 480 camera
    assert lift(str(bag), "--out", str(tmp_path / "out.mcap"), "--no-publish-hri") == 0
    lines = [x for x in capsys.readouterr().out.splitlines() if "depth image refused" in x]
    assert len(lines) == 1 and "320x240" in lines[0] and "640x480" in lines[0]


# ------------------------------------------------------------------ pose-lifter lift


def _joints(out: Path) -> list[np.ndarray]:
    """Per answer, its skeletons' joints (n, 12, 3) metres."""
    return [np.array([skeleton3d_to_joints(s) for s in x.msg.skeletons]).reshape(-1, 12, 3)
            for x in bags.read_messages(out, ["/skeletons_3d"])]


def _stds(out: Path) -> list[np.ndarray]:
    """Per answer, its skeletons' joint_std (n, 12, 3) metres (NaN: unknown)."""
    return [np.array([skeleton3d_to_std(s) for s in x.msg.skeletons]).reshape(-1, 12, 3)
            for x in bags.read_messages(out, ["/skeletons_3d"])]


@pytest.mark.parametrize("compressed", [False, True])
def test_lift_reads_the_bag_s_depth_topic(tmp_path: Path, capsys: pytest.CaptureFixture[str],
                                          compressed: bool) -> None:
    topic = TOPIC_DEPTH_COMPRESSED if compressed else TOPIC_DEPTH
    bag = rgbd_bag(tmp_path / "rgbd.mcap", topic=topic, compressed=compressed)
    out, mono = tmp_path / "out.mcap", tmp_path / "mono.mcap"
    assert lift(str(bag), "--out", str(out), "--no-publish-hri") == 0  # the one depth topic, by default
    assert f"depth from {topic}: {N} of {N} messages paired" in capsys.readouterr().out
    assert lift(str(bag), "--out", str(mono), "--no-publish-hri", "--depth-topic", "none") == 0
    fused, alone = _joints(out), _joints(mono)
    assert len(fused) == len(alone) == N
    for k, (f, a) in enumerate(zip(fused, alone, strict=True)):  # the person sits at the depth
        wall = (WALL_MM + k) / 1000.0
        assert 0.0 < f[..., 2].mean() - wall < NEAR_WALL_M and abs(a[..., 2].mean() - wall) > 2 * NEAR_WALL_M
    for std in _stds(out):  # each joint with its uncertainty
        assert np.isfinite(std).all() and (std > 0).all()
    for fused_std, mono_std in zip(_stds(out), _stds(mono), strict=True):  # the depth is the surer
        assert np.isfinite(mono_std).all() and mono_std[..., 2].mean() > fused_std[..., 2].mean()


def test_no_depth_topic_is_the_monocular_lift(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    bag = rgbd_bag(tmp_path / "rgbd.mcap")
    plain = tmp_path / "plain.mcap"
    with bags.BagWriter(plain, compress=False) as w:  # the same bag without its depth topic
        for raw in bags.read_raw(bag):
            if raw.topic != TOPIC_DEPTH:
                w.write_raw(dataclasses.replace(raw))
    assert lift(str(bag), "--out", str(tmp_path / "none.mcap"), "--depth-topic", "none",
                "--no-publish-hri") == 0
    assert lift(str(plain), "--out", str(tmp_path / "plain_out.mcap"), "--no-publish-hri") == 0
    assert "depth from" not in capsys.readouterr().out
    none, plain_joints = _joints(tmp_path / "none.mcap"), _joints(tmp_path / "plain_out.mcap")
    assert len(none) == N and all(np.array_equal(a, b) for a, b in zip(none, plain_joints, strict=True))


def test_a_named_depth_topic_the_bag_lacks_is_an_error(tmp_path: Path, capsys: pytest.CaptureFixture[str]
                                                       ) -> None:
    bag = rgbd_bag(tmp_path / "rgbd.mcap")
    out = tmp_path / "out.mcap"
    assert lift(str(bag), "--out", str(out), "--depth-topic", "/camera/depth/nope") != 0
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and "/camera/depth/nope" in err[0] and TOPIC_DEPTH in err[0]
    assert not out.exists()


def _lift_all(bag: Path, out: Path, *args: str) -> list[np.ndarray]:
    assert cli.main(["lift", str(bag), "--out", str(out), "--quiet", "--max-messages", str(N),
                     "--no-publish-hri", *args]) == 0
    return _joints(out)


def test_lift_with_depth_on_workers_is_the_serial_lift(tmp_path: Path) -> None:
    """The forked workers (each its own reader of the depth topic; two tracks, two chains) give
    the serial lift's joints, and those are not the monocular ones."""
    bag = rgbd_bag(tmp_path / "rgbd.mcap", source=REPO / "bags" / "two_people.mcap")
    serial = _lift_all(bag, tmp_path / "serial.mcap", "--workers", "1")
    forked = _lift_all(bag, tmp_path / "forked.mcap", "--workers", "2")
    alone = _lift_all(bag, tmp_path / "alone.mcap", "--workers", "1", "--depth-topic", "none")
    assert len(serial) == N and all(np.array_equal(a, b) for a, b in zip(serial, forked, strict=True))
    assert not any(np.allclose(a, b) for a, b in zip(serial, alone, strict=True))


def test_lagged_answers_keep_the_fused_joints(tmp_path: Path) -> None:
    bag = rgbd_bag(tmp_path / "rgbd.mcap")
    lagged = _lift_all(bag, tmp_path / "lagged.mcap", "--workers", "1", "--output-lag", "3",
                       "--smoothing", "0")
    assert len(lagged) == N
    for k, f in enumerate(lagged):
        assert 0.0 < f[..., 2].mean() - (WALL_MM + k) / 1000.0 < NEAR_WALL_M


def _jitter(joints: list[np.ndarray]) -> float:
    """The mean second difference of a one-person recording's joints, metres per frame^2."""
    x = np.array([j[0] for j in joints])
    return float(np.linalg.norm(x[2:] - 2 * x[1:-1] + x[:-2], axis=-1).mean())


def test_the_fused_joints_are_averaged_over_the_track(tmp_path: Path) -> None:
    """Each frame's depth readings err on their own (the sensor, the patch, a reading that was an
    occluder's), so a window over the fused joints averages the errors out: ``pose-lifter lift``
    over the whole track, the lagged node over the frames its lag holds. On the committed RGB-D
    bag (the realistic sensor) both shake a fraction of what the node's per-frame fusion does (a
    window over the poses before the fusion, without one over the fused joints, leaves 0.8-1.0
    of it)."""
    bag = REPO / "bags" / "rgbd" / "punch_rgbd.mcap"
    node = _jitter(_lift_all(bag, tmp_path / "node.mcap", "--smoothing", "0"))
    offline = _jitter(_lift_all(bag, tmp_path / "offline.mcap"))
    lagged = _jitter(_lift_all(bag, tmp_path / "lagged.mcap", "--smoothing", "0", "--output-lag", "3"))
    assert offline < 0.3 * node and lagged < 0.3 * node


def test_the_lift_at_once_gives_the_node_s_answers_with_depth(tmp_path: Path) -> None:
    """``pose-lifter lift --smoothing 0`` answers a recording with depth as the node answers it
    live (:class:`~pose_lifter.messages.answer.AnswerStream`, the node's driver, fed the same
    frames, camera and paired images): the fused joints through each track's filter, bit for bit;
    and the filter moved them (the frames' fusion alone differs)."""
    from pose_lifter.core import Lifter
    from pose_lifter.messages.answer import AnswerStream
    from pose_lifter.messages.convert import intrinsics_from_camera_info
    from pose_lifter.messages.frame import FramePipeline, FrameSettings

    bag = REPO / "bags" / "rgbd" / "punch_rgbd.mcap"
    offline = _lift_all(bag, tmp_path / "at_once.mcap", "--smoothing", "0", "--workers", "1")
    kp = [(x.stamp_ns, x.msg) for x in bags.read_messages(bag, ["/keypoints_2d"])][:N]
    info = next(x.msg for x in bags.read_messages(bag, ["/camera_info"]))
    stamps = [stamp_to_ns(msg.header.stamp) or s for s, msg in kp]
    size = (float(info.width), float(info.height))
    depth = pair_depth(bag, TOPIC_DEPTH, IMAGE, stamps, [size] * len(kp), 0.02)
    with depth.frames() as frames:
        images = {s: frames.image(i) for i, s in enumerate(stamps)}
    stream = AnswerStream(FramePipeline(Lifter(), FrameSettings()), 0, _unread)
    stream.intrinsics = intrinsics_from_camera_info(info)
    stream.depth_of = images.get
    live = [np.array([s.joints_m for s in stream.answer(msg, 0.0, stamp).answers[0].lifted])
            for stamp, msg in kp]
    assert len(live) == len(offline) == len(kp) >= 4
    for a, b in zip(live, offline, strict=True):
        np.testing.assert_array_equal(a, b)  # float64 points, written and read exactly
    unfiltered = AnswerStream(FramePipeline(Lifter(), FrameSettings()), 0, _unread)
    unfiltered.intrinsics, unfiltered.depth_of = stream.intrinsics, images.get
    unfiltered.pipeline.follow_fused(False)
    alone = [np.array([s.joints_m for s in unfiltered.answer(msg, 0.0, stamp).answers[0].lifted])
             for stamp, msg in kp]
    assert not any(np.allclose(a, b) for a, b in zip(alone[1:], live[1:], strict=True))


def _unread(data: bytes) -> Any:
    raise AssertionError("frames are given as messages")
