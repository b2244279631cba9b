"""Where a tracked lift's error lies: x, y against depth, per condition (issue 28's diagnosis).

    .venv/bin/python tools/error_axes.py [--data ../shared/data/cmu] [--split val|eval]
        [--frames 60] [--views 2] [--conditions clean noise0.05] [--set NAME=VALUE ...]

The tracks of ``tools/accuracy.py`` (same cameras, corruption and seeds; the perspective tracks'
lifts know the intrinsics), tracked as the node tracks them. For the fit's own pose
(``TrackedLift.fit_pose_camera``: before the output smoothing and the measurement update) and
for the published one, live and smoothed as ``pose-lifter lift`` smooths, prints the mean
absolute error (mm) in x, y and in depth of the centred camera-frame pose (scaled by the true
leg, no rotation alignment) and P-MPJPE, for ``hybrid`` and ``learned-t``.
"""

from __future__ import annotations

import argparse
import sys
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parent))
import accuracy as acc
from pose_lifter.core import p_mpjpe
from pose_lifter.core.model.skeleton import RIGHT_LOWER_LEG, limb_lengths
from pose_lifter.core.track.policy import TrackPolicy
from pose_lifter.core.track.smoothing import OFFLINE_SMOOTHING_S, centred_smoothing

FRAME_NS = 33_333_333


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--data", default=None)
    ap.add_argument("--split", choices=("val", "eval"), default="val")
    ap.add_argument("--frames", type=int, default=60)
    ap.add_argument("--views", type=int, default=2)
    ap.add_argument("--conditions", nargs="+", default=["clean", "noise0.05"], choices=list(acc.CONDITIONS))
    ap.add_argument("--set", action="append", default=[], help="a LifterOptions field")
    args = ap.parse_args(argv)
    methods = ("hybrid", "learned-t")
    acc._init(acc._parse(args.set), methods)
    acc._STATE["intrinsics"] = True
    tracks = acc._tracks(args.split, args.data, args.frames, args.views)
    print("| condition | method | pose | live: x, y / depth / P-MPJPE | smoothed: x, y / depth / P-MPJPE |")
    print("|---|---|---|---|---|")
    for cond in args.conditions:
        for m in methods:
            sums = np.zeros((2, 2, 3))  # (fit, published) x (live, smoothed) x (xy, z, p-mpjpe)
            frames = 0
            for tr in tracks:
                rng = np.random.default_rng(tr.seed)
                px, conf, world, cam_pose = acc.film_track(tr, acc.CONDITIONS[cond], rng)
                n = len(world)
                leg = limb_lengths(world)[:, RIGHT_LOWER_LEG]
                truth = cam_pose - cam_pose.mean(axis=1, keepdims=True)
                policy = TrackPolicy(acc._STATE["lifters"][m], track_timeout=1e9)
                policy.smoothed_later = True
                perspective = tr.camera[2] == "perspective" or "distance" in acc.CONDITIONS[cond]
                centre = (float(acc.CENTRE[0]), float(acc.CENTRE[1]))
                intr = ((acc.FOCAL, acc.FOCAL), centre) if perspective else None
                poses = np.zeros((2, n, 12, 3))
                for i in range(n):
                    t = policy.lift(0, i * FRAME_NS, px[i], conf[i], intr)
                    own = t.result.pose_camera if t.fit_pose_camera is None else t.fit_pose_camera
                    poses[0, i] = own * leg[i]
                    poses[1, i] = t.result.pose_camera * leg[i]
                stamps = np.arange(n, dtype=np.int64) * FRAME_NS
                ok = np.ones(n, dtype=bool)
                for a in range(2):
                    smoothed = centred_smoothing(poses[a], stamps, ok, OFFLINE_SMOOTHING_S, 1.0)
                    for b, p in enumerate((poses[a], smoothed)):
                        p = p - p.mean(axis=1, keepdims=True)
                        d = np.abs(p - truth)
                        sums[a, b] += n * 1000 * np.array([d[..., :2].mean(), d[..., 2].mean(),
                                                           np.mean(p_mpjpe(p, truth))])
                frames += n
            for a, pose in enumerate(("fit", "published")):
                cells = [" / ".join(f"{v:.1f}" for v in sums[a, b] / frames) for b in range(2)]
                print(f"| {cond} | {m} | {pose} | {cells[0]} | {cells[1]} |", flush=True)
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
