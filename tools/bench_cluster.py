"""What the Dask path costs: the scheduler's overhead per task, and a collection lifted on a
localhost cluster of W worker processes against the local pool, side by side.

    OMP_NUM_THREADS=1 .venv/bin/python tools/bench_cluster.py BAG --copies 4 --workers 1 2 \\
        --work out/cluster [--max-messages N]

For each W: a ``distributed.LocalCluster`` of W processes (one thread each) on this machine;
the round trip of 200 empty tasks (submit -> result, the scheduler's cost per task); then the
collection (``--copies`` hard links of ``BAG``) lifted through it (``lift_collection(...,
scheduler=...)``, the workers load the lifter themselves: their start-up is in the figure) and
by the local pool of W processes (``workers=W``), alternating. Prints poses/s of each over the
lifting's wall time (the command's imports are not in either) and the load average.
"""

from __future__ import annotations

import argparse
import os
import shutil
import sys
import time
from pathlib import Path


def noop(x: int) -> int:
    return x


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("bag")
    ap.add_argument("--copies", type=int, default=4)
    ap.add_argument("--workers", type=int, nargs="+", default=[1, 2])
    ap.add_argument("--work", type=Path, required=True)
    ap.add_argument("--max-messages", type=int, default=None)
    args = ap.parse_args()
    import distributed
    from pose_lifter.core.numeric.threads import one_blas_thread
    from pose_lifter.core.options import LifterOptions
    from pose_lifter.offline.collection import LiftSettings, lift_collection

    one_blas_thread()
    src = args.work / "campaign"
    shutil.rmtree(src, ignore_errors=True)
    src.mkdir(parents=True)
    for i in range(args.copies):
        os.link(args.bag, src / f"bag_{i:02d}.mcap")
    settings = LiftSettings(options=LifterOptions(), max_messages=args.max_messages)
    print(f"collection: {args.copies} x {args.bag}; load average {os.getloadavg()[0]:.1f}", flush=True)
    print(f"{'workers':>7s} {'path':6s} {'s':>7s} {'poses':>7s} {'poses/s':>8s}  load", flush=True)
    for w in args.workers:
        with distributed.LocalCluster(n_workers=w, threads_per_worker=1, processes=True,
                                      dashboard_address=":0") as cluster, \
                distributed.Client(cluster.scheduler_address) as client:
            client.gather(client.map(noop, range(20), pure=False))  # connections up
            t0 = time.perf_counter()
            futures = [client.submit(noop, i, pure=False) for i in range(200)]
            client.gather(futures)
            per_task = (time.perf_counter() - t0) / 200
            print(f"{w:7d} task   {per_task * 1e3:7.2f} ms per empty task (200, submitted at once)",
                  flush=True)
            for path in ("dask", "local"):
                out = args.work / f"out_{path}_{w}"
                s = lift_collection([str(src)], out, settings, workers=w, overwrite=True, progress=False,
                                    scheduler=cluster.scheduler_address if path == "dask" else None)
                print(f"{w:7d} {path:6s} {s.seconds:7.2f} {s.n_poses:7d} {s.poses_per_s:8.0f}  "
                      f"{os.getloadavg()[0]:.1f}", flush=True)
    return 0


if __name__ == "__main__":
    sys.exit(main())
