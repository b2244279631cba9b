"""Accuracy of the lifter's modes on the evaluation split (``make accuracy``).

    .venv/bin/python tools/accuracy.py [--data ../shared/data/cmu] [--split eval|val]
        [--frames 120] [--views 4] [--workers 2] [--conditions clean noise0.1 ...]
        [--out out/accuracy] [--set NAME=VALUE ...] [--bases PATH]
    .venv/bin/python tools/accuracy.py --merge RUN1/accuracy.json RUN2/accuracy.json --out DIR

Tracks: every trial of the split (``eval``: subjects 02, 07, 08 and 09_12, never trained on;
``val``: the training-split trials the prior was not fitted on, for tuning), at 30 Hz, at most
``--frames`` frames each, each filmed from ``--views`` of the 32 cameras (8 azimuths x 2
elevations (0 and 30 degrees) x weak perspective / perspective at 3 m; the views rotate over the
trials so every camera is used), 640x480 pixels with an 800 px focal length.

Conditions: clean; Gaussian 2D noise 0.05 / 0.1 / 0.2 right-lower-leg lengths; 20 % of joints
displaced by 1-3 leg lengths with confidence kept at 1; 15 % of joints missing; limb lengths
scaled per person (one factor per bone group, uniform +-20 %), clean 2D. Faults of real detectors
and cameras (clean 2D otherwise): ``lrswap`` (on 10 % of frames each the arms' and, independently,
the legs' left/right labels swapped, confidence kept), ``lowercut`` (the lower body out of the
image: knees and ankles missing on every frame), ``close`` (a perspective camera at 2 m), ``above``
(the camera 50 degrees above the person, looking down). ``detector6m`` / ``detector3m``: every
fault of a real detector together (:data:`pose_lifter.mocap.detector_model.REALISTIC`: per-joint
noise scaled like the COCO sigmas and correlated over frames, a confidence that falls with the
error, confident outliers, misses, dropped limbs, swaps, the lower body cut, joints outside the
640x480 image lost), a perspective camera at 6 m / 3 m. Not run unless named (diagnostics of the
realistic detector at 6 m): ``detnoise6m`` its noise alone (no other fault), ``detwhite6m`` the
same noise independent from frame to frame, ``detfaults6m`` its faults without the noise.

Methods: ``flat`` (the 2D with zero depth) and ``mean-pose`` floors; ``paper`` (the paper's
method, tracked as the node tracks: cold 30-start first frame, then warm + mirrored starts);
``learned`` (the prior alone, per frame); ``learned-t`` (the prior alone tracked as the node
runs ``mode: learned``: the causal temporal prior) and ``learned-offline`` (the same smoothed over
past and future frames: ``pose-lifter lift --mode learned``); ``hybrid`` tracked (default mode,
the node's per-track policy :class:`pose_lifter.core.track.policy.TrackPolicy`),
``hybrid-lag`` (the node with ``output_lag`` ``--lag`` frames, 3 by default: each frame's pose
refined over the next frames, :mod:`pose_lifter.core.track.lagged`; from 6 frames its lift reads
3 frames ahead, :mod:`pose_lifter.messages.lagged`),
``hybrid-offline`` (the tracks as ``pose-lifter lift`` gives them: without the causal smoothing
of noisy tracks, then smoothed by the centred window of :mod:`pose_lifter.core.track.smoothing`) and
``hybrid-1`` (every frame cold).

Figures: P-MPJPE (mm, similarity-aligned per frame), MPJPE (mm, camera frame, centred on the
joints' centroid, the prediction scaled by the subject's true right-lower-leg length, no
rotation alignment) and jitter (mean acceleration error, mm per frame^2, on the MPJPE poses).
With ``--axes`` also the P-MPJPE of each method's poses with the true x, y put in (their depths
kept) and with the true depths put in (their x, y kept), camera frame: where the error lies.
Writes ``accuracy.json``, ``accuracy.md`` (the table) and ``accuracy.png`` to ``--out``.
Deterministic (seeded corruption, one BLAS thread per worker).
"""

from __future__ import annotations

import argparse
import ast
import json
import multiprocessing as mp
import os
import sys
import time
import warnings
from dataclasses import dataclass, replace
from pathlib import Path
from typing import Any

import numpy as np
from numpy.typing import NDArray

os.environ.setdefault("OMP_NUM_THREADS", "1")
os.environ.setdefault("OPENBLAS_NUM_THREADS", "1")

from pose_lifter.core import Lifter, LifterOptions, PoseBases, p_mpjpe
from pose_lifter.core.errors import PoseLifterError
from pose_lifter.core.model.bases import default_bases_path
from pose_lifter.core.model.skeleton import RIGHT_LOWER_LEG, body_frame, limb_lengths
from pose_lifter.core.track.defaults import AHEAD_LAG
from pose_lifter.core.track.lagged import LaggedPoses
from pose_lifter.core.track.placement import place_in_camera
from pose_lifter.core.track.policy import FramesAhead, TrackPolicy
from pose_lifter.core.track.smoothing import OFFLINE_SMOOTHING_S, centred_smoothing
from pose_lifter.mocap.cmu import load_trial, split_trials
from pose_lifter.mocap.detector_model import LOWER_LEG_JOINTS, REALISTIC, DetectorModel, detect, swap_labels
from pose_lifter.mocap.scenes import corrupt_2d
from pose_lifter.mocap.views import film, limb_scale_factors, scale_limbs, view_rotation

CONDITIONS: dict[str, dict[str, float]] = {
    "clean": {},
    "noise0.05": {"noise": 0.05},
    "noise0.1": {"noise": 0.1},
    "noise0.2": {"noise": 0.2},
    "outliers20": {"outliers": 0.2},
    "missing15": {"missing": 0.15},
    "proportions": {"limbs": 0.2},
    # faults of real detectors and cameras
    "lrswap": {"swap": 0.1},
    "lowercut": {"cut": 1.0},
    "close": {"distance": 2.0},
    "above": {"elevation": 50.0},
    # every fault of a real detector together (pose_lifter.mocap.detector_model.REALISTIC), a
    # perspective camera at 6 m and at 3 m, joints outside the 640x480 image lost
    "detector6m": {"detector": 1.0, "distance": 6.0},
    "detector3m": {"detector": 1.0, "distance": 3.0},
}
#: Diagnostics of the realistic detector (not run unless named): its noise alone, the same noise
#: independent over frames, its faults without the noise; a perspective camera at 6 m.
DIAGNOSTIC_CONDITIONS: dict[str, dict[str, float]] = {
    "detnoise6m": {"detector": 1.0, "distance": 6.0, "faults": 0.0},
    "detwhite6m": {"detector": 1.0, "distance": 6.0, "faults": 0.0, "correlation": 0.0},
    "detfaults6m": {"detector": 1.0, "distance": 6.0, "detector_noise": 0.0},
}
ALL_CONDITIONS = {**CONDITIONS, **DIAGNOSTIC_CONDITIONS}
METHODS = ("flat", "mean-pose", "paper", "learned", "learned-t", "learned-offline", "hybrid",
           "hybrid-lag", "hybrid-offline", "hybrid-1")
AZIMUTHS = tuple(range(0, 360, 45))
ELEVATIONS = (0.0, 30.0)
PROJECTIONS = ("weak", "perspective")
FOCAL, CENTRE, DISTANCE = 800.0, np.array([320.0, 240.0]), 3.0
IMAGE_SIZE = (640.0, 480.0)
CAMERAS = [(a, e, p) for p in PROJECTIONS for e in ELEVATIONS for a in AZIMUTHS]


@dataclass(frozen=True)
class Track:
    name: str
    world: NDArray[np.float64]  # (T, 12, 3) metres
    camera: tuple[float, float, str]
    seed: int


def _parse(spec: list[str]) -> dict[str, Any]:
    out: dict[str, Any] = {}
    for s in spec:
        k, v = s.split("=", 1)
        out[k.strip()] = ast.literal_eval(v.strip())
    return out


_STATE: dict[str, Any] = {}


def _init(settings: dict[str, Any], methods: tuple[str, ...], bases_file: str | None = None,
          offline: dict[str, Any] | None = None) -> None:
    """The lifters of ``methods`` with the options ``settings`` (``offline``: the options the
    ``-offline`` methods take on top, e.g. their temporal prior)."""
    warnings.simplefilter("ignore")
    lifters = {}
    for m in methods:
        if m in ("paper", "learned", "learned-t", "learned-offline", "hybrid", "hybrid-lag", "hybrid-offline",
                 "hybrid-1"):
            mode = "hybrid" if m.startswith("hybrid") else m.removesuffix("-t").removesuffix("-offline")
            bases = PoseBases.load(bases_file or default_bases_path(mode))
            # an offline lift knows each track's next frames (pose-lifter lift: its offline prior)
            # the lagged node reads ahead from AHEAD_LAG on (pose_lifter.messages.lagged)
            ahead = m.endswith("-offline") or (m == "hybrid-lag" and int(_STATE.get("lag", 3)) >= AHEAD_LAG)
            opts = LifterOptions(mode=mode).replace(**{**settings, **((offline or {}) if ahead else {})})
            lifters[m] = Lifter(bases, opts, reads_ahead=ahead)
            lifters[m].warm_up()
    _STATE["lifters"] = lifters
    _STATE["mean"] = PoseBases.load().mean_pose  # the mean-pose floor: the paper's bases, as before


def film_track(track: Track, spec: dict[str, float], rng: np.random.Generator
               ) -> tuple[NDArray[np.float64], NDArray[np.float64], NDArray[np.float64], NDArray[np.float64]]:
    """The 2D a detector gives of ``track`` under condition ``spec`` (:data:`CONDITIONS`).

    Returns
    -------
    px : ndarray, shape (T, 12, 2)
        Pixels (0 where missing).
    conf : ndarray, shape (T, 12)
    world : ndarray, shape (T, 12, 3)
        The filmed person (limbs scaled when the condition says so), metres.
    cam_pose : ndarray, shape (T, 12, 3)
        The centred pose in the camera frame, metres.
    """
    world = track.world
    if spec.get("limbs", 0.0) > 0:
        world = scale_limbs(world, limb_scale_factors(1, spec["limbs"], rng)[0])
    az, el, proj = track.camera
    el = spec.get("elevation", el)
    dist = spec.get("distance", _STATE.get("distance", DISTANCE))  # --distance, a condition's own
    if "distance" in spec:
        proj = "perspective"
    n = len(world)
    rots = np.repeat(view_rotation(az, el)[None], n, axis=0)
    pts, cam_pose, leg = film(world, rots, np.full(n, dist), np.full(n, proj == "perspective"))
    px = FOCAL * pts + CENTRE
    if spec.get("detector", 0.0) > 0:
        return (*detect(px, FOCAL * leg, detector_model(spec), rng, IMAGE_SIZE), world, cam_pose)
    px, conf = corrupt_2d(px, FOCAL * leg, spec.get("noise", 0.0),
                          spec.get("outliers", 0.0), spec.get("missing", 0.0), rng)
    if spec.get("swap", 0.0) > 0:  # a detector's left/right label swaps (arms, legs apart)
        swap_labels(px, conf, spec["swap"], rng)
    if spec.get("cut", 0.0) > 0:  # the lower body out of the image
        px[:, LOWER_LEG_JOINTS] = 0.0
        conf[:, LOWER_LEG_JOINTS] = 0.0
    return px, conf, world, cam_pose


def detector_model(spec: dict[str, float]) -> DetectorModel:
    """The realistic detector, or a diagnostic part of it (:data:`DIAGNOSTIC_CONDITIONS`)."""
    model = REALISTIC
    if spec.get("faults", 1.0) == 0.0:
        model = replace(model, outliers=0.0, missing=0.0, limb_drop=0.0, swap=0.0, lower_cut=0.0)
    if "correlation" in spec:
        model = replace(model, correlation=spec["correlation"])
    if "detector_noise" in spec:
        model = replace(model, noise=spec["detector_noise"])
    return model


def _job(args: tuple[Track, str, tuple[str, ...]]) -> dict[str, Any]:
    track, cond, methods = args
    rng = np.random.default_rng(track.seed)
    px, conf, world, cam_pose = film_track(track, ALL_CONDITIONS[cond], rng)
    n = len(world)
    leg_m = limb_lengths(world)[:, RIGHT_LOWER_LEG]
    truth_c = cam_pose - cam_pose.mean(axis=1, keepdims=True)
    out: dict[str, Any] = {}
    stamps = np.arange(n, dtype=np.int64) * 33_333_333
    # the camera's intrinsics, given to the lift of a perspective track with --intrinsics
    perspective = track.camera[2] == "perspective" or "distance" in ALL_CONDITIONS[cond]
    dist_m = ALL_CONDITIONS[cond].get("distance", _STATE.get("distance", DISTANCE))
    intrinsics = ((FOCAL, FOCAL), (float(CENTRE[0]), float(CENTRE[1]))) if (
        perspective and _STATE.get("intrinsics")) else None
    for m in methods:
        t0 = time.perf_counter()
        preds = np.full((n, 12, 3), np.nan)  # metres, camera frame, centred
        if m == "flat":
            flat = np.concatenate([truth_c[..., :2], np.zeros((n, 12, 1))], axis=-1)
            preds[:] = flat
        elif m == "mean-pose":  # the mean training pose, turned by the true body frame (an oracle)
            preds[:] = np.einsum("jb,nba->nja", _STATE["mean"], body_frame(truth_c)) * leg_m[:, None, None]
        else:
            lifter: Lifter = _STATE["lifters"][m]
            tracked = m in ("hybrid", "hybrid-lag", "hybrid-offline", "learned-t", "learned-offline")
            policy = TrackPolicy(lifter, track_timeout=1e9) if tracked else None
            if policy is not None and m.endswith("-offline"):  # as pose-lifter lift (offline/chains.py)
                policy.smoothed_later = True
            # the node with output_lag (pose_lifter.messages.lagged): each frame refined lag frames late
            lag = int(_STATE.get("lag", 3))  # frames of refinement: the rest of the lag, after the lift's
            lag -= lifter.frames_ahead if m == "hybrid-lag" else 0
            lagged = None
            if policy is not None and m == "hybrid-lag":
                policy.smoothed_later = True
                o = lifter.options
                lagged = LaggedPoses(OFFLINE_SMOOTHING_S, 1.0, o.measurement_depth, o.measurement_gate)
            fit = np.full((n, 12, 3), np.nan)
            depth = np.full(n, np.nan)  # the centroid's depth error (%) on a perspective track
            warm = None
            n_ahead = lifter.frames_ahead
            for i in range(n):
                try:
                    if policy is not None:
                        ahead = (FramesAhead(stamps[i + 1:i + 1 + n_ahead], px[i + 1:i + 1 + n_ahead],
                                             conf[i + 1:i + 1 + n_ahead]) if n_ahead else None)
                        t = policy.lift(0, int(stamps[i]), px[i], conf[i], intrinsics, ahead)
                        r = t.result
                        # what pose-lifter lift smooths: the fit's own pose, or the published
                        # one with the measurement update (pose_lifter.offline.chains.lift_chains)
                        own = (r.pose_camera if t.fit_pose_camera is None or lifter.options.measurement_update
                               else t.fit_pose_camera)
                        fit[i] = own * leg_m[i]
                    else:
                        r = lifter.lift(px[i], conf[i], warm=warm)
                        warm = r.warm_start() if m == "paper" else None
                except PoseLifterError:
                    warm = None
                    continue
                preds[i] = r.pose_camera * leg_m[i]
                if lagged is not None and policy is not None:
                    kept = policy.kept_later().get(0, [])
                    lagged.add(0, int(stamps[i]), r.pose_camera, kept[-1] if kept else None)
                    _lag_out(lagged, stamps, leg_m, preds, i - lag)
                if perspective:  # the node's placement with the focal length and the person's true leg
                    z = place_in_camera(r, float(leg_m[i]), (FOCAL, FOCAL), None, dist_m).mean(axis=0)[2]
                    depth[i] = 100.0 * abs(z - dist_m) / dist_m
            if lagged is not None:  # the input stopped: the frames held are published
                for k in range(max(0, n - lag), n):
                    _lag_out(lagged, stamps, leg_m, preds, k)
            elif policy is not None and policy.smoothed_later:  # the offline measurement update
                index = {int(s): i for i, s in enumerate(stamps)}
                for (_, stamp, _), pose in policy.measured_later().items():
                    fit[index[stamp]] = pose * leg_m[index[stamp]]
            if m in ("hybrid-offline", "learned-offline"):
                ok = np.all(np.isfinite(fit), axis=(1, 2))
                preds[:] = centred_smoothing(np.nan_to_num(fit), stamps, ok, OFFLINE_SMOOTHING_S, 1.0)
                preds[~ok] = np.nan
        ms = 1000.0 * (time.perf_counter() - t0) / n
        ok = np.all(np.isfinite(preds), axis=(1, 2))
        pm = np.full(n, np.nan)
        pm[ok] = 1000.0 * np.asarray(p_mpjpe(preds[ok], truth_c[ok]))
        mp_ = np.full(n, np.nan)
        mp_[ok] = 1000.0 * np.linalg.norm(preds[ok] - truth_c[ok], axis=-1).mean(axis=-1)
        acc = np.full(n, np.nan)
        if n >= 3:
            ap = preds[2:] - 2 * preds[1:-1] + preds[:-2]
            at = truth_c[2:] - 2 * truth_c[1:-1] + truth_c[:-2]
            acc[1:-1] = 1000.0 * np.linalg.norm(ap - at, axis=-1).mean(axis=-1)
        out[m] = {"p_mpjpe": pm.tolist(), "mpjpe": mp_.tolist(), "jitter": acc.tolist(), "ms": ms}
        for key, axes in (("true_xy", slice(0, 2)), ("true_depth", slice(2, 3))):  # --axes
            swapped = preds.copy()
            swapped[..., axes] = truth_c[..., axes]
            vals = np.full(n, np.nan)
            vals[ok] = 1000.0 * np.asarray(p_mpjpe(swapped[ok], truth_c[ok]))
            out[m][key] = vals.tolist()
        if m not in ("flat", "mean-pose") and perspective:
            out[m]["depth_pct"] = depth.tolist()
    return {"track": track.name, "cond": cond, "camera": track.camera, "n": n, "methods": out}


def _lag_out(lagged: LaggedPoses, stamps: NDArray[np.int64], leg_m: NDArray[np.float64],
             preds: NDArray[np.float64], k: int) -> None:
    """Frame ``k``'s lagged pose into ``preds`` (metres), when the frame was lifted."""
    if k < 0 or not np.isfinite(preds[k]).all():
        return
    pose = lagged.pose(0, int(stamps[k]))
    if pose is not None:
        preds[k] = pose * leg_m[k]


def _tracks(split: str, data: str | None, frames: int, views: int, trials: list[str] | None = None,
            cameras: list[tuple[float, float, str]] | None = None) -> list[Track]:
    if trials:
        ids = trials
    elif split == "eval":
        ids = split_trials("eval", data)
    else:  # the prior's held-out training-split trials (tuning)
        from pose_lifter.core.model.prior import PosePrior
        ids = list(PosePrior.load().metadata.get("validation_trials", []))
    cams = cameras or CAMERAS
    out = []
    for k, t in enumerate(ids):
        world = load_trial(t, data, step=4, max_frames=frames)
        for v in range(views):
            cam = cams[(k * views + v) % len(cams)]
            out.append(Track(f"{t}@{cam[0]:.0f}/{cam[1]:.0f}/{cam[2]}", world, cam, 1000 * k + v))
    return out


def _nanmean(a: list[float]) -> float:
    x = np.asarray(a, dtype=np.float64)
    return float(np.nanmean(x)) if np.any(np.isfinite(x)) else float("nan")


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--data", default=None)
    ap.add_argument("--split", choices=("eval", "val"), default="eval")
    ap.add_argument("--frames", type=int, default=120, help="frames per track at 30 Hz")
    ap.add_argument("--views", type=int, default=4, help="cameras per trial (of 32)")
    ap.add_argument("--workers", type=int, default=min(2, os.cpu_count() or 1))
    ap.add_argument("--conditions", nargs="+", default=list(CONDITIONS), choices=list(ALL_CONDITIONS))
    ap.add_argument("--methods", nargs="+", default=list(METHODS), choices=list(METHODS))
    ap.add_argument("--set", action="append", default=[], help="a LifterOptions field, e.g. prior_weight_z=2")
    ap.add_argument("--bases", default=None, help="basis file (default: each mode's packaged one)")
    ap.add_argument("--trials", nargs="+", default=None,
                    help="these trials instead of the split's (e.g. a cross-action fold's class)")
    ap.add_argument("--action", default=None,
                    help="the trials of this MANIFEST action class instead of the split's")
    ap.add_argument("--max-trials", type=int, default=None, help="at most this many of the trials")
    ap.add_argument("--distance", type=float, default=DISTANCE, help="camera distance (m)")
    ap.add_argument("--azimuths", type=float, nargs="+", default=None,
                    help="only these azimuths (degrees, elevation 0, --projection): cameras rotate over them")
    ap.add_argument("--projection", choices=PROJECTIONS, default="perspective",
                    help="the projection of the --azimuths cameras")
    ap.add_argument("--lag", type=int, default=3, help="hybrid-lag: the node's output_lag (frames)")
    ap.add_argument("--intrinsics", action="store_true",
                    help="tracked lifts of perspective tracks know the camera's intrinsics (camera_info)")
    ap.add_argument("--merge", type=Path, nargs="+", default=None,
                    help="no lifting: join these runs' accuracy.json into one table in --out")
    ap.add_argument("--axes", action="store_true",
                    help="also P-MPJPE with the true x, y and with the true depths put in")
    ap.add_argument("--out", type=Path, default=Path("out/accuracy"))
    args = ap.parse_args(argv)
    if args.merge:
        return merge(args.merge, args.out)
    warnings.simplefilter("ignore")
    t0 = time.perf_counter()
    trials = args.trials
    if args.action:
        from pose_lifter.mocap.cmu import read_manifest
        known = set(split_trials("train", args.data)) | set(split_trials("eval", args.data))
        trials = sorted({t.trial for t in read_manifest(args.data)
                         if t.action == args.action and t.trial in known})  # of the two splits only
    if trials and args.max_trials:
        trials = trials[:: max(1, len(trials) // args.max_trials)][: args.max_trials]
    cameras = [(a, 0.0, args.projection) for a in args.azimuths] if args.azimuths else None
    tracks = _tracks(args.split, args.data, args.frames, args.views, trials, cameras)
    methods = tuple(args.methods)
    jobs = [(t, c, methods) for c in args.conditions for t in tracks]
    n_frames = sum(len(t.world) for t in tracks)
    print(f"{args.split} split: {len(tracks)} tracks ({len(tracks) // max(args.views, 1)} trials x "
          f"{args.views} views), {n_frames} frames per condition; {len(jobs)} jobs on {args.workers} workers",
          flush=True)
    settings = _parse(args.set)
    _STATE["distance"] = args.distance
    _STATE["intrinsics"] = args.intrinsics
    _STATE["lag"] = args.lag
    if args.workers > 1:
        with mp.get_context("fork").Pool(args.workers, _init, (settings, methods, args.bases)) as pool:
            results = list(pool.imap_unordered(_job, jobs, chunksize=1))
    else:
        _init(settings, methods, args.bases)
        results = [_job(j) for j in jobs]
    table: dict[str, dict[str, dict[str, float]]] = {}
    for cond in args.conditions:
        rows = [r for r in results if r["cond"] == cond]
        table[cond] = {}
        for m in methods:
            vals = {k: _nanmean([v for r in rows for v in r["methods"][m][k]])
                    for k in ("p_mpjpe", "mpjpe", "jitter", "true_xy", "true_depth")}
            vals["ms"] = float(np.mean([r["methods"][m]["ms"] for r in rows]))
            vals["lifted"] = float(np.mean([np.isfinite(r["methods"][m]["p_mpjpe"]).mean() for r in rows]))
            vals["depth_pct"] = _nanmean([v for r in rows for v in r["methods"][m].get("depth_pct", [])])
            table[cond][m] = vals
    axes = [f"{c} {m} {row[m]['p_mpjpe']:.1f} / {row[m]['true_xy']:.1f} / {row[m]['true_depth']:.1f}"
            for c, row in table.items() for m in methods if m not in ("flat", "mean-pose")]
    footer = ("P-MPJPE (mm) as lifted / with the true x, y / with the true depths: " + ", ".join(axes) + "\n"
              if args.axes else "") + f"wall time {time.perf_counter() - t0:.0f} s"
    header = (f"{args.split} split, {len(tracks)} tracks, {n_frames} frames per condition "
              f"(`tools/accuracy.py {' '.join(argv if argv is not None else sys.argv[1:])}`)")
    _write(table, methods, header, footer, args.out,
           {"table": table, "settings": settings, "split": args.split if not trials else "trials",
            "trials": trials, "distance": args.distance, "cameras": cameras})
    return 0


def _write(table: dict[str, dict[str, dict[str, float]]], methods: tuple[str, ...], header: str, footer: str,
           out: Path, record: dict[str, Any]) -> None:
    """Print the table and write ``accuracy.md``, ``accuracy.json`` (``record``) and ``accuracy.png``."""
    lines = [header, "", "P-MPJPE / MPJPE / jitter (mm, mm, mm per frame^2):", "",
             "| condition | " + " | ".join(methods) + " |", "|---|" + "---|" * len(methods)]
    for cond, row in table.items():
        cells = [f"{row[m]['p_mpjpe']:.1f} / {row[m]['mpjpe']:.1f} / {row[m]['jitter']:.1f}" for m in methods]
        lines.append(f"| {cond} | " + " | ".join(cells) + " |")
    lines += ["", "ms per frame: " + ", ".join(
        f"{m} {np.mean([table[c][m]['ms'] for c in table]):.2f}" for m in methods),
        "frames lifted: " + ", ".join(f"{m} {100 * min(table[c][m]['lifted'] for c in table):.1f} %"
                                      for m in methods)]
    depths = [(c, m, row[m].get("depth_pct", float("nan"))) for c, row in table.items() for m in methods]
    if any(np.isfinite(d) for _, _, d in depths):
        lines.append("centroid depth error (%, perspective tracks, from the camera scale, the focal length "
                     "and the true leg): "
                     + ", ".join(f"{c} {m} {d:.1f}" for c, m, d in depths if np.isfinite(d)))
    lines.append(footer)
    text = "\n".join(lines)
    print(text, flush=True)
    out.mkdir(parents=True, exist_ok=True)
    (out / "accuracy.md").write_text(text + "\n")
    (out / "accuracy.json").write_text(json.dumps(record, indent=1))
    _plot(table, methods, out / "accuracy.png")


def merge(paths: list[Path], out: Path) -> int:
    """``--merge``: one table from several runs' ``accuracy.json`` (same split and conditions; a
    method in a later file replaces the same method of an earlier one), written to ``out``."""
    table: dict[str, dict[str, dict[str, float]]] = {}
    sources: dict[str, str] = {}
    splits = set()
    for p in paths:
        rec = json.loads(p.read_text())
        splits.add(rec.get("split"))
        for cond, row in rec["table"].items():
            table.setdefault(cond, {}).update(row)
            for m in row:
                sources[m] = str(p)
    if len(splits) != 1:
        raise SystemExit(f"--merge: runs of different splits {sorted(map(str, splits))}")
    methods = tuple(m for m in METHODS if m in sources)
    if any(set(methods) - set(row) for row in table.values()):
        raise SystemExit("--merge: a method lacks some of the conditions")
    by_file: dict[str, list[str]] = {}
    for m in methods:
        by_file.setdefault(sources[m], []).append(m)
    parts = "; ".join(f"{', '.join(ms)} from `{f}`" for f, ms in by_file.items())
    header = (f"{splits.pop()} split; merged runs (inputs are seeded per track, so every column sees "
              f"the same corrupted 2D): {parts}")
    _write(table, methods, header, "", out, {"table": table, "merged_from": by_file})
    return 0


def _plot(table: dict[str, dict[str, dict[str, float]]], methods: tuple[str, ...], path: Path) -> None:
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
