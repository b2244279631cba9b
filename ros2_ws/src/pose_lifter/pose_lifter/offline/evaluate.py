"""Evaluate a lifted bag against its ground truth.

:func:`evaluate_bag` matches ``/skeletons_3d`` to ``/ground_truth/skeletons_3d`` by stamp and track
id and reports the errors with two floors that any lifter must beat (see
``shared/notes/method-pitfalls.md``); on an input bag (no ``/skeletons_3d``), the floors only.
"""

from __future__ import annotations

import json
from collections.abc import Callable
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np
from numpy.typing import NDArray

from pose_lifter.core.errors import InvalidInputError
from pose_lifter.core.model.bases import PoseBases
from pose_lifter.core.model.metrics import mpjpe, normalised_error, p_mpjpe, similarity_normalised_error
from pose_lifter.core.model.skeleton import N_JOINTS
from pose_lifter.messages import convert as m
from pose_lifter.messages.names import TOPIC_GROUND_TRUTH, TOPIC_KEYPOINTS, TOPIC_SKELETONS
from pose_lifter.offline.bags import read_messages

__all__ = ["Evaluation", "evaluate_bag", "format_evaluation"]

@dataclass
class Evaluation:
    """Errors of a lifted bag against its ground truth, per matched skeleton.

    Arrays have one entry per matched (stamp, track) pair. Floors are computed on the same
    pairs: ``flat`` is the 2D input with zero depth, ``mean_pose`` the bases' mean pose,
    both similarity-aligned to the truth. ``joint_std_m`` (n_matched, 12, 3) is each estimate's
    ``Skeleton3D.joint_std`` (metres along x, y, z of the camera frame), NaN where the message has
    none.
    """

    n_ground_truth: int
    n_estimates: int
    n_matched: int
    mpjpe_mm: NDArray[np.float64]
    p_mpjpe_mm: NDArray[np.float64]
    normalised: NDArray[np.float64]
    flat_p_mpjpe_mm: NDArray[np.float64]
    flat_normalised: NDArray[np.float64]
    mean_pose_p_mpjpe_mm: NDArray[np.float64]
    mean_pose_normalised: NDArray[np.float64]
    track_ids: NDArray[np.int64]
    joint_std_m: NDArray[np.float64] = field(default_factory=lambda: np.zeros((0, N_JOINTS, 3)))

    def table(self) -> dict[str, dict[str, float | None]]:
        """Mean errors: {row: {"mpjpe_mm", "p_mpjpe_mm", "normalised"}}."""

        def mean(a: NDArray[np.float64]) -> float | None:
            return float(np.mean(a)) if a.size else None

        return {
            "lifter": {"mpjpe_mm": mean(self.mpjpe_mm), "p_mpjpe_mm": mean(self.p_mpjpe_mm),
                       "normalised": mean(self.normalised)},
            "flat_floor": {"mpjpe_mm": None, "p_mpjpe_mm": mean(self.flat_p_mpjpe_mm),
                           "normalised": mean(self.flat_normalised)},
            "mean_pose_floor": {"mpjpe_mm": None, "p_mpjpe_mm": mean(self.mean_pose_p_mpjpe_mm),
                                "normalised": mean(self.mean_pose_normalised)},
        }

    def to_dict(self) -> dict[str, Any]:
        """JSON-ready summary (means, medians, counts, per-track means)."""
        per_track = {}
        for tid in np.unique(self.track_ids):
            sel = self.track_ids == tid
            per_track[str(int(tid))] = {
                "n": int(sel.sum()), "mpjpe_mm": float(self.mpjpe_mm[sel].mean()),
                "p_mpjpe_mm": float(self.p_mpjpe_mm[sel].mean()),
                "normalised": float(self.normalised[sel].mean()),
            }
        return {
            "n_ground_truth": self.n_ground_truth, "n_estimates": self.n_estimates,
            "n_matched": self.n_matched, "mean": self.table(),
            "median": {"lifter": {"mpjpe_mm": _median(self.mpjpe_mm),
                                  "p_mpjpe_mm": _median(self.p_mpjpe_mm),
                                  "normalised": _median(self.normalised)}},
            "per_track": per_track,
        }


def _median(a: NDArray[np.float64]) -> float | None:
    return float(np.median(a)) if a.size else None


def _flat(points: NDArray[np.float64], confidence: NDArray[np.float64]) -> NDArray[np.float64]:
    """2D input with zero depth; missing joints at the centroid of the visible ones."""
    pts = np.array(points, dtype=np.float64, copy=True)
    vis = confidence > 0
    if vis.any():
        pts[~vis] = pts[vis].mean(axis=0)
    return np.concatenate([pts, np.zeros((N_JOINTS, 1))], axis=1)


def evaluate_bag(path: str | Path, bases: PoseBases | None = None) -> Evaluation:
    """Match ``/skeletons_3d`` with ``/ground_truth/skeletons_3d`` by (stamp, track id).

    Parameters
    ----------
    path : path
        A bag written by :func:`lift_bag` (or any bag with both topics and ``/keypoints_2d``).
    bases : PoseBases, optional
        For the mean-pose floor (default: the packaged bases).
    """
    b = bases if bases is not None else PoseBases.load()
    gt: dict[tuple[int, int], NDArray[np.float64]] = {}
    est: dict[tuple[int, int], NDArray[np.float64]] = {}
    std: dict[tuple[int, int], NDArray[np.float64]] = {}
    inp: dict[tuple[int, int], tuple[NDArray[np.float64], NDArray[np.float64]]] = {}
    joints_of = {TOPIC_GROUND_TRUTH: gt, TOPIC_SKELETONS: est}  # the 3D topics: (stamp, track) -> joints
    for x in read_messages(path):
        if x.topic in joints_of:
            s = m.stamp_to_ns(x.msg.header.stamp)
            for sk in x.msg.skeletons:
                joints_of[x.topic][(s, int(sk.track_id))] = m.skeleton3d_to_joints(sk)
                if x.topic == TOPIC_SKELETONS:
                    std[(s, int(sk.track_id))] = m.skeleton3d_to_std(sk)
        elif x.topic == TOPIC_KEYPOINTS:
            s = m.stamp_to_ns(x.msg.header.stamp)
            for sk in x.msg.skeletons:
                try:
                    inp[(s, int(sk.track_id))] = m.skeleton2d_to_arrays(sk, x.msg.layout)
                except InvalidInputError:
                    continue
    if not gt:
        raise InvalidInputError(f"{path} has no {TOPIC_GROUND_TRUTH} messages")
    keys = sorted(k for k in est if k in gt)
    if not est:  # an input bag: floors only, over every ground-truth skeleton with 2D input
        floor_keys = sorted(k for k in gt if k in inp)
    else:
        floor_keys = [k for k in keys if k in inp]
    pred = np.array([est[k] for k in keys]).reshape(-1, N_JOINTS, 3)
    truth = np.array([gt[k] for k in keys]).reshape(-1, N_JOINTS, 3)
    ftruth = np.array([gt[k] for k in floor_keys]).reshape(-1, N_JOINTS, 3)
    flat = np.array([_flat(*inp[k]) for k in floor_keys]).reshape(-1, N_JOINTS, 3)
    meanp = np.broadcast_to(b.mean_pose, ftruth.shape)

    def per_pose(fn: Callable[..., NDArray[np.float64]], p: NDArray[np.float64], g: NDArray[np.float64],
                 factor: float = 1.0) -> NDArray[np.float64]:
        return factor * fn(p, g) if len(g) else np.zeros(0)

    return Evaluation(
        n_ground_truth=len(gt), n_estimates=len(est), n_matched=len(keys),
        mpjpe_mm=per_pose(mpjpe, pred, truth, 1e3), p_mpjpe_mm=per_pose(p_mpjpe, pred, truth, 1e3),
        normalised=per_pose(normalised_error, pred, truth),
        flat_p_mpjpe_mm=per_pose(p_mpjpe, flat, ftruth, 1e3),
        flat_normalised=per_pose(similarity_normalised_error, flat, ftruth),
        mean_pose_p_mpjpe_mm=per_pose(p_mpjpe, meanp, ftruth, 1e3),
        mean_pose_normalised=per_pose(similarity_normalised_error, meanp, ftruth),
        track_ids=np.array([k[1] for k in keys], dtype=np.int64),
        joint_std_m=np.array([std[k] for k in keys]).reshape(-1, N_JOINTS, 3),
    )


def format_evaluation(ev: Evaluation, as_json: bool = False) -> str:
    """The error table as text (or JSON)."""
    if as_json:
        return json.dumps(ev.to_dict(), indent=2, sort_keys=True)

    def f(v: float | None, fmt: str) -> str:
        return "n/a" if v is None else format(v, fmt)

    rows = ev.table()
    lines = [
        f"matched {ev.n_matched} of {ev.n_ground_truth} ground-truth skeletons "
        f"({ev.n_estimates} estimates)",
        f"{'':22s}{'MPJPE mm':>10s}{'P-MPJPE mm':>12s}{'normalised':>12s}",
    ]
    labels = {"lifter": "lifter", "flat_floor": "floor: flat 2D", "mean_pose_floor": "floor: mean pose"}
    for key, label in labels.items():
        r = rows[key]
        lines.append(f"{label:22s}{f(r['mpjpe_mm'], '.1f'):>10s}{f(r['p_mpjpe_mm'], '.1f'):>12s}"
                     f"{f(r['normalised'], '.3f'):>12s}")
    lines.append("normalised: the paper's error in right-lower-leg units (lifter: rotation-aligned, "
                 "own leg = 1; floors: similarity-aligned, truth's leg = 1)")
    if len(np.unique(ev.track_ids)) > 1:
        for tid, d in ev.to_dict()["per_track"].items():
            lines.append(f"  track {tid}: n={d['n']} MPJPE {d['mpjpe_mm']:.1f} mm, "
                         f"P-MPJPE {d['p_mpjpe_mm']:.1f} mm, normalised {d['normalised']:.3f}")
    return "\n".join(lines)
