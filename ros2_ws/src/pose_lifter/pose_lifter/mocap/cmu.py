"""The CMU motion-capture data set: its directory, ``MANIFEST.csv``, the project's train /
evaluation split, and each trial as the 12 model joints.

A trial is loaded from its AMC original where one exists, else from its BVH conversion (the file
formats and their forward kinematics: :mod:`pose_lifter.mocap.formats`, whose names are also
importable from here). Joint positions are ``(frames, 12, 3)`` in metres, Y-up world frame, in
the joint order of :data:`pose_lifter.core.model.skeleton.JOINT_NAMES`.
"""

from __future__ import annotations

import csv
import os
from dataclasses import dataclass
from pathlib import Path
from typing import Final

import numpy as np
from numpy.typing import NDArray

from pose_lifter.mocap.formats import (
    AMC_BONES,
    BVH_JOINTS,
    CMU_UNIT_M,
    THORAX_VECTORS,
    AsfSkeleton,
    BvhFile,
    MocapDataError,
    amc_positions,
    bvh_positions,
    load_amc,
    load_bvh,
    parse_amc,
    parse_asf,
    parse_bvh,
)

__all__ = [
    "AMC_BONES",
    "BVH_JOINTS",
    "CMU_UNIT_M",
    "DATA_ENV_VAR",
    "EVALUATION_SUBJECTS",
    "EVALUATION_TRIALS",
    "THORAX_VECTORS",
    "TRAINING_SUBJECTS",
    "AsfSkeleton",
    "BvhFile",
    "MocapDataError",
    "Trial",
    "amc_positions",
    "bvh_positions",
    "default_data_dir",
    "find_trial",
    "load_amc",
    "load_bvh",
    "load_trial",
    "parse_amc",
    "parse_asf",
    "parse_bvh",
    "read_manifest",
    "resolve_data_dir",
    "split_trials",
    "trials_by_action",
]

#: Environment variable overriding the data directory.
DATA_ENV_VAR: Final[str] = "POSE_LIFTER_CMU_DATA"


# --------------------------------------------------------------------------- data directory


def default_data_dir() -> Path:
    """``../shared/data/cmu`` relative to the repository (or to the working directory)."""
    repo = Path(__file__).resolve().parents[5]
    candidate = repo.parent / "shared" / "data" / "cmu"
    if candidate.is_dir():
        return candidate
    return (Path.cwd().parent / "shared" / "data" / "cmu").resolve()


def resolve_data_dir(data_dir: str | Path | None = None) -> Path:
    """The CMU data directory: the argument, else ``$POSE_LIFTER_CMU_DATA``, else the default.

    Raises
    ------
    MocapDataError
        The directory or its ``MANIFEST.csv`` does not exist.
    """
    if data_dir is not None:
        d = Path(data_dir)
    elif os.environ.get(DATA_ENV_VAR):
        d = Path(os.environ[DATA_ENV_VAR])
    else:
        d = default_data_dir()
    if not (d / "MANIFEST.csv").is_file():
        raise MocapDataError(
            f"CMU mocap data not found at {d} (no MANIFEST.csv). Pass the data directory "
            f"(--data DIR) or set {DATA_ENV_VAR}; the default is ../shared/data/cmu next to the repo."
        )
    return d


# --------------------------------------------------------------------------- manifest


@dataclass(frozen=True)
class Trial:
    """One row of ``MANIFEST.csv``."""

    trial: str
    format: str
    path: Path
    frames: int
    fps: float
    action: str
    paper_split: str
    description: str = ""

    @property
    def subject(self) -> str:
        """Subject id, e.g. ``"09"`` for trial ``"09_01"``."""
        return self.trial.split("_")[0]


def read_manifest(data_dir: str | Path | None = None) -> list[Trial]:
    """All rows of ``MANIFEST.csv`` (paths made absolute)."""
    d = resolve_data_dir(data_dir)
    out: list[Trial] = []
    with (d / "MANIFEST.csv").open(newline="") as f:
        for row in csv.DictReader(f):
            out.append(Trial(
                trial=row["trial"], format=row["format"], path=d / row["path"],
                frames=int(row["frames"]), fps=float(row["fps"]), action=row["action"],
                paper_split=row["paper_split"], description=row.get("cmu_description", "") or "",
            ))
    return out


def find_trial(trial_id: str, data_dir: str | Path | None = None) -> Trial:
    """The manifest row of a trial; the AMC original when both formats exist."""
    rows = [t for t in read_manifest(data_dir) if t.trial == trial_id]
    if not rows:
        raise MocapDataError(f"trial {trial_id!r} is not in the manifest")
    rows.sort(key=lambda t: 0 if t.format == "amc" else 1)
    return rows[0]


#: The project's data split (DEVELOPERS.md). Evaluation: people never trained on (subjects 02, 07,
#: 08) and the long run 09_12; training: the other subjects listed here (subject 09's short runs
#: included). Subjects in neither list (one trial is reserved for an independent check) are
#: used for nothing.
EVALUATION_SUBJECTS: Final[tuple[str, ...]] = ("02", "07", "08")
EVALUATION_TRIALS: Final[tuple[str, ...]] = ("09_12",)
TRAINING_SUBJECTS: Final[tuple[str, ...]] = ("01", "03", "05", "06", "09")


def split_trials(split: str, data_dir: str | Path | None = None) -> list[str]:
    """Trial ids of ``split`` (``"train"``, ``"eval"`` or ``"all"``), sorted, each once.

    ``"train"`` is every trial of :data:`TRAINING_SUBJECTS` except :data:`EVALUATION_TRIALS`;
    ``"eval"`` is every trial of :data:`EVALUATION_SUBJECTS` plus :data:`EVALUATION_TRIALS`;
    ``"all"`` both (every trial the project may use: the cross-action folds' pool).
    """
    ids = sorted({t.trial for t in read_manifest(data_dir)})
    if split == "train":
        return [t for t in ids if t.split("_")[0] in TRAINING_SUBJECTS and t not in EVALUATION_TRIALS]
    if split == "eval":
        return [t for t in ids if t.split("_")[0] in EVALUATION_SUBJECTS or t in EVALUATION_TRIALS]
    if split == "all":
        return sorted(set(split_trials("train", data_dir)) | set(split_trials("eval", data_dir)))
    raise ValueError(f"split must be 'train', 'eval' or 'all', got {split!r}")


def trials_by_action(data_dir: str | Path | None = None) -> dict[str, list[str]]:
    """The usable trials (``split_trials("all")``) by their manifest ``action`` class, sorted."""
    usable = set(split_trials("all", data_dir))
    out: dict[str, set[str]] = {}
    for t in read_manifest(data_dir):
        if t.trial in usable:
            out.setdefault(t.action, set()).add(t.trial)
    return {a: sorted(ts) for a, ts in sorted(out.items())}


# --------------------------------------------------------------------------- trials


def load_trial(
    trial_id: str, data_dir: str | Path | None = None, step: int = 1, max_frames: int | None = None
) -> NDArray[np.float64]:
    """The 12 model joints of a manifest trial, metres, Y-up, shape (F, 12, 3).

    The AMC original is used where a trial exists in both formats.

    Parameters
    ----------
    trial_id : str
        e.g. ``"02_05"``.
    data_dir : path, optional
        See :func:`resolve_data_dir`.
    step : int
        Keep every ``step``-th frame (120 Hz originals: 4 -> 30 Hz).
    max_frames : int, optional
    """
    d = resolve_data_dir(data_dir)
    t = find_trial(trial_id, d)
    if t.format == "amc":
        return load_amc(t.path, step=step, max_frames=max_frames)
    if t.format == "bvh":
        return load_bvh(t.path, step=step, max_frames=max_frames, data_dir=d)
    raise MocapDataError(f"trial {trial_id}: unknown format {t.format!r}")
