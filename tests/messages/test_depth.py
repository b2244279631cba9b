"""pose_lifter.messages.depth: depth images read from each encoding (against messages built
independently: the rosbags typestore's serialiser, Pillow's PNG of image_transport's layout), each
bad input refused with its kind, and the depth buffer's pairing."""

from __future__ import annotations

import io
import struct
import tracemalloc
from types import SimpleNamespace
from typing import Any

import numpy as np
import pytest
from PIL import Image
from pose_lifter.messages.depth import (
    _MM_TO_M,
    MAX_DEPTH_PIXELS,
    DepthBuffer,
    DepthError,
    DepthFault,
    PairFault,
    check_depth_size,
    check_held,
    compressed_depth_image,
    decode_compressed_image_cdr,
    decode_image_cdr,
    depth_image,
    is_compressed_topic,
    read_depth,
)
from pose_lifter.messages.names import COMPRESSED_IMAGE, IMAGE, TOPIC_DEPTH, TOPIC_DEPTH_COMPRESSED
from pose_lifter.messages.typestore import message_factory, pose_lifter_typestore
from tolerances import FLOAT32_REL

H, W = 48, 64
STORE = pose_lifter_typestore()


def _millimetres(seed: int = 0) -> np.ndarray:
    """A uint16 depth image (H, W) of 0.5-6 m in millimetres with 10 % holes (0)."""
    rng = np.random.default_rng(seed)
    mm = rng.integers(500, 6000, (H, W)).astype(np.uint16)
    mm[rng.random((H, W)) < 0.1] = 0
    return mm


def _image_cdr(pixels: np.ndarray, encoding: str, big: bool = False, pad: int = 0) -> bytes:
    """A serialised sensor_msgs/Image of ``pixels`` (rows padded by ``pad`` bytes), written by
    rosbags' serialiser."""
    h, w = pixels.shape
    rows = pixels.astype(pixels.dtype.newbyteorder(">" if big else "<")).view(np.uint8).reshape(h, -1)
    data = np.concatenate([rows, np.full((h, pad), 0xAB, dtype=np.uint8)], axis=1).ravel()
    msg = message_factory(IMAGE, STORE)(height=h, width=w, encoding=encoding, is_bigendian=int(big),
                                        step=rows.shape[1] + pad, data=data)
    msg.header.stamp.sec, msg.header.stamp.nanosec, msg.header.frame_id = 7, 42, "camera_color_optical_frame"
    return bytes(STORE.serialize_cdr(msg, IMAGE))


def _png(pixels: np.ndarray) -> bytes:
    out = io.BytesIO()
    Image.fromarray(pixels).save(out, format="PNG")
    return out.getvalue()


def _compressed(fmt: str, payload: bytes) -> SimpleNamespace:
    return SimpleNamespace(format=fmt, data=payload)


def _config_header(a: float = 0.0, b: float = 0.0, kind: int = 0) -> bytes:
    """compressed_depth_image_transport's ConfigHeader: int32 format, float32 depthParam[2]."""
    return struct.pack("<iff", kind, a, b)


def _refused(fault: DepthFault, read: Any, *args: Any, **kwargs: Any) -> str:
    with pytest.raises(DepthError) as info:
        read(*args, **kwargs)
    assert info.value.fault is fault, str(info.value)
    text = str(info.value)
    assert "\n" not in text and text
    return text


# ------------------------------------------------------------------ encodings


@pytest.mark.parametrize("big", [False, True])
@pytest.mark.parametrize("pad", [0, 6])
@pytest.mark.parametrize("encoding", ["16UC1", "mono16"])
def test_16uc1_round_trip(encoding: str, big: bool, pad: int) -> None:
    mm = _millimetres()
    data = _image_cdr(mm, encoding, big, pad)
    decoded = decode_image_cdr(data)
    assert (decoded.header.stamp.sec, decoded.header.stamp.nanosec) == (7, 42)
    assert decoded.header.frame_id == "camera_color_optical_frame"
    from_rosbags = STORE.deserialize_cdr(data, IMAGE)
    for msg in (decoded, from_rosbags):
        depth = depth_image(msg)
        assert depth.dtype == np.float32 and depth.shape == (H, W)
        np.testing.assert_allclose(depth[mm > 0], mm[mm > 0] / 1000.0, rtol=FLOAT32_REL)
        assert np.isnan(depth[mm == 0]).all()


@pytest.mark.parametrize("big", [False, True])
@pytest.mark.parametrize("pad", [0, 6])
def test_16uc1_kept_in_millimetres(big: bool, pad: int) -> None:
    """``millimetres=True``: a 16-bit image (raw or compressedDepth) as its uint16 millimetres in
    native order, whose metres are the float32 image's: an array of its own, or a read-only view
    of bytes nothing can change (``bytes``, native and unpadded); a 32FC1 image stays float32
    metres."""
    mm = _millimetres(8)
    frozen = _image_cdr(mm, "16UC1", big, pad)
    view = read_depth(decode_image_cdr(frozen), millimetres=True)
    np.testing.assert_array_equal(view, mm)
    shared = np.shares_memory(view, np.frombuffer(frozen, dtype=np.uint8))
    assert shared == (not big and not pad) and view.flags.writeable == (not shared) and view.dtype.isnative
    data = bytearray(frozen)
    for msg in (STORE.deserialize_cdr(bytes(data), IMAGE), decode_image_cdr(data)):
        kept = read_depth(msg, millimetres=True)
        assert kept.dtype == np.uint16 and kept.dtype.isnative and kept.flags.c_contiguous
        np.testing.assert_array_equal(kept, mm)
        np.testing.assert_array_equal(_MM_TO_M[kept], depth_image(msg))
    data[-2 * W * H:] = bytes(2 * W * H)  # the bytes the decoded message views reused: the image is its own
    np.testing.assert_array_equal(kept, mm)
    png = _compressed("16UC1; compressedDepth png", _config_header() + _png(mm))
    np.testing.assert_array_equal(read_depth(png, millimetres=True), mm)
    metres = mm.astype(np.float32) / np.float32(1000.0)
    assert read_depth(decode_image_cdr(_image_cdr(metres, "32FC1")), millimetres=True).dtype == np.float32
    # refused as the metres are: a 16UC1 image written in metres
    _refused(DepthFault.RANGE, read_depth, decode_image_cdr(_image_cdr((mm // 1000).astype(np.uint16),
                                                                       "16UC1")), millimetres=True)


def test_32fc1_round_trip_no_reading_values() -> None:
    metres = _millimetres(1).astype(np.float32) / 1000.0
    bad = np.zeros((H, W), dtype=bool)
    for k, value in enumerate([np.nan, np.inf, -np.inf, 0.0, -1.5]):
        metres[k, :5] = value
        bad[k, :5] = True
    bad |= metres == 0
    depth = depth_image(STORE.deserialize_cdr(_image_cdr(metres, "32FC1", pad=4), IMAGE))
    np.testing.assert_array_equal(depth[~bad], metres[~bad])
    assert np.isnan(depth[bad]).all()
    # big endian too
    np.testing.assert_array_equal(depth_image(decode_image_cdr(_image_cdr(metres, "32FC1", big=True)))[~bad],
                                  metres[~bad])


def test_compressed_depth_16uc1() -> None:
    mm = _millimetres(2)
    msg = _compressed("16UC1; compressedDepth png", _config_header() + _png(mm))
    depth = compressed_depth_image(msg)
    np.testing.assert_allclose(depth[mm > 0], mm[mm > 0] / 1000.0, rtol=FLOAT32_REL)
    assert np.isnan(depth[mm == 0]).all()
    # the older formats (no compression named, or the encoding alone) are png too
    for fmt in ("16UC1; compressedDepth", "16UC1"):
        np.testing.assert_array_equal(compressed_depth_image(_compressed(fmt, msg.data)), depth)


def test_compressed_depth_32fc1_inverse_depth() -> None:
    """The 32FC1 layout of codec.cpp: q = A / d + B (0 beyond depth_max), d = A / (q - B)."""
    depth_max, z0 = 10.0, 100.0  # the publisher's defaults (depth_max, depth_quantization)
    a = np.float32(z0 * (z0 + 1.0))
    b = np.float32(1.0 - a / np.float32(depth_max))
    metres = _millimetres(3).astype(np.float32) / 1000.0
    metres[metres == 0] = np.nan
    metres[0, :3] = 12.0  # beyond depth_max: no reading
    q = np.where(metres < depth_max, a / metres + b, 0).astype(np.uint16)
    ros = STORE.deserialize_cdr(STORE.serialize_cdr(message_factory(COMPRESSED_IMAGE, STORE)(
        format="32FC1; compressedDepth png", data=np.frombuffer(_config_header(a, b) + _png(q), np.uint8)),
        COMPRESSED_IMAGE), COMPRESSED_IMAGE)
    depth = read_depth(ros)
    valid = q > 0
    np.testing.assert_allclose(depth[valid], float(a) / (q[valid] - float(b)), rtol=FLOAT32_REL)
    assert np.isnan(depth[~valid]).all() and np.isnan(depth[0, :3]).all()
    # within one quantisation step (d^2 / A, and the float32 round-off of q) of the publisher's depth
    ok = valid & np.isfinite(metres)
    assert (np.abs(depth[ok] - metres[ok]) <= 1.001 * metres[ok] ** 2 / a).all()


def test_compressed_image_cdr_decoded() -> None:
    mm = _millimetres(4)
    payload = np.frombuffer(_config_header() + _png(mm), np.uint8)
    msg = message_factory(COMPRESSED_IMAGE, STORE)(format="16UC1; compressedDepth png", data=payload)
    msg.header.stamp.sec = 3
    decoded = decode_compressed_image_cdr(bytes(STORE.serialize_cdr(msg, COMPRESSED_IMAGE)))
    assert decoded.header.stamp.sec == 3 and decoded.format == msg.format
    np.testing.assert_array_equal(read_depth(decoded), compressed_depth_image(msg))


def test_topic_transport() -> None:
    assert is_compressed_topic(TOPIC_DEPTH_COMPRESSED) and not is_compressed_topic(TOPIC_DEPTH)


# ------------------------------------------------------------------ bad input


@pytest.mark.parametrize("encoding", ["rgb8", "8UC1", "mono8", "bgr16", "32FC3", ""])
def test_unsupported_encoding(encoding: str) -> None:
    msg = SimpleNamespace(height=H, width=W, encoding=encoding, is_bigendian=0, step=W * 2,
                          data=bytes(H * W * 4))
    assert encoding[:5] in _refused(DepthFault.ENCODING, depth_image, msg)


def test_size_against_camera_info() -> None:
    depth = np.ones((H, W), dtype=np.float32)
    assert check_depth_size(depth, (float(W), float(H))) is depth
    assert "64x48" in _refused(DepthFault.SIZE, check_depth_size, depth, (1280.0, 720.0))
    _refused(DepthFault.SIZE, check_depth_size, depth, (float(H), float(W)))  # transposed
    _refused(DepthFault.NO_CAMERA_INFO, check_depth_size, depth, None)


@pytest.mark.parametrize("encoding", ["16UC1", "32FC1"])
def test_no_readings(encoding: str) -> None:
    dtype = np.uint16 if encoding == "16UC1" else np.float32
    zeros = np.zeros((H, W), dtype=dtype)
    _refused(DepthFault.NO_READINGS, depth_image, decode_image_cdr(_image_cdr(zeros, encoding)))
    if encoding == "32FC1":
        _refused(DepthFault.NO_READINGS, depth_image,
                 decode_image_cdr(_image_cdr(np.full((H, W), np.nan, np.float32), encoding)))
    # one reading off the sampled grid is a reading
    zeros[5, 5] = 2000 if encoding == "16UC1" else 2.0
    assert np.isfinite(depth_image(decode_image_cdr(_image_cdr(zeros, encoding)))).sum() == 1


def test_absurd_range() -> None:
    in_metres = (_millimetres(5) // 1000).astype(np.uint16)  # 16UC1 written in metres: 0-5
    assert "metres" in _refused(DepthFault.RANGE, depth_image,
                                decode_image_cdr(_image_cdr(in_metres, "16UC1")))
    in_mm = _millimetres(6).astype(np.float32)  # 32FC1 written in millimetres
    assert "millimetres" in _refused(DepthFault.RANGE, depth_image,
                                     decode_image_cdr(_image_cdr(in_mm, "32FC1")))
    # the same images in their units are fine
    depth_image(decode_image_cdr(_image_cdr(_millimetres(5), "16UC1")))
    depth_image(decode_image_cdr(_image_cdr(in_mm / 1000.0, "32FC1")))


def test_short_buffer_and_step() -> None:
    data = _millimetres().tobytes()
    msg = SimpleNamespace(height=H, width=W, encoding="16UC1", is_bigendian=0, step=W * 2, data=data[:-1])
    assert str(H * W * 2) in _refused(DepthFault.SHORT, depth_image, msg)
    _refused(DepthFault.SHORT, depth_image, SimpleNamespace(**{**vars(msg), "data": data, "step": W}))
    # a serialised message cut inside its data
    whole = _image_cdr(_millimetres(), "16UC1")
    _refused(DepthFault.SHORT, depth_image, decode_image_cdr(whole[:-100]))
    _refused(DepthFault.SHORT, decode_image_cdr, whole[:30])


def test_huge_image_refused_before_allocation() -> None:
    side = 1 + int(np.sqrt(MAX_DEPTH_PIXELS))
    msg = SimpleNamespace(height=side, width=side, encoding="16UC1", is_bigendian=0, step=2 * side,
                          data=bytes(16))
    tracemalloc.start()
    try:
        text = _refused(DepthFault.TOO_LARGE, depth_image, msg)
        peak = tracemalloc.get_traced_memory()[1]
    finally:
        tracemalloc.stop()
    assert "MAX_DEPTH_PIXELS" in text and peak < 1 << 20
    # nor held for pairing (the node's buffer), nor a compressed payload larger than such an image
    _refused(DepthFault.TOO_LARGE, check_held, msg)
    _refused(DepthFault.TOO_LARGE, check_held, _compressed("16UC1; compressedDepth png", bytes(4 * 100 + 1)),
             max_pixels=100)
    small = SimpleNamespace(**{**vars(msg), "height": 480, "width": 640})
    assert check_held(small) is small
    # a PNG whose header says too many pixels is refused before it is decoded
    payload = _config_header() + _png(_millimetres())
    _refused(DepthFault.TOO_LARGE, compressed_depth_image, _compressed("16UC1; compressedDepth png", payload),
             max_pixels=H * W - 1)


def test_corrupt_compressed_depth() -> None:
    mm = _millimetres(7)
    png = _png(mm)
    fmt = "16UC1; compressedDepth png"
    cases = {
        "short": _config_header()[:8],
        "unknown header format": _config_header(kind=3) + png,
        "no PNG": _config_header() + b"JFIF" + png[4:],
        "truncated PNG": _config_header() + png[: len(png) // 2],
        "8-bit PNG": _config_header() + _png((mm // 256).astype(np.uint8)),
        "broken PNG data": _config_header() + png[:60] + bytes(len(png) - 60),
    }
    for what, payload in cases.items():
        with pytest.raises(DepthError) as info:
            compressed_depth_image(_compressed(fmt, payload))
        assert info.value.fault is DepthFault.CORRUPT, (what, str(info.value))
    nan_header = _config_header(float("nan"), 1.0) + png
    _refused(DepthFault.CORRUPT, compressed_depth_image,
             _compressed("32FC1; compressedDepth png", nan_header))


@pytest.mark.parametrize("fmt", ["16UC1; compressedDepth rvl", "bgr8; jpeg compressed bgr8",
                                 "rgb8; compressedDepth png", "16UC1; png compressed mono16"])
def test_compressed_formats_refused(fmt: str) -> None:
    text = _refused(DepthFault.ENCODING, compressed_depth_image,
                    _compressed(fmt, _config_header() + _png(_millimetres())))
    if "rvl" in fmt:
        assert "png" in text


# ------------------------------------------------------------------ the buffer


def test_buffer_nearest_within_tolerance() -> None:
    buf: DepthBuffer[str] = DepthBuffer(capacity=4, tolerance_ns=10)
    assert buf.pair(100).fault is PairFault.NONE_YET
    for stamp in (100, 133, 166):
        buf.push(stamp, f"d{stamp}")
    assert buf.pair(120).fault is PairFault.GAP  # 20 and 13 away
    got = buf.pair(128)
    assert (got.image, got.fault, got.gap_ns) == ("d133", None, 5)
    assert buf.pair(143).image == "d133" and buf.pair(156).image == "d166"  # exactly the tolerance
    assert buf.pair(144).fault is PairFault.GAP  # 11 from both: never paired outside the tolerance
    assert buf.pair(149).fault is PairFault.GAP  # 16 and 17 away
    buf.push(150, "d150")
    assert buf.pair(149).image == "d150"
    tie: DepthBuffer[str] = DepthBuffer(2, 10)
    tie.push(10, "a")
    tie.push(20, "b")
    assert tie.pair(15).image == "a"  # a tie goes to the older image


def test_buffer_too_old_too_new_and_counts() -> None:
    buf: DepthBuffer[int] = DepthBuffer(capacity=3, tolerance_ns=5)
    assert buf.pair(0).fault is PairFault.NONE_YET
    for stamp in (100, 110, 120):
        buf.push(stamp, stamp)
    old = buf.pair(1000)
    assert old.fault is PairFault.TOO_OLD and old.gap_ns == 120 - 1000 and "-0.000" in old.reason()
    new = buf.pair(50)
    assert new.fault is PairFault.TOO_NEW and new.gap_ns == 50
    assert buf.pair(112).image == 110
    assert buf.paired == 1
    assert buf.unpaired == {PairFault.NONE_YET: 1, PairFault.TOO_OLD: 1, PairFault.TOO_NEW: 1}


def test_buffer_capacity_and_out_of_order_stamps() -> None:
    buf: DepthBuffer[int] = DepthBuffer(capacity=3, tolerance_ns=2)
    for stamp in (30, 10, 40, 20, 50):  # out of order: the newest three stamps are kept
        buf.push(stamp, stamp)
    assert len(buf) == 3 and buf.newest_ns == 50
    assert [buf.pair(s).image for s in (30, 40, 50)] == [30, 40, 50]
    assert buf.pair(10).fault is PairFault.TOO_NEW and buf.pair(20).fault is PairFault.TOO_NEW
    buf.push(5, 5)  # older than everything held: dropped at once
    assert len(buf) == 3 and buf.pair(5).fault is PairFault.TOO_NEW
    buf.push(40, -40)  # the same stamp again: replaced
    assert buf.pair(40).image == -40 and len(buf) == 3
    buf.clear()
    assert len(buf) == 0 and buf.pair(40).fault is PairFault.NONE_YET


def test_buffer_arguments() -> None:
    with pytest.raises(ValueError):
        DepthBuffer(0, 1)
    with pytest.raises(ValueError):
        DepthBuffer(1, -1)
