"""Wall-time phases of one ``pose-lifter lift`` run, unprofiled (issue 9's offline speed).

    OMP_NUM_THREADS=1 .venv/bin/python tools/lift_phases.py lift out/many36.mcap --out /tmp/x.mcap \
        --overwrite --quiet [--mode learned] [--workers 1]

Wraps the functions of the offline path with timers (cumulative seconds, nested phases overlap:
``lift_messages`` holds ``split_chains``, ``lift_chains`` and the message building) and prints one
``PHASES`` line on stderr at exit. ``lift_chains`` is the per-track solve (the core's time) in
one process; with workers it runs in the children and is not seen here. Inside it, ``run_kernel``
(the compiled alternations of a round of lifts, :func:`pose_lifter.core.solve.run_kernel._run_kernel_many`)
and ``prior_network`` (the learned prior's network for the poses of a round,
:meth:`pose_lifter.core.model.prior.PosePrior._forward_small`);
the rest of ``lift_chains`` is the Python around them (tracking, the lifter's set-up, results).
"""

from __future__ import annotations

import atexit
import sys
import time
from typing import Any

T0 = time.perf_counter()
acc: dict[str, float] = {}


def wrap(owner: Any, name: str, key: str | None = None) -> None:
    """Replace ``owner.name`` by a timed call (skipped when ``owner`` lacks it)."""
    f = getattr(owner, name, None)
    if f is None:
        return
    k = key or name

    def timed(*a: Any, **kw: Any) -> Any:
        t = time.perf_counter()
        try:
            return f(*a, **kw)
        finally:
            acc[k] = acc.get(k, 0.0) + time.perf_counter() - t

    setattr(owner, name, timed)


def main() -> int:
    import pose_lifter.cli as cli
    import pose_lifter.messages.convert as m
    import pose_lifter.offline.bags as bags
    import pose_lifter.offline.lift as off
    from pose_lifter.core.lift.lifter import Lifter

    acc["import"] = time.perf_counter() - T0
    wrap(Lifter, "warm_up")
    wrap(off, "check_lift_inputs")
    wrap(off, "split_chains")
    wrap(off, "lift_chains")
    try:
        import pose_lifter.core.solve.run_kernel as rk
        from pose_lifter.core.model.prior import PosePrior
    except ImportError:  # an older layout
        pass
    else:
        wrap(rk, "_run_kernel_many", "run_kernel")
        wrap(PosePrior, "_forward_small", "prior_network")
    wrap(off, "lift_messages")
    wrap(bags.BagWriter, "write", "BagWriter.write")
    wrap(bags.BagWriter, "write_cdr", "BagWriter.write_cdr")
    wrap(bags.BagWriter, "write_raw", "BagWriter.write_raw")
    wrap(bags.BagWriter, "close", "BagWriter.close")
    for n in ("result_to_skeleton3d", "skeleton_markers"):
        wrap(m, n)
    try:
        import pose_lifter.messages.cdr as c
    except ImportError:  # before pose_lifter.messages.cdr
        pass
    else:
        wrap(c.SkeletonFrame, "from_results", "SkeletonFrame.from_results")
        wrap(c, "skeleton3d_array_cdr")
        wrap(c, "marker_array_cdr")

    def report() -> None:
        acc["total"] = time.perf_counter() - T0
        print("PHASES " + " ".join(f"{k}={v:.2f}" for k, v in acc.items()), file=sys.stderr)

    atexit.register(report)
    return int(cli.main(sys.argv[1:]))


if __name__ == "__main__":
    sys.exit(main())
