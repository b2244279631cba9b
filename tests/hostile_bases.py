"""Hostile and careless basis files (issue 10), shared by the offline and the ROS graph tests.

Each builder writes one file into a folder and returns its path; :data:`HOSTILE` names them with
a fragment of the reason the loader must give.
"""

from __future__ import annotations

import io
import json
import zipfile
from collections.abc import Callable
from pathlib import Path

import numpy as np
from pose_lifter.core import PoseBases


def _members(b: PoseBases) -> dict[str, np.ndarray]:
    return {
        "mean": b.mean, "components": b.components, "start_alphas": b.start_alphas,
        "limb_proportions": b.limb_proportions,
        "metadata": np.array(json.dumps({"method": b.method, "n_bases": b.n_bases})),
    }


def write_npz(path: Path, members: dict[str, np.ndarray]) -> Path:
    """An ``.npz`` with these members exactly (no validation: that is the point)."""
    with zipfile.ZipFile(path, "w", compression=zipfile.ZIP_DEFLATED) as zf:
        for name, arr in members.items():
            buf = io.BytesIO()
            np.lib.format.write_array(buf, np.asarray(arr), allow_pickle=False)
            zf.writestr(f"{name}.npy", buf.getvalue())
    return path


def _variant(**changes: np.ndarray | None) -> Callable[[Path], Path]:
    def build(folder: Path) -> Path:
        m = _members(PoseBases.load())
        for k, v in changes.items():
            if v is None:
                del m[k]
            else:
                m[k] = v
        return write_npz(folder / "variant.npz", m)
    return build


def _empty(folder: Path) -> Path:
    p = folder / "empty.npz"
    p.write_bytes(b"")
    return p


def _plain_npy(folder: Path) -> Path:
    p = folder / "plain.npy"
    np.save(p, np.zeros((36, 200)))
    return p


def _zip_bomb(folder: Path) -> Path:
    """A real bomb: 20,000 start rows (32 MB of zeros) in a ~40 kB file."""
    m = _members(PoseBases.load())
    m["start_alphas"] = np.zeros((20_000, 200))
    return write_npz(folder / "bomb.npz", m)


def _lying_header(folder: Path) -> Path:
    """A header announcing 1.25 M start rows (2 GB) with no data behind it: refused from the header."""
    m = _members(PoseBases.load())
    p = write_npz(folder / "lying.npz", {k: v for k, v in m.items() if k != "start_alphas"})
    header = io.BytesIO()
    np.lib.format.write_array_header_1_0(
        header, {"descr": "<f8", "fortran_order": False, "shape": (1_250_000, 200)})
    with zipfile.ZipFile(p, "a") as zf:
        zf.writestr("start_alphas.npy", header.getvalue())  # magic + header, no data
    return p


def _pickled(folder: Path) -> Path:
    m = _members(PoseBases.load())
    buf = io.BytesIO()
    np.lib.format.write_array(buf, np.array([{"a": 1}], dtype=object), allow_pickle=True)
    p = write_npz(folder / "pickled.npz", {k: v for k, v in m.items() if k != "metadata"})
    with zipfile.ZipFile(p, "a") as zf:
        zf.writestr("metadata.npy", buf.getvalue())
    return p


_K = 200
#: name -> (builder, fragment of the refusal's reason)
HOSTILE: dict[str, tuple[Callable[[Path], Path], str]] = {
    "empty file": (_empty, "not an .npz"),
    "plain .npy": (_plain_npy, "not an .npz"),
    "NaN limb proportions": (_variant(limb_proportions=np.full(8, np.nan)), "limb_proportions"),
    "zero limb proportions": (_variant(limb_proportions=np.zeros(8)), "limb_proportions"),
    "list as metadata": (_variant(metadata=np.array("[1, 2]")), "JSON object"),
    "k = 0": (_variant(components=np.zeros((36, 0)), start_alphas=np.zeros((1, 0))), "k >= 1"),
    "zero start poses": (_variant(start_alphas=np.zeros((0, _K))), "at least one start"),
    "zero component": (_variant(components=np.hstack([np.eye(36), np.zeros((36, _K - 36))])),
                       "zero vectors"),
    "missing member": (_variant(limb_proportions=None), "missing ['limb_proportions.npy']"),
    "extra member": (_variant(weights=np.zeros(3)), "unexpected ['weights.npy']"),
    "integer components": (_variant(components=np.ones((36, _K), dtype=np.int64)), "dtype kind"),
    "2-d mean": (_variant(mean=np.zeros((36, 1))), "dimensions"),
    "wrong mean size": (_variant(mean=np.zeros(30)), "shapes must be"),
    "pickled metadata": (_pickled, "dtype kind"),
    "zip bomb (20,000 starts)": (_zip_bomb, "MAX_START_POSES"),
    "lying header (1.25 M starts)": (_lying_header, "MAX_START_POSES"),
    "inf in mean": (_variant(mean=np.full(36, np.inf)), "non-finite"),
    "4 MB metadata": (_variant(metadata=np.array('{"a": "' + "x" * 1_000_000 + '"}')),
                      "characters, more than"),
}
