"""Whole-command wall time of lifting a collection of bags, ``pose-lifter lift DIR --out OUT``,
of this checkout and of a ``before`` checkout, side by side, alternating in every repetition.

    git worktree add --detach ../before <commit>
    OMP_NUM_THREADS=1 .venv/bin/python tools/bench_collection.py out/many36.mcap --copies 20 \\
        --before ../before --work out/coll [--reps 1] [--workers 0]

The collection is ``--copies`` hard links of ``BAG`` (distinct files to the lifter). Prints, per
code and repetition, the wall time, poses/s (poses lifted over the whole wall time: imports,
kernel loading, pools, reading, writing) and the CPU seconds of the command and its workers,
the machine's load average around each run, and the start-up: a run that lifts one message of
two small committed bags, timed twice: from its launch to the first bag task starting in a worker
("ready": imports, kernel loading, the pool; stamped by a wrapper around the checkout's
``collection.lift_one``) and to its end ("start-up": also the two tiny bags' checks, reading,
writing and the exit). ``--single`` also
times both codes on ``BAG`` alone (``lift BAG --out FILE``). ``--cores 1`` pins every command to
one core (``taskset``): the throughput of one worker, for the scaling table of docs/collections.md.
"""

from __future__ import annotations

import argparse
import os
import re
import resource
import shutil
import statistics
import subprocess
import sys
import time
from pathlib import Path

PACKAGE = Path("ros2_ws/src/pose_lifter")
REPO = Path(__file__).resolve().parents[1]
SMALL = [REPO / "bags" / "walk_clean.mcap", REPO / "bags" / "punch_clean.mcap"]


def run_command(package: Path, cmd: list[str], cores: int) -> str:
    """Run ``cmd`` with the checkout ``package`` on ``PYTHONPATH``, one BLAS thread, pinned to
    ``cores`` cores (0: all); its stdout, or exit with its stderr when it fails."""
    if cores:
        cmd = ["taskset", "-c", ",".join(str(c) for c in range(cores)), *cmd]
    env = dict(os.environ, PYTHONPATH=str(package), OMP_NUM_THREADS="1", OPENBLAS_NUM_THREADS="1")
    done = subprocess.run(cmd, env=env, capture_output=True, text=True)
    if done.returncode != 0:
        raise SystemExit(f"{' '.join(cmd)} failed ({done.returncode}):\n{done.stderr[-2000:]}")
    return done.stdout


def pose_lifter(package: Path, args: list[str], cores: int) -> tuple[float, float, str]:
    """(wall s, CPU s of the command and its children, stdout) of one ``pose-lifter`` command."""
    before = resource.getrusage(resource.RUSAGE_CHILDREN)
    t0 = time.perf_counter()
    stdout = run_command(package, [str(Path(sys.executable).parent / "pose-lifter"), *args], cores)
    wall = time.perf_counter() - t0
    after = resource.getrusage(resource.RUSAGE_CHILDREN)
    cpu = (after.ru_utime - before.ru_utime) + (after.ru_stime - before.ru_stime)
    return wall, cpu, stdout


#: Runs the ``pose-lifter`` command line of the checkout on ``PYTHONPATH`` and writes the wall
#: clock time at which the first bag task starts (in whichever process) to the file ``argv[1]``.
READY_PROBE = """
import os, sys, time
stamp = sys.argv.pop(1)
import pose_lifter.offline.collection as c
lift_one = c.lift_one
def first_task(*args, **kwargs):
    try:
        fd = os.open(stamp, os.O_WRONLY | os.O_CREAT | os.O_EXCL)
    except FileExistsError:
        pass
    else:
        os.write(fd, repr(time.time()).encode())
        os.close(fd)
    return lift_one(*args, **kwargs)
c.lift_one = first_task
from pose_lifter.cli import main
sys.argv[0] = "pose-lifter"
sys.exit(main())
"""


def ready_time(package: Path, args: list[str], cores: int, stamp: Path) -> float:
    """Seconds from launching ``pose-lifter ARGS`` (``READY_PROBE``) to its first bag task."""
    stamp.unlink(missing_ok=True)
    t0 = time.time()
    run_command(package, [sys.executable, "-c", READY_PROBE, str(stamp), *args], cores)
    return float(stamp.read_text()) - t0


def poses_of(stdout: str) -> int:
    """Poses lifted, from a one-bag line (``lifted N of``) or a collection summary (``N poses``)."""
    single = [int(x) for x in re.findall(r"lifted (\d+) of", stdout)]
    many = [int(x) for x in re.findall(r"(\d+) poses lifted", stdout)]
    return sum(single) + sum(many)


def load() -> str:
    return f"{os.getloadavg()[0]:.1f}"


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("bag")
    ap.add_argument("--before", required=True, type=Path, help="a checkout of the code before the change")
    ap.add_argument("--after", type=Path, default=REPO, help="this checkout (default)")
    ap.add_argument("--work", type=Path, required=True, help="scratch directory (inputs and outputs)")
    ap.add_argument("--copies", type=int, default=20)
    ap.add_argument("--reps", type=int, default=1)
    ap.add_argument("--workers", type=int, default=0, help="--workers of the commands (0: their default)")
    ap.add_argument("--cores", type=int, default=0, help="pin the commands to this many cores (0: all)")
    ap.add_argument("--single", action="store_true", help="also time lift BAG --out FILE alone")
    ap.add_argument("--skip-before", action="store_true", help="time this checkout only")
    ap.add_argument("--startup-only", action="store_true", help="time only the start-up runs")
    ap.add_argument("--mode", choices=("hybrid", "paper", "learned"),
                    help="--mode of the commands (default: theirs)")
    args = ap.parse_args()
    codes = {"before": args.before / PACKAGE, "after": args.after / PACKAGE}
    if args.skip_before:
        del codes["before"]
    src = args.work / "campaign"
    shutil.rmtree(src, ignore_errors=True)
    src.mkdir(parents=True)
    for i in range(args.copies):
        os.link(args.bag, src / f"bag_{i:02d}.mcap")
    extra = (["--quiet", "--overwrite"] + (["--workers", str(args.workers)] if args.workers else [])
             + (["--mode", args.mode] if args.mode else []))

    def collection(key: str) -> tuple[float, float, int]:
        run = ["lift", str(src), "--out", str(args.work / f"out_{key}"), *extra]
        wall, cpu, stdout = pose_lifter(codes[key], run, args.cores)
        return wall, cpu, poses_of(stdout)

    def tiny(out: str) -> list[str]:  # one message of each of the two small bags
        return ["lift", *map(str, SMALL), "--out", str(args.work / out), "--max-messages", "1", *extra]

    def startup(key: str) -> float:
        return pose_lifter(codes[key], tiny(f"start_{key}"), args.cores)[0]

    def ready(key: str) -> float:
        return ready_time(codes[key], tiny(f"ready_{key}"), args.cores, args.work / f"ready_{key}.stamp")

    def single(key: str) -> tuple[float, float, int]:
        run = ["lift", args.bag, "--out", str(args.work / "single.mcap"), *extra]
        wall, cpu, stdout = pose_lifter(codes[key], run, args.cores)
        return wall, cpu, poses_of(stdout)

    for key in codes:  # untimed: compiles each checkout's kernels when its cache is cold
        startup(key)
    print(f"collection: {args.copies} x {args.bag}; cores {args.cores or os.cpu_count()}, "
          f"--workers {args.workers or 'default'}, --mode {args.mode or 'default'}; "
          f"load average {load()} at the start", flush=True)
    print(f"{'what':11s} {'code':6s} {'rep':>3s} {'wall s':>8s} {'poses':>7s} {'poses/s':>8s} "
          f"{'CPU s':>7s}  load", flush=True)
    rows: dict[tuple[str, str], list[float]] = {}
    for rep in range(args.reps):
        for what, fn in (("ready", None), ("start-up", None), ("single", single if args.single else None),
                         ("collection", None if args.startup_only else collection)):
            if what in ("single", "collection") and fn is None:
                continue
            for key in codes:
                if what in ("ready", "start-up"):
                    wall = ready(key) if what == "ready" else startup(key)
                    print(f"{what:11s} {key:6s} {rep:3d} {wall:8.2f} {'':>7s} {'':>8s} {'':>7s}  {load()}",
                          flush=True)
                    rows.setdefault((what, key), []).append(wall)
                    continue
                assert fn is not None
                wall, cpu, poses = fn(key)
                rows.setdefault((what, key), []).append(poses / wall)
                print(f"{what:11s} {key:6s} {rep:3d} {wall:8.2f} {poses:7d} {poses / wall:8.0f} {cpu:7.1f}  "
                      f"{load()}", flush=True)
    unit = {"ready": " s", "start-up": " s"}
    print("medians: " + "; ".join(f"{w} {k} {statistics.median(v):.2f}{unit.get(w, ' poses/s')}"
                                  for (w, k), v in rows.items()), flush=True)
    return 0


if __name__ == "__main__":
    sys.exit(main())
