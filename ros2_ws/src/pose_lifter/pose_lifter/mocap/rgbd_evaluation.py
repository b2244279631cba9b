"""Metric accuracy with a depth camera: the monocular lift, the naive depth lookup and the fused
lift side by side (``make rgbd-accuracy``, ``tools/rgbd_accuracy.py``).

Tracks: :func:`pose_lifter.mocap.evaluation.evaluation_tracks` (the evaluation split's trials, or
a cross-action fold's class, at 30 Hz), each filmed by a pinhole camera (640x480 pixels, 800 px
focal length, principal point at the image centre) at each of :data:`DISTANCES` from the joints'
centroid (:func:`film_rgbd`): from the directions of :func:`rgbd_cameras` (the accuracy table's
azimuths, level, and optionally :data:`ELEVATED`), the camera at the height of the hip centre (or
above it), looking at it, following the person. The 2D goes through the realistic detector
(:data:`pose_lifter.mocap.detector_model.REALISTIC`, joints outside the image lost: at 1.5 m the
image holds about 0.9 m of the body's height, so shoulders and ankles are lost on most frames),
and each frame's depth image is rendered from the true joints (a wall and a floor that stay put
over the track: :func:`pose_lifter.mocap.depth_model.scene_backgrounds`) and sensed by
:mod:`pose_lifter.mocap.depth_model` (:data:`~pose_lifter.mocap.depth_model.REALISTIC` unless
told). The detector and the depth sensor draw from their own generators, seeded per track and
distance: every method sees the same 2D and the same depth images.

Methods (:data:`METHODS`), each tracked as the node tracks (the default hybrid mode through
:class:`~pose_lifter.core.track.policy.TrackPolicy`, knowing the intrinsics as the node does from
``camera_info``):

* ``mono``: the monocular lift placed as the node places it without depth
  (:func:`pose_lifter.core.depth.place.place_people`: the default 0.43 m leg, the uncertainty of
  :func:`~pose_lifter.core.depth.monocular_std`);
* ``naive``: what users do today: each joint at the depth reading of its rounded pixel (the
  detector's 2D and labels as given), back-projected on its ray (``z K^-1 [u v 1]``); a joint the
  lifter does not use (confidence below its ``confidence_threshold``), outside the image or on a
  pixel without a reading keeps the ``mono`` joint; no uncertainty;
* ``fused``: the live lift placed on the frame's depth image as the node places it
  (:func:`fuse_person`: :func:`~pose_lifter.core.depth.place.place_people`'s fusion, the frame's
  2D with the labels the track gave the 3D joints), followed along the track by the filter the
  node answers through (:func:`~pose_lifter.core.depth.track_filter.filter_track`);
* ``fused-lag``: the node with ``output_lag`` (3): each frame's pose refined over the next
  frames (:class:`~pose_lifter.core.track.later.Refiner`, as ``hybrid-lag`` of :mod:`.evaluation`),
  then placed again with the depth readings its frame's lift took, as the lagged node does;
* ``fused-offline``: ``pose-lifter lift`` of an RGB-D recording: each track lifted with its next
  frames known (the offline prior) and refined over the whole track (the offline measurement update
  and the centred smoothing, as ``hybrid-offline`` of :mod:`.evaluation`), each pose then placed
  again with the depth readings of its frame's lift, as ``pose_lifter.offline.chains.refine_chain``
  places it;
* ``true-depth``: a floor, not a method: each joint of ``mono`` moved along its ray to the true
  joint's depth (what a perfect depth reading of every joint centre would give the live lift):
  the error left is the lift's image of the joints, from the detector's 2D.

Figures per frame (:func:`rgbd_figures`; means over every lifted frame in :func:`summarise`):
P-MPJPE (mm, similarity-aligned), metric MPJPE (mm, camera frame, no alignment), root error (mm,
the distance between the predicted and the true hip centres, the mean of the two hips), the wrists'
metric error (mm), jitter (:func:`~pose_lifter.mocap.evaluation.frame_figures`' acceleration error,
on the metric joints), the share of joints read from depth, and the coverage of the predicted
standard deviations (:func:`coverage_counts`): the fraction of true joint coordinates within 1 and
2 standard deviations on their axis (Gaussian: 68.3 / 95.4 %) and of whole joints inside the 1- and
2-sigma ellipsoid (chi-square with 3 degrees of freedom: 19.9 / 73.9 %), over all joints, over
those read from depth and over those filled from the prior.
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass, field
from itertools import pairwise
from typing import Any

import numpy as np
from numpy.typing import NDArray

from pose_lifter.core.depth.place import place_people
from pose_lifter.core.depth.smooth import LagWindow, scaled_joints, smooth_fused
from pose_lifter.core.depth.track_filter import filter_track
from pose_lifter.core.depth.uncertainty import LAGGED_STD_FACTOR, SMOOTHED_STD_FACTOR
from pose_lifter.core.model.skeleton import JOINT_NAMES, N_JOINTS, RIGHT_LOWER_LEG, limb_lengths
from pose_lifter.core.results import LiftResult
from pose_lifter.core.track.placement import (
    DEFAULT_DISTANCE_M,
    DEFAULT_LEG_LENGTH_M,
    CameraIntrinsics,
)
from pose_lifter.core.track.smoothing import OFFLINE_SMOOTHING_S
from pose_lifter.messages.frame import labelled_2d
from pose_lifter.messages.lagged import LAG_SMOOTHING_S
from pose_lifter.mocap import depth_model
from pose_lifter.mocap import evaluation as ev
from pose_lifter.mocap.detector_model import REALISTIC, detect
from pose_lifter.mocap.views import film, view_rotation

__all__ = ["AXIS_TARGETS", "DISTANCES", "GROUPS", "JOINT_TARGETS", "METHODS", "STD_BINS_M", "RgbdEvaluator",
           "coverage", "coverage_by_std", "coverage_counts", "evaluate_jobs", "film_rgbd", "fuse_person",
           "naive_lookup", "render_table", "rgbd_cameras", "rgbd_figures", "root_error", "summarise"]

METHODS = ("mono", "naive", "fused", "fused-lag", "fused-offline", "true-depth")
#: The refined methods: each the fused lift of the refined poses of one lift of
#: :mod:`.evaluation` (the lagged node's; ``pose-lifter lift``'s, over the whole track).
REFINED = {"fused-lag": "hybrid-lag", "fused-offline": "hybrid-offline"}
#: Camera distances (m, to the joints' centroid).
DISTANCES = (1.5, 3.0, 5.0)
#: The elevation (degrees, looking down) of the optional elevated views.
ELEVATED = 30.0
INTRINSICS: CameraIntrinsics = ((ev.FOCAL, ev.FOCAL), (float(ev.CENTRE[0]), float(ev.CENTRE[1])))
IMAGE_SIZE = (int(ev.IMAGE_SIZE[0]), int(ev.IMAGE_SIZE[1]))  #: (width, height) pixels
HIPS = (JOINT_NAMES.index("left_hip"), JOINT_NAMES.index("right_hip"))
#: The wrists: the joints a robot reaches for, and the ones the depth reads worst (an arm across or
#: behind the body).
WRISTS = (JOINT_NAMES.index("left_wrist"), JOINT_NAMES.index("right_wrist"))
#: Gaussian coverage of k standard deviations: on one axis, and of a 3D joint's k-sigma ellipsoid
#: (chi-square with 3 degrees of freedom), k = 1, 2.
AXIS_TARGETS = (0.683, 0.954)
JOINT_TARGETS = (0.199, 0.739)
#: The joints a coverage is counted over: all, those read from depth, those filled from the prior.
GROUPS = ("all", "depth", "prior")
#: The edges of the bins of a coordinate's predicted standard deviation (metres) that its coverage
#: is also counted in (:func:`coverage_by_std`): honest deviations cover alike, narrow or wide.
STD_BINS_M = (0.03, 0.06, 0.12)
#: The figures averaged over the frames (mm; ``from_depth`` a fraction of the joints).
FIGURES = ("p_mpjpe", "mpjpe", "root", "wrists", "jitter", "from_depth")
#: The node's ``output_lag`` of ``fused-lag`` (frames).
LAG = 3
#: The largest gap within one track (seconds): :mod:`.evaluation`'s refinement's.
GAP_S = 1.0
#: The smoothed methods, each with the scale of its averaged standard deviations
#: (:mod:`pose_lifter.core.depth.smooth`).
STD_FACTORS = {"fused-lag": LAGGED_STD_FACTOR, "fused-offline": SMOOTHED_STD_FACTOR}


def rgbd_cameras(elevations: Sequence[float] = (0.0,)) -> list[tuple[float, float, str]]:
    """The cameras the tracks rotate over: each of the accuracy table's azimuths at each of
    ``elevations`` (degrees), perspective, the elevations alternating first."""
    return [(float(a), float(e), "perspective") for a in ev.AZIMUTHS for e in elevations]


def film_rgbd(track: ev.Track, distance: float, rng: np.random.Generator
              ) -> tuple[NDArray[np.float64], NDArray[np.float64], NDArray[np.float64]]:
    """``track`` filmed by its camera's direction (azimuth, elevation) from ``distance`` metres,
    the camera at the height of the hip centre on every frame (elevation 0) or above it, looking
    at it, the joints' centroid ``distance`` ahead: the 2D of the realistic detector (joints
    outside the image lost) and the true joints.

    Returns
    -------
    px : ndarray, shape (T, 12, 2)
        Pixels.
    conf : ndarray, shape (T, 12)
    truth : ndarray, shape (T, 12, 3)
        Metres, camera optical frame.
    """
    az, el, _ = track.camera
    n = len(track.world)
    rots = np.repeat(view_rotation(az, el)[None], n, axis=0)
    _, cam, leg = film(track.world, rots, np.full(n, distance), np.ones(n, dtype=bool))
    hips = cam[:, list(HIPS)].mean(axis=1)  # (T, 3)
    truth = cam - np.stack([np.zeros(n), hips[:, 1], np.full(n, -distance)], axis=1)[:, None, :]
    (fx, fy), (cx, cy) = INTRINSICS
    z = truth[..., 2]
    clean = np.stack([fx * truth[..., 0] / z + cx, fy * truth[..., 1] / z + cy], axis=-1)
    px, conf = detect(clean, fx * leg, REALISTIC, rng, ev.IMAGE_SIZE)
    return px, conf, truth


def root_error(pred: NDArray[np.float64], truth: NDArray[np.float64]) -> NDArray[np.float64]:
    """The distance (T,; metres; NaN where ``pred`` is not finite) between the predicted and the
    true hip centres (the mean of the two hips) of poses ``pred`` and ``truth`` (T, 12, 3)."""
    hips = list(HIPS)
    return np.asarray(np.linalg.norm(pred[:, hips].mean(axis=1) - truth[:, hips].mean(axis=1), axis=-1))


def rgbd_figures(pred: NDArray[np.float64], truth: NDArray[np.float64]) -> dict[str, list[float]]:
    """Per frame (lists of T; mm; NaN where not lifted) of placed poses ``pred`` against the true
    joints ``truth`` (both (T, 12, 3), metres, camera frame): ``p_mpjpe`` (similarity-aligned),
    ``mpjpe`` (no alignment), ``root`` (:func:`root_error`), ``jitter`` (acceleration error,
    mm per frame^2) and ``wrists`` (the metric error of the two wrists, :data:`WRISTS`)."""
    figures = ev.frame_figures(pred, truth)
    root = 1000.0 * root_error(pred, truth)
    w = list(WRISTS)
    wrists = 1000.0 * np.linalg.norm(pred[:, w] - truth[:, w], axis=-1).mean(axis=1)
    return {"p_mpjpe": figures["p_mpjpe"], "mpjpe": figures["mpjpe"], "root": root.tolist(),
            "wrists": wrists.tolist(), "jitter": figures["jitter"]}


def coverage_counts(err: NDArray[np.float64], std: NDArray[np.float64]) -> NDArray[np.int64]:
    """How many of the joints' errors ``err`` (N, 3; predicted minus true) their predicted
    standard deviations ``std`` (N, 3; per axis, > 0) cover: (5,) the joints counted (those with
    finite values), the coordinates within 1 and within 2 standard deviations
    (``|err_axis| <= k std_axis``), and the joints inside the 1- and 2-sigma ellipsoids
    (``sum_axis (err_axis / std_axis)^2 <= k^2``)."""
    ok = np.isfinite(err).all(axis=1) & np.isfinite(std).all(axis=1) & (std > 0).all(axis=1)
    z = np.abs(err[ok]) / std[ok]
    d2 = (z * z).sum(axis=1)
    return np.array([ok.sum(), (z <= 1.0).sum(), (z <= 2.0).sum(), (d2 <= 1.0).sum(), (d2 <= 4.0).sum()],
                    dtype=np.int64)


def coverage_by_std(err: NDArray[np.float64], std: NDArray[np.float64]) -> NDArray[np.int64]:
    """Per bin of the predicted standard deviation (:data:`STD_BINS_M`: below the first edge, between
    the edges, from the last on), the coordinates of the errors ``err`` (N, 3; predicted minus true)
    with finite deviations ``std`` (N, 3; > 0) counted, those within 1 and those within 2 standard
    deviations: (len(STD_BINS_M) + 1, 3)."""
    e, sd = np.abs(np.asarray(err, dtype=np.float64)).ravel(), np.asarray(std, dtype=np.float64).ravel()
    ok = np.isfinite(e) & np.isfinite(sd) & (sd > 0)
    z = e[ok] / sd[ok]
    b = np.searchsorted(np.array(STD_BINS_M), sd[ok], side="right")
    return np.array([[(b == k).sum(), ((b == k) & (z <= 1.0)).sum(), ((b == k) & (z <= 2.0)).sum()]
                     for k in range(len(STD_BINS_M) + 1)], dtype=np.int64)


def coverage(counts: NDArray[np.int64] | Sequence[int]) -> dict[str, float]:
    """The fractions of :func:`coverage_counts` (NaN with no joint): ``axis1``, ``axis2`` (of the
    coordinates), ``joint1``, ``joint2`` (of the joints) and the joints counted, ``joints``."""
    c = np.asarray(counts, dtype=np.float64)
    n = c[0]
    if n == 0:
        return {"axis1": np.nan, "axis2": np.nan, "joint1": np.nan, "joint2": np.nan, "joints": 0.0}
    return {"axis1": c[1] / (3 * n), "axis2": c[2] / (3 * n), "joint1": c[3] / n, "joint2": c[4] / n,
            "joints": float(n)}


def naive_lookup(depth: NDArray[np.float32], intrinsics: CameraIntrinsics, points: NDArray[np.float64],
                 usable: NDArray[np.bool_], fallback: NDArray[np.float64]
                 ) -> tuple[NDArray[np.float64], NDArray[np.bool_]]:
    """Each joint at the depth reading of its rounded pixel, back-projected on its ray.

    Parameters
    ----------
    depth : ndarray, shape (H, W)
        Metres along the optical axis, NaN where there is no reading.
    intrinsics : ((fx, fy), (cx, cy))
    points : ndarray, shape (12, 2)
        Pixels (u column, v row).
    usable : ndarray of bool, shape (12,)
        The joints to look up (the others keep ``fallback``).
    fallback : ndarray, shape (12, 3)
        Metres, camera frame: where a joint goes without a reading.

    Returns
    -------
    joints : ndarray, shape (12, 3)
        ``z K^-1 [u v 1]`` at the reading ``z = depth[round(v), round(u)]``, else ``fallback``.
    read : ndarray of bool, shape (12,)
        The joints placed from a reading.
    """
    (fx, fy), (cx, cy) = intrinsics
    h, w = depth.shape
    uv = np.rint(np.asarray(points, dtype=np.float64))
    inside = usable & np.isfinite(uv).all(axis=1) & (uv[:, 0] >= 0) & (uv[:, 0] < w) & (uv[:, 1] >= 0) & (
        uv[:, 1] < h)
    z = np.full(len(uv), np.nan)
    z[inside] = depth[uv[inside, 1].astype(np.int64), uv[inside, 0].astype(np.int64)]
    read = np.isfinite(z) & (z > 0)
    ray = np.stack([(uv[:, 0] - cx) / fx, (uv[:, 1] - cy) / fy, np.ones(len(uv))], axis=1)
    out = np.array(fallback, dtype=np.float64)
    out[read] = z[read, None] * ray[read]
    return out, read


@dataclass
class _Method:
    """One method's joints over a track: placed joints (T, 12, 3, metres; NaN where not lifted),
    standard deviations (T, 12, 3; NaN: none) and the joints read from depth (T, 12)."""

    n: int
    joints: NDArray[np.float64] = field(init=False)
    std: NDArray[np.float64] = field(init=False)
    from_depth: NDArray[np.bool_] = field(init=False)
    read: NDArray[np.bool_] = field(init=False)  #: the joints with a depth reading (T, 12)

    def __post_init__(self) -> None:
        self.joints = np.full((self.n, N_JOINTS, 3), np.nan)
        self.std = np.full((self.n, N_JOINTS, 3), np.nan)
        self.from_depth = np.zeros((self.n, N_JOINTS), dtype=bool)
        self.read = np.zeros((self.n, N_JOINTS), dtype=bool)

    def put(self, i: int, joints: NDArray[np.float64], std: NDArray[np.float64] | None,
            from_depth: NDArray[np.bool_], read: NDArray[np.bool_] | None = None) -> None:
        self.joints[i] = joints
        if std is not None:
            self.std[i] = std
        self.from_depth[i] = from_depth
        if read is not None:
            self.read[i] = read

    def record(self, truth: NDArray[np.float64]) -> dict[str, Any]:
        """Its figures per frame (:func:`rgbd_figures`, ``from_depth``: the share of joints read
        from depth, NaN where not lifted), ``coverage``: per group of :data:`GROUPS` the
        :func:`coverage_counts` over the track, and ``by_std``: its :func:`coverage_by_std` (both
        None without standard deviations)."""
        out: dict[str, Any] = rgbd_figures(self.joints, truth)
        lifted = np.isfinite(self.joints).all(axis=(1, 2))
        out["from_depth"] = np.where(lifted, self.from_depth.mean(axis=1), np.nan).tolist()
        if np.isfinite(self.std).any():
            err = (self.joints - truth).reshape(-1, 3)
            std = self.std.reshape(-1, 3)
            depth = self.from_depth.reshape(-1)
            masks = {"all": np.ones(len(depth), dtype=bool), "depth": depth, "prior": ~depth}
            out["coverage"] = {g: coverage_counts(err[k], std[k]).tolist() for g, k in masks.items()}
            out["by_std"] = coverage_by_std(err, std).tolist()
        else:
            out["coverage"], out["by_std"] = None, None
        return out


class RgbdEvaluator:
    """The lifts of a run and the figures of one track at one camera distance.

    Parameters
    ----------
    methods : sequence of str
        Of :data:`METHODS`.
    settings : dict
        :class:`~pose_lifter.core.LifterOptions` fields (e.g. a fold's ``prior_file``).
    bases_file : str, optional
        The hybrid bases (default: the packaged ones).
    sensor : DepthSensor, optional
        Default :data:`pose_lifter.mocap.depth_model.REALISTIC`.
    std_factors : dict, optional
        Per smoothed method (:data:`STD_FACTORS`' keys), the scale of its averaged standard
        deviations (default :data:`STD_FACTORS`).
    normalised_errors : bool
        Each record holds ``normalised_errors``: per smoothed method, its errors over its standard
        deviations per coordinate of every lifted frame whose 2D shows the body whole, of each
        frame's own fusion (``frames``) and smoothed (``smoothed``): what ``make
        depth-calibration`` measures :data:`STD_FACTORS` on.
    """

    def __init__(self, methods: Sequence[str], settings: dict[str, Any], bases_file: str | None = None,
                 sensor: depth_model.DepthSensor | None = None,
                 std_factors: dict[str, float] | None = None, normalised_errors: bool = False) -> None:
        unknown = sorted(set(methods) - set(METHODS))
        if unknown:
            raise ValueError(f"unknown methods {unknown} (of {list(METHODS)})")
        self.methods = tuple(methods)
        self.sensor = sensor or depth_model.REALISTIC
        lifts = ("hybrid", *(lift for m, lift in REFINED.items() if m in self.methods))
        self.lifts = ev.Evaluator(lifts, settings, ev.Setup(intrinsics=True, lag=LAG), bases_file)
        self.threshold = self.lifts.lifters["hybrid"].options.confidence_threshold
        self.std_factors = {**STD_FACTORS, **(std_factors or {})}
        self.normalised_errors = normalised_errors

    def evaluate(self, track: ev.Track, distance: float) -> dict[str, Any]:
        """Each method's figures of ``track`` filmed at ``distance`` metres: a record with the
        track's name, its camera, the distance, the frame count ``n`` and ``methods``: per method
        the lists of :meth:`_Method.record`."""
        det_seed, depth_seed = np.random.SeedSequence([track.seed, round(1000 * distance)]).spawn(2)
        px, conf, truth = film_rgbd(track, distance, np.random.default_rng(det_seed))
        depth_rng = np.random.default_rng(depth_seed)
        leg_m = limb_lengths(track.world)[:, RIGHT_LOWER_LEG]
        n = len(truth)
        _, live = self.lifts.lifts("hybrid", px, conf, leg_m, distance)
        refined = {m: self.lifts.lifts(lift, px, conf, leg_m, distance) for m, lift in REFINED.items()
                   if m in self.methods}
        out = {m: _Method(n) for m in METHODS}
        live_lag = _Method(n)
        observed = {m: np.zeros((n, N_JOINTS), dtype=bool) for m in refined}  # the joints the 2D shows
        up = view_rotation(*track.camera[:2]) @ np.array([0.0, 1.0, 0.0])  # the world's up, camera frame
        scene = depth_model.scene_backgrounds(truth[None], np.repeat(up[None], n, axis=0))
        for i in range(n):
            rendered = depth_model.render_depth(truth[i][None], INTRINSICS, IMAGE_SIZE, scene[i])
            depth = depth_model.sense(rendered, self.sensor, depth_rng)
            t = live[i]
            if t is not None:
                points = labelled_2d(px[i], conf[i], t.swapped)[0][None]
                mono = place_people([t.result], points, INTRINSICS, DEFAULT_LEG_LENGTH_M, DEFAULT_DISTANCE_M)
                out["mono"].put(i, mono.joints_m[0], mono.std_m[0], np.zeros(N_JOINTS, dtype=bool))
                usable = conf[i] >= self.threshold
                joints, read = naive_lookup(depth, INTRINSICS, px[i], usable, mono.joints_m[0])
                out["naive"].put(i, joints, None, read)
                if "fused" in self.methods:
                    out["fused"].put(i, *fuse_person(depth, points, t.result, t.result.pose_camera))
                x0 = mono.joints_m[0]
                out["true-depth"].put(i, x0 * (truth[i, :, 2] / x0[:, 2])[:, None], None,
                                      np.ones(N_JOINTS, dtype=bool))
            for m, (poses, results) in refined.items():
                tl = results[i]
                if tl is not None and np.isfinite(poses[i]).all():
                    points = labelled_2d(px[i], conf[i], tl.swapped)[0][None]
                    out[m].put(i, *fuse_person(depth, points, tl.result, poses[i] / leg_m[i]))
                    observed[m][i] = tl.result.weights > 0
                    if m == "fused-lag":  # the frame as lifted, fused: what the lag holds of it
                        live_lag.put(i, *fuse_person(depth, points, tl.result, tl.result.pose_camera))
        record: dict[str, Any] = {"track": track.name, "camera": track.camera, "distance": distance, "n": n}
        stamps = np.arange(n, dtype=np.int64) * ev.FRAME_NS
        fused = out["fused"]  # answered at once: the node's filter along the track
        placed = np.asarray(np.isfinite(fused.joints).all(axis=(1, 2)), dtype=bool)
        fused.joints = filter_track(stamps, fused.joints, fused.std, placed, GAP_S)
        normalised: dict[str, dict[str, list[float]]] = {}
        for m in [m for m in STD_FACTORS if m in self.methods]:
            f = out[m]
            frames = (f.joints - truth) / f.std
            lifted = np.asarray(np.isfinite(f.joints).all(axis=(1, 2)), dtype=bool)
            scaled = scaled_joints(observed[m], f.read)
            factor = np.where(scaled, self.std_factors[m], 1.0)
            if m == "fused-lag":  # the lagged node's window
                out[m] = f = _lag_window(f, live_lag, stamps, factor)
            else:  # pose-lifter lift averages each track's fused joints
                f.joints, f.std = smooth_fused(f.joints, f.std, stamps, lifted, OFFLINE_SMOOTHING_S, GAP_S,
                                               factor)
            # the factors are measured on the joints they scale: read, or of a body shown whole
            counted = lifted[:, None] & scaled
            normalised[m] = {"frames": frames[counted].ravel().tolist(),
                             "smoothed": ((f.joints - truth) / f.std)[counted].ravel().tolist()}
        if self.normalised_errors:
            record["normalised_errors"] = normalised
        return {**record, "methods": {m: out[m].record(truth) for m in self.methods}}


def _lag_window(lagged: _Method, live: _Method, stamps: NDArray[np.int64], std_factor: NDArray[np.float64]
                ) -> _Method:
    """The lagged node's window (:class:`~pose_lifter.core.depth.smooth.LagWindow`) over
    ``lagged``'s fused joints (its refined poses fused, as
    :meth:`pose_lifter.messages.lagged.LaggedFrames._refined` fuses them): each frame averaged
    with the frames before it as refined and fused and the :data:`LAG` frames after it as lifted
    and fused (``live``)."""
    out = _Method(lagged.n)
    out.from_depth, out.read = lagged.from_depth, lagged.read
    window = LagWindow(LAG_SMOOTHING_S, GAP_S)
    for i in range(lagged.n):
        if np.isfinite(lagged.joints[i]).all():
            held = range(i + 1, min(lagged.n, i + LAG + 1))
            after = [(int(stamps[k]), live.joints[k], live.std[k]) for k in held
                     if np.isfinite(live.joints[k]).all()]
            out.joints[i], out.std[i] = window.average(0, (int(stamps[i]), lagged.joints[i], lagged.std[i]),
                                                       after, std_factor[i])
    return out


def fuse_person(depth: NDArray[np.float32], points: NDArray[np.float64], result: LiftResult,
                pose: NDArray[np.float64]
                ) -> tuple[NDArray[np.float64], NDArray[np.float64], NDArray[np.bool_], NDArray[np.bool_]]:
    """One person placed on a depth image by :func:`pose_lifter.core.depth.place.place_people`
    (the node's, the lagged node's and the offline lift's placement), with the joints it read
    from depth: the lift placed with its own pose, then ``pose`` (12, 3; the lift's
    ``pose_camera`` or its refinement over later frames, leg units) placed again with the
    readings that took, as the lagged node places a refined pose.

    Parameters
    ----------
    depth : ndarray of float32, shape (H, W)
    points : ndarray, shape (1, 12, 2)
        The 2D the lift read, labelled as its joints (pixels).
    result : LiftResult
    pose : ndarray, shape (12, 3)

    Returns
    -------
    joints : ndarray, shape (12, 3)
        Metres, camera frame.
    std : ndarray, shape (12, 3)
        Metres, per axis.
    from_depth : ndarray of bool, shape (12,)
        The joints whose reading the fusion kept.
    read : ndarray of bool, shape (12,)
        The joints with a reading (their patch read, not hidden): those a window's scale applies
        to (:func:`~pose_lifter.core.depth.smooth.window_std_factor`).
    """
    placed = place_people([result], points, INTRINSICS, DEFAULT_LEG_LENGTH_M, DEFAULT_DISTANCE_M, depth=depth)
    if not np.array_equal(pose, result.pose_camera):
        placed = place_people([result], points, INTRINSICS, DEFAULT_LEG_LENGTH_M, DEFAULT_DISTANCE_M,
                              poses=pose[None], readings=placed.readings)
    assert placed.from_depth is not None and placed.readings is not None
    return placed.joints_m[0], placed.std_m[0], placed.from_depth[0], np.isfinite(placed.readings.depth_m[0])


def evaluate_jobs(jobs: Sequence[tuple[ev.Track, float]], methods: Sequence[str], settings: dict[str, Any],
                  bases_file: str | None = None, workers: int = 1) -> list[dict[str, Any]]:
    """:meth:`RgbdEvaluator.evaluate` of every ``(track, distance)`` of ``jobs`` over ``workers``
    processes (:func:`~pose_lifter.mocap.evaluation.run_jobs`; the records in the order they finish)."""
    return ev.run_jobs(jobs, RgbdEvaluator, (tuple(methods), settings, bases_file), workers)


def summarise(results: Sequence[dict[str, Any]], distances: Sequence[float], methods: Sequence[str]
              ) -> dict[str, dict[str, dict[str, Any]]]:
    """Per distance (``"3 m"``; with several camera elevations among ``results``, per distance
    and elevation: ``"3 m, level"``, ``"3 m, 30 deg above"``) and method: the means over every
    lifted frame of ``results`` (records of :meth:`RgbdEvaluator.evaluate`) of :data:`FIGURES`,
    the share of frames ``lifted``, ``coverage``: per group of :data:`GROUPS` the
    :func:`coverage` over every joint, and ``by_std``: the :func:`coverage_by_std` counts over
    every coordinate (both None for a method without uncertainty)."""
    elevations = sorted({float(r["camera"][1]) for r in results})
    table: dict[str, dict[str, dict[str, Any]]] = {}
    for d in distances:
        for el in elevations:
            rows = [r["methods"] for r in results if r["distance"] == d and float(r["camera"][1]) == el]
            if not rows:
                continue
            row: dict[str, dict[str, Any]] = {}
            for m in methods:
                vals: dict[str, Any] = {k: ev.nanmean([v for r in rows for v in r[m][k]]) for k in FIGURES}
                vals["lifted"] = float(np.mean(np.concatenate([np.isfinite(r[m]["mpjpe"]) for r in rows])))
                counts = [r[m]["coverage"] for r in rows if r[m]["coverage"] is not None]
                vals["coverage"] = ({g: coverage(np.sum([c[g] for c in counts], axis=0)) for g in GROUPS}
                                    if counts else None)
                by_std = [r[m]["by_std"] for r in rows if r[m].get("by_std") is not None]
                vals["by_std"] = np.sum(by_std, axis=0).tolist() if by_std else None
                row[m] = vals
            view = "" if len(elevations) == 1 else ", level" if el == 0 else f", {el:g} deg above"
            table[f"{d:g} m{view}"] = row
    return table


Table = dict[str, dict[str, dict[str, Any]]]


def mean_table(tables: Sequence[Table]) -> Table:
    """The mean of :func:`summarise` tables of the same rows (e.g. the cross-action folds: each
    class weighs the same): of each figure and each coverage fraction (NaN-aware), the joints
    counted summed."""
    out: dict[str, dict[str, dict[str, Any]]] = {}
    for d, row in tables[0].items():
        out[d] = {}
        for m, first in row.items():
            cells = [t[d][m] for t in tables]
            vals: dict[str, Any] = {k: ev.nanmean([c[k] for c in cells]) for k in (*FIGURES, "lifted")}
            covs = [c["coverage"] for c in cells if c["coverage"] is not None]
            vals["coverage"] = None if first["coverage"] is None else {
                g: {k: (float(np.sum([c[g][k] for c in covs])) if k == "joints"
                        else ev.nanmean([c[g][k] for c in covs if c[g]["joints"]]))
                    for k in covs[0][g]} for g in GROUPS}
            by_std = [c["by_std"] for c in cells if c.get("by_std") is not None]
            vals["by_std"] = np.sum(by_std, axis=0).tolist() if by_std else None  # pooled over the tables
            out[d][m] = vals
    return out


def _pair(cov: dict[str, dict[str, float]] | None, group: str, kind: str) -> str:
    """``"68.1 / 95.2"`` (%) of a group's 1- and 2-sigma coverage of ``kind`` (axis, joint), or ``-``."""
    if cov is None or not cov[group]["joints"]:
        return "-"
    return f"{100 * cov[group][kind + '1']:.1f} / {100 * cov[group][kind + '2']:.1f}"


def render_table(table: dict[str, dict[str, dict[str, Any]]], methods: Sequence[str], header: str,
                 footer: str = "") -> str:
    """The markdown of a :func:`summarise` table: ``header``, a row per distance and method of
    the errors, then of the coverage, then of the coverage by predicted deviation, ``footer``."""
    lines = [header, "", "| distance | method | P-MPJPE (mm) | metric MPJPE (mm) | root (mm) | wrists (mm) "
             "| jitter (mm/frame^2) | read from depth | frames lifted |", "|---" * 9 + "|"]
    for d, row in table.items():
        for m in methods:
            v = row[m]
            lines.append(f"| {d} | {m} | {v['p_mpjpe']:.1f} | {v['mpjpe']:.1f} | {v['root']:.1f} | "
                         f"{v['wrists']:.1f} | {v['jitter']:.1f} | {100 * v['from_depth']:.1f} % | "
                         f"{100 * v['lifted']:.1f} % |")
    lines += ["", f"Coverage (%) of the predicted standard deviations: true coordinates within 1 / 2 sigma "
              f"per axis (Gaussian {100 * AXIS_TARGETS[0]:.1f} / {100 * AXIS_TARGETS[1]:.1f}), true joints "
              f"inside the 1 / 2 sigma ellipsoid (chi-square, 3 dof: {100 * JOINT_TARGETS[0]:.1f} / "
              f"{100 * JOINT_TARGETS[1]:.1f}); joints read from depth and filled from the prior apart:", "",
              "| distance | method | axis: all | axis: depth | axis: prior | ellipsoid: all "
              "| ellipsoid: depth | ellipsoid: prior |", "|---|---|---|---|---|---|---|---|"]
    for d, row in table.items():
        for m in methods:
            cov = row[m]["coverage"]
            cells = [_pair(cov, g, kind) for kind in ("axis", "joint") for g in GROUPS]
            lines.append(f"| {d} | {m} | " + " | ".join(cells) + " |")
    edges = [f"{100 * e:g}" for e in STD_BINS_M]
    bins = [f"< {edges[0]}", *(f"{a}-{b}" for a, b in pairwise(edges)), f">= {edges[-1]}"]
    lines += ["", "Coverage per axis by the predicted standard deviation (cm): % of the coordinates within "
              "1 / 2 sigma, and the bin's share of the coordinates:", "",
              "| distance | method | " + " | ".join(f"sigma {b}" for b in bins) + " |",
              "|---" * (len(bins) + 2) + "|"]
    for d, row in table.items():
        for m in methods:
            counts = row[m].get("by_std")
            if counts is None:
                continue
            n_all = max(sum(c[0] for c in counts), 1)
            cells = [f"{100 * c[1] / c[0]:.1f} / {100 * c[2] / c[0]:.1f} ({100 * c[0] / n_all:.0f} %)"
                     if c[0] else "-" for c in counts]
            lines.append(f"| {d} | {m} | " + " | ".join(cells) + " |")
    if footer:
        lines += ["", footer]
    return "\n".join(lines)
