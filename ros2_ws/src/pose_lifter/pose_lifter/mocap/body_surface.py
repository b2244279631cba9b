"""The body surface of mocap people and its ideal depth image: what a depth camera films
(:mod:`pose_lifter.mocap.depth_model` adds the sensor's faults).

**The body surface** (:func:`body_primitives`), built from the 12 model joints alone (metres,
camera optical frame); radii are adult values in metres (anthropometric girths / 2 pi, rounded,
after Gordon et al., *ANSUR 1988*: upper arm 0.30-0.33 m, forearm 0.26-0.28 m, wrist 0.17 m,
thigh 0.50-0.60 m, calf 0.35-0.38 m):

* the limbs as capsules (cylinders with spherical ends): upper arms :data:`UPPER_ARM_RADIUS`,
  forearms :data:`FOREARM_RADIUS` tapering to :data:`WRIST_RADIUS` (two capsules joined at the
  forearm's middle), thighs :data:`THIGH_RADIUS`, shins :data:`SHIN_RADIUS`;
* a hand, a sphere of :data:`HAND_RADIUS` :data:`HAND_OFFSET` beyond the wrist along the
  forearm; a foot, a capsule of :data:`FOOT_RADIUS` from the heel to the toes along the body's
  facing direction, its sole :data:`ANKLE_HEIGHT` below the ankle;
* the torso, an elliptic cylinder along the spine (body frame of
  :func:`pose_lifter.core.model.skeleton.body_frame`: x hip to hip, y hip centre to shoulder
  centre, z the facing direction), :data:`TORSO_HALF_WIDTH` x :data:`TORSO_HALF_DEPTH` half axes
  (0.33 m wide, 0.2 m deep), from :data:`TORSO_BELOW_HIPS` below the hip centre to
  :data:`TORSO_ABOVE_SHOULDERS` above the shoulder centre;
* a neck capsule and a head sphere of :data:`HEAD_RADIUS` above the shoulder centre along the
  spine (:data:`HEAD_ABOVE_SHOULDERS`).

**Rendering** (:func:`render_depth`): each pixel's ray is cast against every primitive, exactly
(quadratics), over the primitive's image bounding box only (the projected corners of boxes
around its end spheres, or around the torso), and the nearest hit kept: the ideal z-depth
(along the optical axis, not ray length) and which person and part it belongs to. Rays are
written ``t (x_n, y_n, 1)`` with ``x_n = (u - cx) / fx``, ``y_n = (v - cy) / fy`` (pixel
centres at integer u, v), so a hit's ray parameter ``t`` is its z-depth. Behind the people a
:class:`Background`: a wall perpendicular to the optical axis and a floor, the plane
:data:`ANKLE_HEIGHT` below the lowest ankle along the camera's up direction (the virtual cameras
of :mod:`pose_lifter.mocap.scenes` look horizontally: up is -y); :func:`scene_backgrounds` keeps
them put over a sequence.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Final

import numpy as np
from numpy.typing import NDArray

from pose_lifter.core.errors import InvalidInputError
from pose_lifter.core.model.skeleton import N_JOINTS, body_frame
from pose_lifter.core.track.placement import CameraIntrinsics

__all__ = [
    "ANKLE_HEIGHT",
    "PART_NAMES",
    "Background",
    "BodyPrimitives",
    "RenderedDepth",
    "body_primitives",
    "render_depth",
    "scene_backgrounds",
]

UPPER_ARM_RADIUS: Final[float] = 0.05
FOREARM_RADIUS: Final[float] = 0.042
WRIST_RADIUS: Final[float] = 0.035
HAND_RADIUS: Final[float] = 0.045
#: Metres from the wrist to the hand sphere's centre, along the forearm.
HAND_OFFSET: Final[float] = 0.07
THIGH_RADIUS: Final[float] = 0.08
SHIN_RADIUS: Final[float] = 0.055
FOOT_RADIUS: Final[float] = 0.035
#: Heel and toe ends of the foot capsule: metres behind / ahead of the ankle along the facing direction.
FOOT_BACK: Final[float] = 0.03
FOOT_FRONT: Final[float] = 0.13
#: Metres from the ankle joint down to the sole (and the floor).
ANKLE_HEIGHT: Final[float] = 0.075
TORSO_HALF_WIDTH: Final[float] = 0.165
TORSO_HALF_DEPTH: Final[float] = 0.10
TORSO_BELOW_HIPS: Final[float] = 0.06
TORSO_ABOVE_SHOULDERS: Final[float] = 0.04
NECK_RADIUS: Final[float] = 0.055
NECK_LENGTH: Final[float] = 0.12
HEAD_RADIUS: Final[float] = 0.10
#: Metres from the shoulder centre up the spine to the head's centre.
HEAD_ABOVE_SHOULDERS: Final[float] = 0.25

#: The body parts of the label maps (:attr:`RenderedDepth.part`), in this order.
PART_NAMES: Final[tuple[str, ...]] = (
    "torso", "neck", "head",
    "left_upper_arm", "left_forearm", "left_hand", "right_upper_arm", "right_forearm", "right_hand",
    "left_thigh", "left_shin", "left_foot", "right_thigh", "right_shin", "right_foot",
)
_PART: Final[dict[str, int]] = {name: i for i, name in enumerate(PART_NAMES)}
_LSH, _LEL, _LWR, _RSH, _REL, _RWR, _LHIP, _LKN, _LANK, _RHIP, _RKN, _RANK = range(N_JOINTS)
_ANKLES: Final[tuple[int, int]] = (_LANK, _RANK)


@dataclass(frozen=True)
class BodyPrimitives:
    """The solids of people's bodies (P people), camera frame, metres.

    Attributes
    ----------
    capsule_a, capsule_b : ndarray, shape (P, C, 3)
        Capsule end points.
    capsule_radius : ndarray, shape (C,)
    capsule_part : tuple of int
        Part index (:data:`PART_NAMES`) of each capsule.
    sphere_centre : ndarray, shape (P, S, 3)
    sphere_radius : ndarray, shape (S,)
    sphere_part : tuple of int
    torso_rotation : ndarray, shape (P, 3, 3)
        Rows: the torso's width, spine and depth axes.
    torso_centre : ndarray, shape (P, 3)
        On the spine, midway between the hip and shoulder centres.
    torso_extent : ndarray, shape (P, 2)
        Lowest and highest spine coordinates of the torso, relative to the centre.
    """

    capsule_a: NDArray[np.float64]
    capsule_b: NDArray[np.float64]
    capsule_radius: NDArray[np.float64]
    capsule_part: tuple[int, ...]
    sphere_centre: NDArray[np.float64]
    sphere_radius: NDArray[np.float64]
    sphere_part: tuple[int, ...]
    torso_rotation: NDArray[np.float64]
    torso_centre: NDArray[np.float64]
    torso_extent: NDArray[np.float64]


def body_primitives(joints_cam: NDArray[np.float64]) -> BodyPrimitives:
    """The body surface (module docstring) of people given by their 12 joints.

    Parameters
    ----------
    joints_cam : ndarray, shape (P, 12, 3)
        Metres, camera optical frame.

    Returns
    -------
    BodyPrimitives
    """
    j = np.asarray(joints_cam, dtype=np.float64)
    frame = body_frame(j)  # (P, 3, 3) rows x (hip to hip), y (spine), z (facing)
    up, fwd = frame[:, 1], frame[:, 2]
    hips = 0.5 * (j[:, _LHIP] + j[:, _RHIP])
    shoulders = 0.5 * (j[:, _LSH] + j[:, _RSH])
    caps_a, caps_b, radii, parts = [], [], [], []

    def capsule(a: NDArray[np.float64], b: NDArray[np.float64], r: float, part: str) -> None:
        caps_a.append(a)
        caps_b.append(b)
        radii.append(r)
        parts.append(_PART[part])

    sph_c, sph_r, sph_p = [], [], []
    for side, (sh, el, wr) in (("left", (_LSH, _LEL, _LWR)), ("right", (_RSH, _REL, _RWR))):
        capsule(j[:, sh], j[:, el], UPPER_ARM_RADIUS, f"{side}_upper_arm")
        mid = 0.5 * (j[:, el] + j[:, wr])
        capsule(j[:, el], mid, FOREARM_RADIUS, f"{side}_forearm")
        capsule(mid, j[:, wr], WRIST_RADIUS, f"{side}_forearm")
        along = j[:, wr] - j[:, el]
        along /= np.maximum(np.linalg.norm(along, axis=-1, keepdims=True), 1e-9)
        sph_c.append(j[:, wr] + HAND_OFFSET * along)
        sph_r.append(HAND_RADIUS)
        sph_p.append(_PART[f"{side}_hand"])
    sole = ANKLE_HEIGHT - FOOT_RADIUS
    for side, (hip, kn, ank) in (("left", (_LHIP, _LKN, _LANK)), ("right", (_RHIP, _RKN, _RANK))):
        capsule(j[:, hip], j[:, kn], THIGH_RADIUS, f"{side}_thigh")
        capsule(j[:, kn], j[:, ank], SHIN_RADIUS, f"{side}_shin")
        capsule(j[:, ank] - FOOT_BACK * fwd - sole * up, j[:, ank] + FOOT_FRONT * fwd - sole * up,
                FOOT_RADIUS, f"{side}_foot")
    capsule(shoulders, shoulders + NECK_LENGTH * up, NECK_RADIUS, "neck")
    sph_c.append(shoulders + HEAD_ABOVE_SHOULDERS * up)
    sph_r.append(HEAD_RADIUS)
    sph_p.append(_PART["head"])
    centre = 0.5 * (hips + shoulders)
    low = np.einsum("pi,pi->p", hips - centre, up) - TORSO_BELOW_HIPS
    high = np.einsum("pi,pi->p", shoulders - centre, up) + TORSO_ABOVE_SHOULDERS
    return BodyPrimitives(
        np.stack(caps_a, axis=1), np.stack(caps_b, axis=1), np.array(radii), tuple(parts),
        np.stack(sph_c, axis=1), np.array(sph_r), tuple(sph_p),
        frame, centre, np.stack([low, high], axis=1),
    )


@dataclass(frozen=True)
class Background:
    """What is behind the people.

    Attributes
    ----------
    wall_depth : float or None
        z-depth (metres) of a wall perpendicular to the optical axis; None: ``wall_behind``
        behind the people's mean joint depth (no wall when there are no people).
    wall_behind : float
        Metres behind the people's mean joint depth, when ``wall_depth`` is None.
    floor : bool
        A floor, the plane ``up . p = floor_height`` of camera-frame points p.
    floor_height : float or None
        Metres (negative: below the camera); None: :data:`ANKLE_HEIGHT` below the image's lowest
        ankle along ``up`` (no floor when there are no people).
    up : tuple of float
        The world's up direction in the camera frame (unit; the scenes' cameras look
        horizontally: (0, -1, 0)).
    """

    wall_depth: float | None = None
    wall_behind: float = 2.5
    floor: bool = True
    floor_height: float | None = None
    up: tuple[float, float, float] = (0.0, -1.0, 0.0)

    def __post_init__(self) -> None:
        if self.wall_depth is not None and not (np.isfinite(self.wall_depth) and self.wall_depth > 0):
            raise InvalidInputError(f"Background.wall_depth must be a positive depth, got {self.wall_depth}")
        for name in ("wall_behind", "floor_height"):
            if getattr(self, name) is not None and not np.isfinite(getattr(self, name)):
                raise InvalidInputError(f"Background.{name} must be finite, got {getattr(self, name)}")
        if not np.isclose(np.linalg.norm(self.up), 1.0):
            raise InvalidInputError(f"Background.up must be a unit vector, got {self.up}")


@dataclass(frozen=True)
class RenderedDepth:
    """An ideal depth image.

    Attributes
    ----------
    depth : ndarray, shape (H, W), float64
        z-depth, metres; inf where the ray hits nothing.
    person : ndarray, shape (H, W), int16
        Index of the person seen at each pixel; -1 background (wall, floor) or nothing.
    part : ndarray, shape (H, W), int16
        Body part (:data:`PART_NAMES`) seen at each pixel; -1 where ``person`` is -1.
    intrinsics : CameraIntrinsics
        ((fx, fy), (cx, cy)) pixels.
    """

    depth: NDArray[np.float64]
    person: NDArray[np.int16]
    part: NDArray[np.int16]
    intrinsics: CameraIntrinsics


class _Canvas:
    """The z-buffer being drawn, with the normalised ray coordinates of its rows and columns."""

    def __init__(self, intrinsics: CameraIntrinsics, size: tuple[int, int]) -> None:
        (fx, fy), (cx, cy) = intrinsics
        w, h = size
        self.fx, self.fy, self.cx, self.cy, self.w, self.h = fx, fy, cx, cy, w, h
        self.xn = (np.arange(w, dtype=np.float64) - cx) / fx  # (W,)
        self.yn = (np.arange(h, dtype=np.float64) - cy) / fy  # (H,)
        self.depth = np.full((h, w), np.inf)
        self.person = np.full((h, w), -1, dtype=np.int16)
        self.part = np.full((h, w), -1, dtype=np.int16)

    def boxes(self, centres: NDArray[np.float64], radius: NDArray[np.float64]) -> list[list[int]]:
        """Per primitive ``[v0, v1, u0, u1]``: the rows and columns covering the projection of
        spheres about ``centres`` (n, k, 3), of radius ``radius`` (n,) (conservatively: the
        projections of the corners of their bounding boxes; a capsule lies inside the hull of its
        end spheres, a torso inside the hull of its box's corners); empty (v0 >= v1 or u0 >= u1)
        outside the image, the whole image when one reaches the camera plane."""
        r = np.asarray(radius, dtype=np.float64)[:, None, None]
        z = centres[..., 2:3]
        with np.errstate(divide="ignore"):
            inv = np.concatenate([1.0 / (z - r), 1.0 / (z + r)], axis=-1)  # (n, k, 2)
        side = np.array([-1.0, 1.0])
        us = self.fx * ((centres[..., 0:1] + side * r)[..., :, None] * inv[..., None, :]) + self.cx
        vs = self.fy * ((centres[..., 1:2] + side * r)[..., :, None] * inv[..., None, :]) + self.cy
        us, vs = us.reshape(len(us), -1), vs.reshape(len(vs), -1)
        out = np.stack([np.floor(vs.min(axis=1)), np.ceil(vs.max(axis=1)) + 1,
                        np.floor(us.min(axis=1)), np.ceil(us.max(axis=1)) + 1], axis=1)
        out = np.clip(out, 0, [self.h, self.h, self.w, self.w])
        near = np.any(z[..., 0] - r[..., 0] <= 1e-6, axis=1)
        out[near] = [0, self.h, 0, self.w]
        return out.astype(np.int64).tolist()  # type: ignore[no-any-return]

    def rays(self, box: list[int]) -> tuple[NDArray[np.float64], NDArray[np.float64]]:
        """(1, cols) x and (rows, 1) y normalised ray coordinates of a box."""
        return self.xn[None, box[2]:box[3]], self.yn[box[0]:box[1], None]

    def draw(self, box: list[int], t: NDArray[np.float64], person: int, part: int) -> None:
        """Keep the hits ``t`` (box-shaped, inf = none) nearer than what is drawn."""
        rows, cols = slice(box[0], box[1]), slice(box[2], box[3])
        d = self.depth[rows, cols]
        nearer = t < d
        d[nearer] = t[nearer]
        self.person[rows, cols][nearer] = person
        self.part[rows, cols][nearer] = part


def _sphere_t(xn: NDArray[np.float64], yn: NDArray[np.float64], c: NDArray[np.float64], r: float,
              dd: NDArray[np.float64] | None = None) -> NDArray[np.float64]:
    """Nearest positive ray parameter (= z-depth) of rays ``t (xn, yn, 1)`` hitting a sphere; inf
    where they miss. ``dd``: the rays' squared norms, if known."""
    if dd is None:
        dd = xn * xn + yn * yn + 1.0
    dc = xn * c[0] + yn * c[1] + c[2]
    disc = dc * dc - dd * (c @ c - r * r)
    with np.errstate(invalid="ignore"):
        t = (dc - np.sqrt(disc)) / dd
    return np.where(t > 0, t, np.inf)  # NaN (a miss) > 0 is False


def _capsule_t(xn: NDArray[np.float64], yn: NDArray[np.float64], a: NDArray[np.float64],
               b: NDArray[np.float64], r: float) -> NDArray[np.float64]:
    """Nearest positive ray parameter of rays hitting a capsule (segment a-b, radius r)."""
    dd = xn * xn + yn * yn + 1.0
    t = np.minimum(_sphere_t(xn, yn, a, r, dd), _sphere_t(xn, yn, b, r, dd))
    axis = b - a
    length = float(np.linalg.norm(axis))
    if length < 1e-9:
        return t
    e = axis / length
    de = xn * e[0] + yn * e[1] + e[2]
    ae = float(a @ e)
    # |t d_perp - a_perp|^2 = r^2 with d_perp = d - (d.e) e, a_perp = a - (a.e) e
    qa = dd - de * de
    qb = xn * a[0] + yn * a[1] + (a[2] - de * ae)
    qc = a @ a - ae * ae - r * r
    disc = qb * qb - qa * qc
    with np.errstate(invalid="ignore", divide="ignore"):
        tc = (qb - np.sqrt(disc)) / qa
        s = tc * de - ae  # position of the hit along the axis, metres from a
        ok = (tc > 0) & (s >= 0) & (s <= length)  # False where NaN (a miss)
    return np.where(ok & (tc < t), tc, t)


def _torso_t(xn: NDArray[np.float64], yn: NDArray[np.float64], rot: NDArray[np.float64],
             centre: NDArray[np.float64], extent: NDArray[np.float64]) -> NDArray[np.float64]:
    """Nearest positive ray parameter of rays hitting the torso's capped elliptic cylinder: in the
    torso frame (rows of ``rot``) ``(x/a)^2 + (z/b)^2 <= 1`` and ``low <= y <= high``; a ray enters
    the solid at the later of its entries into the cylinder and the slab."""
    dx = xn * rot[0, 0] + yn * rot[0, 1] + rot[0, 2]
    dy = xn * rot[1, 0] + yn * rot[1, 1] + rot[1, 2]
    dz = xn * rot[2, 0] + yn * rot[2, 1] + rot[2, 2]
    cx, cy, cz = rot @ centre
    ia, ib = 1.0 / TORSO_HALF_WIDTH**2, 1.0 / TORSO_HALF_DEPTH**2
    qa = dx * dx * ia + dz * dz * ib
    qb = dx * cx * ia + dz * cz * ib
    qc = cx * cx * ia + cz * cz * ib - 1.0
    disc = qb * qb - qa * qc
    with np.errstate(invalid="ignore", divide="ignore"):
        root = np.sqrt(disc)
        t_in, t_out = (qb - root) / qa, (qb + root) / qa
        s0, s1 = (extent[0] + cy) / dy, (extent[1] + cy) / dy
    slab_in, slab_out = np.minimum(s0, s1), np.maximum(s0, s1)
    flat = np.abs(dy) < 1e-12  # ray parallel to the caps: inside the slab or never
    inside = (extent[0] <= -cy) & (-cy <= extent[1])
    slab_in = np.where(flat, -np.inf if inside else np.inf, slab_in)
    slab_out = np.where(flat, np.inf if inside else -np.inf, slab_out)
    enter, leave = np.maximum(t_in, slab_in), np.minimum(t_out, slab_out)
    ok = (disc >= 0) & (qa > 1e-12) & (enter <= leave) & (enter > 0)
    return np.where(ok, enter, np.inf)


def _background(canvas: _Canvas, joints: NDArray[np.float64], background: Background) -> None:
    """Draw the wall and the floor (person -1) into the empty canvas."""
    wall = background.wall_depth
    if wall is None and len(joints):
        wall = float(joints[..., 2].mean()) + background.wall_behind
    if wall is not None and wall > 0:
        canvas.depth[:] = wall
    height = background.floor_height
    if height is None and len(joints):
        height = float((joints[:, _ANKLES] @ np.asarray(background.up)).min()) - ANKLE_HEIGHT
    if background.floor and height is not None:
        up = np.asarray(background.up, dtype=np.float64)
        toward = canvas.yn[:, None] * up[1] + up[2]  # (H, 1): up . ray, per row when up has no x
        if up[0] != 0.0:
            toward = toward + canvas.xn[None, :] * up[0]
        with np.errstate(divide="ignore", invalid="ignore"):
            tf = height / toward
        tf = np.where(np.isfinite(tf) & (tf > 0), tf, np.inf)
        np.minimum(canvas.depth, tf, out=canvas.depth)


def scene_backgrounds(joints_cam: NDArray[np.float64], up: NDArray[np.float64], wall_behind: float = 2.5
                      ) -> list[Background]:
    """Per frame the background of a filmed sequence that stays put: a wall ``wall_behind``
    behind the people's mean joint depth over all frames, and a floor :data:`ANKLE_HEIGHT` below
    the lowest ankle of all frames (the camera's height taken as constant).

    Parameters
    ----------
    joints_cam : ndarray, shape (P, T, 12, 3)
        Metres, each frame's camera optical frame.
    up : ndarray, shape (T, 3)
        The world's up direction in each frame's camera frame (``R @ (0, 1, 0)`` of the frame's
        world -> camera rotation R).
    wall_behind : float

    Returns
    -------
    list of Background, one per frame
    """
    j = np.asarray(joints_cam, dtype=np.float64)
    u = np.asarray(up, dtype=np.float64)
    wall = float(j[..., 2].mean()) + wall_behind
    floor = float(np.einsum("ptak,tk->pta", j[:, :, _ANKLES], u).min()) - ANKLE_HEIGHT
    return [Background(wall_depth=wall, floor_height=floor, up=(float(x), float(y), float(z)))
            for x, y, z in u]


def render_depth(joints_cam: NDArray[np.float64], intrinsics: CameraIntrinsics,
                 size: tuple[int, int] = (640, 480), background: Background | None = Background()
                 ) -> RenderedDepth:
    """The ideal depth image of people (module docstring).

    Parameters
    ----------
    joints_cam : ndarray, shape (P, 12, 3)
        The people's joints, metres, camera optical frame (every joint in front of the camera);
        P may be 0.
    intrinsics : CameraIntrinsics
        ((fx, fy), (cx, cy)) pixels.
    size : (width, height)
        Pixels.
    background : Background or None
        None: nothing behind the people (inf).

    Returns
    -------
    RenderedDepth
    """
    j = np.asarray(joints_cam, dtype=np.float64)
    if j.ndim != 3 or j.shape[1:] != (N_JOINTS, 3):
        raise InvalidInputError(f"joints_cam must be (P, {N_JOINTS}, 3), got {j.shape}")
    if not np.all(np.isfinite(j)) or np.any(j[..., 2] <= 0):
        raise InvalidInputError("joints_cam must be finite and in front of the camera (z > 0)")
    (fx, fy), _ = intrinsics
    if not (fx > 0 and fy > 0) or size[0] < 1 or size[1] < 1:
        raise InvalidInputError(f"bad camera: intrinsics {intrinsics}, size {size}")
    canvas = _Canvas(intrinsics, (int(size[0]), int(size[1])))
    if background is not None:
        _background(canvas, j, background)
    if len(j):
        prim = body_primitives(j)
        n_people, n_caps, n_spheres = len(j), len(prim.capsule_part), len(prim.sphere_part)
        # the torso lies inside the hull of its bounding box's 8 corners
        signs = np.array([(sx, top, sz) for sx in (-1, 1) for top in (0, 1) for sz in (-1, 1)])
        local = np.empty((n_people, 8, 3))
        local[..., 0] = signs[:, 0] * TORSO_HALF_WIDTH
        local[..., 1] = prim.torso_extent[:, signs[:, 1]]
        local[..., 2] = signs[:, 2] * TORSO_HALF_DEPTH
        corners = prim.torso_centre[:, None] + local @ prim.torso_rotation
        torso_boxes = canvas.boxes(corners, np.zeros(n_people))
        cap_boxes = canvas.boxes(np.stack([prim.capsule_a, prim.capsule_b], axis=2).reshape(-1, 2, 3),
                                 np.tile(prim.capsule_radius, n_people))
        sphere_boxes = canvas.boxes(prim.sphere_centre.reshape(-1, 1, 3),
                                    np.tile(prim.sphere_radius, n_people))
        for p in range(n_people):
            box = torso_boxes[p]
            if box[0] < box[1] and box[2] < box[3]:
                canvas.draw(box, _torso_t(*canvas.rays(box), prim.torso_rotation[p], prim.torso_centre[p],
                                          prim.torso_extent[p]), p, _PART["torso"])
            for k, part in enumerate(prim.capsule_part):
                box = cap_boxes[p * n_caps + k]
                if box[0] < box[1] and box[2] < box[3]:
                    canvas.draw(box, _capsule_t(*canvas.rays(box), prim.capsule_a[p, k], prim.capsule_b[p, k],
                                                float(prim.capsule_radius[k])), p, part)
            for k, part in enumerate(prim.sphere_part):
                box = sphere_boxes[p * n_spheres + k]
                if box[0] < box[1] and box[2] < box[3]:
                    canvas.draw(box, _sphere_t(*canvas.rays(box), prim.sphere_centre[p, k],
                                               float(prim.sphere_radius[k])), p, part)
    return RenderedDepth(canvas.depth, canvas.person, canvas.part, intrinsics)
