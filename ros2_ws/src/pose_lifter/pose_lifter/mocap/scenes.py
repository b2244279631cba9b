"""Virtual camera scenes from mocap: people filmed by a pinhole camera, turned into bags.

A scene places one or more mocap clips (metres, Y-up world) in front of a virtual 640x480
pinhole camera several metres away (weak-perspective-like), projects the 12 model joints to
COCO-17 pixels, and can corrupt the 2D like a detector: Gaussian noise (in right-lower-leg
units, as in the paper), gross outliers and missing joints. A bag of a scene can also carry the
depth image a depth camera registered to the virtual camera reads
(:mod:`pose_lifter.mocap.depth_model`: the body surface in front of a wall and a floor, seen
through its REALISTIC sensor).

Frames: world Y-up; camera optical frame x right, y down, z forward. The world->camera map is
a proper rotation (y -> -y AND z -> -z when looking along -Z), never a mirror.
"""

from __future__ import annotations

import io
import struct
from collections.abc import Iterator, Sequence
from dataclasses import dataclass, field, replace
from pathlib import Path
from typing import Any, Final, Literal

import numpy as np
from numpy.typing import NDArray

from pose_lifter.core.errors import InvalidInputError
from pose_lifter.core.model.skeleton import RIGHT_LOWER_LEG, body_frame, limb_lengths
from pose_lifter.messages import names
from pose_lifter.messages.layouts import get_layout

__all__ = [
    "CAMERA_FRAME",
    "COMPRESSED_DEPTH_FORMAT",
    "DEPTH_ENCODING",
    "FOCAL_PX",
    "IMAGE_HEIGHT",
    "IMAGE_WIDTH",
    "PRINCIPAL_POINT",
    "Scene",
    "SceneOptions",
    "build_scene",
    "compressed_depth_data",
    "corrupt_2d",
    "depth_to_mm",
    "film_trials",
    "in_sequence",
    "look_at",
    "project",
    "scene_messages",
    "to_coco17",
]

IMAGE_WIDTH: Final[int] = 640
IMAGE_HEIGHT: Final[int] = 480
#: Focal length of the virtual camera, pixels (fx = fy).
FOCAL_PX: Final[float] = 800.0
#: Principal point (cx, cy), pixels.
PRINCIPAL_POINT: Final[tuple[float, float]] = (320.0, 240.0)
CAMERA_FRAME: Final[str] = "virtual_camera_optical_frame"
_UP: Final[NDArray[np.float64]] = np.array([0.0, 1.0, 0.0])
_START_NS: Final[int] = 1_000_000_000
#: The depth image's encoding: millimetres, 0 = no reading.
DEPTH_ENCODING: Final[str] = "16UC1"
#: ``sensor_msgs/CompressedImage.format`` of image_transport's compressedDepth PNG of a 16UC1 image.
COMPRESSED_DEPTH_FORMAT: Final[str] = "16UC1; compressedDepth png"
#: zlib level of the compressedDepth PNG: a noisy depth image compresses 4 % less at 3 than at 9,
#: five times faster (image_transport's own default, png_level 9, decodes the same).
_PNG_LEVEL: Final[int] = 3
#: The depth sensor's random stream, next to the 2D corruption's, from the scene's seed.
_DEPTH_STREAM: Final[int] = 1


@dataclass(frozen=True)
class SceneOptions:
    """How the people are filmed and how the 2D is corrupted.

    Attributes
    ----------
    fps : float
        Output frame rate (the 120 Hz mocap is subsampled by ``round(120 / fps)``).
    view_angle : float
        Degrees about the vertical axis between the camera and the first person's initial
        facing direction (0 = camera in front, 90 = camera at the person's left, 180 = behind).
    orbit_speed : float
        Degrees per second the camera orbits about the vertical axis (0 = static).
    distance : float
        Metres from the camera to the people's centroid.
    follow : bool
        The camera slides along with the people (1 s moving average), keeping them in view.
    spacing : float
        Metres between neighbouring people, across the image.
    noise : float
        Std of 2D Gaussian noise in right-lower-leg units (per person per frame).
    outliers : float
        Fraction of model joints displaced far (1-3 leg lengths in a random direction),
        confidence kept: a detector that is confidently wrong.
    missing : float
        Fraction of model joints reported missing (confidence 0, coordinates 0).
    seed : int
    """

    fps: float = 30.0
    view_angle: float = 0.0
    orbit_speed: float = 0.0
    distance: float = 5.0
    follow: bool = True
    spacing: float = 1.4
    noise: float = 0.0
    outliers: float = 0.0
    missing: float = 0.0
    seed: int = 0

    def __post_init__(self) -> None:
        if not 0 < self.fps <= 120:
            raise InvalidInputError(f"fps must be in (0, 120], got {self.fps}")
        if self.distance <= 0:
            raise InvalidInputError(f"distance must be > 0, got {self.distance}")
        for name in ("noise", "outliers", "missing"):
            v = getattr(self, name)
            if v < 0 or (name != "noise" and v > 1):
                raise InvalidInputError(f"{name} out of range: {v}")


@dataclass
class Scene:
    """A filmed scene.

    Attributes
    ----------
    joints_camera : ndarray, shape (P, T, 12, 3)
        True joints in the camera optical frame, metres.
    points_2d : ndarray, shape (P, T, 12, 2)
        Observed pixels of the 12 model joints (after corruption).
    confidence : ndarray, shape (P, T, 12)
    clean_2d : ndarray, shape (P, T, 12, 2)
        Pixels before corruption.
    stamps_ns : ndarray, shape (T,)
    track_ids : list of int
    rotations : ndarray, shape (T, 3, 3)
        World -> camera rotation per frame.
    metadata : dict
    """

    joints_camera: NDArray[np.float64]
    points_2d: NDArray[np.float64]
    confidence: NDArray[np.float64]
    clean_2d: NDArray[np.float64]
    stamps_ns: NDArray[np.int64]
    track_ids: list[int]
    rotations: NDArray[np.float64]
    metadata: dict[str, Any] = field(default_factory=dict)


def look_at(camera: NDArray[np.float64], target: NDArray[np.float64]) -> NDArray[np.float64]:
    """World (Y-up) -> camera optical rotation for a camera at ``camera`` looking at ``target``.

    Rows are the camera axes in world coordinates: z forward, y down (world up made
    orthogonal to z, negated), x = y cross z (right). Always a proper rotation.

    Returns
    -------
    ndarray, shape (3, 3)
    """
    z = np.asarray(target, dtype=np.float64) - np.asarray(camera, dtype=np.float64)
    z /= np.linalg.norm(z)
    y = -(_UP - (_UP @ z) * z)
    n = np.linalg.norm(y)
    if n < 1e-9:
        raise InvalidInputError("camera looks straight up or down")
    y /= n
    x = np.cross(y, z)
    rot = np.stack([x, y, z])
    assert np.linalg.det(rot) > 0.999  # a rotation, never a mirror
    return rot


def project(points_cam: NDArray[np.float64], focal: float = FOCAL_PX,
            principal_point: tuple[float, float] = PRINCIPAL_POINT) -> NDArray[np.float64]:
    """Pinhole projection of camera-frame points (..., 3) -> pixels (..., 2)."""
    p = np.asarray(points_cam, dtype=np.float64)
    if np.any(p[..., 2] <= 0):
        raise InvalidInputError("points behind the camera")
    return np.stack([focal * p[..., 0] / p[..., 2] + principal_point[0],
                     focal * p[..., 1] / p[..., 2] + principal_point[1]], axis=-1)


def _moving_average(x: NDArray[np.float64], window: int) -> NDArray[np.float64]:
    if window <= 1 or len(x) < 2:
        return x.copy()
    w = min(window, len(x))
    pad = np.concatenate([np.repeat(x[:1], w // 2, axis=0), x, np.repeat(x[-1:], w - 1 - w // 2, axis=0)])
    kernel = np.ones(w) / w
    return np.stack([np.convolve(pad[:, k], kernel, mode="valid") for k in range(x.shape[1])], axis=1)


def _facing_yaw(pose: NDArray[np.float64]) -> float:
    """Yaw (radians, about +Y, from +Z towards +X) of a pose's facing direction."""
    z = body_frame(pose)[2]
    return float(np.arctan2(z[0], z[2]))


def _yaw_matrix(angle: float) -> NDArray[np.float64]:
    c, s = np.cos(angle), np.sin(angle)
    return np.array([[c, 0.0, s], [0.0, 1.0, 0.0], [-s, 0.0, c]])


def build_scene(people: Sequence[NDArray[np.float64]], options: SceneOptions,
                source_fps: float = 120.0, track_ids: Sequence[int] | None = None) -> Scene:
    """Film people (mocap clips already at the output rate) with the virtual camera.

    Parameters
    ----------
    people : sequence of ndarray, shape (T_p, 12, 3)
        Metres, Y-up world, one clip per person (cut to the shortest).
    options : SceneOptions
    source_fps : float
        Frame rate of the clips (for stamps and orbit).
    track_ids : sequence of int, optional
        Default 0, 1, ...

    Returns
    -------
    Scene
    """
    if not people:
        raise InvalidInputError("a scene needs at least one person")
    n = min(len(p) for p in people)
    if n < 1:
        raise InvalidInputError("empty clip")
    clips = [np.asarray(p[:n], dtype=np.float64) for p in people]
    # each person: centred on its own mean floor position, turned to face +Z at frame 0
    placed = []
    for clip in clips:
        centre = clip.mean(axis=(0, 1))
        centre[1] = 0.0
        turn = _yaw_matrix(-_facing_yaw(clip[0]))
        placed.append((clip - centre) @ turn.T)
    # spread people across the view direction of the first frame
    yaw0 = np.deg2rad(options.view_angle)
    across = np.array([np.cos(yaw0), 0.0, -np.sin(yaw0)])  # camera's right at frame 0
    offsets = (np.arange(len(placed)) - 0.5 * (len(placed) - 1)) * options.spacing
    people_w = np.stack([p + o * across for p, o in zip(placed, offsets, strict=True)])  # (P, T, 12, 3)

    centroid = people_w.mean(axis=(0, 2))  # (T, 3)
    if options.follow:
        target = _moving_average(centroid, max(1, round(source_fps)))
    else:
        target = np.repeat(centroid.mean(axis=0, keepdims=True), n, axis=0)
    t = np.arange(n) / source_fps
    yaw = yaw0 + np.deg2rad(options.orbit_speed) * t
    cams = target + options.distance * np.stack([np.sin(yaw), np.zeros(n), np.cos(yaw)], axis=1)
    rots = np.stack([look_at(c, g) for c, g in zip(cams, target, strict=True)])
    joints_cam = np.einsum("tij,ptkj->ptki", rots, people_w - cams[None, :, None, :])
    clean = project(joints_cam)
    rng = np.random.default_rng(options.seed)
    leg_px = FOCAL_PX * limb_lengths(joints_cam)[..., RIGHT_LOWER_LEG] / joints_cam[..., 2].mean(axis=-1)
    pts, conf = corrupt_2d(clean, leg_px, options.noise, options.outliers, options.missing, rng)
    ids = list(track_ids) if track_ids is not None else list(range(len(clips)))
    stamps = _START_NS + np.round(t * 1e9).astype(np.int64)
    return Scene(joints_cam, pts, conf, clean, stamps, ids, rots,
                 {"n_frames": n, "n_people": len(clips), "seed": options.seed})


def in_sequence(scenes: Sequence[Scene], gap_s: float = 1.0) -> list[Scene]:
    """Scenes re-stamped to follow one another, as a camera records people who come and go one
    at a time: each scene's first frame ``gap_s`` seconds after the previous scene's last frame
    (its frames keep their spacing). The first scene keeps its stamps."""
    if gap_s <= 0:
        raise InvalidInputError(f"gap_s must be > 0, got {gap_s}")
    out: list[Scene] = []
    for scene in scenes:
        offset = 0 if not out else int(out[-1].stamps_ns[-1]) + round(gap_s * 1e9) - int(scene.stamps_ns[0])
        out.append(replace(scene, stamps_ns=scene.stamps_ns + offset))
    return out


def film_trials(trials: Sequence[str], data_dir: str | Path, options: SceneOptions, start: float = 0.0,
                frames: int | None = None, one_after_another: bool = False, one_track: bool = False
                ) -> list[Scene]:
    """Film CMU trials (one person each, track ids 0, 1, ... in order) at ``options.fps``.

    Parameters
    ----------
    trials : sequence of str
        Trial ids, e.g. ``"02_05"``.
    data_dir : path
        The CMU data directory (:func:`pose_lifter.mocap.cmu.resolve_data_dir`).
    options : SceneOptions
    start : float
        Seconds into each trial.
    frames : int, optional
        At most this many frames of each trial (default: all).
    one_after_another : bool
        False: one scene, the people side by side, cut to the shortest clip. True: one scene per
        trial, each of its own length and its corruption seeded ``options.seed + k``, each
        starting a second after the previous one ended (:func:`in_sequence`).
    one_track : bool
        With ``one_after_another``: every trial on track 0, each starting a frame after the
        previous one ended (one person recorded at length, changing motion).

    Returns
    -------
    list of Scene
    """
    from pose_lifter.mocap import cmu

    if one_track and not one_after_another:
        raise InvalidInputError("one track is for trials one after another "
                                "(--one-track needs --one-after-another)")
    people = []
    for t in trials:
        row = cmu.find_trial(t, data_dir)
        step = max(1, round(row.fps / options.fps))
        clip = cmu.load_trial(t, data_dir, step=1)[round(start * row.fps)::step]
        if frames is not None:
            clip = clip[:frames]
        if len(clip) == 0:
            raise InvalidInputError(f"trial {t} has no frames after {start} s")
        people.append(clip)
    if not one_after_another:
        return [build_scene(people, options, source_fps=options.fps)]
    return in_sequence([build_scene([p], replace(options, seed=options.seed + k), options.fps,
                                    [0 if one_track else k]) for k, p in enumerate(people)],
                       1.0 / options.fps if one_track else 1.0)


def corrupt_2d(
    clean: NDArray[np.float64], leg_px: NDArray[np.float64], noise: float, outliers: float,
    missing: float, rng: np.random.Generator,
) -> tuple[NDArray[np.float64], NDArray[np.float64]]:
    """Detector-like corruption of 2D joints.

    Parameters
    ----------
    clean : ndarray, shape (..., 12, 2)
        Pixels.
    leg_px : ndarray, shape (...)
        Projected right-lower-leg length (pixels per leg unit) of each skeleton.
    noise : float
        Gaussian std in leg units.
    outliers : float
        Fraction of joints displaced by 1-3 leg lengths in a random direction.
    missing : float
        Fraction of joints with confidence 0 (coordinates set to 0).
    rng : numpy Generator

    Returns
    -------
    points : ndarray, shape (..., 12, 2)
    confidence : ndarray, shape (..., 12)
    """
    pts = np.array(clean, dtype=np.float64, copy=True)
    scale = np.asarray(leg_px, dtype=np.float64)[..., None, None]
    shape = pts.shape[:-1]
    if noise > 0:
        pts += rng.normal(0.0, noise, size=pts.shape) * scale
    conf = np.ones(shape)
    if outliers > 0:
        hit = rng.random(shape) < outliers
        angle = rng.uniform(0, 2 * np.pi, size=shape)
        mag = rng.uniform(1.0, 3.0, size=shape)
        disp = np.stack([np.cos(angle), np.sin(angle)], axis=-1) * mag[..., None] * scale
        pts = np.where(hit[..., None], pts + disp, pts)
    if missing > 0:
        gone = rng.random(shape) < missing
        conf[gone] = 0.0
        pts[gone] = 0.0
    return pts, conf


def to_coco17(points: NDArray[np.float64], confidence: NDArray[np.float64]
              ) -> tuple[NDArray[np.float64], NDArray[np.float64]]:
    """12 model joints -> COCO-17 keypoints; nose, eyes and ears get the shoulder midpoint
    with confidence 0.

    Parameters
    ----------
    points : ndarray, shape (12, 2)
    confidence : ndarray, shape (12,)

    Returns
    -------
    keypoints : ndarray, shape (17, 2)
    confidence : ndarray, shape (17,)
    """
    lay = get_layout("coco17")
    kp = np.zeros((lay.n_keypoints, 2))
    cf = np.zeros(lay.n_keypoints)
    idx = np.asarray(lay.model_indices)
    kp[idx] = points
    cf[idx] = confidence
    face = [i for i in range(lay.n_keypoints) if i not in set(lay.model_indices)]
    kp[face] = 0.5 * (points[0] + points[3])
    return kp, cf


def depth_to_mm(depth: NDArray[np.floating]) -> NDArray[np.uint16]:
    """A depth image (H, W) in metres, NaN = none, as 16UC1 millimetres (0 = none; rounded,
    readings beyond 65.535 m dropped)."""
    mm = np.round(np.asarray(depth, dtype=np.float64) * 1000.0)
    with np.errstate(invalid="ignore"):
        ok = np.isfinite(mm) & (mm >= 1) & (mm <= 65535)
    return np.where(ok, mm, 0).astype(np.uint16)


def compressed_depth_data(mm: NDArray[np.uint16]) -> bytes:
    """``CompressedImage.data`` of a 16UC1 image (H, W millimetres) in image_transport's
    compressedDepth PNG format: a 12-byte ``ConfigHeader`` (int32 ``compressionFormat``,
    INV_DEPTH = 0, then float32 ``depthParam[2]``, both 0 for a 16-bit image whose values are
    stored as they are), then the 16-bit grayscale PNG of the image. Layout of
    ros-perception/image_transport_plugins, compressed_depth_image_transport:
    include/compressed_depth_image_transport/compression_common.hpp (``ConfigHeader``) and
    src/codec.cpp (``encodeCompressedDepthImage``: ``ConfigHeader compressionConfig {}``, format
    ``INV_DEPTH``, the quantisation parameters set only for 32FC1; the header memcpy'd in front
    of ``cv::imencode(".png", ...)``), read by ``decodeCompressedDepthImage``. Native byte order:
    little-endian, as on the x86-64 and arm64 machines that record it."""
    from PIL import Image

    buf = io.BytesIO()
    image = Image.fromarray(np.ascontiguousarray(mm, dtype=np.uint16))  # mode I;16: 16-bit grayscale
    image.save(buf, format="PNG", compress_level=_PNG_LEVEL)
    return struct.pack("<iff", 0, 0.0, 0.0) + buf.getvalue()


def _depth_message(header: Any, depth: NDArray[np.float32], kind: Literal["raw", "compressed"]
                   ) -> tuple[str, Any, str]:
    """(topic, message, type name) of one depth image: a 16UC1 ``sensor_msgs/Image`` (little-endian,
    step = 2 width) or its compressedDepth ``sensor_msgs/CompressedImage``."""
    from pose_lifter.messages.typestore import message_factory

    mm = depth_to_mm(depth)
    if kind == "compressed":
        data = np.frombuffer(compressed_depth_data(mm), dtype=np.uint8)
        make = message_factory(names.COMPRESSED_IMAGE)
        msg = make(header=header, format=COMPRESSED_DEPTH_FORMAT, data=data)
        return names.TOPIC_DEPTH_COMPRESSED, msg, names.COMPRESSED_IMAGE
    h, w = mm.shape
    msg = message_factory(names.IMAGE)(
        header=header, height=h, width=w, encoding=DEPTH_ENCODING, is_bigendian=0, step=2 * w,
        data=np.frombuffer(mm.astype("<u2").tobytes(), dtype=np.uint8))
    return names.TOPIC_DEPTH, msg, names.IMAGE


def scene_messages(scene: Scene, depth: Literal["raw", "compressed"] | None = None, camera_info: bool = True
                   ) -> Iterator[tuple[str, int, Any, str]]:
    """A scene as the messages of a bag, ``(topic, stamp_ns, message, type name)`` in time order
    (rosbags messages): ``/keypoints_2d`` (coco17 pixels), ``/ground_truth/skeletons_3d`` (camera
    optical frame, metres) and ``/camera_info``. The offline writer stores them
    (:func:`pose_lifter.offline.bags.write_messages`, as ``pose-lifter make-bag`` does).

    ``depth`` adds each frame's depth image, registered to the virtual camera (the camera_info's
    stamp and frame), as :mod:`pose_lifter.mocap.depth_model`'s REALISTIC sensor reads the
    people in front of a wall 2.5 m behind them and on a floor, both static over the scene
    (:func:`~pose_lifter.mocap.depth_model.scene_backgrounds`), seeded by the scene's seed: ``"raw"`` a 16UC1
    ``sensor_msgs/Image`` on ``names.TOPIC_DEPTH``, ``"compressed"`` its compressedDepth PNG
    (:func:`compressed_depth_data`) on ``names.TOPIC_DEPTH_COMPRESSED``. ``camera_info`` False
    leaves ``/camera_info`` out (a detector's bag without the camera's calibration)."""
    from pose_lifter.messages import convert as m
    from pose_lifter.mocap import depth_model

    if depth not in (None, "raw", "compressed"):
        raise InvalidInputError(f"depth must be None, 'raw' or 'compressed', got {depth!r}")
    types = m.rosbags_types()
    rng = np.random.default_rng([int(scene.metadata.get("seed", 0)), _DEPTH_STREAM])
    intrinsics = ((FOCAL_PX, FOCAL_PX), PRINCIPAL_POINT)
    if depth is not None:
        backgrounds = depth_model.scene_backgrounds(scene.joints_camera, scene.rotations @ _UP)
    for ti, stamp in enumerate(scene.stamps_ns):
        header = m.make_header(int(stamp), CAMERA_FRAME, types)
        skels2d, skels3d = [], []
        for pi, tid in enumerate(scene.track_ids):
            kp, cf = to_coco17(scene.points_2d[pi, ti], scene.confidence[pi, ti])
            skels2d.append(m.arrays_to_skeleton2d(kp, cf, tid, types))
            skels3d.append(m.skeleton3d_from_joints(tid, scene.joints_camera[pi, ti], types))
        if camera_info:
            info = m.camera_info(header, IMAGE_WIDTH, IMAGE_HEIGHT, FOCAL_PX, FOCAL_PX, *PRINCIPAL_POINT,
                                 types)
            yield (names.TOPIC_CAMERA_INFO, int(stamp), info, names.CAMERA_INFO)
        yield (names.TOPIC_KEYPOINTS, int(stamp), m.skeleton2d_array(header, "coco17", skels2d, types),
               names.SKELETON2D_ARRAY)
        yield (names.TOPIC_GROUND_TRUTH, int(stamp), m.skeletons3d_array(header, skels3d, types),
               names.SKELETON3D_ARRAY)
        if depth is not None:
            rendered = depth_model.render_depth(scene.joints_camera[:, ti], intrinsics,
                                                (IMAGE_WIDTH, IMAGE_HEIGHT), backgrounds[ti])
            topic, msg, msgtype = _depth_message(
                header, depth_model.sense(rendered, depth_model.REALISTIC, rng), depth)
            yield (topic, int(stamp), msg, msgtype)
