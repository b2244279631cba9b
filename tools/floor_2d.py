"""What a condition's 2D alone costs a lift: the floor of following it (issue 28's diagnosis).

    .venv/bin/python tools/floor_2d.py [--data ../shared/data/cmu] [--split eval|val]
        [--frames 90] [--views 4] [--conditions clean noise0.05 detector6m ...]

The tracks, cameras, corruptions and seeds of ``tools/accuracy.py``. For each frame, the filmed
person's true centred camera-frame pose with each joint's x, y taken from the 2D the condition
gives, back-projected at the joint's true depth (a joint without 2D keeps its true x, y), against
the truth: P-MPJPE (mm). A lift that knew every depth and followed the 2D would score this. Twice:
with the 2D as given, and with each track's 2D first smoothed over past and future frames by
:func:`pose_lifter.core.track.later.smooth_track_2d` (what ``pose-lifter lift``'s measurement
update reads). The conditions are ``tools/accuracy.py``'s, its diagnostics of the realistic
detector included (``detnoise6m``: its per-joint noise correlated over frames, no other fault;
``detwhite6m``: the same noise independent from frame to frame).
"""

from __future__ import annotations

import argparse
import sys
from pathlib import Path

import numpy as np
from numpy.typing import NDArray

sys.path.insert(0, str(Path(__file__).resolve().parent))
import accuracy as acc
from pose_lifter.core import p_mpjpe
from pose_lifter.core.track.later import smooth_track_2d

FRAME_NS = 33_333_333


def floors(track: acc.Track, cond: str) -> tuple[NDArray[np.float64], NDArray[np.float64]]:
    """Per frame of ``track`` the P-MPJPE (mm) of the true pose with the x, y of condition
    ``cond``'s 2D, as given and smoothed."""
    spec = acc.ALL_CONDITIONS[cond]
    px, conf, _, cam = acc.film_track(track, spec, np.random.default_rng(track.seed))
    perspective = track.camera[2] == "perspective" or "distance" in spec
    dist = spec.get("distance", acc.DISTANCE)
    depth = cam[..., 2] + dist if perspective else np.full(cam.shape[:2], dist)
    truth = cam - cam.mean(axis=1, keepdims=True)
    used = conf > 0
    smoothed, _ = smooth_track_2d(px, used, np.arange(len(px), dtype=np.int64) * FRAME_NS)
    out = []
    for points in (px, smoothed):
        xy = (points - acc.CENTRE) / acc.FOCAL * depth[..., None]
        ok = used & np.isfinite(xy).all(axis=-1)
        pred = np.concatenate([np.where(ok[..., None], xy, cam[..., :2]), cam[..., 2:]], axis=-1)
        pred -= pred.mean(axis=1, keepdims=True)
        out.append(1000.0 * np.asarray(p_mpjpe(pred, truth), dtype=np.float64))
    return out[0], out[1]


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--data", default=None)
    ap.add_argument("--split", choices=("val", "eval"), default="eval")
    ap.add_argument("--frames", type=int, default=90)
    ap.add_argument("--views", type=int, default=4)
    ap.add_argument("--conditions", nargs="+", choices=list(acc.ALL_CONDITIONS),
                    default=["clean", "noise0.05", "noise0.1", "detector6m", "detector3m", "detnoise6m",
                             "detwhite6m", "detfaults6m"])
    args = ap.parse_args(argv)
    tracks = acc._tracks(args.split, args.data, args.frames, args.views)
    print(f"{args.split}: {len(tracks)} tracks, {sum(len(t.world) for t in tracks)} frames per condition; "
          "P-MPJPE (mm) of the true pose with the x, y of the condition's 2D")
    print("| condition | the 2D as given | smoothed over past and future frames |")
    print("|---|---|---|")
    for cond in args.conditions:
        raw, smoothed = zip(*(floors(t, cond) for t in tracks), strict=True)
        print(f"| {cond} | {np.mean(np.concatenate(raw)):.1f} | {np.mean(np.concatenate(smoothed)):.1f} |")
    return 0


if __name__ == "__main__":
    sys.exit(main())
