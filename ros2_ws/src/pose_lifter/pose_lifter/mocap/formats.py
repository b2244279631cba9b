"""The CMU motion-capture file formats: ASF/AMC originals and the BVH conversion, parsed and
turned into joint positions by forward kinematics.

Every loader returns joint positions of shape ``(frames, 12, 3)`` in metres, Y-up world
frame, in the joint order of :data:`pose_lifter.core.model.skeleton.JOINT_NAMES`.

Joint mapping (see ``shared/data/README.md``):

- ASF/AMC: the END point of the bones ``lclavicle, lhumerus, lradius, rclavicle, rhumerus,
  rradius, lhipjoint, lfemur, ltibia, rhipjoint, rfemur, rtibia``; forward kinematics follows
  the ASF ``axis`` (with its order), ``dof`` (in its order) and ``:root order`` fields:
  ``R_bone = R_parent C M C^-1``, ``end = parent_end + length * R_bone @ direction``.
- BVH: the position of ``LeftArm, LeftForeArm, LeftHand, RightArm, RightForeArm, RightHand,
  LeftUpLeg, LeftLeg, LeftFoot, RightUpLeg, RightLeg, RightFoot``. Two traps of the CMU BVH
  conversion are handled: frame 0 is a T-pose (dropped), and the ASF ``thorax`` bone was lost,
  so its vector is inserted between ``Spine1`` and its children (read from the subject's
  ``.asf`` when present, else from :data:`THORAX_VECTORS`).

Units: CMU length unit x 0.0254 / 0.45 = metres.

No parsing library is used: the PyPI candidates are parse-only (``bvh``), unmaintained
(``asfamc-parser`` 0.0.2) or per-frame object trees (``bvhio``); forward kinematics here is
vectorised over frames with numpy and checked against the README's numbers and AMC/BVH
agreement in ``tests/mocap/test_mocap.py``.
"""

from __future__ import annotations

import re
import warnings
from collections.abc import Sequence
from dataclasses import dataclass, field
from functools import lru_cache
from pathlib import Path
from typing import Final

import numpy as np
from numpy.typing import NDArray

from pose_lifter.core.errors import PoseLifterError

__all__ = [
    "AMC_BONES",
    "BVH_JOINTS",
    "CMU_UNIT_M",
    "THORAX_VECTORS",
    "AsfSkeleton",
    "BvhFile",
    "MocapDataError",
    "amc_positions",
    "bvh_positions",
    "load_amc",
    "load_bvh",
    "parse_amc",
    "parse_asf",
    "parse_bvh",
]

#: Metres per CMU length unit.
CMU_UNIT_M: Final[float] = 0.0254 / 0.45
#: ASF bones whose end points are the 12 model joints, in model order.
AMC_BONES: Final[tuple[str, ...]] = (
    "lclavicle", "lhumerus", "lradius", "rclavicle", "rhumerus", "rradius",
    "lhipjoint", "lfemur", "ltibia", "rhipjoint", "rfemur", "rtibia",
)
#: BVH joints whose positions are the 12 model joints, in model order.
BVH_JOINTS: Final[tuple[str, ...]] = (
    "LeftArm", "LeftForeArm", "LeftHand", "RightArm", "RightForeArm", "RightHand",
    "LeftUpLeg", "LeftLeg", "LeftFoot", "RightUpLeg", "RightLeg", "RightFoot",
)
#: The ASF thorax vectors (CMU units) of the subjects whose BVH files need them (data README).
THORAX_VECTORS: Final[dict[str, tuple[float, float, float]]] = {
    "01": (0.04085, 2.06391, 0.04828),
    "02": (0.00151, 2.06805, 0.00804),
    "07": (0.06167, 2.20558, -0.1721),
    "09": (-0.0017, 2.00562, 0.11066),
}
_BVH_THORAX_PARENT: Final[str] = "Spine1"
_BVH_UPPER_BODY: Final[frozenset[str]] = frozenset(BVH_JOINTS[:6])


class MocapDataError(PoseLifterError, FileNotFoundError):
    """The CMU data directory, its manifest or a trial is missing or unreadable."""


# --------------------------------------------------------------------------- rotations


def _axis_rotation(axis: str, angles_deg: NDArray[np.float64]) -> NDArray[np.float64]:
    """Rotation matrices about one axis, shape (F, 3, 3)."""
    a = np.deg2rad(np.asarray(angles_deg, dtype=np.float64))
    c, s = np.cos(a), np.sin(a)
    out = np.zeros((*a.shape, 3, 3))
    i = "xyz".index(axis.lower())
    j, k = (i + 1) % 3, (i + 2) % 3
    out[..., i, i] = 1.0
    out[..., j, j] = c
    out[..., k, k] = c
    out[..., k, j] = s
    out[..., j, k] = -s
    return out


def _euler(order: str, angles_deg: NDArray[np.float64]) -> NDArray[np.float64]:
    """Rotation applying the axes in ``order`` one after the other (first axis first).

    ``angles_deg`` has shape (F, len(order)); returns (F, 3, 3) = R_last ... R_first.
    """
    ang = np.atleast_2d(np.asarray(angles_deg, dtype=np.float64))
    out = np.broadcast_to(np.eye(3), (ang.shape[0], 3, 3)).copy()
    for n, ax in enumerate(order):
        out = _axis_rotation(ax, ang[:, n]) @ out
    return out


# --------------------------------------------------------------------------- ASF / AMC


@dataclass
class _Bone:
    name: str
    direction: NDArray[np.float64] = field(default_factory=lambda: np.zeros(3))
    length: float = 0.0
    axis: NDArray[np.float64] = field(default_factory=lambda: np.zeros(3))
    axis_order: str = "XYZ"
    dof: tuple[str, ...] = ()


@dataclass(frozen=True)
class AsfSkeleton:
    """A parsed ASF skeleton (CMU units, degrees).

    Attributes
    ----------
    bones : dict
        name -> bone record (direction, length, axis, axis_order, dof).
    parents : dict
        bone name -> parent name (``"root"`` for the root's children).
    root_order : tuple of str
        AMC channel order of the root, e.g. ``("TX", "TY", "TZ", "RX", "RY", "RZ")``.
    root_axis : str
        Axis order of the root orientation.
    root_orientation : ndarray, shape (3,)
    """

    bones: dict[str, _Bone]
    parents: dict[str, str]
    root_order: tuple[str, ...]
    root_axis: str
    root_orientation: NDArray[np.float64]

    def vector(self, bone: str) -> NDArray[np.float64]:
        """``length * direction`` of a bone, CMU units, shape (3,)."""
        b = self.bones[bone]
        return np.asarray(b.length * b.direction)


def _floats(tokens: Sequence[str]) -> NDArray[np.float64]:
    return np.array([float(t) for t in tokens], dtype=np.float64)


def _cache_key(path: str | Path) -> tuple[str, float]:
    p = Path(path)
    if not p.is_file():
        raise MocapDataError(f"mocap file not found: {p}")
    return str(p.resolve()), p.stat().st_mtime


def parse_asf(path: str | Path) -> AsfSkeleton:
    """Parse an ASF skeleton file (cached per file)."""
    return _parse_asf_cached(*_cache_key(path))


@lru_cache(maxsize=16)
def _parse_asf_cached(path: str, _mtime: float) -> AsfSkeleton:
    text = Path(path).read_text(errors="replace")
    section = ""
    bones: dict[str, _Bone] = {}
    parents: dict[str, str] = {}
    root_order: tuple[str, ...] = ("TX", "TY", "TZ", "RX", "RY", "RZ")
    root_axis = "XYZ"
    root_orientation = np.zeros(3)
    current: _Bone | None = None
    for raw in text.splitlines():
        line = raw.strip()
        if not line or line.startswith("#"):
            continue
        if line.startswith(":"):
            section = line.split()[0][1:].lower()
            continue
        tok = line.split()
        key = tok[0].lower()
        if section == "root":
            if key == "order":
                root_order = tuple(t.upper() for t in tok[1:])
            elif key == "axis":
                root_axis = tok[1].upper()
            elif key == "orientation":
                root_orientation = _floats(tok[1:4])
        elif section == "bonedata":
            if key == "begin":
                current = _Bone(name="")
            elif key == "end":
                if current is not None and current.name:
                    bones[current.name] = current
                current = None
            elif current is not None:
                if key == "name":
                    current.name = tok[1]
                elif key == "direction":
                    current.direction = _floats(tok[1:4])
                elif key == "length":
                    current.length = float(tok[1])
                elif key == "axis":
                    current.axis = _floats(tok[1:4])
                    current.axis_order = tok[4].upper() if len(tok) > 4 else "XYZ"
                elif key == "dof":
                    current.dof = tuple(t.lower() for t in tok[1:])
        elif section == "hierarchy" and key not in ("begin", "end"):
            for child in tok[1:]:
                parents[child] = tok[0]
    if not bones or not parents:
        raise MocapDataError(f"{path}: not an ASF skeleton (no bonedata/hierarchy)")
    return AsfSkeleton(bones, parents, root_order, root_axis, root_orientation)


def parse_amc(path: str | Path) -> dict[str, NDArray[np.float64]]:
    """Parse an AMC motion file (cached per file).

    Returns
    -------
    dict
        bone name (and ``"root"``) -> values of shape (frames, n_dof), degrees / CMU units.
    """
    return _parse_amc_cached(*_cache_key(path))


@lru_cache(maxsize=8)
def _parse_amc_cached(path: str, _mtime: float) -> dict[str, NDArray[np.float64]]:
    lines = Path(path).read_text(errors="replace").splitlines()
    start = next((i for i, ln in enumerate(lines) if ln.strip().upper() == ":DEGREES"), None)
    if start is None:
        start = max((i for i, ln in enumerate(lines) if ln.startswith(":")), default=-1)
    body = [ln for ln in lines[start + 1 :] if ln.strip() and not ln.lstrip().startswith("#")]
    fast = _parse_amc_regular(body)
    if fast is not None:
        return fast
    values: dict[str, list[list[float]]] = {}
    n_frames = 0
    for ln in body:
        tok = ln.split()
        if len(tok) == 1 and tok[0].isdigit():
            n_frames += 1
            continue
        values.setdefault(tok[0], []).append([float(v) for v in tok[1:]])
    out: dict[str, NDArray[np.float64]] = {}
    for name, rows in values.items():
        if len(rows) != n_frames:
            raise MocapDataError(f"{path}: bone {name} appears in {len(rows)} of {n_frames} frames")
        out[name] = np.asarray(rows, dtype=np.float64)
    if n_frames == 0 or "root" not in out:
        raise MocapDataError(f"{path}: no AMC frames")
    return out


def _parse_amc_regular(body: list[str]) -> dict[str, NDArray[np.float64]] | None:
    """Vectorised parse when every frame lists the same bones in the same order (CMU files);
    None otherwise (the caller falls back to the line-by-line parser)."""
    if not body or not body[0].strip().isdigit():
        return None
    try:
        per_frame = next(i for i, ln in enumerate(body[1:], 1) if ln.strip().isdigit())
    except StopIteration:
        per_frame = len(body)
    if len(body) % per_frame:
        return None
    layout = [ln.split() for ln in body[1:per_frame]]
    names = [t[0] for t in layout]
    counts = [len(t) - 1 for t in layout]
    width = 1 + sum(1 + c for c in counts)
    tokens = "\n".join(body).split()
    n_frames = len(body) // per_frame
    if len(tokens) != n_frames * width:
        return None
    grid = np.array(tokens, dtype=object).reshape(n_frames, width)
    col = 1
    out: dict[str, NDArray[np.float64]] = {}
    for name, c in zip(names, counts, strict=True):
        if not np.all(grid[:, col] == name):
            return None
        out[name] = grid[:, col + 1 : col + 1 + c].astype(np.float64)
        col += 1 + c
    return out if "root" in out else None


def amc_positions(
    skeleton: AsfSkeleton, motion: dict[str, NDArray[np.float64]], bones: Sequence[str] = AMC_BONES,
    frames: slice | None = None,
) -> NDArray[np.float64]:
    """Forward kinematics: end points of ``bones``, shape (F, len(bones), 3), CMU units.

    Parameters
    ----------
    skeleton : AsfSkeleton
    motion : dict
        From :func:`parse_amc`.
    bones : sequence of str
    frames : slice, optional
        Only these frames.
    """
    sl = frames if frames is not None else slice(None)
    root = motion["root"][sl]
    n = root.shape[0]
    order = skeleton.root_order
    trans = np.stack([root[:, order.index(c)] if c in order else np.zeros(n) for c in ("TX", "TY", "TZ")],
                     axis=1)
    rot_channels = [c for c in order if c.startswith("R")]
    root_angles = np.stack([root[:, order.index(c)] for c in rot_channels], axis=1)
    c_root = _euler(skeleton.root_axis, skeleton.root_orientation[None])[0]
    m_root = _euler("".join(c[1] for c in rot_channels), root_angles)
    rot: dict[str, NDArray[np.float64]] = {"root": c_root @ m_root @ c_root.T}
    end: dict[str, NDArray[np.float64]] = {"root": trans}

    def solve(name: str) -> None:
        if name in end:
            return
        parent = skeleton.parents.get(name)
        if parent is None or name not in skeleton.bones:
            raise MocapDataError(f"bone {name!r} is not in the skeleton hierarchy")
        solve(parent)
        b = skeleton.bones[name]
        c = _euler(b.axis_order, b.axis[None])[0]
        rot_dof = [d for d in b.dof if d in ("rx", "ry", "rz")]
        if rot_dof:
            if name not in motion:
                raise MocapDataError(f"bone {name!r} has dof {b.dof} but no motion channels")
            vals = motion[name][sl]
            ang = np.stack([vals[:, b.dof.index(d)] for d in rot_dof], axis=1)
            local = c @ _euler("".join(d[1] for d in rot_dof), ang) @ c.T
            rot[name] = rot[parent] @ local
        else:
            rot[name] = rot[parent]
        end[name] = end[parent] + b.length * np.einsum("fij,j->fi", rot[name], b.direction)

    for bone in bones:
        solve(bone)
    return np.stack([end[b] for b in bones], axis=1)


def load_amc(
    amc_path: str | Path, asf_path: str | Path | None = None, step: int = 1,
    max_frames: int | None = None,
) -> NDArray[np.float64]:
    """The 12 model joints of an AMC motion, metres, shape (F, 12, 3).

    Parameters
    ----------
    amc_path : path
    asf_path : path, optional
        Default: ``SS.asf`` next to ``SS_TT.amc``.
    step : int
        Keep every ``step``-th frame.
    max_frames : int, optional
        Keep at most this many (after subsampling).
    """
    amc = Path(amc_path)
    asf = Path(asf_path) if asf_path is not None else amc.with_name(amc.stem.split("_")[0] + ".asf")
    skel = parse_asf(asf)
    motion = parse_amc(amc)
    sl = slice(0, None if max_frames is None else max_frames * step, _check_step(step))
    return amc_positions(skel, motion, AMC_BONES, sl) * CMU_UNIT_M


def _check_step(step: int) -> int:
    if int(step) < 1:
        raise ValueError(f"step must be >= 1, got {step}")
    return int(step)


# --------------------------------------------------------------------------- BVH


@dataclass(frozen=True)
class BvhFile:
    """A parsed BVH file (CMU units, degrees).

    Attributes
    ----------
    names : list of str
        Joints in file order (End Sites omitted).
    parents : list of int
        Parent index per joint (-1 for the root).
    offsets : ndarray, shape (J, 3)
    channels : list of tuple of str
        Channel names per joint, e.g. ``("Zrotation", "Yrotation", "Xrotation")``.
    channel_start : list of int
        Column of each joint's first channel in ``motion``.
    motion : ndarray, shape (frames, n_channels)
        All frames, the T-pose frame 0 included.
    frame_time : float
        Seconds.
    """

    names: list[str]
    parents: list[int]
    offsets: NDArray[np.float64]
    channels: list[tuple[str, ...]]
    channel_start: list[int]
    motion: NDArray[np.float64]
    frame_time: float


def parse_bvh(path: str | Path) -> BvhFile:
    """Parse a BVH file (cached per file)."""
    return _parse_bvh_cached(*_cache_key(path))


@lru_cache(maxsize=8)
def _parse_bvh_cached(path: str, _mtime: float) -> BvhFile:
    text = Path(path).read_text(errors="replace")
    head, sep, motion_text = text.partition("MOTION")
    if not sep:
        raise MocapDataError(f"{path}: no MOTION section")
    names: list[str] = []
    parents: list[int] = []
    offsets: list[NDArray[np.float64]] = []
    channels: list[tuple[str, ...]] = []
    starts: list[int] = []
    stack: list[int] = []
    pending: int | None = None
    in_end_site = False
    n_channels = 0
    for raw in head.splitlines():
        tok = raw.split()
        if not tok:
            continue
        key = tok[0]
        if key in ("ROOT", "JOINT"):
            names.append(tok[1])
            parents.append(stack[-1] if stack else -1)
            offsets.append(np.zeros(3))
            channels.append(())
            starts.append(n_channels)
            pending = len(names) - 1
        elif key == "End":
            in_end_site = True
            pending = None
        elif key == "{":
            if pending is not None:
                stack.append(pending)
                pending = None
            elif in_end_site:
                stack.append(-2)
        elif key == "}":
            top = stack.pop()
            if top == -2:
                in_end_site = False
        elif key == "OFFSET" and not in_end_site and stack:
            offsets[stack[-1]] = _floats(tok[1:4])
        elif key == "CHANNELS" and stack and not in_end_site:
            k = int(tok[1])
            channels[stack[-1]] = tuple(tok[2 : 2 + k])
            starts[stack[-1]] = n_channels
            n_channels += k
    m = re.search(r"Frames:\s*(\d+)\s*Frame Time:\s*([0-9.eE+-]+)", motion_text)
    if m is None:
        raise MocapDataError(f"{path}: no Frames / Frame Time in the MOTION section")
    n_frames = int(m.group(1))
    data = np.array(motion_text[m.end():].split(), dtype=np.float64)
    if data.size != n_frames * n_channels:
        raise MocapDataError(
            f"{path}: {data.size} motion values for {n_frames} frames x {n_channels} channels"
        )
    return BvhFile(names, parents, np.array(offsets), channels, starts,
                   data.reshape(n_frames, n_channels), float(m.group(2)))


def bvh_positions(
    bvh: BvhFile, joints: Sequence[str] = BVH_JOINTS, frames: slice | None = None,
    extra_offsets: dict[str, NDArray[np.float64]] | None = None,
) -> NDArray[np.float64]:
    """Forward kinematics: positions of ``joints``, shape (F, len(joints), 3), CMU units.

    ``pos_j = pos_parent + R_parent @ (offset_j + extra_offsets[j])``; ``R_j = R_parent @ L_j``
    with ``L_j`` the product of the joint's rotation channels in file order (``Rz @ Ry @ Rx``
    for ``Zrotation Yrotation Xrotation``).
    """
    motion = bvh.motion[frames if frames is not None else slice(None)]
    n = motion.shape[0]
    extra = extra_offsets or {}
    index = {name: i for i, name in enumerate(bvh.names)}
    rot: dict[int, NDArray[np.float64]] = {}
    pos: dict[int, NDArray[np.float64]] = {}

    def solve(i: int) -> None:
        if i in pos:
            return
        p = bvh.parents[i]
        chans = bvh.channels[i]
        cols = motion[:, bvh.channel_start[i] : bvh.channel_start[i] + len(chans)]
        rot_axes = "".join(c[0].lower() for c in chans if c.endswith("rotation"))
        ang = np.stack([cols[:, k] for k, c in enumerate(chans) if c.endswith("rotation")], axis=1) \
            if rot_axes else np.zeros((n, 0))
        # BVH channels are intrinsic: "Zrotation Yrotation Xrotation" is Rz @ Ry @ Rx, i.e.
        # the last listed axis is applied first
        local = _euler(rot_axes[::-1], ang[:, ::-1]) if rot_axes else np.broadcast_to(np.eye(3), (n, 3, 3))
        offset = bvh.offsets[i] + extra.get(bvh.names[i], np.zeros(3))
        if p < 0:
            t = np.zeros((n, 3))
            for k, c in enumerate(chans):
                if c.endswith("position"):
                    t[:, "XYZ".index(c[0].upper())] = cols[:, k]
            pos[i] = t + offset
            rot[i] = local
        else:
            solve(p)
            pos[i] = pos[p] + np.einsum("fij,j->fi", rot[p], offset)
            rot[i] = rot[p] @ local

    out = []
    for name in joints:
        if name not in index:
            raise MocapDataError(f"BVH joint {name!r} not found")
        solve(index[name])
        out.append(pos[index[name]])
    return np.stack(out, axis=1)


def _thorax_vector(subject: str, data_dir: Path | None, bvh: BvhFile) -> NDArray[np.float64]:
    if data_dir is not None:
        asf = data_dir / "asf_amc" / f"{subject}.asf"
        if asf.is_file():
            return parse_asf(asf).vector("thorax")
    if subject in THORAX_VECTORS:
        return np.array(THORAX_VECTORS[subject])
    # unknown subject: mean direction of the known thorax vectors, scaled like the subject's
    # upper back (the Spine1 offset), which is about as long as the thorax in every ASF here.
    # Leave-one-out on the known subjects (estimate from the others, 200 frames of 02_02, 07_03,
    # 09_12): every arm joint moves 1.9, 13.4 and 8.8 mm.
    known = np.array(list(THORAX_VECTORS.values()))
    direction = known.mean(axis=0) / np.linalg.norm(known.mean(axis=0))
    spine1 = bvh.offsets[bvh.names.index(_BVH_THORAX_PARENT)]
    warnings.warn(
        f"no thorax vector known for subject {subject}: using the mean direction scaled to the "
        "subject's upper back (arm joints off by 2-13 mm when measured leave-one-out on subjects "
        "02, 07, 09)", stacklevel=3,
    )
    return np.asarray(direction * np.linalg.norm(spine1))


def load_bvh(
    path: str | Path, thorax: NDArray[np.float64] | None = None, step: int = 1,
    max_frames: int | None = None, data_dir: str | Path | None = None,
) -> NDArray[np.float64]:
    """The 12 model joints of a CMU BVH file, metres, shape (F, 12, 3), T-pose frame dropped.

    Parameters
    ----------
    path : path
    thorax : ndarray, shape (3,), optional
        The subject's ASF thorax vector (CMU units). Default: from ``<data>/asf_amc/SS.asf``
        when it exists (``data_dir``, or inferred from ``<data>/bvh/SS/SS_TT.bvh``), else
        :data:`THORAX_VECTORS`, else an estimate (with a warning).
    step : int
        Keep every ``step``-th frame (counted after the dropped T-pose).
    max_frames : int, optional
    data_dir : path, optional
    """
    p = Path(path)
    bvh = parse_bvh(p)
    subject = p.stem.split("_")[0]
    if thorax is None:
        d = Path(data_dir) if data_dir is not None else p.resolve().parents[2]
        thorax = _thorax_vector(subject, d, bvh)
    thorax = np.asarray(thorax, dtype=np.float64).reshape(3)
    children = [bvh.names[i] for i, par in enumerate(bvh.parents)
                if par >= 0 and bvh.names[par] == _BVH_THORAX_PARENT]
    step = _check_step(step)
    stop = None if max_frames is None else 1 + max_frames * step
    pts = bvh_positions(bvh, BVH_JOINTS, slice(1, stop, step), {c: thorax for c in children})
    return pts * CMU_UNIT_M
