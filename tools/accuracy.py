"""Accuracy of the lifter's modes on the evaluation split (``make accuracy``).

    .venv/bin/python tools/accuracy.py [--data ../shared/data/cmu] [--split eval|val]
        [--frames 120] [--views 4] [--workers 2] [--conditions clean noise0.1 ...]
        [--out out/accuracy] [--set NAME=VALUE ...] [--bases PATH]
    .venv/bin/python tools/accuracy.py --merge RUN1/accuracy.json RUN2/accuracy.json --out DIR

The tracks, conditions, methods and figures are :mod:`pose_lifter.mocap.evaluation`'s. Writes
``accuracy.md`` (the table, stamped with the git commit and the CPU model it was measured on),
``accuracy.json`` and ``accuracy.png`` to ``--out``. Deterministic (seeded corruption, one BLAS
thread per worker).
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

import numpy as np
from pose_lifter.mocap import evaluation as ev

REPO = Path(__file__).resolve().parents[1]


def _parser() -> argparse.ArgumentParser:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--data", default=None)
    ap.add_argument("--split", choices=("eval", "val"), default="eval")
    ap.add_argument("--frames", type=int, default=120, help="frames per track at 30 Hz")
    ap.add_argument("--views", type=int, default=4, help="cameras per trial (of 32)")
    ap.add_argument("--workers", type=int, default=min(2, os.cpu_count() or 1))
    ap.add_argument("--conditions", nargs="+", default=list(ev.CONDITIONS), choices=list(ev.ALL_CONDITIONS))
    ap.add_argument("--methods", nargs="+", default=list(ev.METHODS), choices=list(ev.METHODS))
    ap.add_argument("--set", action="append", default=[], help="a LifterOptions field, e.g. prior_weight_z=2")
    ap.add_argument("--bases", default=None, help="basis file (default: each mode's packaged one)")
    ap.add_argument("--trials", nargs="+", default=None,
                    help="these trials instead of the split's (e.g. a cross-action fold's class)")
    ap.add_argument("--action", default=None,
                    help="the trials of this MANIFEST action class instead of the split's")
    ap.add_argument("--max-trials", type=int, default=None, help="at most this many of the trials")
    ap.add_argument("--distance", type=float, default=ev.DISTANCE, help="camera distance (m)")
    ap.add_argument("--azimuths", type=float, nargs="+", default=None,
                    help="only these azimuths (degrees, elevation 0, --projection): cameras rotate over them")
    ap.add_argument("--projection", choices=ev.PROJECTIONS, default="perspective",
                    help="the projection of the --azimuths cameras")
    ap.add_argument("--lag", type=int, default=3, help="hybrid-lag: the node's output_lag (frames)")
    ap.add_argument("--intrinsics", action="store_true",
                    help="tracked lifts of perspective tracks know the camera's intrinsics (camera_info)")
    ap.add_argument("--merge", type=Path, nargs="+", default=None,
                    help="no lifting: join these runs' accuracy.json into one table in --out")
    ap.add_argument("--axes", action="store_true",
                    help="also P-MPJPE with the true x, y and with the true depths put in")
    ap.add_argument("--out", type=Path, default=Path("out/accuracy"))
    return ap


def main(argv: list[str] | None = None) -> int:
    args = _parser().parse_args(argv)
    if args.merge:
        try:
            table, methods, header, by_file = ev.merge_runs(args.merge)
        except ValueError as err:
            raise SystemExit(f"--merge: {err}") from None
        stamps = {json.loads(Path(f).read_text()).get("measured_at", "an unknown commit") for f in by_file}
        record = {"table": table, "merged_from": by_file}
        write(table, methods, header, "", args.out, record, " and ".join(sorted(stamps)))
        return 0
    warnings.simplefilter("ignore")
    t0 = time.perf_counter()
    trials = ev.action_trials(args.action, args.data) if args.action else args.trials
    if trials and args.max_trials:
        trials = trials[:: max(1, len(trials) // args.max_trials)][: args.max_trials]
    cameras = [(a, 0.0, args.projection) for a in args.azimuths] if args.azimuths else None
    tracks = ev.evaluation_tracks(args.split, args.data, args.frames, args.views, trials, cameras)
    methods = tuple(args.methods)
    jobs = [(t, c) for c in args.conditions for t in tracks]
    n_frames = sum(len(t.world) for t in tracks)
    print(f"{args.split} split: {len(tracks)} tracks ({len(tracks) // max(args.views, 1)} trials x "
          f"{args.views} views), {n_frames} frames per condition; {len(jobs)} jobs on {args.workers} workers",
          flush=True)
    settings = ev.parse_settings(args.set)
    setup = ev.Setup(args.distance, args.intrinsics, args.lag)
    results = ev.evaluate_jobs(jobs, methods, settings, setup, args.bases, workers=args.workers)
    table = ev.summarise(results, args.conditions, methods)
    axes = [f"{c} {m} {row[m]['p_mpjpe']:.1f} / {row[m]['true_xy']:.1f} / {row[m]['true_depth']:.1f}"
            for c, row in table.items() for m in methods if m in ev.LIFTED]
    footer = ("P-MPJPE (mm) as lifted / with the true x, y / with the true depths: " + ", ".join(axes) + "\n"
              if args.axes else "") + f"wall time {time.perf_counter() - t0:.0f} s"
    header = (f"{args.split} split, {len(tracks)} tracks, {n_frames} frames per condition "
              f"(`tools/accuracy.py {' '.join(argv if argv is not None else sys.argv[1:])}`)")
    write(table, methods, header, footer, args.out,
          {"table": table, "settings": settings, "split": args.split if not trials else "trials",
           "trials": trials, "distance": args.distance, "cameras": cameras}, ev.run_stamp(REPO))
    return 0


def write(table: dict[str, dict[str, dict[str, float]]], methods: tuple[str, ...], header: str, footer: str,
          out: Path, record: dict[str, Any], stamp: str) -> None:
    """Print the table and write ``accuracy.md`` (its header followed by ``stamp``: the commit
    and the CPU model it was measured on), ``accuracy.json`` (``record`` and the stamp) and
    ``accuracy.png``."""
    text = ev.render_table(table, methods, f"{header}; measured at {stamp}", footer)
    print(text, flush=True)
    out.mkdir(parents=True, exist_ok=True)
    (out / "accuracy.md").write_text(text + "\n")
    (out / "accuracy.json").write_text(json.dumps({**record, "measured_at": stamp}, indent=1))
    plot(table, methods, out / "accuracy.png")


def plot(table: dict[str, dict[str, dict[str, float]]], methods: tuple[str, ...], path: Path) -> None:
    """A bar chart of each condition's P-MPJPE per method."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    conds = list(table)
    fig, ax = plt.subplots(figsize=(10, 4))
    width = 0.8 / len(methods)
    for i, m in enumerate(methods):
        ax.bar(np.arange(len(conds)) + i * width, [table[c][m]["p_mpjpe"] for c in conds], width, label=m)
    ax.set_xticks(np.arange(len(conds)) + 0.4 - width / 2, conds)
    ax.set_ylabel("P-MPJPE (mm)")
    ax.set_title("Evaluation split (subjects 02, 07, 08, 09_12), tracked at 30 Hz")
    ax.legend(ncol=len(methods), fontsize=8)
    fig.tight_layout()
    fig.savefig(path, dpi=100)


if __name__ == "__main__":
    sys.exit(main())
