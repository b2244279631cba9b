"""Metric accuracy with a depth camera: mono, naive depth lookup, fused, fused three frames late
(``make rgbd-accuracy``).

    .venv/bin/python tools/rgbd_accuracy.py [--data ../shared/data/cmu] [--frames 90] [--views 2]
        [--distances 1.5 3 5] [--elevated] [--methods mono naive fused fused-lag true-depth] [--workers 2]
        [--trials T ...] [--max-trials N] [--fold CLASS --folds DIR] [--set NAME=VALUE ...]
        [--out out/rgbd_accuracy] [--calibrate]
    .venv/bin/python tools/rgbd_accuracy.py --merge RUN1 RUN2 ... --out DIR

The tracks, the depth images, the methods and the figures are
:mod:`pose_lifter.mocap.rgbd_evaluation`'s. ``--fold CLASS`` lifts the trials of a motion class
with the priors ``tools/cross_action.py`` trained without it (``DIR/CLASS.npz`` and, when present,
its causal temporal prior ``DIR/CLASS_w4.npz``; ``make cross-action`` writes them to
``out/cross_action/folds``); ``--merge`` prints the mean of such runs' tables (each class weighs the
same; ``make rgbd-cross-action``). Writes ``rgbd_accuracy.md`` (the tables, stamped with the git commit
and the CPU model) and ``rgbd_accuracy.json`` (the table and each track's figures) to ``--out``.
Deterministic (the detector and the depth sensor seeded per track and distance).
"""

from __future__ import annotations

import argparse
import json
import os
import sys
import time
import warnings
from pathlib import Path
from typing import Any

os.environ.setdefault("OMP_NUM_THREADS", "1")
os.environ.setdefault("OPENBLAS_NUM_THREADS", "1")

from pose_lifter.mocap import evaluation as ev
from pose_lifter.mocap import rgbd_evaluation as rgbd

REPO = Path(__file__).resolve().parents[1]


def _parser() -> argparse.ArgumentParser:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--data", default=None)
    ap.add_argument("--frames", type=int, default=90, help="frames per track at 30 Hz")
    ap.add_argument("--views", type=int, default=2, help="cameras per trial")
    ap.add_argument("--distances", type=float, nargs="+", default=list(rgbd.DISTANCES),
                    help="camera distances (m)")
    ap.add_argument("--elevated", action="store_true",
                    help=f"the cameras alternate between level and {rgbd.ELEVATED:g} degrees above")
    ap.add_argument("--methods", nargs="+", default=list(rgbd.METHODS), choices=list(rgbd.METHODS))
    ap.add_argument("--workers", type=int, default=min(2, os.cpu_count() or 1))
    ap.add_argument("--trials", nargs="+", default=None, help="these trials instead of the split's")
    ap.add_argument("--max-trials", type=int, default=None, help="at most this many of the trials, spread")
    ap.add_argument("--fold", default=None,
                    help="a cross-action fold: this MANIFEST class's trials, lifted with its fold's priors")
    ap.add_argument("--folds", type=Path, default=Path("out/cross_action/folds"),
                    help="the fold priors' directory (tools/cross_action.py)")
    ap.add_argument("--set", action="append", default=[], help="a LifterOptions field, e.g. prior_weight_z=2")
    ap.add_argument("--bases", default=None, help="hybrid bases (default: the packaged ones)")
    ap.add_argument("--out", type=Path, default=Path("out/rgbd_accuracy"))
    ap.add_argument("--merge", type=Path, nargs="+", default=None,
                    help="the mean table of these runs' directories (e.g. one per cross-action fold)")
    ap.add_argument("--calibrate", action="store_true",
                    help="measure the fusion's constants on the training split's held-out trials instead "
                         "(pose_lifter.mocap.depth_calibration; make depth-calibration) and print them")
    return ap


def fold_settings(cls: str, folds: Path) -> dict[str, Any]:
    """The LifterOptions of a cross-action fold: its single-frame prior and, when trained, its
    causal temporal prior (else the temporal prior off, as ``tools/cross_action.py`` without
    ``--temporal``: the packaged one has seen every class)."""
    prior = folds / f"{cls}.npz"
    if not prior.is_file():
        raise SystemExit(f"--fold {cls}: no fold prior {prior} (train it: tools/cross_action.py --train-only "
                         f"--classes {cls} --folds {folds})")
    temporal = folds / f"{cls}_w4.npz"
    if temporal.is_file():
        return {"prior_file": str(prior), "temporal_prior": True, "temporal_prior_file": str(temporal)}
    return {"prior_file": str(prior), "temporal_prior": False}


def _merge(runs: list[Path], out: Path) -> int:
    """Print (and write to ``out``) the mean table of the runs in ``runs``' directories."""
    records = [json.loads((r / "rgbd_accuracy.json").read_text()) for r in runs]
    methods = records[0]["methods"]
    table = rgbd.mean_table([r["table"] for r in records])
    what = ", ".join(str(r["fold"] or "eval split") for r in records)
    header = (f"RGB-D accuracy, the mean over {len(records)} runs ({what}; each weighs the same), "
              f"measured at {'; '.join(sorted({r['measured_at'] for r in records}))}")
    text = rgbd.render_table(table, methods, header)
    print(text)
    out.mkdir(parents=True, exist_ok=True)
    (out / "rgbd_accuracy.md").write_text(text + "\n")
    return 0


def main(argv: list[str] | None = None) -> int:
    args = _parser().parse_args(argv)
    warnings.simplefilter("ignore")
    t0 = time.perf_counter()
    if args.merge:
        return _merge(args.merge, args.out)
    settings = ev.parse_settings(args.set)
    trials = args.trials
    if args.fold:
        if "fused-offline" in args.methods:  # its lift reads ahead through the packaged offline prior
            raise SystemExit("--fold: fused-offline needs a fold's offline prior (the packaged one has seen "
                             "every class); leave it out of --methods")
        settings.update(fold_settings(args.fold, args.folds))
        trials = ev.action_trials(args.fold, args.data)
    split = "val" if args.calibrate else "eval"
    if args.max_trials:
        trials = trials or ev.split_ids(split, args.data)
        trials = trials[:: max(1, len(trials) // args.max_trials)][: args.max_trials]
    cameras = rgbd.rgbd_cameras((0.0, rgbd.ELEVATED) if args.elevated else (0.0,))
    if args.calibrate:  # the training split's trials the packaged prior was not fitted on
        from pose_lifter.mocap.depth_calibration import calibrate, format_calibration, smoothed_std_factor

        tracks = ev.evaluation_tracks(split, args.data, args.frames, args.views, trials, cameras)
        print(f"{len(tracks)} training-split tracks (held out of the prior), distances {args.distances}",
              flush=True)
        print(format_calibration(calibrate(tracks, args.distances, settings)), flush=True)
        factor, n = smoothed_std_factor(tracks, args.distances, settings, args.workers)
        print(f"SMOOTHED_STD_FACTOR = {factor:.3f}  # {n} coordinates")
        print(f"measured at {ev.run_stamp(REPO)}, {time.perf_counter() - t0:.0f} s")
        return 0
    tracks = ev.evaluation_tracks("eval", args.data, args.frames, args.views, trials, cameras)
    jobs = [(t, d) for d in args.distances for t in tracks]
    n_frames = sum(len(t.world) for t in tracks)
    what = f"fold {args.fold} (motion never trained on)" if args.fold else "eval split"
    print(f"{what}: {len(tracks)} tracks, {n_frames} frames per distance; {len(jobs)} jobs on "
          f"{args.workers} workers", flush=True)
    results = rgbd.evaluate_jobs(jobs, args.methods, settings, args.bases, args.workers)
    table = rgbd.summarise(results, args.distances, args.methods)
    command = " ".join(argv if argv is not None else sys.argv[1:])
    stamp = ev.run_stamp(REPO)
    header = (f"RGB-D accuracy, {what}: {len(tracks)} tracks, {n_frames} frames per distance, the realistic "
              f"detector and depth sensor (`tools/rgbd_accuracy.py {command}`); measured at {stamp}")
    text = rgbd.render_table(table, args.methods, header, f"wall time {time.perf_counter() - t0:.0f} s")
    print(text, flush=True)
    args.out.mkdir(parents=True, exist_ok=True)
    (args.out / "rgbd_accuracy.md").write_text(text + "\n")
    record = {"table": table, "settings": settings, "trials": trials, "fold": args.fold,
              "distances": args.distances, "methods": args.methods, "measured_at": stamp, "tracks": results}
    (args.out / "rgbd_accuracy.json").write_text(json.dumps(record, indent=1))
    return 0


if __name__ == "__main__":
    sys.exit(main())
