"""Speed benchmark of the lifter on the committed bags (``make bench``).

Prints, in one run, for the default hybrid mode and beside it the paper's method alone:

* warm-started tracking latency per person-frame (the node's use: each track through the core's
  per-track policy ``TrackPolicy``), median / p95 / max, with the mean objective and the
  P-MPJPE against the bags' ground truth (right-lower-leg units);
* cold-start latency with the default multi-start (``n_starts`` k-means centres);
* fast path vs the cvxpy+Clarabel reference path (``camera_solver=pose_solver="cvxpy"``: the
  same alternation and pose ADM with every Q-step solved by Clarabel and the camera by the
  reference L1 camera solver) on a few frames: time ratio, objective and 3D-error agreement;
* offline throughput (poses/s) of per-track warm-started lifting, in one process and with a
  process pool over tracks, and whether the pooled results are identical;
* peak resident memory (``resource.getrusage``).

``--prior-rows [N ...]`` prints instead the learned priors' layer pass per row at these row counts
and this CPU's facts (``make bench-prior``, :func:`prior_rows`).

BLAS threads are pinned to 1 (threadpoolctl). Times are wall-clock ``perf_counter``; on a
loaded machine they are pessimistic (the CPU time is printed beside them).

Usage::

    python tools/bench.py [--bags bags/*.mcap] [--frames N] [--cold N] [--ref-frames N]
    python tools/bench.py --prior-rows [1 2 8 32 72] [--reps 5]
"""

from __future__ import annotations

import argparse
import functools
import glob
import multiprocessing
import os
import platform
import resource
import statistics
import sys
import time
import warnings
from collections import defaultdict
from collections.abc import Callable, Sequence
from concurrent.futures import ProcessPoolExecutor
from dataclasses import dataclass
from pathlib import Path
from typing import Any

os.environ.setdefault("OMP_NUM_THREADS", "1")
os.environ.setdefault("OPENBLAS_NUM_THREADS", "1")

import numpy as np
from numpy.typing import NDArray
from pose_lifter.core.errors import InvalidInputError, PoseLifterError
from pose_lifter.core.lift.lifter import Lifter
from pose_lifter.core.model.bases import PoseBases, default_bases_path
from pose_lifter.core.model.metrics import p_mpjpe
from pose_lifter.core.model.skeleton import normalise_pose
from pose_lifter.core.options import LifterOptions
from pose_lifter.core.results import LiftResult
from pose_lifter.core.track.policy import TrackPolicy
from pose_lifter.messages import convert as m
from pose_lifter.messages.names import TOPIC_GROUND_TRUTH, TOPIC_KEYPOINTS
from pose_lifter.offline.bags import read_messages
from threadpoolctl import threadpool_limits

REPO = Path(__file__).resolve().parents[1]
Arr = NDArray[np.float64]


@dataclass
class Track:
    """One person's frames from one bag: 2D input and (if present) ground truth."""

    name: str
    points: list[Arr]
    confidence: list[Arr]
    truth: list[Arr | None]


def load_tracks(paths: Sequence[str], max_frames: int) -> list[Track]:
    """Per-(bag, track id) sequences of 12-joint 2D keypoints with ground truth."""
    tracks: list[Track] = []
    for path in paths:
        inp: dict[int, list[tuple[int, Arr, Arr]]] = defaultdict(list)
        gt: dict[tuple[int, int], Arr] = {}
        for x in read_messages(path, [TOPIC_KEYPOINTS]):
            s = m.stamp_to_ns(x.msg.header.stamp)
            for sk in x.msg.skeletons:
                try:
                    pts, conf = m.skeleton2d_to_arrays(sk, x.msg.layout)
                except InvalidInputError:
                    continue
                inp[int(sk.track_id)].append((s, pts, conf))
        try:
            for x in read_messages(path, [TOPIC_GROUND_TRUTH]):
                s = m.stamp_to_ns(x.msg.header.stamp)
                for sk in x.msg.skeletons:
                    gt[(s, int(sk.track_id))] = m.skeleton3d_to_joints(sk)
        except Exception:  # bags without ground truth: no error column
            pass
        for tid, frames in sorted(inp.items()):
            frames = frames[:max_frames]
            tracks.append(Track(f"{Path(path).stem}#{tid}", [f[1] for f in frames], [f[2] for f in frames],
                                [gt.get((f[0], tid)) for f in frames]))
    return tracks


def error(res: LiftResult, truth: Arr | None) -> float:
    """P-MPJPE in right-lower-leg units (NaN without ground truth)."""
    if truth is None:
        return float("nan")
    return float(p_mpjpe(res.pose, normalise_pose(truth)))


def pct(a: Sequence[float], q: float) -> float:
    return float(np.percentile(np.asarray(a), q)) if len(a) else float("nan")


def lift_track(lifter: Lifter, tr: Track, warm_start: bool = True
               ) -> tuple[list[LiftResult | None], list[float], list[float], list[bool]]:
    """Lift a track frame by frame at 30 Hz through the node's per-track policy
    (:class:`pose_lifter.core.track.policy.TrackPolicy`)."""
    results: list[LiftResult | None] = []
    wall: list[float] = []
    cpu: list[float] = []
    warmed: list[bool] = []
    policy = TrackPolicy(lifter, warm_start=warm_start)
    for i, (pts, conf) in enumerate(zip(tr.points, tr.confidence, strict=True)):
        t0, c0 = time.perf_counter(), time.process_time()
        try:
            tracked = policy.lift(0, i * 33_333_333, pts, conf)  # 30 Hz
            res: LiftResult | None = tracked.result
            was_warm = tracked.warm_started
        except PoseLifterError:
            res, was_warm = None, False
        wall.append(time.perf_counter() - t0)
        cpu.append(time.process_time() - c0)
        warmed.append(was_warm)
        results.append(res)
    return results, wall, cpu, warmed


#: The lifter of the pool workers, inherited through fork (as in pose_lifter.offline.lift).
_POOL: dict[str, Lifter] = {}


def _pool_worker(tr: Track) -> list[tuple[Arr, float] | None]:
    with threadpool_limits(1):
        res, *_ = lift_track(_POOL["lifter"], tr)
    return [None if r is None else (r.pose, r.objective) for r in res]


def row(label: str, wall_ms: Sequence[float], cpu_ms: Sequence[float]) -> str:
    return (f"  {label:<34s} n={len(wall_ms):4d}  median {pct(wall_ms, 50):9.1f}  p95 {pct(wall_ms, 95):9.1f}"
            f"  max {pct(wall_ms, 100):9.1f} ms   (cpu median {pct(cpu_ms, 50):.1f} ms)")


def cpu_model() -> str:
    """The CPU's model name as /proc/cpuinfo gives it (else the platform's processor string)."""
    info = Path("/proc/cpuinfo")
    if info.is_file():
        for line in info.read_text().splitlines():
            if line.startswith("model name"):
                return line.split(":", 1)[1].strip()
    return platform.processor() or "unknown"


def blas_forward(prior: Any, x: NDArray[np.float32]) -> NDArray[np.float32]:
    """The prior's hidden and output layers (before de-standardising) through numpy's matrix
    products in float32."""
    layers = prior._layers32
    h = np.maximum(x @ layers[0][0] + layers[0][1], 0.0)
    for k in range(prior.blocks):
        (wa, ba), (wb, bb) = layers[1 + 2 * k], layers[2 + 2 * k]
        h = h + np.maximum(np.maximum(h @ wa + ba, 0.0) @ wb + bb, 0.0)
    out: NDArray[np.float32] = h @ layers[-1][0] + layers[-1][1]
    return out


def per_row_us(f: Callable[[], Any], rows: int, reps: int) -> float:
    """Median over ``reps`` timings of ``f`` (each repeated to about 600 rows), microseconds per row."""
    f()
    calls = max(1, 600 // rows)
    times = []
    for _ in range(reps):
        t = time.perf_counter()
        for _ in range(calls):
            f()
        times.append((time.perf_counter() - t) / calls / rows * 1e6)
    return statistics.median(times)


def inputs(prior: Any, rows: int, rng: np.random.Generator) -> NDArray[np.float32]:
    """The network's inputs (rows, 36 * window) for random 2D skeletons, one joint in ten missing."""
    w = prior.window
    pts = rng.normal(size=(rows, w, 12, 2))
    vis = rng.random((rows, w, 12)) > 0.1
    vis[..., :2] = True
    feats = [prior.features(pts[i, 0] if w == 1 else pts[i], vis[i, 0] if w == 1 else vis[i])[0]
             for i in range(rows)]
    return np.ascontiguousarray(np.stack(feats), dtype=np.float32)


def prior_rows(rows: Sequence[int], reps: int) -> int:
    """``--prior-rows``: the learned priors' layer pass per row at a few row counts, compiled
    (:meth:`PosePrior._forward_small`, what the lift runs) and through numpy's float32 matrix
    products (BLAS), for random 2D skeletons (one joint in ten missing); the median of ``reps``
    timings of ~600 rows each. One row reads every weight (4-5 MB): at 1 row the pass is bound by
    reading them, at many by arithmetic. Then the CPU model, numba's target, OpenBLAS's kernel and
    whether any weight is subnormal: what differs between machines (docs/bench.md)."""
    from pose_lifter.core.model.prior import DEFAULT_OFFLINE_PRIOR_PATH, PosePrior

    rng = np.random.default_rng(0)
    print(f"CPU: {cpu_model()}")
    try:
        import llvmlite.binding as llvm

        print(f"numba's target: {llvm.get_host_cpu_name()}")
    except ImportError:
        print("numba's target: numba not installed (the layer pass runs as numpy)")
    try:
        from threadpoolctl import threadpool_info

        blas = [f"{i.get('internal_api')} {i.get('version')} kernel {i.get('architecture')}, "
                f"{i.get('num_threads')} threads" for i in threadpool_info() if i.get("user_api") == "blas"]
        print(f"BLAS: {'; '.join(blas) or 'not found'}")
    except ImportError:
        print("BLAS: threadpoolctl not installed")
    for name, path in (("node's prior", None), ("offline prior", DEFAULT_OFFLINE_PRIOR_PATH)):
        prior = PosePrior.load(path)
        layers = prior._layers32
        size = sum(w.nbytes + b.nbytes for w, b in layers)
        tiny = np.finfo(np.float32).tiny
        sub = sum(int(np.count_nonzero((w != 0) & (np.abs(w) < tiny))) for w, _ in layers)
        print(f"\n{name}: window {prior.window}, {len(layers)} layers, "
              f"{size / 1e6:.2f} MB of float32 weights, {sub} subnormal")
        print(f"{'rows':>5}  {'compiled us/row':>15}  {'BLAS us/row':>11}")
        for n in rows:
            x = inputs(prior, n, rng)
            compiled = per_row_us(functools.partial(prior._forward_small, x), n, reps)
            gemm = per_row_us(functools.partial(blas_forward, prior, x), n, reps)
            print(f"{n:5d}  {compiled:15.1f}  {gemm:11.1f}")
    return 0




def main(argv: Sequence[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--bags", nargs="*", default=sorted(glob.glob(str(REPO / "bags" / "*.mcap"))))
    ap.add_argument("--frames", type=int, default=30, help="frames per track for the tracking run")
    ap.add_argument("--cold", type=int, default=6, help="cold-start frames (spread over the tracks)")
    ap.add_argument("--ref-frames", type=int, default=2, help="frames for the reference comparison")
    ap.add_argument("--ref-alternations", type=int, default=2,
                    help="alternations of both paths in the reference comparison (the reference is slow)")
    ap.add_argument("--workers", type=int, default=2)
    ap.add_argument("--prior-rows", type=int, nargs="*", default=None, metavar="N",
                    help="only the priors' layer pass per row at these row counts (default 1 2 8 32 72)")
    ap.add_argument("--reps", type=int, default=5, help="--prior-rows: timings per row count")
    a = ap.parse_args(argv)
    if a.prior_rows is not None:
        return prior_rows(a.prior_rows or [1, 2, 8, 32, 72], a.reps)
    warnings.filterwarnings("ignore")
    threadpool_limits(1)
    bases = PoseBases.load()
    tracks = load_tracks(a.bags, a.frames)
    n_frames = sum(len(t.points) for t in tracks)
    print(f"bench: {len(a.bags)} bags, {len(tracks)} tracks, {n_frames} person-frames; BLAS threads 1; "
          f"load average {os.getloadavg()[0]:.1f} on {os.cpu_count()} cpus")
    modes = (("hybrid (default)", LifterOptions()), ("paper's method", LifterOptions(mode="paper")))
    for label, opts in modes:
        bench_options(label, opts, a, PoseBases.load(default_bases_path(opts.mode)), tracks)

    # 4. fast vs reference path on a few frames, same options apart from the solvers
    if a.ref_frames > 0:
        reference_comparison(bases, tracks, a.ref_frames, a.ref_alternations)

    kb = resource.getrusage(resource.RUSAGE_SELF).ru_maxrss
    kb_c = resource.getrusage(resource.RUSAGE_CHILDREN).ru_maxrss
    print(f"\npeak RSS: {kb / 1024:.0f} MB (this process), {kb_c / 1024:.0f} MB (largest pool worker)")
    return 0


def bench_options(label: str, opts: LifterOptions, a: argparse.Namespace, bases: PoseBases,
                  tracks: list[Track]) -> None:
    """Sections 1-3 (tracking latency, cold starts, offline throughput) for one option set."""
    print(f"\n=== {label}: mode={opts.mode} (n_starts={opts.n_starts}, n_refine={opts.n_refine}, "
          f"max_alternations={opts.max_alternations})")

    # 1. warm-started tracking (first frame of each track is cold and reported separately)
    lf = Lifter(bases, opts)
    lf.warm_up()  # compile / load the kernels first, as the node does before it subscribes
    wall_w: list[float] = []
    cpu_w: list[float] = []
    wall_c: list[float] = []
    cpu_c: list[float] = []
    errs: list[float] = []
    objs: list[float] = []
    for tr in tracks:
        res, wall, cpu, warmed = lift_track(lf, tr)
        for r, w_, c_, wm, gt in zip(res, wall, cpu, warmed, tr.truth, strict=True):
            (wall_w if wm else wall_c).append(1e3 * w_)
            (cpu_w if wm else cpu_c).append(1e3 * c_)
            if r is not None:
                errs.append(error(r, gt))
                objs.append(r.objective)
    print("\nfast path, per person-frame:")
    print(row("warm-started tracking", wall_w, cpu_w))
    print(row("cold (first frame of a track)", wall_c, cpu_c))

    # 2. cold starts with the full multi-start on frames spread over the tracks
    wall_k: list[float] = []
    cpu_k: list[float] = []
    picks = [(t, i) for t in tracks for i in range(0, len(t.points), max(1, len(t.points) // 2))][: a.cold]
    for tr, i in picks:
        t0, c0 = time.perf_counter(), time.process_time()
        try:
            lf.lift(tr.points[i], tr.confidence[i])
        except PoseLifterError:
            continue
        wall_k.append(1e3 * (time.perf_counter() - t0))
        cpu_k.append(1e3 * (time.process_time() - c0))
    print(row(f"cold, {opts.n_starts}-start multi-start", wall_k, cpu_k))
    print(f"  tracking quality: mean objective {np.mean(objs):.4f}, P-MPJPE vs ground truth "
          f"{np.nanmean(errs):.4f} (right-lower-leg units) over {len(errs)} frames")

    # 3. offline throughput over every frame of the bags: one process, and a fork pool over
    #    tracks (the chains of `pose-lifter lift --workers N`); identical results?
    full_tracks = load_tracks(a.bags, 10**9)
    n_full = sum(len(t.points) for t in full_tracks)
    lf_off = Lifter(bases, opts)
    lf_off.warm_up()
    t0 = time.perf_counter()
    single = [[None if r is None else (r.pose, r.objective) for r in lift_track(lf_off, tr)[0]]
              for tr in full_tracks]
    t_single = time.perf_counter() - t0
    print(f"\noffline, every frame of the bags ({len(full_tracks)} tracks, {n_full} person-frames; per-track "
          f"warm starts, a track's first frame cold):")
    print(f"  1 process:    {n_full / t_single:8.1f} poses/s")
    order = sorted(range(len(full_tracks)), key=lambda i: len(full_tracks[i].points), reverse=True)
    _POOL["lifter"] = lf_off
    t0 = time.perf_counter()
    with ProcessPoolExecutor(max_workers=a.workers, mp_context=multiprocessing.get_context("fork")) as ex:
        pooled_in_order = list(ex.map(_pool_worker, [full_tracks[i] for i in order]))
    t_pool = time.perf_counter() - t0
    _POOL.clear()
    pooled: list[list[tuple[Arr, float] | None]] = [[] for _ in full_tracks]
    for i, res in zip(order, pooled_in_order, strict=True):
        pooled[i] = res
    same = all(
        (p is None and r is None) or (p is not None and r is not None and np.array_equal(p[0], r[0])
                                      and p[1] == r[1])
        for pr, rr in zip(pooled, single, strict=True) for p, r in zip(pr, rr, strict=True)
    )
    longest = max(len(t.points) for t in full_tracks)
    print(f"  {a.workers} processes: {n_full / t_pool:8.1f} poses/s (incl. pool start-up; bounded by the "
          f"longest track, {longest} frames, whose warm-start chain is sequential), results identical to "
          f"one process: {same}")


def reference_comparison(bases: PoseBases, tracks: list[Track], n_frames: int, n_alt: int) -> None:
    """Fast and reference paths on the first frames of the first track (same start, options).

    The reference is the paper's algorithm with its convex subproblems handed to cvxpy + Clarabel
    (every Q-step of the inner alpha-step ADM) and the camera step to the reference camera solver.
    The fast paths run the same alternation from the same start; differences come from the
    subproblem solvers (closed forms, capped ADMs, another alpha-step algorithm) and, the problem
    being nonconvex, from the local minima these lead to. Objective differences are signed:
    negative = the fast path ends lower (better) than the reference.
    """
    print(f"\nfast vs cvxpy+Clarabel reference ({n_frames} frames, one start, "
          f"{n_alt} alternations; the reference runs the paper's inner ADM alpha-step with cvxpy "
          "Q-steps):")
    base = LifterOptions(mode="paper", n_starts=1, max_alternations=n_alt, warm_flip=False)
    ref_label = "reference (Clarabel Q-step, reference camera)"
    variants = {
        "fast (compiled run, Riemannian alpha-step)": base,
        ref_label: base.replace(camera_solver="cvxpy", pose_solver="cvxpy"),
    }
    frames = [(tr, i) for tr in tracks[:1] for i in range(min(n_frames, len(tr.points)))]
    out: dict[str, tuple[list[float], list[float], list[float]]] = {}
    for label, o in variants.items():
        lfv = Lifter(bases, o)
        lfv.lift(frames[0][0].points[0], frames[0][0].confidence[0])  # compile / load kernels
        ts, ob, er = [], [], []
        for tr, i in frames:
            t0 = time.perf_counter()
            r = lfv.lift(tr.points[i], tr.confidence[i])
            ts.append(1e3 * (time.perf_counter() - t0))
            ob.append(r.objective)
            er.append(error(r, tr.truth[i]))
        out[label] = (ts, ob, er)
        print(f"  {label:<46s} median {pct(ts, 50):10.1f} ms  objective {np.mean(ob):.4f}  "
              f"P-MPJPE {np.nanmean(er):.4f}")
    ref = out[ref_label]
    for label in list(variants)[:-1]:
        ts, ob, er = out[label]
        d_obj = (np.array(ob) - ref[1]) / np.abs(ref[1])
        d_err = (np.array(er) - ref[2]) / np.array(ref[2])
        ok = int(np.sum(d_obj <= 0.01))
        print(f"  {label}: {pct(ref[0], 50) / pct(ts, 50):8.1f}x faster; objective vs reference "
              f"{', '.join(f'{d:+.1%}' for d in d_obj)} (<= +1 % on {ok} of {len(ob)}); 3D error "
              f"{', '.join(f'{d:+.1%}' for d in d_err)}")


if __name__ == "__main__":
    sys.exit(main())
