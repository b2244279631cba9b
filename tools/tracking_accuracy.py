"""Tracking accuracy on unseen CMU trials: warm-started lifting of whole sequences.

Each of the paper's test trials (walk, run, punch; MANIFEST ``paper_split=test``) is seen
from one of four yaws (trial index modulo 4) under clean weak-perspective projection, and
lifted frame by frame with the paper's method (``mode="paper"``; ``--compare "mode='hybrid'"``
for the default mode): a cold multi-start on the first frame, then warm starts from the
previous frame (plus the screened depth-mirrored start). Prints, per option
set, the mean P-MPJPE (mm, similarity-aligned per frame) over all frames, the mean final
objective and the time per frame. Deterministic.

    .venv/bin/python tools/tracking_accuracy.py [--frames 60] [--step 4] [--data ../shared/data/cmu]
        [--compare "pose_max_iter=20" ...]
"""

from __future__ import annotations

import argparse
import ast
import time
import warnings

import numpy as np
from pose_lifter.core import Lifter, LifterOptions, PoseBases, normalise_pose, p_mpjpe
from pose_lifter.core.model.skeleton import limb_lengths
from pose_lifter.mocap.cmu import load_trial, read_manifest
from scipy.spatial.transform import Rotation
from threadpoolctl import threadpool_limits


def _parse(spec: str) -> dict[str, object]:
    """``"a=1, b='x'"`` -> ``{"a": 1, "b": "x"}`` (Python literals)."""
    out: dict[str, object] = {}
    for part in filter(None, (p.strip() for p in spec.split(","))):
        k, v = part.split("=", 1)
        out[k.strip()] = ast.literal_eval(v.strip())
    return out


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--data", default=None, help="CMU data dir (default ../shared/data/cmu)")
    ap.add_argument("--frames", type=int, default=60, help="frames per trial (after --step)")
    ap.add_argument("--step", type=int, default=4, help="keep every step-th mocap frame (120 Hz -> 30 Hz)")
    ap.add_argument("--compare", action="append", default=[],
                    help="an option set to compare with the defaults, e.g. \"pose_max_iter=20\"")
    args = ap.parse_args()
    warnings.simplefilter("ignore")
    trials = list(dict.fromkeys(t.trial for t in read_manifest(args.data) if t.paper_split == "test"))
    yaws = (0.0, 45.0, 90.0, 135.0)
    seqs = []
    for k, t in enumerate(trials):
        frames = load_trial(t, args.data, step=args.step, max_frames=args.frames)
        rot = (Rotation.from_euler("x", 180, degrees=True)
               * Rotation.from_euler("y", yaws[k % len(yaws)], degrees=True)).as_matrix()
        truth = [normalise_pose(f) for f in frames]
        legs = [limb_lengths(f)[7] * 1000.0 for f in frames]
        pts = [100.0 * y @ rot[:2].T + np.array([320.0, 240.0]) for y in truth]
        seqs.append((truth, legs, pts))
    n = sum(len(s[0]) for s in seqs)
    print(f"{len(seqs)} unseen trials, {n} frames (step {args.step}, at most {args.frames} per trial), "
          f"yaws {yaws}")
    bases = PoseBases.load()
    print(f"{'options':<40} {'P-MPJPE mm':>10} {'median':>8} {'objective':>10} {'ms/frame':>9}")
    with threadpool_limits(1):
        for spec in ["", *args.compare]:
            lifter = Lifter(bases, LifterOptions(mode="paper").replace(**_parse(spec)))
            lifter.warm_up()
            errs, objs = [], []
            t0 = time.perf_counter()
            for truth, legs, pts in seqs:
                warm = None
                for y, leg, x in zip(truth, legs, pts, strict=True):
                    r = lifter.lift(x, warm=warm)
                    warm = r.warm_start()
                    errs.append(leg * float(p_mpjpe(r.pose, y)))
                    objs.append(r.objective)
            ms = 1000.0 * (time.perf_counter() - t0) / n
            print(f"{spec or 'defaults':<40} {np.mean(errs):10.1f} {np.median(errs):8.1f} "
                  f"{np.mean(objs):10.4f} {ms:9.1f}", flush=True)


if __name__ == "__main__":
    main()
