"""A lifted skeleton as a REP-155 body: its frames, joint angles and URDF (numpy only).

REP-155 (ros4hri) describes a person as a kinematic model whose links and joints carry the
body id as a suffix (``l_shoulder_<id>``): a root ``body_<id>``, a waist and torso, a head on
three joints, and per arm and leg three revolute joints at the shoulder / hip (yaw, pitch, roll:
``l_y_shoulder``, ``l_p_shoulder``, ``l_r_shoulder``) and one hinge (``l_elbow``, ``l_knee``).
This module maps the paper's 12 joints onto that model.

Frames
------
- ``body_<id>``: origin at the hip midpoint; y from the right hip to the left hip, z "up" along
  the torso (the hip midpoint -> shoulder midpoint direction made orthogonal to y), x = y × z
  (forward). The torso's lean is therefore in the body frame's orientation, and the waist joint
  stays at 0.
- Per limb segment (``l_shoulder_<id>`` upper arm, ``l_elbow_<id>`` forearm, ``l_hip_<id>``
  thigh, ``l_knee_<id>`` shin), the segment runs along the link's -z from its origin (the
  joint); the hinge below it (elbow, knee) turns about the link's -y, so the elbow bends toward
  the link's +x and the knee toward its -x. ``l_wrist_<id>`` and ``l_ankle_<id>`` sit at the
  segment's end.
- The head, which the 12 joints do not fix, stays on its three joints at 0.

:func:`body_frames` gives every link's transform from its URDF parent, with the 12 joint links
exactly at the joints (composing them reproduces the joints to rounding). :func:`joint_angles`
gives the joint angles, and :func:`forward_kinematics` the joints that the angles give through
the URDF of :func:`body_urdf`, whose dimensions come from one skeleton (:func:`body_dimensions`).
The URDF is rigid where the lifted skeleton is not (the torso can twist about its axis, the
shoulder and hip widths are a frame's), so that forward kinematics reproduces the joints up to
the torso's deviation from the URDF's torso; the limbs keep their lengths along a track.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Final, NamedTuple

import numpy as np
from numpy.typing import NDArray

from pose_lifter.core.model.skeleton import JOINT_NAMES
from pose_lifter.messages.convert import quaternions_xyzw

__all__ = [
    "HEAD_JOINTS",
    "LINKS",
    "REVOLUTE_JOINTS",
    "BodyDimensions",
    "BodyPose",
    "LinkTransform",
    "body_dimensions",
    "body_frames",
    "body_pose",
    "body_urdf",
    "compose",
    "forward_kinematics",
    "joint_angles",
    "joint_link_names",
]

_J = {name: i for i, name in enumerate(JOINT_NAMES)}
#: Below this |sin| an Euler decomposition is at its singularity (one angle set to 0).
_SINGULAR: Final[float] = 1e-9

#: The chains of the 12 joints: (side, kind, (upper joint, middle joint, end joint)).
_CHAINS: Final[tuple[tuple[str, str, tuple[int, int, int]], ...]] = (
    ("l", "arm", (_J["left_shoulder"], _J["left_elbow"], _J["left_wrist"])),
    ("r", "arm", (_J["right_shoulder"], _J["right_elbow"], _J["right_wrist"])),
    ("l", "leg", (_J["left_hip"], _J["left_knee"], _J["left_ankle"])),
    ("r", "leg", (_J["right_hip"], _J["right_knee"], _J["right_ankle"])),
)
#: URDF link names of each chain: (upper segment, lower segment, end) per kind.
_LINKS: Final[dict[str, tuple[str, str, str]]] = {"arm": ("shoulder", "elbow", "wrist"),
                                                    "leg": ("hip", "knee", "ankle")}

#: The head's joints (REP-155 names without the id suffix), not estimated: always 0.
HEAD_JOINTS: Final[tuple[str, ...]] = ("r_head", "y_head", "p_head")


def _axes(side: str, kind: str) -> tuple[NDArray[np.float64], ...]:
    """The REP-155 joint axes (yaw, pitch, roll, hinge) of one limb, in the model's convention."""
    reflect = 1.0 if side == "l" else -1.0
    if kind == "arm":
        return (np.array([0.0, 0.0, -reflect]), np.array([reflect, 0.0, 0.0]),
                np.array([0.0, 0.0, reflect]), np.array([0.0, -1.0, 0.0]))
    return (np.array([0.0, 0.0, -1.0]), np.array([reflect, 0.0, 0.0]),
            np.array([0.0, -1.0, 0.0]), np.array([0.0, -1.0, 0.0]))


def _limb_joint_names(side: str, kind: str) -> tuple[str, str, str, str]:
    root, hinge = ("shoulder", "elbow") if kind == "arm" else ("hip", "knee")
    return (f"{side}_y_{root}", f"{side}_p_{root}", f"{side}_r_{root}", f"{side}_{hinge}")


#: Every revolute joint of the model, in the order of the published ``JointState`` (no suffix).
REVOLUTE_JOINTS: Final[tuple[str, ...]] = (
    "waist", *HEAD_JOINTS, *(n for side, kind, _ in _CHAINS for n in _limb_joint_names(side, kind)))


#: The joint axes of each chain, by (side, kind).
_AXES: Final[dict[tuple[str, str], tuple[NDArray[np.float64], ...]]] = {
    (side, kind): _axes(side, kind) for side, kind, _ in _CHAINS}


def joint_link_names() -> dict[str, str]:
    """The link (no suffix) whose origin is each of the 12 joints: ``{"left_elbow": "l_elbow", ...}``."""
    out: dict[str, str] = {}
    for side, kind, idx in _CHAINS:
        for joint, link in zip(idx, _LINKS[kind], strict=True):
            out[JOINT_NAMES[joint]] = f"{side}_{link}"
    return out


def _rotation(axis: NDArray[np.float64], angle: float) -> NDArray[np.float64]:
    """Rotation by ``angle`` about the unit ``axis`` (Rodrigues), shape (3, 3)."""
    k = np.array([[0.0, -axis[2], axis[1]], [axis[2], 0.0, -axis[0]], [-axis[1], axis[0], 0.0]])
    out: NDArray[np.float64] = np.eye(3) + math.sin(angle) * k + (1.0 - math.cos(angle)) * (k @ k)
    return out


def _link_order() -> tuple[tuple[str, str], ...]:
    """(parent, child) of every link, parents first (``""``: the skeleton's own frame)."""
    links = [("", "body"), ("body", "waist"), ("waist", "torso")]
    parent = "torso"
    for name in (*HEAD_JOINTS, "head"):
        links.append((parent, name))
        parent = name
    for side, kind, _ in _CHAINS:
        root = "shoulder" if kind == "arm" else "hip"
        upper, lower, end = (f"{side}_{n}" for n in _LINKS[kind])
        links += [("torso" if kind == "arm" else "body", f"{side}_y_{root}"),
                  (f"{side}_y_{root}", f"{side}_p_{root}"), (f"{side}_p_{root}", upper),
                  (upper, lower), (lower, end)]
    return tuple(links)


#: Every link of the body as (parent, child), parents first: the rows of :class:`BodyPose`.
LINKS: Final[tuple[tuple[str, str], ...]] = _link_order()
_HEAD_ROWS: Final[int] = 3 + len(HEAD_JOINTS) + 1  # body, waist, torso, the head chain


@dataclass(frozen=True)
class LinkTransform:
    """One link's pose relative to its parent: ``child = parent · (translation, rotation)``.

    Attributes
    ----------
    parent, child : str
        Link names without the body suffix (``""`` as parent: the skeleton's own frame).
    translation : ndarray, shape (3,)
        Metres, in the parent's frame.
    rotation : ndarray, shape (3, 3)
        Columns: the child's axes in the parent's frame.
    """

    parent: str
    child: str
    translation: NDArray[np.float64]
    rotation: NDArray[np.float64]


@dataclass(frozen=True)
class BodyPose:
    """One skeleton as the REP-155 model: every link's transform and the joint angles.

    Attributes
    ----------
    translations : ndarray, shape (len(LINKS), 3)
        Each link's origin in its parent's frame (row i: ``LINKS[i]``), metres.
    quaternions : ndarray, shape (len(LINKS), 4)
        Each link's rotation from its parent, unit quaternions (x, y, z, w).
    angles : ndarray, shape (len(REVOLUTE_JOINTS),)
        The joint angles (radians) in the order of :data:`REVOLUTE_JOINTS`.
    """

    translations: NDArray[np.float64]
    quaternions: NDArray[np.float64]
    angles: NDArray[np.float64]

    def frames(self) -> list[LinkTransform]:
        """The transforms as :class:`LinkTransform` (rotation matrices), in :data:`LINKS` order."""
        return [LinkTransform(p, c, t, _matrix(q))
                for (p, c), t, q in zip(LINKS, self.translations, self.quaternions, strict=True)]

    def angle_map(self) -> dict[str, float]:
        """``{joint name (no suffix): angle}``."""
        return dict(zip(REVOLUTE_JOINTS, (float(a) for a in self.angles), strict=True))


def _matrix(q: NDArray[np.float64]) -> NDArray[np.float64]:
    """The rotation matrix of a unit quaternion (x, y, z, w)."""
    x, y, z, w = (float(v) for v in q)
    return np.array([[1 - 2 * (y * y + z * z), 2 * (x * y - z * w), 2 * (x * z + y * w)],
                     [2 * (x * y + z * w), 1 - 2 * (x * x + z * z), 2 * (y * z - x * w)],
                     [2 * (x * z - y * w), 2 * (y * z + x * w), 1 - 2 * (x * x + y * y)]])


def body_pose(joints: NDArray[np.float64], head_offset: float = 0.0) -> BodyPose:
    """The REP-155 model of one skeleton: every link's transform from its parent (``body`` from
    the skeleton's frame) and the joint angles. Composing a joint link's chain gives the joint
    (to rounding).

    Parameters
    ----------
    joints : ndarray, shape (12, 3)
        The paper's 12 joints (any right-handed frame, metres).
    head_offset : float
        Height of the (unestimated) head joints above the torso link, metres.

    Raises
    ------
    ValueError
        Non-finite joints, or a skeleton without a hip line, a torso or a limb segment.
    """
    joints = np.asarray(joints, dtype=np.float64)
    if joints.shape != (len(JOINT_NAMES), 3):
        raise ValueError(f"joints must have shape ({len(JOINT_NAMES)}, 3), got {joints.shape}")
    (pose,) = body_poses(joints[None], head_offset)
    if pose is None:
        raise ValueError("degenerate skeleton: non-finite joints, or no hip line, torso or limb segment")
    return pose


def _cross_rows(a: NDArray[np.float64], b: NDArray[np.float64]) -> NDArray[np.float64]:
    """Row-wise a × b over the last axis (size 3)."""
    out: NDArray[np.float64] = np.stack([a[..., 1] * b[..., 2] - a[..., 2] * b[..., 1],
                                         a[..., 2] * b[..., 0] - a[..., 0] * b[..., 2],
                                         a[..., 0] * b[..., 1] - a[..., 1] * b[..., 0]], axis=-1)
    return out


def _rows_dot(a: NDArray[np.float64], b: NDArray[np.float64]) -> NDArray[np.float64]:
    out: NDArray[np.float64] = np.einsum("...k,...k->...", a, b)
    return out


#: Per chain (paper order of _CHAINS): its joints, the hinge's bending sign (+x elbow, -x knee),
#: whether it hangs from the torso (arms) and its four joint axes.
_CHAIN_JOINTS: Final[NDArray[np.intp]] = np.array([idx for _, _, idx in _CHAINS], dtype=np.intp)
_CHAIN_SIGN: Final[NDArray[np.float64]] = np.array([1.0 if k == "arm" else -1.0 for _, k, _ in _CHAINS])
_CHAIN_ARM: Final[NDArray[np.bool_]] = np.array([k == "arm" for _, k, _ in _CHAINS])
_CHAIN_AXES: Final[NDArray[np.float64]] = np.array([_axes(s, k) for s, k, _ in _CHAINS])  # (4, 4, 3)
#: The Euler sequences' signs: s1 (z), s2 (x), s3 (z for arms, y for legs) per chain.
_S1: Final[NDArray[np.float64]] = _CHAIN_AXES[:, 0, 2]
_S2: Final[NDArray[np.float64]] = _CHAIN_AXES[:, 1, 0]
_S3: Final[NDArray[np.float64]] = np.where(_CHAIN_ARM, _CHAIN_AXES[:, 2, 2], _CHAIN_AXES[:, 2, 1])


class _BodyFrames(NamedTuple):
    """The body frames of B skeletons (NaN or 0 norms where a skeleton is degenerate).

    Attributes
    ----------
    origin : ndarray, shape (B, 3)
        The hip midpoints.
    ny, nz : ndarray, shape (B,)
        Lengths of the hip line and of the torso's up direction made orthogonal to it.
    rb : ndarray, shape (B, 3, 3)
        The frames' rotations, columns x, y, z.
    local : ndarray, shape (B, 12, 3)
        The joints in the body frame.
    torso : ndarray, shape (B,)
        Height of the shoulder midpoint in the body frame.
    """

    origin: NDArray[np.float64]
    ny: NDArray[np.float64]
    nz: NDArray[np.float64]
    rb: NDArray[np.float64]
    local: NDArray[np.float64]
    torso: NDArray[np.float64]


class _Limbs(NamedTuple):
    """The four limb chains (paper order of ``_CHAINS``) of B skeletons in their body frames.

    Attributes
    ----------
    root : ndarray, shape (B, 4, 3)
        Each chain's first joint (shoulder, hip).
    len1, len2 : ndarray, shape (B, 4)
        Lengths of its upper and lower segments.
    rot : ndarray, shape (B, 4, 3, 3)
        The upper segment's link frame (columns x, y, z; the segment along -z).
    hinge : ndarray, shape (B, 4)
        The elbow or knee angle.
    """

    root: NDArray[np.float64]
    len1: NDArray[np.float64]
    len2: NDArray[np.float64]
    rot: NDArray[np.float64]
    hinge: NDArray[np.float64]


def _body_frames(j: NDArray[np.float64]) -> _BodyFrames:
    """The body frames (module docstring) of the skeletons ``j`` (B, 12, 3); the caller ignores
    the floating-point warnings of degenerate ones."""
    lh, rh = j[:, _J["left_hip"]], j[:, _J["right_hip"]]
    ls, rs = j[:, _J["left_shoulder"]], j[:, _J["right_shoulder"]]
    origin = 0.5 * (lh + rh)
    y = lh - rh
    ny = np.sqrt(_rows_dot(y, y))
    y = y / ny[:, None]
    up = 0.5 * (ls + rs) - origin
    z = up - _rows_dot(up, y)[:, None] * y
    nz = np.sqrt(_rows_dot(z, z))
    z = z / nz[:, None]
    rb = np.stack([_cross_rows(y, z), y, z], axis=-1)  # (B, 3, 3), columns x, y, z
    local = np.einsum("bjk,bkl->bjl", j - origin[:, None], rb)
    torso = 0.5 * (local[:, _J["left_shoulder"], 2] + local[:, _J["right_shoulder"], 2])
    return _BodyFrames(origin, ny, nz, rb, local, torso)


def _limbs(local: NDArray[np.float64]) -> _Limbs:
    """The limb chains of the skeletons ``local`` (B, 12, 3, body frames); the caller ignores the
    floating-point warnings of degenerate ones."""
    a, b, c = (local[:, _CHAIN_JOINTS[:, k]] for k in range(3))  # (B, 4, 3)
    seg1, seg2 = b - a, c - b
    len1, len2 = np.sqrt(_rows_dot(seg1, seg1)), np.sqrt(_rows_dot(seg2, seg2))
    d1, d2 = seg1 / len1[..., None], seg2 / len2[..., None]
    zl = -d1
    perp = d2 - _rows_dot(d2, d1)[..., None] * d1
    nperp = np.sqrt(_rows_dot(perp, perp))
    # a straight limb has no bending plane: x from the body's forward axis (or any normal)
    ex = np.array([1.0, 0.0, 0.0])
    fallback = ex - zl[..., 0:1] * zl
    other = _cross_rows(zl, np.where(np.abs(zl[..., 0:1]) < 0.9, ex, np.array([0.0, 1.0, 0.0])))
    fallback = np.where((_rows_dot(fallback, fallback) < 1e-18)[..., None], other, fallback)
    xl = np.where((nperp > 1e-9)[..., None], _CHAIN_SIGN[:, None] * perp / nperp[..., None],
                  fallback / np.sqrt(_rows_dot(fallback, fallback))[..., None])
    rot = np.stack([xl, _cross_rows(zl, xl), zl], axis=-1)  # (B, 4, 3, 3)
    hinge = np.arctan2(_rows_dot(d2, xl), -_rows_dot(d2, zl))
    return _Limbs(a, len1, len2, rot, hinge)


def _chain_angles(rot: NDArray[np.float64], hinge: NDArray[np.float64]) -> NDArray[np.float64]:
    """The four joint angles (B, 4, 4) of each chain: the Euler angles of its link frames ``rot``
    (B, 4, 3, 3) about the chain's yaw, pitch and roll axes, and its ``hinge`` (B, 4); the caller
    ignores the floating-point warnings of degenerate skeletons."""
    # arms: R = Rz(p1) Rx(p2) Rz(p3), the branch q2 = s2 p2 >= 0
    q2_arm = np.arccos(np.clip(rot[..., 2, 2], -1.0, 1.0))
    p2_arm = _S2 * q2_arm
    sb = np.sin(p2_arm)
    sing = np.abs(sb) < _SINGULAR
    sbs = np.where(sing, 1.0, sb)
    p1_arm = np.where(sing, 0.0, np.arctan2(rot[..., 0, 2] / sbs, -rot[..., 1, 2] / sbs))
    p3_arm = np.where(sing, np.arctan2(np.where(np.cos(p2_arm) > 0, rot[..., 1, 0], -rot[..., 1, 0]),
                                       rot[..., 0, 0]),
                      np.arctan2(rot[..., 2, 0] / sbs, rot[..., 2, 1] / sbs))
    # legs: R = Rz(p1) Rx(p2) Ry(p3)
    p2_leg = np.arcsin(np.clip(rot[..., 2, 1], -1.0, 1.0))
    cb = np.cos(p2_leg)
    sing = np.abs(cb) < _SINGULAR
    cbs = np.where(sing, 1.0, cb)
    p1_leg = np.where(sing, 0.0, np.arctan2(-rot[..., 0, 1] / cbs, rot[..., 1, 1] / cbs))
    p3_leg = np.where(sing, np.arctan2(rot[..., 0, 2], rot[..., 0, 0]),
                      np.arctan2(-rot[..., 2, 0] / cbs, rot[..., 2, 2] / cbs))
    out: NDArray[np.float64] = np.stack([_S1 * np.where(_CHAIN_ARM, p1_arm, p1_leg),
                                         np.where(_CHAIN_ARM, q2_arm, _S2 * p2_leg),
                                         _S3 * np.where(_CHAIN_ARM, p3_arm, p3_leg), hinge], axis=-1)
    return out


def _link_arrays(frames: _BodyFrames, limbs: _Limbs, q: NDArray[np.float64], head_offset: float
                 ) -> tuple[NDArray[np.float64], NDArray[np.float64], NDArray[np.float64]]:
    """Every link's translation (B, len(LINKS), 3) and quaternion (B, len(LINKS), 4) from its
    parent, and the joint angles (B, len(REVOLUTE_JOINTS)), from the body ``frames``, the
    ``limbs`` and their joint angles ``q`` (B, 4, 4); the body links' rotations are left at the
    identity."""
    n = q.shape[0]
    n_links = len(LINKS)
    trans = np.zeros((n, n_links, 3))
    quats = np.zeros((n, n_links, 4))
    quats[..., 3] = 1.0
    trans[:, 0] = frames.origin
    trans[:, 2, 2] = frames.torso
    trans[:, 3, 2] = head_offset
    chain_rows = _HEAD_ROWS + 5 * np.arange(len(_CHAINS))
    base = np.where(_CHAIN_ARM[:, None], np.array([0.0, 0.0, 1.0]) * frames.torso[:, None, None], 0.0)
    trans[:, chain_rows] = limbs.root - base
    trans[:, chain_rows + 3, 2] = -limbs.len1
    trans[:, chain_rows + 4, 2] = -limbs.len2
    half = 0.5 * q  # single-axis rotations: (axis sin(q/2), cos(q/2)) for y, p, r and the hinge
    rows = chain_rows[:, None] + np.arange(4)  # (4, 4)
    quats[:, rows, :3] = _CHAIN_AXES * np.sin(half)[..., None]
    quats[:, rows, 3] = np.cos(half)
    angles = np.zeros((n, len(REVOLUTE_JOINTS)))
    angles[:, 1 + len(HEAD_JOINTS):] = q.reshape(n, -1)
    return trans, quats, angles


def body_poses(joints: NDArray[np.float64], head_offset: float = 0.0) -> list[BodyPose | None]:
    """:func:`body_pose` of several skeletons at once (shape (B, 12, 3)), None for a skeleton
    the model cannot be fitted to (non-finite, no hip line, torso or limb segment)."""
    j = np.asarray(joints, dtype=np.float64)
    if j.ndim != 3 or j.shape[1:] != (len(JOINT_NAMES), 3):
        raise ValueError(f"joints must have shape (B, {len(JOINT_NAMES)}, 3), got {j.shape}")
    n = j.shape[0]
    with np.errstate(invalid="ignore", divide="ignore"):
        frames = _body_frames(j)
        limbs = _limbs(frames.local)
        q = _chain_angles(limbs.rot, limbs.hinge)
    ok = (np.isfinite(j).all(axis=(1, 2)) & (frames.ny > 1e-12) & (frames.nz > 1e-12)
          & (limbs.len1 > 1e-12).all(axis=1) & (limbs.len2 > 1e-12).all(axis=1)
          & np.isfinite(q).all(axis=(1, 2)))
    trans, quats, angles = _link_arrays(frames, limbs, q, head_offset)
    if ok.any():  # the body frames' rotations, one conversion for the frame's bodies
        quats[ok, 0] = quaternions_xyzw(frames.rb[ok])
    return [BodyPose(trans[k], quats[k], angles[k]) if ok[k] else None for k in range(n)]


def joint_angles(joints: NDArray[np.float64]) -> dict[str, float]:
    """The model's revolute joint angles (radians, no suffix) of one skeleton (12, 3): one per
    name of :data:`REVOLUTE_JOINTS`, the waist and head at 0."""
    return body_pose(joints).angle_map()


def body_frames(joints: NDArray[np.float64], head_offset: float = 0.0) -> list[LinkTransform]:
    """Every link of the body as a transform from its URDF parent, in :data:`LINKS` order
    (:func:`body_pose` as rotation matrices)."""
    return body_pose(joints, head_offset).frames()


def compose(frames: list[LinkTransform]) -> dict[str, tuple[NDArray[np.float64], NDArray[np.float64]]]:
    """Each link's (position (3,), rotation (3, 3)) in the skeleton's frame, from the chain."""
    out: dict[str, tuple[NDArray[np.float64], NDArray[np.float64]]] = {"": (np.zeros(3), np.eye(3))}
    for f in frames:
        p, r = out[f.parent]
        out[f.child] = (p + r @ f.translation, r @ f.rotation)
    return out


@dataclass(frozen=True)
class BodyDimensions:
    """The rigid dimensions of a body's URDF, metres.

    Attributes
    ----------
    torso : float
        Height of the shoulder line above the hip midpoint, along the torso.
    shoulders, hips : dict
        Half widths: ``{"l": ..., "r": ...}`` (the side's joint from the torso / body axis).
    upper, lower : dict
        Segment lengths per chain, keyed ``"l_arm"``, ``"r_arm"``, ``"l_leg"``, ``"r_leg"``.
    """

    torso: float
    shoulders: dict[str, float]
    hips: dict[str, float]
    upper: dict[str, float]
    lower: dict[str, float]


def body_dimensions(joints: NDArray[np.float64]) -> BodyDimensions:
    """The URDF dimensions of one skeleton (shape (12, 3), metres), read off its
    :func:`body_pose` (the shoulders' and hips' offsets, the segments' lengths)."""
    t = body_pose(joints).translations
    upper: dict[str, float] = {}
    lower: dict[str, float] = {}
    shoulders: dict[str, float] = {}
    hips: dict[str, float] = {}
    for k, (side, kind, _) in enumerate(_CHAINS):
        row = _HEAD_ROWS + 5 * k
        (shoulders if kind == "arm" else hips)[side] = float(np.linalg.norm(t[row]))
        upper[f"{side}_{kind}"] = -float(t[row + 3, 2])
        lower[f"{side}_{kind}"] = -float(t[row + 4, 2])
    return BodyDimensions(torso=float(t[2, 2]), shoulders=shoulders, hips=hips, upper=upper, lower=lower)


def forward_kinematics(dims: BodyDimensions, angles: dict[str, float]) -> NDArray[np.float64]:
    """The 12 joints (shape (12, 3), in the body frame) that ``angles`` give through the URDF
    of ``dims``: the kinematics a ``robot_state_publisher`` runs on the published joint states."""
    out = np.zeros((len(JOINT_NAMES), 3))
    for side, kind, (a, b, c) in _CHAINS:
        axes = _axes(side, kind)
        q = [angles[n] for n in _limb_joint_names(side, kind)]
        key = f"{side}_{kind}"
        sgn = 1.0 if side == "l" else -1.0
        if kind == "arm":
            base = np.array([0.0, sgn * dims.shoulders[side], dims.torso])
        else:
            base = np.array([0.0, sgn * dims.hips[side], 0.0])
        r = _rotation(axes[0], q[0]) @ _rotation(axes[1], q[1]) @ _rotation(axes[2], q[2])
        out[a] = base
        out[b] = base + r @ np.array([0.0, 0.0, -dims.upper[key]])
        r = r @ _rotation(axes[3], q[3])
        out[c] = out[b] + r @ np.array([0.0, 0.0, -dims.lower[key]])
    return out


def _fmt(v: float) -> str:
    return f"{v:.6g}"


def body_urdf(body_id: str, dims: BodyDimensions, radius: float = 0.03) -> str:
    """The REP-155 URDF of one body (links and joints suffixed ``_<body_id>``), from ``dims``.

    Joint limits are left wide (±pi): the angles are those of an estimated pose, published as
    they are.
    """
    s = f"_{body_id}"
    lines = ['<?xml version="1.0"?>', f'<robot name="human{s}">',
             '  <material name="skin"><color rgba="1 0.7 0 1"/></material>']

    def link(name: str, length: float = 0.0, sphere: float = 0.0) -> None:
        lines.append(f'  <link name="{name}{s}">')
        if length > 0:
            lines.append(f'    <visual><origin xyz="0 0 {_fmt(-length / 2)}" rpy="0 0 0"/><geometry>'
                         f'<cylinder length="{_fmt(length)}" radius="{_fmt(radius)}"/></geometry>'
                         '<material name="skin"/></visual>')
        if sphere > 0:
            lines.append(f'    <visual><geometry><sphere radius="{_fmt(sphere)}"/></geometry>'
                         '<material name="skin"/></visual>')
        lines.append("  </link>")

    def joint(name: str, parent: str, child: str, xyz: tuple[float, float, float],
              axis: NDArray[np.float64] | None) -> None:
        kind = "fixed" if axis is None else "revolute"
        origin = " ".join(_fmt(v) for v in xyz)
        lines.append(f'  <joint name="{name}{s}" type="{kind}"><parent link="{parent}{s}"/>'
                     f'<child link="{child}{s}"/><origin xyz="{origin}" rpy="0 0 0"/>')
        if axis is not None:
            lines.append(f'    <axis xyz="{" ".join(_fmt(float(v)) for v in axis)}"/>'
                         '<limit lower="-3.14159" upper="3.14159" effort="1000" velocity="10"/>')
        lines.append("  </joint>")

    head = 0.12 * dims.torso / 0.5 if dims.torso > 0 else 0.1
    link("body")
    link("waist")
    link("torso", sphere=radius)
    joint("waist", "body", "waist", (0.0, 0.0, 0.0), np.array([0.0, 1.0, 0.0]))
    joint("torso", "waist", "torso", (0.0, 0.0, dims.torso), None)
    head_axes = {"r_head": np.array([1.0, 0.0, 0.0]), "y_head": np.array([0.0, 0.0, 1.0]),
                 "p_head": np.array([0.0, -1.0, 0.0])}
    parent = "torso"
    for name in HEAD_JOINTS:
        link(name)
        joint(name, parent, name, (0.0, 0.0, 0.0), head_axes[name])
        parent = name
    link("head", sphere=head)
    joint("head", parent, "head", (0.0, 0.0, head), None)
    for side, kind, _ in _CHAINS:
        axes = _axes(side, kind)
        key = f"{side}_{kind}"
        sgn = 1.0 if side == "l" else -1.0
        root, hinge = ("shoulder", "elbow") if kind == "arm" else ("hip", "knee")
        parent = "torso" if kind == "arm" else "body"
        width = dims.shoulders[side] if kind == "arm" else dims.hips[side]
        upper, lower, end = (f"{side}_{n}" for n in _LINKS[kind])
        link(f"{side}_y_{root}", sphere=radius)
        link(f"{side}_p_{root}")
        link(upper, length=dims.upper[key])
        link(lower, length=dims.lower[key])
        link(end, sphere=radius)
        joint(f"{side}_y_{root}", parent, f"{side}_y_{root}", (0.0, sgn * width, 0.0), axes[0])
        joint(f"{side}_p_{root}", f"{side}_y_{root}", f"{side}_p_{root}", (0.0, 0.0, 0.0), axes[1])
        joint(f"{side}_r_{root}", f"{side}_p_{root}", upper, (0.0, 0.0, 0.0), axes[2])
        joint(f"{side}_{hinge}", upper, lower, (0.0, 0.0, -dims.upper[key]), axes[3])
        joint(end, lower, end, (0.0, 0.0, -dims.lower[key]), None)
    lines.append("</robot>")
    return "\n".join(lines) + "\n"
