"""Depth images in: ``sensor_msgs/Image`` and image_transport's ``compressedDepth`` read into the
package's depth image, the checks of what a depth camera sends, and the pairing of each
keypoints frame with the depth image of its stamp.

The package's depth image is a ``float32`` array (H, W) of metres along the optical axis, NaN
where there is no reading; pixel (u, v) is ``depth[v, u]``. Read with ``millimetres=True`` (the
node and the offline lift), a 16-bit image stays uint16 millimetres, 0 where there is no reading
(:data:`~pose_lifter.core.depth.reading.DepthArray`; a read-only view of the message's bytes
where they are read-only, e.g. ``bytes``, else a copy of its own): the fusion reads a few patches
of it, each pixel as the float32 metres the conversion would give, so the whole image is never
converted.

Encodings read (:func:`depth_image`):

* ``16UC1``: millimetres, 0 = no reading (RealSense, OAK-D, Orbbec, Azure Kinect);
* ``mono16``: read as ``16UC1``. No major driver publishes depth so, but hand-written RealSense
  publishers do (``cv_bridge.cv2_to_imgmsg(np.asanyarray(depth_frame.get_data()), "mono16")``,
  the z16 millimetres of pyrealsense2, seen in several public ROS 2 nodes);
* ``32FC1``: metres, NaN, +-inf, 0 and negative values = no reading (ZED, depth_image_proc).

``sensor_msgs/CompressedImage`` in image_transport's ``compressedDepth`` format
(:func:`compressed_depth_image`), as ros-perception/image_transport_plugins writes it
(``compressed_depth_image_transport/src/codec.cpp``, ``encodeCompressedDepthImage``, and the
``ConfigHeader`` of ``include/compressed_depth_image_transport/compression_common.hpp``):
``format`` is ``"<encoding>; compressedDepth png"`` (older publishers: ``"<encoding>;
compressedDepth"`` or the encoding alone), ``data`` a 12-byte ``ConfigHeader`` (int32 ``format``,
0 = ``INV_DEPTH``; float32 ``depthParam[2]`` = ``depthQuantA, depthQuantB``, native little
endian) followed by a 16-bit greyscale PNG. For ``16UC1`` the PNG holds the millimetres; for
``32FC1`` a quantised inverse depth ``q`` (0 = no reading), depth = ``A / (q - B)`` metres. The
PNG is decoded with Pillow. The ``compressedDepth rvl`` format is refused (republish it with
``png``).

Every refusal is a :class:`DepthError` whose :attr:`~DepthError.fault` (:class:`DepthFault`)
says which kind, in one line; the caller warns once per kind and lifts the frame from the 2D
alone. The pixel count is checked against :data:`MAX_DEPTH_PIXELS` before anything is
allocated. Messages are read by attribute name (rclpy and rosbags classes alike, or the
records :func:`decode_image_cdr` and :func:`decode_compressed_image_cdr` read straight from
the serialised bytes, the data a view of them). No rclpy.

:class:`DepthBuffer` pairs a keypoints frame with the image of the nearest stamp within a
tolerance (the smallest correct message_filters ApproximateTime for two topics, one of which
waits for the other).
"""

from __future__ import annotations

import bisect
import io
import struct
from collections import Counter
from dataclasses import dataclass
from enum import StrEnum
from typing import TYPE_CHECKING, Any, Final, Generic, NamedTuple, TypeVar

import numpy as np
from numpy.typing import NDArray

from pose_lifter.core.errors import InvalidInputError
from pose_lifter.core.numeric.jit import HAVE_NUMBA, njit_nogil
from pose_lifter.messages.cdr import DecodedHeader, DecodedStamp

if TYPE_CHECKING:  # the fusion (numba, the placement) is loaded with the first lift, not here
    from pose_lifter.core.depth.reading import DepthArray

__all__ = [
    "COMPRESSED_SUFFIX",
    "MAX_DEPTH_PIXELS",
    "MAX_MEDIAN_M",
    "MIN_MEDIAN_M",
    "DecodedCompressedImage",
    "DecodedImage",
    "DepthBuffer",
    "DepthError",
    "DepthFault",
    "PairFault",
    "Pairing",
    "camera_info_missing",
    "check_depth_size",
    "check_held",
    "compressed_depth_image",
    "decode_compressed_image_cdr",
    "decode_image_cdr",
    "depth_image",
    "is_compressed_topic",
    "read_depth",
    "warm_up",
]

#: Pixels of a depth image at most (4096 x 4096, 64 MiB as float32): a larger one is refused
#: before any array is allocated.
MAX_DEPTH_PIXELS: Final[int] = 4096 * 4096
#: The median of an image's readings below this (metres) is absurd: a 16UC1 image written in
#: metres (every person closer than any depth camera's minimum range).
MIN_MEDIAN_M: Final[float] = 0.1
#: The median of an image's readings above this (metres) is absurd: a 32FC1 image written in
#: millimetres (beyond any depth camera's range).
MAX_MEDIAN_M: Final[float] = 100.0
#: image_transport's topic suffix of the compressedDepth transport.
COMPRESSED_SUFFIX: Final[str] = "/compressedDepth"
#: Every 16th row and column are read to judge an image's range (median of the readings).
_RANGE_STRIDE: Final[int] = 16
_CONFIG_HEADER: Final = struct.Struct("<iff")  # compressedDepth's ConfigHeader
_INV_DEPTH: Final[int] = 0
_PNG_MAGIC: Final[bytes] = b"\x89PNG\r\n\x1a\n"
#: uint16 millimetres -> float32 metres, 0 -> NaN (one gather: cheaper than a multiply and a mask)
_MM_TO_M: Final[NDArray[np.float32]] = np.arange(65536, dtype=np.float32) / np.float32(1000.0)
_MM_TO_M[0] = np.nan
_MM_TO_M.flags.writeable = False
_SIXTEEN_BIT: Final[frozenset[str]] = frozenset({"16UC1", "mono16"})
_ENCODINGS: Final[str] = "16UC1 (millimetres), 32FC1 (metres) or mono16 (as 16UC1)"


class DepthFault(StrEnum):
    """Why a depth image is refused (the short kind a node counts and warns once per period)."""

    ENCODING = "depth: unsupported encoding"
    SIZE = "depth: size differs from camera_info"
    NO_CAMERA_INFO = "depth: no camera_info"
    NO_READINGS = "depth: no readings"
    RANGE = "depth: absurd range"
    SHORT = "depth: data shorter than step * height"
    TOO_LARGE = "depth: image too large"
    CORRUPT = "depth: corrupt compressedDepth"


class DepthError(InvalidInputError):
    """A depth image the lift cannot use; :attr:`fault` says which kind, the message why in one line."""

    def __init__(self, fault: DepthFault, text: str) -> None:
        super().__init__(text)
        self.fault = fault


# --------------------------------------------------------------------------- reading


def _size(height: Any, width: Any, max_pixels: int) -> tuple[int, int]:
    """(height, width) as ints, checked: positive, at most ``max_pixels`` pixels."""
    h, w = int(height), int(width)
    if h <= 0 or w <= 0:
        raise DepthError(DepthFault.NO_READINGS, f"depth image of {w}x{h} pixels: empty")
    if h * w > max_pixels:
        raise DepthError(DepthFault.TOO_LARGE, f"depth image of {w}x{h} pixels, more than the "
                         f"{max_pixels} pixels a depth image may have (MAX_DEPTH_PIXELS)")
    return h, w


def _metres(depth: DepthArray) -> NDArray[np.float32]:
    """``depth`` as float32 metres, NaN where no reading (uint16 millimetres converted)."""
    if depth.dtype == np.uint16:
        return np.take(_MM_TO_M, np.asarray(depth, dtype=np.intp))
    return np.asarray(depth, dtype=np.float32)


def _checked_readings(depth: DepthArray, encoding: str) -> DepthArray:
    """``depth`` (float32 metres, or uint16 millimetres) refused when it holds no reading, or when
    the median of its readings in metres (every :data:`_RANGE_STRIDE`-th row and column; all of
    them when those hold none) is absurd."""
    sample = _metres(depth[::_RANGE_STRIDE, ::_RANGE_STRIDE])
    valid = sample[np.isfinite(sample)]
    if not valid.size:
        metres = _metres(depth)
        valid = metres[np.isfinite(metres)]
        if not valid.size:
            raise DepthError(DepthFault.NO_READINGS, f"{encoding} depth image of {depth.shape[1]}x"
                             f"{depth.shape[0]} pixels without a single reading (all 0 or NaN)")
    median = float(np.median(valid))
    if median < MIN_MEDIAN_M:
        hint = " (written in metres? 16UC1 holds millimetres)" if encoding in _SIXTEEN_BIT else ""
        raise DepthError(DepthFault.RANGE, f"{encoding} depth image whose median reading is {median:.4g} m, "
                         f"closer than {MIN_MEDIAN_M} m{hint}")
    if median > MAX_MEDIAN_M:
        hint = " (written in millimetres? 32FC1 holds metres)" if encoding == "32FC1" else ""
        raise DepthError(DepthFault.RANGE, f"{encoding} depth image whose median reading is {median:.4g} m, "
                         f"farther than {MAX_MEDIAN_M:g} m{hint}")
    return depth


@njit_nogil
def _millimetres_kernel(raw: NDArray[np.uint16], out: NDArray[np.float32]) -> None:  # pragma: no cover
    """``out[i, j]`` = ``raw[i, j]`` / 1000 as float32 (correctly rounded, as :data:`_MM_TO_M`),
    NaN where it is 0."""
    h, w = raw.shape
    for i in range(h):
        for j in range(w):
            v = raw[i, j]
            out[i, j] = np.float32(v) / np.float32(1000.0) if v else np.float32(np.nan)


def _sixteen_bit(raw: NDArray[np.uint16], millimetres: bool = False) -> DepthArray:
    """uint16 millimetres (H, W), any strides or byte order -> float32 metres, 0 -> NaN (the
    compiled kernel: 640x480 in ~0.06 ms; without numba a table look-up, ~0.4 ms); with
    ``millimetres``, the millimetres kept: ``raw`` itself when it is a native, C-ordered view of
    read-only bytes (the CDR decoders' views of ``bytes``, which nothing can change), else a
    native, C-ordered copy of its own (~0.015 ms)."""
    if millimetres:
        if not raw.flags.writeable and raw.dtype.isnative and raw.flags.c_contiguous:
            return raw
        return np.array(raw, dtype=np.uint16, order="C")
    if not raw.dtype.isnative:
        raw = raw.astype(np.uint16)
    if not HAVE_NUMBA:
        return np.take(_MM_TO_M, raw)
    out = np.empty(raw.shape, dtype=np.float32)
    _millimetres_kernel(raw, out)
    return out


def warm_up() -> None:
    """Compile (or load from their cache) the millimetre kernel and the fusion's
    (:func:`pose_lifter.core.depth.fuse.compile_kernels`), so that no frame pays for them."""
    from pose_lifter.core.depth.fuse import compile_kernels

    _sixteen_bit(np.ones((1, 1), dtype=np.uint16))
    compile_kernels()


def depth_image(msg: Any, max_pixels: int = MAX_DEPTH_PIXELS, millimetres: bool = False) -> DepthArray:
    """A ``sensor_msgs/Image`` (``height``, ``width``, ``encoding``, ``is_bigendian``, ``step``,
    ``data``) as the package's depth image.

    Returns
    -------
    ndarray of float32, shape (height, width)
        Metres, NaN where there is no reading (see the module doc for each encoding). With
        ``millimetres``, a 16-bit encoding's image is uint16 millimetres, 0 where there is no
        reading (:data:`~pose_lifter.core.depth.reading.DepthArray`: the fusion reads its patches
        without converting the whole image).

    Raises
    ------
    DepthError
        Another encoding; more than ``max_pixels`` pixels (before any allocation); ``step`` less
        than a row's bytes or ``data`` shorter than ``step * height``; no reading at all; the
        median reading absurd (:data:`MIN_MEDIAN_M`, :data:`MAX_MEDIAN_M`).
    """
    encoding = str(msg.encoding)
    if encoding in _SIXTEEN_BIT:
        itemsize, kind = 2, "u2"
    elif encoding == "32FC1":
        itemsize, kind = 4, "f4"
    else:
        raise DepthError(DepthFault.ENCODING, f"depth image encoding {encoding[:40]!r} is not a depth "
                         f"encoding: {_ENCODINGS}")
    h, w = _size(msg.height, msg.width, max_pixels)
    step = int(msg.step)
    data = msg.data
    buf = (np.frombuffer(data, dtype=np.uint8) if not isinstance(data, list | tuple)
           else np.asarray(data, dtype=np.uint8))
    if step < w * itemsize:
        raise DepthError(DepthFault.SHORT, f"{encoding} depth image of {w}x{h} pixels with step {step}, "
                         f"less than a row's {w * itemsize} bytes")
    if buf.size < step * h:
        raise DepthError(DepthFault.SHORT, f"{encoding} depth image of {w}x{h} pixels, step {step}: "
                         f"{buf.size} data bytes, fewer than step * height = {step * h}")
    dtype = np.dtype((">" if msg.is_bigendian else "<") + kind)
    raw = np.ndarray((h, w), dtype=dtype, buffer=buf, strides=(step, itemsize))
    depth: DepthArray
    if itemsize == 2:
        depth = _sixteen_bit(raw, millimetres)
    else:
        depth = raw.astype(np.float32)  # a copy, native order
        depth[~(depth > 0.0) | np.isinf(depth)] = np.nan  # NaN, inf, 0, negative: no reading
    return _checked_readings(depth, encoding)


def compressed_depth_image(msg: Any, max_pixels: int = MAX_DEPTH_PIXELS, millimetres: bool = False
                           ) -> DepthArray:
    """A ``sensor_msgs/CompressedImage`` (``format``, ``data``) in image_transport's
    ``compressedDepth`` format (see the module doc) as the package's depth image.

    Returns
    -------
    ndarray of float32, shape (H, W)
        Metres, NaN where there is no reading; with ``millimetres``, a 16-bit encoding's image
        as uint16 millimetres, 0 where there is none (as :func:`depth_image`).

    Raises
    ------
    DepthError
        Another encoding or compression (``rvl`` too); a corrupt payload (short or unknown
        ``ConfigHeader``, a PNG that does not decode, is not 16-bit greyscale, or a 32FC1
        quantisation that is not finite); more than ``max_pixels`` pixels (read from the PNG's
        header, before it is decoded); no reading; an absurd range.
    """
    from PIL import Image

    fmt = str(msg.format)
    encoding, _, compression = (part.strip() for part in fmt.partition(";"))
    if encoding not in _SIXTEEN_BIT and encoding != "32FC1":
        raise DepthError(DepthFault.ENCODING, f"compressed depth format {fmt[:60]!r}: the encoding is not "
                         f"{_ENCODINGS}")
    if compression not in ("", "compressedDepth", "compressedDepth png"):
        what = ("compressedDepth rvl is not read: republish with the png format (the publisher's "
                "format parameter)" if compression.startswith("compressedDepth rvl")
                else "not image_transport's compressedDepth png")
        raise DepthError(DepthFault.ENCODING, f"compressed depth format {fmt[:60]!r}: {what}")
    data = memoryview(msg.data if not isinstance(msg.data, np.ndarray) else msg.data.data).cast("B")
    if len(data) <= _CONFIG_HEADER.size + len(_PNG_MAGIC):
        raise DepthError(DepthFault.CORRUPT, f"compressedDepth payload of {len(data)} bytes: shorter than "
                         "its 12-byte header and a PNG")
    kind, quant_a, quant_b = _CONFIG_HEADER.unpack_from(data, 0)
    if kind != _INV_DEPTH:
        raise DepthError(DepthFault.CORRUPT, f"compressedDepth header of unknown format {kind} (expected "
                         f"{_INV_DEPTH}, INV_DEPTH)")
    png = data[_CONFIG_HEADER.size:]
    if bytes(png[:len(_PNG_MAGIC)]) != _PNG_MAGIC:
        raise DepthError(DepthFault.CORRUPT, "compressedDepth payload: no PNG after its 12-byte header")
    try:
        with Image.open(io.BytesIO(png), formats=["PNG"]) as im:
            _size(im.height, im.width, max_pixels)  # from the PNG header, nothing decoded yet
            if im.mode not in ("I;16", "I;16B", "I"):
                raise DepthError(DepthFault.CORRUPT, f"compressedDepth PNG of mode {im.mode!r}, not 16-bit "
                                 "greyscale")
            raw = np.asarray(im)
    except DepthError:
        raise
    except Image.DecompressionBombError as exc:
        raise DepthError(DepthFault.TOO_LARGE, f"compressedDepth PNG: {exc}"[:200]) from None
    except Exception as exc:  # Pillow's errors of a broken PNG: OSError, SyntaxError, ValueError, ...
        raise DepthError(DepthFault.CORRUPT, f"compressedDepth PNG does not decode: {exc}"[:200]) from None
    if raw.dtype != np.uint16:  # mode "I" (int32) of a 16-bit PNG
        if raw.size and (raw.min() < 0 or raw.max() > 65535):
            raise DepthError(DepthFault.CORRUPT, "compressedDepth PNG with values outside 16 bits")
        raw = raw.astype(np.uint16)
    if encoding != "32FC1":
        return _checked_readings(_sixteen_bit(raw, millimetres), encoding)
    if not (np.isfinite(quant_a) and np.isfinite(quant_b)):
        raise DepthError(DepthFault.CORRUPT, f"compressedDepth header with non-finite quantisation "
                         f"({quant_a}, {quant_b})")
    # codec.cpp: depth = depthQuantA / (q - depthQuantB), q = 0: no reading
    with np.errstate(divide="ignore", invalid="ignore"):
        depth = np.float32(quant_a) / (raw.astype(np.float32) - np.float32(quant_b))
    depth[(raw == 0) | ~(depth > 0.0) | np.isinf(depth)] = np.nan
    return _checked_readings(depth, encoding)


def check_held(msg: Any, max_pixels: int = MAX_DEPTH_PIXELS) -> Any:
    """``msg`` (an ``Image`` or a ``CompressedImage``) when it may be held for pairing, else
    :class:`DepthError`: an image of more than ``max_pixels`` pixels, or a compressed payload of
    more bytes than such an image's float32 pixels (nothing is decoded)."""
    if hasattr(msg, "format"):
        if len(msg.data) > 4 * max_pixels:
            raise DepthError(DepthFault.TOO_LARGE, f"compressed depth image of {len(msg.data)} bytes, more "
                             f"than {4 * max_pixels} (MAX_DEPTH_PIXELS float32 pixels)")
        return msg
    _size(msg.height, msg.width, max_pixels)
    return msg


def read_depth(msg: Any, max_pixels: int = MAX_DEPTH_PIXELS, millimetres: bool = False) -> DepthArray:
    """An ``Image`` (:func:`depth_image`) or a ``CompressedImage`` (it has ``format``:
    :func:`compressed_depth_image`) as the package's depth image (``millimetres``: a 16-bit
    image as uint16 millimetres, see there)."""
    if hasattr(msg, "format"):
        return compressed_depth_image(msg, max_pixels, millimetres)
    return depth_image(msg, max_pixels, millimetres)


def check_depth_size(depth: DepthArray, camera_size: tuple[float, float] | None) -> DepthArray:
    """``depth`` when it has the size of the camera whose ``camera_info`` gave ``camera_size``
    ((width, height) pixels), else :class:`DepthError`: a depth image that is not registered to
    the keypoints' camera (e.g. the raw depth topic instead of the aligned one), or no
    ``camera_info`` at all (None): the depth cannot be placed without the intrinsics."""
    if camera_size is None:
        raise camera_info_missing()
    width, height = round(camera_size[0]), round(camera_size[1])
    if depth.shape != (height, width):
        raise DepthError(DepthFault.SIZE, f"depth image of {depth.shape[1]}x{depth.shape[0]} pixels, "
                         f"camera_info of {width}x{height}: not registered to the keypoints' camera (use "
                         "the depth aligned to the colour image)")
    return depth


def camera_info_missing() -> DepthError:
    """The refusal of a depth image that came before any ``camera_info``."""
    return DepthError(DepthFault.NO_CAMERA_INFO, "a depth image but no camera_info: depth needs the "
                      "intrinsics of the keypoints' camera (remap camera_info)")


def is_compressed_topic(topic: str) -> bool:
    """A depth topic of image_transport's compressedDepth transport (``.../compressedDepth``:
    ``CompressedImage``), else a raw ``Image`` topic."""
    return topic.rstrip("/").endswith(COMPRESSED_SUFFIX)


# --------------------------------------------------------------------------- CDR


@dataclass(frozen=True)
class DecodedImage:
    """A ``sensor_msgs/Image`` read from its CDR bytes (:func:`decode_image_cdr`); ``data`` is a
    view of those bytes."""

    header: DecodedHeader
    height: int
    width: int
    encoding: str
    is_bigendian: int
    step: int
    data: memoryview


@dataclass(frozen=True)
class DecodedCompressedImage:
    """A ``sensor_msgs/CompressedImage`` read from its CDR bytes; ``data`` is a view of them."""

    header: DecodedHeader
    format: str
    data: memoryview


class _Reader:
    """CDR reading: offsets counted from the end of the 4-byte encapsulation header, each
    primitive aligned to its size; little or big endian as the header says."""

    __slots__ = ("buf", "end", "pos")

    def __init__(self, data: Any) -> None:
        self.buf = memoryview(data).cast("B")
        if len(self.buf) < 4 or self.buf[0] != 0 or self.buf[1] not in (0, 1):
            raise DepthError(DepthFault.CORRUPT, "depth message: not CDR")
        self.end = "<" if self.buf[1] == 1 else ">"
        self.pos = 4

    def _take(self, n: int) -> memoryview:
        if self.pos + n > len(self.buf):
            raise DepthError(DepthFault.SHORT, f"depth message of {len(self.buf)} bytes ends inside a field")
        out = self.buf[self.pos:self.pos + n]
        self.pos += n
        return out

    def u32(self) -> int:
        self.pos += -(self.pos - 4) % 4
        return int(struct.unpack(self.end + "I", self._take(4))[0])

    def u8(self) -> int:
        return int(self._take(1)[0])

    def string(self) -> str:
        n = self.u32()
        return bytes(self._take(n)[:-1] if n else b"").decode(errors="replace")

    def header(self) -> DecodedHeader:
        sec = self.u32()
        sec = sec - (1 << 32) if sec >= 1 << 31 else sec  # int32
        return DecodedHeader(DecodedStamp(sec, self.u32()), self.string())


def decode_header_cdr(data: Any) -> DecodedHeader:
    """The ``std_msgs/Header`` that a serialised message (an ``Image``, a ``CompressedImage``)
    starts with, read from its first bytes alone; :class:`DepthError` when they end inside it."""
    return _Reader(data).header()


def decode_image_cdr(data: Any) -> DecodedImage:
    """A serialised ``sensor_msgs/Image`` read into its fields (no copy of the pixels);
    :class:`DepthError` when the bytes end early."""
    r = _Reader(data)
    header = r.header()
    height, width = r.u32(), r.u32()
    encoding = r.string()
    big = r.u8()
    step = r.u32()
    n = r.u32()
    return DecodedImage(header, height, width, encoding, big, step, r._take(min(n, len(r.buf) - r.pos)))


def decode_compressed_image_cdr(data: Any) -> DecodedCompressedImage:
    """A serialised ``sensor_msgs/CompressedImage`` read into its fields (no copy of the payload)."""
    r = _Reader(data)
    header = r.header()
    fmt = r.string()
    n = r.u32()
    return DecodedCompressedImage(header, fmt, r._take(n))


# --------------------------------------------------------------------------- pairing

T = TypeVar("T")


class PairFault(StrEnum):
    """Why a frame has no depth partner."""

    NONE_YET = "no depth image yet"
    TOO_OLD = "depth images all older than the tolerance"
    TOO_NEW = "depth images all newer than the tolerance"
    GAP = "no depth image within the tolerance"


class Pairing(NamedTuple, Generic[T]):
    """A frame's depth partner (``image``; None: none, ``fault`` says why) and the stamp gap
    (ns) to the nearest image held (the partner's; 0 when none is held)."""

    image: T | None
    fault: PairFault | None
    gap_ns: int

    def reason(self) -> str:
        """The fault in words, with the gap (``""`` when paired)."""
        if self.fault is None:
            return ""
        if self.fault is PairFault.NONE_YET:
            return str(self.fault)
        return f"{self.fault} (nearest {self.gap_ns / 1e9:+.3f} s from the frame)"


class DepthBuffer(Generic[T]):
    """The newest depth images by stamp, and each keypoints frame's partner among them.

    Parameters
    ----------
    capacity : int
        Images held at most (the newest stamps; memory is bounded by it).
    tolerance_ns : int
        A frame's partner is the image of the nearest stamp at most this far from the frame's
        (ties: the older image); never one farther.

    Attributes
    ----------
    paired : int
        Frames given a partner.
    unpaired : Counter of PairFault
        Frames without one, by why.
    """

    def __init__(self, capacity: int, tolerance_ns: int) -> None:
        if capacity < 1:
            raise ValueError(f"capacity must be >= 1, got {capacity}")
        if tolerance_ns < 0:
            raise ValueError(f"tolerance_ns must be >= 0, got {tolerance_ns}")
        self.capacity, self.tolerance_ns = capacity, tolerance_ns
        self._stamps: list[int] = []  # increasing
        self._images: list[T] = []
        self.paired = 0
        self.unpaired: Counter[PairFault] = Counter()

    def __len__(self) -> int:
        return len(self._stamps)

    @property
    def newest_ns(self) -> int | None:
        """The newest stamp held (None: none)."""
        return self._stamps[-1] if self._stamps else None

    def push(self, stamp_ns: int, image: T) -> None:
        """Hold ``image`` of ``stamp_ns`` (an image of the same stamp is replaced); beyond
        ``capacity`` the oldest stamp is dropped (this one, if it is the oldest)."""
        k = bisect.bisect_left(self._stamps, stamp_ns)
        if k < len(self._stamps) and self._stamps[k] == stamp_ns:
            self._images[k] = image
            return
        self._stamps.insert(k, stamp_ns)
        self._images.insert(k, image)
        if len(self._stamps) > self.capacity:
            del self._stamps[0], self._images[0]

    def clear(self) -> None:
        """Forget the images (the counts stay)."""
        self._stamps.clear()
        self._images.clear()

    def pair(self, stamp_ns: int) -> Pairing[T]:
        """The partner of a frame of ``stamp_ns`` (counted in :attr:`paired` or :attr:`unpaired`)."""
        out = self._nearest(stamp_ns)
        if out.fault is None:
            self.paired += 1
        else:
            self.unpaired[out.fault] += 1
        return out

    def _nearest(self, stamp_ns: int) -> Pairing[T]:
        if not self._stamps:
            return Pairing(None, PairFault.NONE_YET, 0)
        k = bisect.bisect_left(self._stamps, stamp_ns)
        candidates = [i for i in (k - 1, k) if 0 <= i < len(self._stamps)]
        best = min(candidates, key=lambda i: (abs(self._stamps[i] - stamp_ns), i))
        gap = self._stamps[best] - stamp_ns
        if abs(gap) <= self.tolerance_ns:
            return Pairing(self._images[best], None, gap)
        if self._stamps[-1] < stamp_ns:
            return Pairing(None, PairFault.TOO_OLD, gap)
        if self._stamps[0] > stamp_ns:
            return Pairing(None, PairFault.TOO_NEW, gap)
        return Pairing(None, PairFault.GAP, gap)
