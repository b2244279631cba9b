"""RGB-D bags: ``pose-lifter make-bag --depth`` and the committed bags/rgbd/punch_rgbd.mcap, read back
with the independent ``mcap`` reader: each frame's depth image is registered to the virtual camera
(camera_info's size, stamp and frame), 16UC1 little-endian millimetres or image_transport's
compressedDepth PNG, and shows the filmed person at the ground truth's depth."""

from __future__ import annotations

import io
import struct
from pathlib import Path
from typing import Any

import numpy as np
import pytest
from cmu_data import needs_data
from mcap_check import check_mcap
from pose_lifter import cli
from pose_lifter.messages import names
from pose_lifter.mocap import scenes
from pose_lifter.mocap.depth_model import REALISTIC

REPO = Path(__file__).resolve().parents[2]
RGBD_BAG = REPO / "bags" / "rgbd" / "punch_rgbd.mcap"


def _decoded(path: Path) -> dict[str, list[Any]]:
    """Every message of a bag per topic, decoded by mcap-ros2-support, in log order."""
    from mcap.reader import make_reader
    from mcap_ros2.decoder import DecoderFactory

    out: dict[str, list[Any]] = {}
    with open(path, "rb") as f:
        reader = make_reader(f, decoder_factories=[DecoderFactory()])
        for _s, channel, _m, msg in reader.iter_decoded_messages():
            out.setdefault(channel.topic, []).append(msg)
    return out


def _stamp(msg: Any) -> int:
    return int(msg.header.stamp.sec) * 1_000_000_000 + int(msg.header.stamp.nanosec)


def _raw_mm(img: Any) -> np.ndarray:
    assert img.encoding == "16UC1" and img.is_bigendian == 0 and img.step == 2 * img.width
    return np.frombuffer(bytes(img.data), dtype="<u2").reshape(img.height, img.width)


def _compressed_mm(img: Any) -> np.ndarray:
    from PIL import Image

    assert img.format == "16UC1; compressedDepth png"
    data = bytes(img.data)
    assert struct.unpack("<iff", data[:12]) == (0, 0.0, 0.0)  # ConfigHeader: INV_DEPTH, no quantisation
    png = data[12:]
    assert png[:8] == b"\x89PNG\r\n\x1a\n" and png[24] == 16 and png[25] == 0  # 16-bit grayscale
    return np.asarray(Image.open(io.BytesIO(png)), dtype=np.uint16)


def _check_registered(msgs: dict[str, list[Any]], topic: str, decode: Any) -> list[np.ndarray]:
    """The depth images match camera_info frame by frame; returns them (mm)."""
    infos, depths, truth = msgs[names.TOPIC_CAMERA_INFO], msgs[topic], msgs[names.TOPIC_GROUND_TRUTH]
    assert len(depths) == len(infos) == len(truth) > 0
    images = []
    for info, img, gt in zip(infos, depths, truth, strict=True):
        assert _stamp(img) == _stamp(info) and img.header.frame_id == info.header.frame_id
        mm = decode(img)
        assert mm.shape == (info.height, info.width)
        # readings within the sensor's range, holes as 0
        reading = mm > 0
        assert 0.5 < reading.mean() < 0.99
        assert mm[reading].min() >= 1000 * REALISTIC.min_range_m and mm.max() <= 1000 * REALISTIC.max_range_m
        # the person at the ground truth's depth: the torso between the hips and shoulders
        joints = np.array([[p.x, p.y, p.z] for p in gt.skeletons[0].joints])
        k = np.asarray(info.k).reshape(3, 3)
        mid = 0.5 * (joints[[0, 3]].mean(axis=0) + joints[[6, 9]].mean(axis=0))
        u, v = (k @ mid)[:2] / mid[2]
        patch = mm[int(v) - 3:int(v) + 4, int(u) - 3:int(u) + 4]
        surface = np.median(patch[patch > 0]) / 1000.0
        assert mid[2] - 0.25 < surface < mid[2]  # the torso's front surface, in front of its axis
        images.append(mm)
    return images


def test_committed_rgbd_bag_is_registered_to_the_camera() -> None:
    counts = check_mcap(RGBD_BAG)
    assert counts == {names.TOPIC_CAMERA_INFO: 4, names.TOPIC_KEYPOINTS: 4, names.TOPIC_GROUND_TRUTH: 4,
                      names.TOPIC_DEPTH: 4}
    msgs = _decoded(RGBD_BAG)
    images = _check_registered(msgs, names.TOPIC_DEPTH, _raw_mm)
    assert not np.array_equal(images[0], images[1])  # a new sensor draw each frame
    # a static wall 2.5 m behind the person: the top corner's median is the same on every frame
    truth = np.array([[[p.x, p.y, p.z] for p in m.skeletons[0].joints]
                      for m in msgs[names.TOPIC_GROUND_TRUTH]])
    corner = [np.median(mm[:40, :40][mm[:40, :40] > 0]) / 1000.0 for mm in images]
    np.testing.assert_allclose(corner, truth[..., 2].mean() + 2.5, atol=0.01)
    assert RGBD_BAG.stat().st_size < 2_000_000


@needs_data
def test_make_bag_depth_raw_and_compressed_carry_the_same_image(tmp_path: Path) -> None:
    common = ["make-bag", "07_05", "--frames", "3", "--distance", "3", "--noise", "0.05", "--seed", "4",
              "--depth"]
    raw, comp = tmp_path / "raw.mcap", tmp_path / "comp.mcap"
    assert cli.main([*common, "--out", str(raw)]) == 0
    assert cli.main([*common, "--depth-format", "compressed", "--out", str(comp)]) == 0
    assert check_mcap(comp) == {names.TOPIC_CAMERA_INFO: 3, names.TOPIC_KEYPOINTS: 3,
                                names.TOPIC_GROUND_TRUTH: 3, names.TOPIC_DEPTH_COMPRESSED: 3}
    a = _check_registered(_decoded(raw), names.TOPIC_DEPTH, _raw_mm)
    b = _check_registered(_decoded(comp), names.TOPIC_DEPTH_COMPRESSED, _compressed_mm)
    for x, y in zip(a, b, strict=True):
        assert np.array_equal(x, y)  # the scene's seed decides the sensor's draws; PNG is lossless
    # a bag without --depth has no depth topic, and the 2D does not depend on it
    plain = tmp_path / "plain.mcap"
    assert cli.main([*common[:-1], "--out", str(plain)]) == 0
    assert names.TOPIC_DEPTH not in check_mcap(plain)
    kp = [m.skeletons[0].keypoints[5].x for m in _decoded(plain)[names.TOPIC_KEYPOINTS]]
    assert kp == [m.skeletons[0].keypoints[5].x for m in _decoded(raw)[names.TOPIC_KEYPOINTS]]


@needs_data
def test_make_bag_depth_with_a_close_following_camera(tmp_path: Path) -> None:
    out = tmp_path / "near.mcap"
    assert cli.main(["make-bag", "02_05", "--start", "3", "--frames", "2", "--distance", "1.5", "--depth",
                     "--out", str(out)]) == 0
    _check_registered(_decoded(out), names.TOPIC_DEPTH, _raw_mm)


def test_depth_to_mm_and_a_bad_format() -> None:
    mm = scenes.depth_to_mm(np.array([[np.nan, 0.0004, 1.2344, 70.0]], dtype=np.float32))
    assert mm.dtype == np.uint16 and mm.tolist() == [[0, 0, 1234, 0]]
    sc = scenes.build_scene([np.zeros((2, 12, 3)) + np.arange(12)[:, None] * 0.1], scenes.SceneOptions())
    with pytest.raises(ValueError, match="'rvl'"):
        list(scenes.scene_messages(sc, depth="rvl"))  # type: ignore[arg-type]
