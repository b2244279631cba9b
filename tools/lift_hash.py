"""A stable hash of what the solver computes, to prove that a refactor changes no result.

Usage::

    .venv/bin/python tools/lift_hash.py [--bags bags/*.mcap] [--max-messages N] [--starts N]
        [--modes paper hybrid learned] [-v]

Four sections, each a sha256 of float64 values rounded to ``1e-9`` (``--decimals``), and a total:

* ``lifts paper`` / ``lifts hybrid``: every committed bag lifted offline the way ``pose-lifter
  lift`` does (:func:`pose_lifter.offline.lift.lift_messages`: per-track warm starts through the
  node's per-track policy, metric placement from ``/camera_info``), in ``mode="paper"`` and
  ``mode="hybrid"`` (``--modes``: ``learned`` can be added, or lifted alone; either changes the
  total). Per lifted skeleton (in message and track order): stamp, track id,
  warm-started flag, the metric joints, the model-frame pose, the coefficients, the camera
  (rotation, scale, translation), the objective, reprojection error, limb violation and the
  alternation counts. Failed skeletons enter with their error message.
* ``metrics``: the lifted metric joints of both modes against the bags' ground truth (matched
  by stamp and track id): :func:`~pose_lifter.core.model.metrics.mpjpe`, ``p_mpjpe``,
  ``normalised_error`` and ``procrustes_align`` per skeleton, and the floors of
  :func:`pose_lifter.offline.evaluate.evaluate_bag` on each input bag.
* ``pose_step``: a few :func:`pose_lifter.core.solve.pose_step.pose_step` calls recorded while lifting the
  first bag in each mode through the Python run loop (``Runs.compiled`` False:
  :func:`pose_lifter.core.reference.runs.alternation_loop`; the compiled run calls no Python
  ``pose_step``; the loop runs the same steps, ``tests/core/solve/test_run_kernel.py``) (every
  ``--record-every``-th call, up to ``--record`` per mode), replayed with the recorded settings,
  without the prior's rows and without limb constraints (the compiled linear alpha-step): their
  objectives, limb violations, iteration counts and coefficients.

Run it before a refactor and after it, on one machine and install: the lines must be identical.
It is a before/after tool, not a reference: the tracked solves are chaotic in round-off (a
last-bit change grows by about 10x per warm-started frame), so the hash depends on the CPU, the
BLAS kernel OpenBLAS picks (``OPENBLAS_CORETYPE``) and numba's target (printed in the header). A
hash that differs on another machine is not a regression; compare two checkouts on the same one.
"""

from __future__ import annotations

import argparse
import copy
import glob
import hashlib
import os
import sys
import time
from collections.abc import Callable, Iterable
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

os.environ.setdefault("OMP_NUM_THREADS", "1")
os.environ.setdefault("OPENBLAS_NUM_THREADS", "1")

import numpy as np
from numpy.typing import NDArray
from pose_lifter.core.errors import PoseLifterError
from pose_lifter.core.lift import runs as lifter_module
from pose_lifter.core.lift.lifter import Lifter
from pose_lifter.core.model.bases import PoseBases, default_bases_path
from pose_lifter.core.model.metrics import mpjpe, normalised_error, p_mpjpe, procrustes_align
from pose_lifter.core.numeric.jit import HAVE_NUMBA
from pose_lifter.core.options import LifterOptions
from pose_lifter.core.results import LiftResult, StartKind
from pose_lifter.core.solve import pose_step as pose_module
from pose_lifter.messages import convert as m
from pose_lifter.messages.names import TOPIC_CAMERA_INFO, TOPIC_GROUND_TRUTH, TOPIC_KEYPOINTS
from pose_lifter.offline.bags import read_messages
from pose_lifter.offline.evaluate import evaluate_bag
from pose_lifter.offline.lift import FrameLift, LiftSummary, lift_messages
from pose_lifter.offline.settings import LiftSettings

REPO = Path(__file__).resolve().parents[1]
#: Warm starts per track, the node's causal poses (no centred smoothing).
NODE = LiftSettings(smoothing_s=0.0)
MODES = ("paper", "hybrid")


class Digest:
    """sha256 over rounded float64 values, integers and strings, fed in a fixed order."""

    def __init__(self, decimals: int) -> None:
        self._h = hashlib.sha256()
        self._decimals = decimals
        self.n_values = 0

    def floats(self, *values: Any) -> None:
        for v in values:
            a = np.round(np.asarray(v, dtype=np.float64), self._decimals) + 0.0  # -0.0 -> 0.0
            self._h.update(str(a.shape).encode())
            self._h.update(np.ascontiguousarray(a).tobytes())
            self.n_values += a.size

    def ints(self, *values: int) -> None:
        self._h.update(np.asarray(values, dtype=np.int64).tobytes())
        self.n_values += len(values)

    def text(self, s: str) -> None:
        self._h.update(s.encode() + b"\0")

    def hexdigest(self) -> str:
        return self._h.hexdigest()


@dataclass
class Recorder:
    """Wraps the lifter's ``pose_step`` and keeps a copy of every ``every``-th call's arguments."""

    every: int
    limit: int
    calls: list[tuple[tuple[Any, ...], dict[str, Any]]] = field(default_factory=list)
    n_seen: int = 0

    def wrap(self, fn: Callable[..., Any]) -> Callable[..., Any]:
        def recorded(*args: Any, **kwargs: Any) -> Any:
            if self.n_seen % self.every == 0 and len(self.calls) < self.limit:
                model = args[4]  # PoseModel: shared, not copied (it is read-only data)
                kept = {k: v for k, v in kwargs.items() if k != "qstep_fn"}
                self.calls.append((tuple(a if a is model else copy.deepcopy(a) for a in args),
                                   copy.deepcopy(kept)))
            self.n_seen += 1
            return fn(*args, **kwargs)

        return recorded


def _keypoints(bag: Path) -> tuple[list[tuple[int, Any]], list[tuple[int, Any]]]:
    kps: list[tuple[int, Any]] = []
    infos: list[tuple[int, Any]] = []
    for x in read_messages(bag, [TOPIC_KEYPOINTS, TOPIC_CAMERA_INFO]):
        (kps if x.topic == TOPIC_KEYPOINTS else infos).append((x.stamp_ns, x.msg))
    return kps, infos


#: Where the kept run began, as hashed: a cold start's index, or a fixed negative code per kind.
START_CODES = {StartKind.WARM: -1, StartKind.MIRRORED: -2, StartKind.PRIOR: -3, StartKind.LEARNED: -4}


def _hash_result(d: Digest, f: FrameLift, r: LiftResult) -> None:
    d.ints(f.stamp_ns, f.track_id, int(f.warm_started), r.n_iter, r.total_alternations, r.n_starts,
           START_CODES.get(r.start, r.start_index), int(r.converged))
    d.floats(f.joints_m, r.pose, r.alpha, r.camera.rotation, r.camera.scale, r.camera.translation,
             r.objective, r.reprojection_error, r.limb_violation, r.weights)


def lift_bags(bags: Iterable[Path], mode: str, starts: int | None,
              max_messages: int | None, d: Digest, recorder: Recorder | None, verbose: bool
              ) -> dict[Path, list[FrameLift]]:
    """Lift every bag in ``mode`` (with the mode's packaged bases) into ``d``; record pose-step
    calls of the first bag. Returns the lifted skeletons of each bag."""
    frames: dict[Path, list[FrameLift]] = {}
    original = lifter_module.pose_step
    for i, bag in enumerate(bags):
        opts = LifterOptions(mode=mode)
        # n_starts is the paper mode's own (refused in another mode)
        lifter = Lifter(PoseBases.load(default_bases_path(mode)),
                        opts if starts is None or mode != "paper" else opts.replace(n_starts=starts))
        kps, infos = _keypoints(bag)
        if max_messages is not None:
            kps = kps[:max_messages]
        summary = LiftSummary()

        def on_frame(stamp: int, msg: Any, lifted: list[FrameLift], results: list[Any]) -> None:
            for f, r in zip(lifted, results, strict=True):
                _hash_result(d, f, r)

        d.text(f"{bag.name} {mode}")
        if recorder is not None and i == 0:
            # the compiled run calls no Python pose_step: the calls are recorded from a lift of
            # this bag through the Python loop (Runs.compiled False), not hashed; the hashed lift
            # below is the default (compiled) path's
            ref = Lifter(lifter.bases, lifter.options)
            ref.runs.compiled = False
            lifter_module.pose_step = recorder.wrap(original)  # type: ignore[assignment]
            try:
                lift_messages(kps, infos, ref, NODE)
            finally:
                lifter_module.pose_step = original  # type: ignore[assignment]
        try:
            t0 = time.perf_counter()
            frames[bag] = lift_messages(kps, infos, lifter, NODE, on_frame=on_frame, summary=summary)
        finally:
            lifter_module.pose_step = original  # type: ignore[assignment]
        for failure in summary.failures:
            d.text(failure)
        d.ints(summary.n_skeletons, summary.n_lifted, summary.n_failed, summary.n_warm)
        if verbose:
            print(f"  {mode:6s} {bag.name:22s} {summary.n_lifted:4d} lifted, {summary.n_failed} failed, "
                  f"{time.perf_counter() - t0:6.1f} s", file=sys.stderr, flush=True)
    return frames


def hash_metrics(lifted: dict[str, dict[Path, list[FrameLift]]], d: Digest) -> int:
    """Errors of the lifted skeletons against the ground truth, and the input bags' floors, into
    ``d``; returns the number of matched skeletons."""
    n = 0
    bags = sorted({bag for per_bag in lifted.values() for bag in per_bag})
    for bag in bags:
        truth: dict[tuple[int, int], NDArray[np.float64]] = {}
        for x in read_messages(bag, [TOPIC_GROUND_TRUTH]):
            s = m.stamp_to_ns(x.msg.header.stamp)
            for sk in x.msg.skeletons:
                truth[(s, int(sk.track_id))] = m.skeleton3d_to_joints(sk)
        for mode, per_bag in lifted.items():
            pairs = [(f.joints_m, truth[(f.stamp_ns, f.track_id)]) for f in per_bag.get(bag, [])
                     if (f.stamp_ns, f.track_id) in truth]
            d.text(f"{bag.name} {mode} {len(pairs)}")
            if not pairs:
                continue
            pred = np.array([p for p, _ in pairs])
            gt = np.array([g for _, g in pairs])
            d.floats(mpjpe(pred, gt), p_mpjpe(pred, gt), normalised_error(pred, gt),
                     procrustes_align(pred, gt))
            n += len(pairs)
        ev = evaluate_bag(bag)  # an input bag: the floors only
        d.floats(ev.flat_p_mpjpe_mm, ev.flat_normalised, ev.mean_pose_p_mpjpe_mm, ev.mean_pose_normalised)
    return n


def _solver_settings(kwargs: dict[str, Any]) -> list[tuple[str, dict[str, Any], dict[str, Any], bool]]:
    """(name, option overrides, keyword overrides, drop the limb constraints) of each replay of one
    recorded call."""
    plain = {"prior": None}
    return [
        ("recorded", {}, {}, False),
        ("no prior", {}, plain, False),
        ("no limbs", {}, plain, True),
    ]


def replay_pose_steps(calls: list[tuple[tuple[Any, ...], dict[str, Any]]], d: Digest, verbose: bool) -> int:
    """Replay each recorded call with every solver setting into ``d``; returns the number of solves.
    A recorded call is ``pose_step(points, projection, translation, weights, model, alpha0,
    options, **kwargs)``."""
    n = 0
    for j, (args, kwargs) in enumerate(calls):
        for name, opt_over, kw_over, no_limbs in _solver_settings(kwargs):
            a = [*copy.deepcopy(args[:4]), args[4], *copy.deepcopy(args[5:])]
            opts = a[6]
            if no_limbs:
                v = opts.method
                opt_over = {**opt_over, "variant": f"{v.loss.upper()}NA{'WS' if v.sparsity else 'NS'}"}
            a[6] = opts.replace(**opt_over)
            kw = {**copy.deepcopy(kwargs), **kw_over}
            d.text(f"call {j} {name}")
            try:
                res = pose_module.pose_step(*a, **kw)
            except PoseLifterError as exc:
                d.text(f"{type(exc).__name__}: {exc}")
                continue
            d.ints(res.n_iter, int(res.converged))
            d.floats(res.objective, res.limb_violation, res.alpha)
            n += 1
            if verbose:
                print(f"  call {j:2d} {name:20s} objective {res.objective:.12f} after {res.n_iter} "
                      "iterations", file=sys.stderr)
    return n


def _machine() -> str:
    """What the hash depends on besides the code: numpy, its BLAS kernel, numba and its target."""
    from threadpoolctl import threadpool_info

    blas = ", ".join(f"{i.get('internal_api')} {i.get('architecture')}" for i in threadpool_info()
                     if i.get("user_api") == "blas")
    numba = "off"
    if HAVE_NUMBA:
        from numba.core import config

        numba = f"{config.CPU_NAME or 'host'} target"
    return f"numpy {np.__version__} (BLAS {blas or 'unknown'}), numba {numba}"


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0] if __doc__ else None)
    ap.add_argument("--bags", nargs="*", default=sorted(glob.glob(str(REPO / "bags" / "*.mcap"))))
    ap.add_argument("--max-messages", type=int, default=None, help="lift only the first N messages of a bag")
    ap.add_argument("--starts", type=int, default=None,
                    help="n_starts of the paper mode's cold solves (default: the LifterOptions default)")
    ap.add_argument("--decimals", type=int, default=9, help="round to 10**-decimals before hashing")
    ap.add_argument("--record", type=int, default=6, help="pose_step calls recorded per mode")
    ap.add_argument("--record-every", type=int, default=25, help="record every N-th pose_step call")
    ap.add_argument("--modes", nargs="+", default=list(MODES), choices=["paper", "hybrid", "learned"],
                    help="the modes lifted (default paper and hybrid: the total the before/after comparisons "
                         "quote; learned adds its own section and changes the total)")
    ap.add_argument("-v", "--verbose", action="store_true", help="per-bag times and per-call objectives")
    args = ap.parse_args(argv)
    bags = [Path(b) for b in args.bags]
    if not bags:
        ap.error("no bags")
    Lifter(None, LifterOptions(mode="hybrid")).warm_up()  # compile or load the kernels first
    starts = LifterOptions().n_starts if args.starts is None else args.starts
    print(f"lift_hash: {len(bags)} bags ({', '.join(b.stem for b in bags)}), starts {starts}, "
          f"max messages {args.max_messages}, rounded to 1e-{args.decimals}; {_machine()}")
    total = Digest(args.decimals)
    calls: list[tuple[tuple[Any, ...], dict[str, Any]]] = []
    lifted: dict[str, dict[Path, list[FrameLift]]] = {}
    for mode in args.modes:
        d = Digest(args.decimals)
        rec = Recorder(args.record_every, args.record)
        lifted[mode] = lift_bags(bags, mode, args.starts, args.max_messages, d, rec, args.verbose)
        calls.extend(rec.calls)
        n = sum(len(f) for f in lifted[mode].values())
        print(f"lifts {mode:7s} {d.hexdigest()}  ({n} skeletons, {d.n_values} values)", flush=True)
        total.text(d.hexdigest())
    d = Digest(args.decimals)
    n = hash_metrics(lifted, d)
    print(f"metrics       {d.hexdigest()}  ({n} matched skeletons)", flush=True)
    total.text(d.hexdigest())
    d = Digest(args.decimals)
    n = replay_pose_steps(calls, d, args.verbose)
    print(f"pose_step     {d.hexdigest()}  ({len(calls)} recorded calls, {n} solves)")
    total.text(d.hexdigest())
    print(f"total         {total.hexdigest()}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
