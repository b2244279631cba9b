"""Accuracy of the full method on unseen CMU actions, beside both floors (issue 2).

Clean weak-perspective 2D of the paper's test actions (walk, run, punch; MANIFEST
``paper_split=test``) seen from four yaw angles is lifted with the packaged bases (learned
on subject 01's playground trials only). Prints P-MPJPE (mm, similarity-aligned) for the
flat floor (2D with zero depth), the mean-pose floor and the lifter with 1, 10 and 30 starts.

    .venv/bin/python tools/core_accuracy.py [--frames-per-trial 3] [--data ../shared/data/cmu]
        [--starts 1,10,30] [--set NAME=VALUE ...]
"""

from __future__ import annotations

import argparse
import ast
import time

import numpy as np
from pose_lifter.core import Lifter, LifterOptions, PoseBases, normalise_pose, p_mpjpe
from pose_lifter.core.model.skeleton import limb_lengths
from pose_lifter.mocap.cmu import load_trial, read_manifest
from scipy.spatial.transform import Rotation
from threadpoolctl import threadpool_limits


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--data", default=None, help="CMU data dir (default ../shared/data/cmu)")
    ap.add_argument("--frames-per-trial", type=int, default=3)
    ap.add_argument("--starts", default="1,10,30")
    ap.add_argument("--set", action="append", default=[], metavar="NAME=VALUE",
                    help="override a LifterOptions field (Python literal), e.g. --set eta_growth=1.1")
    args = ap.parse_args()
    overrides = {k: ast.literal_eval(v) for k, v in (a.split("=", 1) for a in args.set)}
    trials = list(dict.fromkeys(t.trial for t in read_manifest(args.data) if t.paper_split == "test"))
    yaws = (0.0, 45.0, 90.0, 135.0)
    poses, legs = [], []
    for t in trials:
        frames = load_trial(t, args.data, step=1)
        idx = np.linspace(0, len(frames) - 1, args.frames_per_trial + 2)[1:-1].astype(int)
        for i in idx:
            poses.append(normalise_pose(frames[i]))
            legs.append(limb_lengths(frames[i])[7] * 1000.0)  # mm per leg unit
    bases = PoseBases.load()
    cases = []
    for k, (y, leg) in enumerate(zip(poses, legs, strict=True)):
        yaw = yaws[k % len(yaws)]
        rot = (
            Rotation.from_euler("x", 180, degrees=True) * Rotation.from_euler("y", yaw, degrees=True)
        ).as_matrix()
        cases.append((y, leg, 100.0 * y @ rot[:2].T + np.array([320.0, 240.0])))
    print(f"{len(cases)} poses from {len(trials)} unseen trials ({', '.join(trials)}), yaw {yaws}")
    flat = [leg * float(p_mpjpe(np.c_[x, np.zeros(12)], y)) for y, leg, x in cases]
    meanp = [leg * float(p_mpjpe(bases.mean_pose, y)) for y, leg, _ in cases]
    print(f"{'method':<28} {'P-MPJPE mm':>10} {'median':>8} {'ms/pose':>8}")
    print(f"{'flat floor (2D, zero depth)':<28} {np.mean(flat):10.1f} {np.median(flat):8.1f} {'':>8}")
    print(f"{'mean-pose floor':<28} {np.mean(meanp):10.1f} {np.median(meanp):8.1f} {'':>8}")
    with threadpool_limits(1):
        for n in (int(s) for s in args.starts.split(",")):
            lifter = Lifter(bases, LifterOptions(mode="paper", n_starts=n).replace(**overrides))
            lifter.warm_up()  # compile / load the kernels outside the timing
            t0 = time.perf_counter()
            results = [lifter.lift(x) for _, _, x in cases]
            ms = 1000.0 * (time.perf_counter() - t0) / len(cases)
            errs = [c[1] * float(p_mpjpe(r.pose, c[0])) for r, c in zip(results, cases, strict=True)]
            name = f"full method, {n} starts"
            print(f"{name:<28} {np.mean(errs):10.1f} {np.median(errs):8.1f} {ms:8.0f}"
                  f"   objective mean {np.mean([r.objective for r in results]):.4f}")


if __name__ == "__main__":
    main()
