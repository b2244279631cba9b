"""Accuracy of the lifter's modes on filmed CMU tracks (``make accuracy``, ``make cross-action``).

Tracks: CMU trials at 30 Hz (:func:`evaluation_tracks`: every trial of a split, at most ``frames``
frames each, each filmed from ``views`` of the 32 :data:`CAMERAS`: 8 azimuths x 2 elevations (0 and
30 degrees) x weak perspective / perspective at 3 m; the views rotate over the trials so every
camera is used), 640x480 pixels with an 800 px focal length.

Conditions (:data:`CONDITIONS`): clean; Gaussian 2D noise 0.05 / 0.1 / 0.2 right-lower-leg
lengths; 20 % of joints displaced by 1-3 leg lengths with confidence kept at 1; 15 % of joints
missing; limb lengths scaled per person (one factor per bone group, uniform +-20 %), clean 2D.
Faults of real detectors and cameras (clean 2D otherwise): ``lrswap`` (on 10 % of frames each the
arms' and, independently, the legs' left/right labels swapped, confidence kept), ``lowercut``
(knees and ankles missing on every frame), ``close`` (a perspective camera at 2 m), ``above`` (the
camera 50 degrees above the person, looking down). ``detector6m`` / ``detector3m``: every fault
of a real detector together (:data:`pose_lifter.mocap.detector_model.REALISTIC`), a perspective
camera at 6 m / 3 m, joints outside the image lost. :data:`DIAGNOSTIC_CONDITIONS` (run only when
named) split the realistic detector at 6 m: its noise alone (``detnoise6m``), the same noise
independent from frame to frame (``detwhite6m``), its faults without the noise (``detfaults6m``).

Methods (:data:`METHODS`): ``flat`` (the 2D with zero depth) and ``mean-pose`` (the mean training
pose turned by the true body frame) floors; ``paper`` (the paper's method, warm-started from the
previous frame); ``learned`` (the prior alone, per frame); ``learned-t`` (the prior alone tracked
as the node runs ``mode: learned``) and ``learned-offline`` (the same smoothed over past and future
frames, ``pose-lifter lift --mode learned``); ``hybrid`` (the default mode tracked by the node's
per-track policy :class:`pose_lifter.core.track.policy.TrackPolicy`), ``hybrid-lag`` (the node
with ``output_lag``: each frame refined over the next ``lag`` frames), ``hybrid-offline`` (the
tracks as ``pose-lifter lift`` gives them: smoothed over past and future frames) and ``hybrid-1``
(every frame cold).

Figures per frame (:meth:`Evaluator.evaluate`): P-MPJPE (mm, similarity-aligned), MPJPE (mm,
camera frame, centred on the joints' centroid, the prediction scaled by the subject's true
right-lower-leg length, no rotation alignment), jitter (acceleration error, mm per frame^2, on the
MPJPE poses), the P-MPJPE with the true x, y put in and with the true depths put in (where the
error lies), and on perspective tracks the centroid's depth error (%) of the node's placement.
Deterministic: the corruption is seeded per track, the lifts are.
"""

from __future__ import annotations

import ast
import json
import multiprocessing as mp
import platform
import subprocess
import time
import warnings
from collections.abc import Callable, Sequence
from dataclasses import dataclass, replace
from pathlib import Path
from typing import Any, Protocol, cast

import numpy as np
from numpy.typing import NDArray

from pose_lifter.core import Lifter, LifterOptions, PoseBases, p_mpjpe
from pose_lifter.core.errors import PoseLifterError
from pose_lifter.core.model.bases import default_bases_path
from pose_lifter.core.model.skeleton import RIGHT_LOWER_LEG, body_frame, limb_lengths
from pose_lifter.core.options import Mode
from pose_lifter.core.track.defaults import AHEAD_LAG
from pose_lifter.core.track.later import Placement, Refiner
from pose_lifter.core.track.placement import place_in_camera
from pose_lifter.core.track.policy import FramesAhead, TrackedLift, TrackPolicy
from pose_lifter.core.track.smoothing import OFFLINE_SMOOTHING_S
from pose_lifter.mocap.cmu import load_trial, read_manifest, split_trials
from pose_lifter.mocap.detector_model import LOWER_LEG_JOINTS, REALISTIC, DetectorModel, detect, swap_labels
from pose_lifter.mocap.scenes import corrupt_2d
from pose_lifter.mocap.views import film, limb_scale_factors, scale_limbs, view_rotation

__all__ = [
    "ALL_CONDITIONS", "CAMERAS", "CONDITIONS", "DIAGNOSTIC_CONDITIONS", "METHODS", "Evaluator", "Setup",
    "Track", "detector_model", "evaluate_jobs", "evaluation_tracks", "film_track", "frame_figures",
    "merge_runs", "nanmean", "parse_settings", "render_table", "run_jobs", "run_stamp", "split_ids",
    "summarise",
]

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
#: The methods that lift (the others are floors), and those tracked by the node's per-track policy.
LIFTED = METHODS[2:]
TRACKED = ("hybrid", "hybrid-lag", "hybrid-offline", "learned-t", "learned-offline")
AZIMUTHS = tuple(range(0, 360, 45))
ELEVATIONS = (0.0, 30.0)
PROJECTIONS = ("weak", "perspective")
FOCAL, CENTRE, DISTANCE = 800.0, np.array([320.0, 240.0]), 3.0
IMAGE_SIZE = (640.0, 480.0)
CAMERAS = [(a, e, p) for p in PROJECTIONS for e in ELEVATIONS for a in AZIMUTHS]
#: The figures averaged over a condition's frames by :func:`summarise`.
FIGURES = ("p_mpjpe", "mpjpe", "jitter", "true_xy", "true_depth")
#: A 30 Hz track's frame period, ns.
FRAME_NS = 33_333_333


@dataclass(frozen=True)
class Track:
    """A filmed person: a trial's poses seen by one camera, its corruption seeded by ``seed``."""

    name: str
    world: NDArray[np.float64]  #: (T, 12, 3) metres, world frame
    camera: tuple[float, float, str]  #: azimuth (deg), elevation (deg), "weak" | "perspective"
    seed: int


@dataclass(frozen=True)
class Setup:
    """What every lift of a run shares: the camera distance (m; a condition may set its own),
    whether tracked lifts of perspective tracks know the camera's intrinsics (as the node with
    ``camera_info``), and ``hybrid-lag``'s ``output_lag`` (frames)."""

    distance: float = DISTANCE
    intrinsics: bool = False
    lag: int = 3


def parse_settings(spec: Sequence[str]) -> dict[str, Any]:
    """``NAME=VALUE`` pairs (``VALUE`` a Python literal) as a dict, e.g. of LifterOptions fields."""
    out: dict[str, Any] = {}
    for s in spec:
        k, v = s.split("=", 1)
        out[k.strip()] = ast.literal_eval(v.strip())
    return out


def film_track(track: Track, spec: dict[str, float], rng: np.random.Generator, distance: float = DISTANCE
               ) -> tuple[NDArray[np.float64], NDArray[np.float64], NDArray[np.float64], NDArray[np.float64]]:
    """The 2D a detector gives of ``track`` under condition ``spec`` (:data:`ALL_CONDITIONS`), the
    camera at ``distance`` metres unless the condition sets its own.

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
    dist = spec.get("distance", distance)
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


class Evaluator:
    """The lifters of a run's methods, and the figures of one track under one condition.

    Parameters
    ----------
    methods : sequence of str
        Of :data:`METHODS`.
    settings : dict
        :class:`~pose_lifter.core.LifterOptions` fields every lifter takes.
    setup : Setup
    bases_file : str, optional
        The bases of every lifting method (default: each mode's packaged ones).
    offline : dict, optional
        Further options of the lifts that read ahead (the ``-offline`` methods, and ``hybrid-lag``
        from a lag of :data:`~pose_lifter.core.track.defaults.AHEAD_LAG`), e.g. their prior.
    """

    def __init__(self, methods: Sequence[str], settings: dict[str, Any], setup: Setup = Setup(),
                 bases_file: str | None = None, offline: dict[str, Any] | None = None) -> None:
        self.methods = tuple(methods)
        self.setup = setup
        self.lifters: dict[str, Lifter] = {}
        for m in self.methods:
            if m not in LIFTED:
                continue
            name = "hybrid" if m.startswith("hybrid") else m.removesuffix("-t").removesuffix("-offline")
            mode = cast(Mode, name)
            bases = PoseBases.load(bases_file or default_bases_path(mode))
            # an offline lift knows each track's next frames (pose-lifter lift: its offline prior);
            # the lagged node reads ahead from AHEAD_LAG on (pose_lifter.messages.lagged)
            ahead = m.endswith("-offline") or (m == "hybrid-lag" and setup.lag >= AHEAD_LAG)
            opts = LifterOptions(mode=mode).replace(**{**settings, **((offline or {}) if ahead else {})})
            self.lifters[m] = Lifter(bases, opts, reads_ahead=ahead)
            self.lifters[m].warm_up()
        self.mean_pose = PoseBases.load().mean_pose  # the mean-pose floor: the paper's bases

    def evaluate(self, track: Track, condition: str) -> dict[str, Any]:
        """Each method's figures per frame of ``track`` filmed under ``condition``: a record with
        the track's name, the condition, the camera, the frame count ``n`` and ``methods``: per
        method ``p_mpjpe``, ``mpjpe``, ``jitter``, ``true_xy``, ``true_depth`` (lists of T, NaN
        where not lifted), ``ms`` (per frame) and on perspective tracks ``depth_pct``."""
        spec = ALL_CONDITIONS[condition]
        rng = np.random.default_rng(track.seed)
        px, conf, world, cam_pose = film_track(track, spec, rng, self.setup.distance)
        n = len(world)
        leg_m = limb_lengths(world)[:, RIGHT_LOWER_LEG]
        truth = cam_pose - cam_pose.mean(axis=1, keepdims=True)
        perspective = track.camera[2] == "perspective" or "distance" in spec
        filmed = _Film(px, conf, leg_m, np.arange(n, dtype=np.int64) * FRAME_NS, perspective,
                       spec.get("distance", self.setup.distance))
        out: dict[str, Any] = {}
        for m in self.methods:
            t0 = time.perf_counter()
            depth = None
            if m == "flat":
                preds = np.concatenate([truth[..., :2], np.zeros((n, 12, 1))], axis=-1)
            elif m == "mean-pose":  # the mean training pose, turned by the true body frame (an oracle)
                preds = np.einsum("jb,nba->nja", self.mean_pose, body_frame(truth)) * leg_m[:, None, None]
            else:
                preds, depth = self._lift(m, filmed)
            ms = 1000.0 * (time.perf_counter() - t0) / n
            out[m] = {**frame_figures(preds, truth), "ms": ms}
            if depth is not None and perspective:
                out[m]["depth_pct"] = depth.tolist()
        return {"track": track.name, "cond": condition, "camera": track.camera, "n": n, "methods": out}

    def lifts(self, m: str, px: NDArray[np.float64], conf: NDArray[np.float64], leg_m: NDArray[np.float64],
              distance: float) -> tuple[NDArray[np.float64], list[TrackedLift | None]]:
        """Tracked method ``m``'s lifts of a perspective track at ``distance`` metres (``px`` (T,
        12, 2) pixels at 30 Hz, ``conf`` (T, 12), the true right lower leg ``leg_m`` (T,) metres):
        its poses (T, 12, 3; as :meth:`evaluate` scores them: camera frame, centred, times
        ``leg_m``; NaN where not lifted; ``hybrid-lag``: each frame's refined pose) and each
        frame's tracked lift (None where not lifted)."""
        if m not in TRACKED:
            raise ValueError(f"{m} is not a tracked method ({', '.join(TRACKED)})")
        results: list[TrackedLift | None] = []
        filmed = _Film(px, conf, leg_m, np.arange(len(px), dtype=np.int64) * FRAME_NS, True, distance)
        return self._lift(m, filmed, results)[0], results

    def _lift(self, m: str, filmed: _Film, results: list[TrackedLift | None] | None = None
              ) -> tuple[NDArray[np.float64], NDArray[np.float64]]:
        """Method ``m``'s poses of ``filmed`` (T, 12, 3) (metres, camera frame, centred; NaN where
        not lifted) and the centroid's depth error (%) per frame on a perspective track; each
        frame's tracked lift appended to ``results`` (None where not lifted; tracked methods)."""
        lifter = self.lifters[m]
        n = len(filmed.px)
        intrinsics = ((FOCAL, FOCAL), (float(CENTRE[0]), float(CENTRE[1]))) if (
            filmed.perspective and self.setup.intrinsics) else None
        policy = TrackPolicy(lifter, track_timeout=1e9) if m in TRACKED else None
        # the refiner: of the node with output_lag (pose_lifter.messages.lagged), each frame refined
        # lag frames late, or of pose-lifter lift (pose_lifter.offline.chains), the whole track
        lag = self.setup.lag - (lifter.frames_ahead if m == "hybrid-lag" else 0)  # after the lift's
        refiner = None
        if policy is not None and (m == "hybrid-lag" or m.endswith("-offline")):
            policy.smoothed_later = True
            o = lifter.options
            refiner = Refiner(self.setup.lag if m == "hybrid-lag" else None, OFFLINE_SMOOTHING_S, 1.0,
                              o.measurement_depth, o.measurement_gate)
        preds = np.full((n, 12, 3), np.nan)
        refined: list[int] = []  # the frames given to the refiner
        depth = np.full(n, np.nan)
        stamps, leg_m = filmed.stamps, filmed.leg_m
        warm = None
        k_ahead = lifter.frames_ahead
        for i in range(n):
            try:
                if policy is not None:
                    nxt = slice(i + 1, i + 1 + k_ahead)
                    ahead = FramesAhead(stamps[nxt], filmed.px[nxt], filmed.conf[nxt]) if k_ahead else None
                    t = policy.lift(0, int(stamps[i]), filmed.px[i], filmed.conf[i], intrinsics, ahead)
                    r = t.result
                else:
                    r = lifter.lift(filmed.px[i], filmed.conf[i], warm=warm)
                    warm = r.warm_start() if m == "paper" else None
            except PoseLifterError:
                warm = None
                if results is not None:
                    results.append(None)
                continue
            if results is not None and policy is not None:
                results.append(t)
            preds[i] = r.pose_camera * leg_m[i]
            if refiner is not None and policy is not None:
                # what is refined, centred, times the true leg: the published pose (the lagged
                # node's) or offline the fit's own, the published one with the measurement update
                # (pose_lifter.offline.chains.refine_chain)
                own = (r.pose_camera if t.fit_pose_camera is None or lifter.options.measurement_update
                       or refiner.horizon is not None else t.fit_pose_camera)
                kept = policy.kept_later().get(0, [])
                refiner.add(0, int(stamps[i]), own, kept[-1] if kept else None,
                            Placement(None, np.zeros(3), float(leg_m[i])))
                refined.append(i)
                if refiner.horizon is not None:
                    _lag_out(refiner, stamps, preds, i - lag)
            if filmed.perspective:  # the node's placement with the focal length and the true leg
                z = place_in_camera(r, float(leg_m[i]), (FOCAL, FOCAL), None, filmed.distance).mean(axis=0)[2]
                depth[i] = 100.0 * abs(z - filmed.distance) / filmed.distance
        if refiner is not None and refiner.horizon is not None:  # the input stopped: the frames held
            for k in range(max(0, n - lag), n):
                _lag_out(refiner, stamps, preds, k)
        elif refiner is not None:
            preds[refined] = refiner.poses(0)
        return preds, depth


@dataclass(frozen=True)
class _Film:
    """A filmed track as the lifts read it."""

    px: NDArray[np.float64]  #: (T, 12, 2) pixels
    conf: NDArray[np.float64]  #: (T, 12)
    leg_m: NDArray[np.float64]  #: (T,) the true right lower leg, metres
    stamps: NDArray[np.int64]  #: (T,) ns
    perspective: bool
    distance: float  #: the camera's distance, metres


def frame_figures(preds: NDArray[np.float64], truth: NDArray[np.float64]) -> dict[str, Any]:
    """The per-frame figures (mm; lists of T, NaN where not lifted) of poses ``preds`` against
    ``truth``, both (T, 12, 3) metres in the camera frame: ``mpjpe`` compares them as given (the
    accuracy table's are centred, :mod:`.rgbd_evaluation`'s placed)."""
    n = len(truth)
    ok = np.all(np.isfinite(preds), axis=(1, 2))
    pm = np.full(n, np.nan)
    pm[ok] = 1000.0 * np.asarray(p_mpjpe(preds[ok], truth[ok]))
    mp_ = np.full(n, np.nan)
    mp_[ok] = 1000.0 * np.linalg.norm(preds[ok] - truth[ok], axis=-1).mean(axis=-1)
    acc = np.full(n, np.nan)
    if n >= 3:
        ap = preds[2:] - 2 * preds[1:-1] + preds[:-2]
        at = truth[2:] - 2 * truth[1:-1] + truth[:-2]
        acc[1:-1] = 1000.0 * np.linalg.norm(ap - at, axis=-1).mean(axis=-1)
    out: dict[str, Any] = {"p_mpjpe": pm.tolist(), "mpjpe": mp_.tolist(), "jitter": acc.tolist()}
    for key, axes in (("true_xy", slice(0, 2)), ("true_depth", slice(2, 3))):
        swapped = preds.copy()
        swapped[..., axes] = truth[..., axes]
        vals = np.full(n, np.nan)
        vals[ok] = 1000.0 * np.asarray(p_mpjpe(swapped[ok], truth[ok]))
        out[key] = vals.tolist()
    return out


def _lag_out(lagged: Refiner, stamps: NDArray[np.int64], preds: NDArray[np.float64], k: int) -> None:
    """Frame ``k``'s lagged pose (metres) into ``preds``, when the frame was lifted."""
    if k < 0 or not np.isfinite(preds[k]).all():
        return
    pose = lagged.pose(0, int(stamps[k]))
    if pose is not None:
        preds[k] = pose


def split_ids(split: str, data: str | None) -> list[str]:
    """The trials of ``split``: ``eval``, subjects 02, 07, 08 and 09_12, never trained on; ``val``,
    the training-split trials the packaged prior was not fitted on (tuning, calibration)."""
    if split == "eval":
        return split_trials("eval", data)
    from pose_lifter.core.model.prior import PosePrior

    return list(PosePrior.load().metadata.get("validation_trials", []))


def evaluation_tracks(split: str, data: str | None, frames: int, views: int,
                      trials: Sequence[str] | None = None,
                      cameras: Sequence[tuple[float, float, str]] | None = None) -> list[Track]:
    """The tracks of ``trials`` (default: the split's; ``eval``: subjects 02, 07, 08 and 09_12,
    never trained on; ``val``: the training-split trials the packaged prior was not fitted on),
    at 30 Hz, at most ``frames`` frames each, each seen by ``views`` of ``cameras`` (default
    :data:`CAMERAS`), the cameras rotating over the trials."""
    ids = list(trials) if trials else split_ids(split, data)
    cams = list(cameras or CAMERAS)
    out = []
    for k, t in enumerate(ids):
        world = load_trial(t, data, step=4, max_frames=frames)
        for v in range(views):
            cam = cams[(k * views + v) % len(cams)]
            out.append(Track(f"{t}@{cam[0]:.0f}/{cam[1]:.0f}/{cam[2]}", world, cam, 1000 * k + v))
    return out


def action_trials(action: str, data: str | None) -> list[str]:
    """The trials of a MANIFEST action class, of the training and evaluation splits only."""
    known = set(split_trials("train", data)) | set(split_trials("eval", data))
    return sorted({t.trial for t in read_manifest(data) if t.action == action and t.trial in known})


class _Evaluates(Protocol):
    """What :func:`run_jobs` runs: an evaluator of one job's arguments."""

    def evaluate(self, *job: Any) -> dict[str, Any]: ...


_WORKER: dict[str, _Evaluates] = {}


def _start_worker(make: Callable[..., _Evaluates], init: tuple[Any, ...]) -> None:
    """A pool worker's initialiser: its own evaluator ``make(*init)``."""
    warnings.simplefilter("ignore")
    _WORKER["evaluator"] = make(*init)


def _worker_job(job: tuple[Any, ...]) -> dict[str, Any]:
    return _WORKER["evaluator"].evaluate(*job)


def run_jobs(jobs: Sequence[tuple[Any, ...]], make: Callable[..., _Evaluates], init: tuple[Any, ...],
             workers: int = 1) -> list[dict[str, Any]]:
    """``evaluate(*job)`` of every job of ``jobs`` by evaluators ``make(*init)`` (e.g. an
    :class:`Evaluator`), one per process over ``workers`` processes (the records in the order
    they finish)."""
    if workers > 1:
        with mp.get_context("fork").Pool(workers, _start_worker, (make, init)) as pool:
            return list(pool.imap_unordered(_worker_job, jobs, chunksize=1))
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        evaluator = make(*init)
        return [evaluator.evaluate(*job) for job in jobs]


def evaluate_jobs(jobs: Sequence[tuple[Track, str]], methods: Sequence[str], settings: dict[str, Any],
                  setup: Setup = Setup(), bases_file: str | None = None,
                  offline: dict[str, Any] | None = None, workers: int = 1) -> list[dict[str, Any]]:
    """:meth:`Evaluator.evaluate` of every ``(track, condition)`` of ``jobs``, over ``workers``
    processes (each with its own lifters; the records in the order they finish)."""
    return run_jobs(jobs, Evaluator, (tuple(methods), settings, setup, bases_file, offline), workers)


def nanmean(values: Sequence[float]) -> float:
    """The mean of the finite values (NaN when there is none)."""
    x = np.asarray(values, dtype=np.float64)
    return float(np.nanmean(x)) if np.any(np.isfinite(x)) else float("nan")


def summarise(results: Sequence[dict[str, Any]], conditions: Sequence[str], methods: Sequence[str]
              ) -> dict[str, dict[str, dict[str, float]]]:
    """Per condition and method, the means over every frame of ``results`` (records of
    :meth:`Evaluator.evaluate`) of :data:`FIGURES` and ``depth_pct``, the mean ``ms`` per frame
    over the tracks and the share of frames ``lifted`` (mean over the tracks)."""
    table: dict[str, dict[str, dict[str, float]]] = {}
    for cond in conditions:
        rows = [r for r in results if r["cond"] == cond]
        table[cond] = {}
        for m in methods:
            vals = {k: nanmean([v for r in rows for v in r["methods"][m][k]]) for k in FIGURES}
            vals["ms"] = float(np.mean([r["methods"][m]["ms"] for r in rows]))
            vals["lifted"] = float(np.mean([np.isfinite(r["methods"][m]["p_mpjpe"]).mean() for r in rows]))
            vals["depth_pct"] = nanmean([v for r in rows for v in r["methods"][m].get("depth_pct", [])])
            table[cond][m] = vals
    return table


def render_table(table: dict[str, dict[str, dict[str, float]]], methods: Sequence[str], header: str,
                 footer: str = "") -> str:
    """The markdown of a :func:`summarise` table: ``header``, a row per condition of P-MPJPE /
    MPJPE / jitter per method, the time per frame, the share lifted, the depth errors, ``footer``."""
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
    if footer:
        lines.append(footer)
    return "\n".join(lines)


def merge_runs(paths: Sequence[Path]) -> tuple[dict[str, dict[str, dict[str, float]]], tuple[str, ...], str,
                                                dict[str, list[str]]]:
    """One table from several runs' ``accuracy.json`` (same split and conditions; a method in a
    later file replaces the same method of an earlier one): the table, its methods, a header
    saying where each method comes from, and the methods per file.

    Raises
    ------
    ValueError
        The runs are of different splits, or a method lacks some of the conditions.
    """
    table: dict[str, dict[str, dict[str, float]]] = {}
    sources: dict[str, str] = {}
    splits = set()
    for p in paths:
        rec = json.loads(Path(p).read_text())
        splits.add(rec.get("split"))
        for cond, row in rec["table"].items():
            table.setdefault(cond, {}).update(row)
            for m in row:
                sources[m] = str(p)
    if len(splits) != 1:
        raise ValueError(f"runs of different splits {sorted(map(str, splits))}")
    methods = tuple(m for m in METHODS if m in sources)
    if any(set(methods) - set(row) for row in table.values()):
        raise ValueError("a method lacks some of the conditions")
    by_file: dict[str, list[str]] = {}
    for m in methods:
        by_file.setdefault(sources[m], []).append(m)
    parts = "; ".join(f"{', '.join(ms)} from `{f}`" for f, ms in by_file.items())
    header = (f"{splits.pop()} split; merged runs (inputs are seeded per track, so every column sees "
              f"the same corrupted 2D): {parts}")
    return table, methods, header, by_file


def run_stamp(repo: Path | None = None) -> str:
    """What a table was measured on: the git commit of ``repo`` (``-dirty`` with uncommitted
    changes; ``unknown`` outside a checkout) and the CPU model (``/proc/cpuinfo``, else
    :func:`platform.processor`)."""
    commit = "unknown"
    try:
        git = ["git", "-C", str(repo or Path.cwd())]
        commit = subprocess.run([*git, "rev-parse", "--short", "HEAD"], capture_output=True, text=True,
                                check=True).stdout.strip()
        dirty = subprocess.run([*git, "status", "--porcelain", "--untracked-files=no"], capture_output=True,
                               text=True, check=True).stdout.strip()
        commit += "-dirty" if dirty else ""
    except (OSError, subprocess.CalledProcessError):
        pass
    cpu = platform.processor() or platform.machine()
    try:
        for line in Path("/proc/cpuinfo").read_text().splitlines():
            if line.startswith("model name"):
                cpu = line.split(":", 1)[1].strip()
                break
    except OSError:
        pass
    return f"commit {commit}, CPU {cpu}"
