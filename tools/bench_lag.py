"""What the node's ``output_lag`` costs: the frame pipeline over a committed bag, as the node runs
it, without a lag and with one, side by side in one run.

    .venv/bin/python tools/bench_lag.py [--bag bags/five_people.mcap] [--lags 0 3] [--reps 3]

Per lag: CPU time per person-frame of the whole pipeline (check, lift, placement and, with a
lag, the refinement of each held frame: :class:`pose_lifter.messages.lagged.LaggedFrames`; from a
lag of 6 the lift reads 3 frames ahead),
median over ``--reps`` passes (the first pass, which compiles and loads, is not counted), and
the share of it the refinement takes. Single process, one BLAS thread.
"""

from __future__ import annotations

import argparse
import os
import sys
import time
from pathlib import Path
from typing import Any

os.environ.setdefault("OMP_NUM_THREADS", "1")
os.environ.setdefault("OPENBLAS_NUM_THREADS", "1")

import numpy as np
from pose_lifter.core import Lifter, LifterOptions
from pose_lifter.messages import convert as m
from pose_lifter.messages.frame import FramePipeline, FrameSettings, LiftedSkeleton
from pose_lifter.messages.lagged import LaggedFrames
from pose_lifter.messages.names import TOPIC_CAMERA_INFO, TOPIC_KEYPOINTS
from pose_lifter.offline.bags import read_messages

REPO = Path(__file__).resolve().parents[1]


def one_pass(lifter: Lifter, frames: list[tuple[int, object]], intrinsics: object, lag: int
             ) -> tuple[float, float, int]:
    """CPU seconds of the whole pass, of the lag's refinement alone, and person-frames answered."""
    pipeline = FramePipeline(lifter, FrameSettings())
    lagged: LaggedFrames[int] | None = LaggedFrames(pipeline, lag) if lag else None
    total = refine = 0.0
    answered = 0
    for i, (stamp, msg) in enumerate(frames):
        t0 = time.process_time()
        checked = pipeline.check(msg)
        if lagged is None:
            answered += sum(isinstance(x, LiftedSkeleton) for x in pipeline.frame(checked, stamp, intrinsics))  # type: ignore[arg-type]
            total += time.process_time() - t0
            continue
        answered += sum(len(f.lifted) for f in lagged.lift(i, stamp, intrinsics, checked))  # type: ignore[arg-type]
        total += time.process_time() - t0
    if lagged is not None:
        t0 = time.process_time()
        answered += sum(len(f.lifted) for f in lagged.flush())
        total += time.process_time() - t0
        refine, REFINE[0] = REFINE[0], 0.0
    return total, refine, answered


#: CPU seconds in the lag's refinement (LaggedFrames._hold and a flush's _refined), timed by
#: wrapping them here.
REFINE = [0.0]
_DEPTH = [0]


def _timed(fn: Any) -> Any:
    def wrapper(*args: Any, **kwargs: Any) -> Any:
        t0 = time.process_time()
        _DEPTH[0] += 1
        try:
            return fn(*args, **kwargs)
        finally:
            _DEPTH[0] -= 1
            if not _DEPTH[0]:
                REFINE[0] += time.process_time() - t0
    return wrapper


LaggedFrames._hold = _timed(LaggedFrames._hold)  # type: ignore[method-assign]
LaggedFrames._refined = _timed(LaggedFrames._refined)  # type: ignore[method-assign]


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--bag", type=Path, default=REPO / "bags" / "five_people.mcap")
    ap.add_argument("--lags", type=int, nargs="+", default=[0, 3])
    ap.add_argument("--reps", type=int, default=3)
    args = ap.parse_args(argv)
    recorded = list(read_messages(args.bag, [TOPIC_KEYPOINTS, TOPIC_CAMERA_INFO]))
    frames = [(x.stamp_ns, x.msg) for x in recorded if x.topic == TOPIC_KEYPOINTS]
    info = next((x.msg for x in recorded if x.topic == TOPIC_CAMERA_INFO), None)
    intrinsics = m.intrinsics_from_camera_info(info) if info is not None else None
    lifter = Lifter(options=LifterOptions())
    lifter.warm_up()
    print(f"{args.bag.name}: {len(frames)} frames; CPU ms per person-frame, median of {args.reps} passes")
    print("| output_lag | whole pipeline | the lag's refinement | person-frames |")
    print("|---|---|---|---|")
    for lag in args.lags:
        one_pass(lifter, frames, intrinsics, lag)  # compiles and loads
        runs = [one_pass(lifter, frames, intrinsics, lag) for _ in range(args.reps)]
        n = runs[0][2]
        whole = 1000.0 * float(np.median([r[0] for r in runs])) / n
        refine = 1000.0 * float(np.median([r[1] for r in runs])) / n
        print(f"| {lag} | {whole:.3f} | {refine:.3f} | {n} |")
    return 0


if __name__ == "__main__":
    sys.exit(main())
