"""End-to-end wall time of ``pose-lifter lift`` before/after a change, side by side (issue 9).

    git worktree add --detach /tmp/before <commit>
    OMP_NUM_THREADS=1 .venv/bin/python tools/bench_lift.py out/many36.mcap \\
        --before /tmp/before --reps 3 [--modes learned hybrid] [--workers 1 0] [--variant L1NAWS]

Runs the installed ``pose-lifter`` of this virtualenv with ``PYTHONPATH`` pointing at the
``before`` checkout's package (its code, this environment) and at this checkout's, alternating
before/after in every repetition so that a loaded machine hurts both alike; prints the median
wall time, poses/s and CPU seconds (user + system of the command and its workers: less
sensitive to other jobs than wall time) per (mode, workers) and code. ``--workers 0`` is the
default (the cores). The first run of a checkout compiles its solver kernels (~40 s): one
untimed run of each checkout comes first (``--no-warm-up`` skips it).
"""

from __future__ import annotations

import argparse
import os
import re
import resource
import statistics
import subprocess
import sys
import time
from pathlib import Path

PACKAGE = Path("ros2_ws/src/pose_lifter")


def run(package: Path, bag: str, mode: str, workers: int, variant: str = "full") -> tuple[float, float, int]:
    """(wall seconds, CPU seconds, poses lifted) of one ``pose-lifter lift`` of ``bag`` (the paper's
    ``variant``)."""
    cmd = [str(Path(sys.executable).parent / "pose-lifter"), "lift", bag, "--out", "/tmp/bench_lift.mcap",
           "--overwrite", "--quiet", "--mode", mode, "--variant", variant]
    if workers:
        cmd += ["--workers", str(workers)]
    env = dict(os.environ, PYTHONPATH=str(package), OMP_NUM_THREADS="1")
    before = resource.getrusage(resource.RUSAGE_CHILDREN)
    t0 = time.perf_counter()
    out = subprocess.run(cmd, env=env, check=True, capture_output=True, text=True).stdout
    wall = time.perf_counter() - t0
    after = resource.getrusage(resource.RUSAGE_CHILDREN)
    cpu = (after.ru_utime - before.ru_utime) + (after.ru_stime - before.ru_stime)
    match = re.search(r"lifted (\d+) of", out)
    return wall, cpu, int(match.group(1)) if match else 0


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("bag")
    ap.add_argument("--before", required=True, type=Path, help="a checkout of the code before the change")
    ap.add_argument("--after", type=Path, default=Path.cwd(), help="this checkout (default)")
    ap.add_argument("--reps", type=int, default=3)
    ap.add_argument("--modes", nargs="+", default=["learned", "hybrid"])
    ap.add_argument("--workers", nargs="+", type=int, default=[1, 0])
    ap.add_argument("--variant", default="full", help="the paper's variant (the paper mode's ablations)")
    ap.add_argument("--no-warm-up", action="store_true")
    args = ap.parse_args()
    codes = {"before": args.before / PACKAGE, "after": args.after / PACKAGE}
    if not args.no_warm_up:
        for package in codes.values():
            run(package, args.bag, args.modes[0], 1, args.variant)  # compiles its kernels if needed
    print(f"{'mode':8s} {'workers':>7s} {'code':6s} {'median s':>9s} {'poses/s':>8s} {'CPU s':>7s}  runs (s)",
          flush=True)
    for mode in args.modes:
        for workers in args.workers:
            times: dict[str, list[float]] = {k: [] for k in codes}
            cpus: dict[str, list[float]] = {k: [] for k in codes}
            poses = 0
            for _ in range(args.reps):
                for key, package in codes.items():
                    wall, cpu, poses = run(package, args.bag, mode, workers, args.variant)
                    times[key].append(wall)
                    cpus[key].append(cpu)
            for key in codes:
                med = statistics.median(times[key])
                runs = " ".join(f"{t:.2f}" for t in times[key])
                print(f"{mode:8s} {workers or 'default':>7} {key:6s} {med:9.2f} {poses / med:8.0f} "
                      f"{statistics.median(cpus[key]):7.2f}  {runs}", flush=True)
    return 0


if __name__ == "__main__":
    sys.exit(main())
