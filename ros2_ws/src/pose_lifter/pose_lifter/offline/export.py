"""``pose-lifter export``: the 3D skeletons of a bag as CSV, NPZ or JSON (no MCAP needed).

One row per lifted skeleton, in bag order:

- CSV (``pandas.read_csv(f)``), one line per joint, the unit in each column's name:
  ``stamp_ns, frame_id, track_id, joint, x_m, y_m, z_m, observed`` plus the skeleton's
  ``reprojection_error_px`` and ``warm_started`` on each line (flags as 1 / 0), then the joint's
  standard deviation ``std_x_m, std_y_m, std_z_m``;
- NPZ (``numpy.load(f)``, no pickle): ``stamp_ns (N,)``, ``track_id (N,)``, ``joints (N, 12, 3)``
  metres, ``observed (N, 12)``, ``joint_names (12,)``, ``frame_id (N,)``, ``reprojection_error
  (N,)`` pixels, ``objective (N,)``, ``warm_started (N,)``, ``joint_std (N, 12, 3)`` metres;
- JSON: ``{"joint_names": [...], "units": {...}, "frames": [{"stamp_ns", "frame_id",
  "skeletons": [{"track_id", "joints", "observed", "reprojection_error", "objective",
  "warm_started", "joint_std"}]}]}`` (one entry per message, also the empty ones).

Joints are in the message's frame (the camera optical frame: x right, y down, z forward).
``observed`` is ``Skeleton3D.observed``: per joint, whether the 2D input showed it (else its 3D
position is the pose model's alone). A message without the flags (ground truth, or a bag written
before the field) gives an empty CSV cell, JSON ``null`` and NPZ ``False``. ``joint_std`` is
``Skeleton3D.joint_std``: per joint, the standard deviation of its position along x, y and z of
that frame; where a message has none (ground truth, or a bag written before the field) it is an
empty CSV cell, JSON ``null`` and NPZ NaN.

The file is written next to its final name and renamed at the end: an error leaves nothing.
"""

from __future__ import annotations

import csv
import json
import os
import tempfile
from pathlib import Path
from typing import IO, Any, Final

import numpy as np

from pose_lifter.core.model.skeleton import JOINT_NAMES
from pose_lifter.messages import convert as m
from pose_lifter.messages.names import SKELETON3D_ARRAY, TOPIC_SKELETONS
from pose_lifter.offline.bags import BagError, bag_topics, check_output, read_messages

__all__ = ["CSV_COLUMNS", "FORMATS", "UNITS", "export_skeletons"]

FORMATS: Final[tuple[str, ...]] = (".csv", ".npz", ".json")
#: The CSV header: one line per joint, units in the names (metres, pixels).
CSV_COLUMNS: Final[tuple[str, ...]] = ("stamp_ns", "frame_id", "track_id", "joint", "x_m", "y_m", "z_m",
                                       "observed", "reprojection_error_px", "warm_started",
                                       "std_x_m", "std_y_m", "std_z_m")
#: The units of the JSON's numbers (its ``units`` entry).
UNITS: Final[dict[str, str]] = {"stamp_ns": "nanoseconds", "joints": "metres (camera optical frame)",
                                "reprojection_error": "pixels", "objective": "normalised",
                                "joint_std": "metres (standard deviation along x, y, z of the joints' frame)"}


def _frames(bag: str | Path, topic: str) -> list[dict[str, Any]]:
    topics = bag_topics(bag)
    if topic not in topics:
        raise BagError(f"{bag} has no topic {topic!r}; its topics: {sorted(topics)}")
    if topics[topic] != SKELETON3D_ARRAY:
        raise BagError(f"topic {topic!r} is {topics[topic]}, not {SKELETON3D_ARRAY}")
    frames = []
    for x in read_messages(bag, [topic]):
        skels = [{
            "track_id": int(s.track_id),
            "joints": m.skeleton3d_to_joints(s).tolist(),
            "observed": [bool(v) for v in s.observed] if len(s.observed) == len(JOINT_NAMES) else None,
            "reprojection_error": float(s.reprojection_error),
            "objective": float(s.objective),
            "warm_started": bool(s.warm_started),
            "joint_std": _joint_std(s),
        } for s in x.msg.skeletons]
        frames.append({"stamp_ns": m.stamp_to_ns(x.msg.header.stamp), "frame_id": str(x.msg.header.frame_id),
                       "skeletons": skels})
    return frames


def _joint_std(skel: Any) -> list[list[float]] | None:
    """A skeleton's ``joint_std`` (12, 3) in the core order, or None where it has none."""
    std = m.skeleton3d_to_std(skel)
    return std.tolist() if np.all(np.isfinite(std)) else None


def _write(path: Path, frames: list[dict[str, Any]], handle: Any) -> None:
    rows = [(f, s) for f in frames for s in f["skeletons"]]
    if path.suffix == ".json":
        json.dump({"joint_names": list(JOINT_NAMES), "units": UNITS, "frames": frames}, handle)
    elif path.suffix == ".csv":
        w = csv.writer(handle)
        w.writerow(CSV_COLUMNS)
        for f, s in rows:
            flags = s["observed"] or [""] * len(JOINT_NAMES)
            std = [[repr(v) for v in xyz] for xyz in s["joint_std"]] if s["joint_std"] else \
                [["", "", ""]] * len(JOINT_NAMES)
            for name, (x, y, z), seen, sd in zip(JOINT_NAMES, s["joints"], flags, std, strict=True):
                w.writerow([f["stamp_ns"], f["frame_id"], s["track_id"], name, repr(x), repr(y), repr(z),
                            seen if seen == "" else int(seen), repr(s["reprojection_error"]),
                            int(s["warm_started"]), *sd])
    else:
        np.savez_compressed(
            handle,
            stamp_ns=np.array([f["stamp_ns"] for f, _ in rows], dtype=np.int64),
            track_id=np.array([s["track_id"] for _, s in rows], dtype=np.int64),
            joints=np.array([s["joints"] for _, s in rows], dtype=np.float64).reshape(
                len(rows), len(JOINT_NAMES), 3),
            observed=np.array([s["observed"] or [False] * len(JOINT_NAMES) for _, s in rows],
                              dtype=bool).reshape(len(rows), len(JOINT_NAMES)),
            joint_names=np.array(JOINT_NAMES),
            frame_id=np.array([f["frame_id"] for f, _ in rows], dtype=np.str_),
            reprojection_error=np.array([s["reprojection_error"] for _, s in rows], dtype=np.float64),
            objective=np.array([s["objective"] for _, s in rows], dtype=np.float64),
            warm_started=np.array([s["warm_started"] for _, s in rows], dtype=bool),
            joint_std=np.array([s["joint_std"] or np.full((len(JOINT_NAMES), 3), np.nan) for _, s in rows],
                               dtype=np.float64).reshape(len(rows), len(JOINT_NAMES), 3),
        )


def export_skeletons(bag: str | Path, out: str | Path, topic: str = TOPIC_SKELETONS,
                     overwrite: bool = False) -> tuple[int, int]:
    """Write the ``Skeleton3DArray`` messages of ``topic`` to ``out`` (format from its suffix).

    Returns
    -------
    (messages, skeletons) : tuple of int

    Raises
    ------
    BagError
        Unknown suffix, existing output (without ``overwrite``), missing directory, missing topic
        or wrong type.
    """
    path = check_output(out, FORMATS, overwrite)
    frames = _frames(bag, topic)
    fd, tmp = tempfile.mkstemp(prefix=f".{path.name}.", dir=path.parent.resolve())
    try:
        handle: IO[Any]
        with (os.fdopen(fd, "wb") if path.suffix == ".npz" else os.fdopen(fd, "w", newline="")) as handle:
            _write(path, frames, handle)
        mask = os.umask(0)  # mkstemp's file is private (0600); the export gets a new file's mode
        os.umask(mask)
        os.chmod(tmp, 0o666 & ~mask)
        os.replace(tmp, path)
    except BaseException:
        Path(tmp).unlink(missing_ok=True)
        raise
    return len(frames), sum(len(f["skeletons"]) for f in frames)
