"""Train the downstream action-recognition example on CMU mocap and compare 3D vs 2D input.

    .venv/bin/python tools/action_recognition_eval.py [--data ../shared/data/cmu]
        [--lifted-train 900 --model-input lifted]
        [--model-out ros2_ws/src/pose_lifter/pose_lifter/data/actions_knn.npz] [--json out.json]

Classes are the MANIFEST actions with at least two trials: walk, run, dance, basketball and
playground (subject 01: climb, swing, hang, jump down). Per class, every third trial (sorted by
id) is held out; the others train. The test trials are never seen in training (same subjects,
different recordings: dance is all subject 05, basketball all subject 06), and neither are the
trials the lifter's learned priors were trained on (read from their metadata; tools/train_prior.py
holds out the first 3 per class): by default every other held-out trial is used
(``--max-test-trials``), ``--test-windows`` windows per class spread evenly over the class's
test trials and in time.

Every test window is filmed from its own random camera azimuth (uniform 0-360 deg, 10 deg
elevation, scaled orthographic, Gaussian pixel noise), the camera fixed over the window's span,
and classified three ways:

* ``2d``      k-NN on normalised 2D keypoints, trained on projections of the training windows
              from 8 azimuths (the 2D baseline: no lifter);
* ``3d-lift/MODE`` the 2D is lifted with the core Lifter in each ``--modes`` mode (paper,
              learned, hybrid) as the lifter node does (``--lift track``): every 30 Hz frame from
              ``--lead-in`` seconds before the window to its end is one track of a
              :class:`TrackPolicy` (warm starts, the causal temporal prior, the outlier gate,
              per-joint carry-over), and the window's poses are taken from that output;
              ``--lift window`` lifts only the window's 4 poses, warm-started (the old protocol);
              then k-NN on view-normalised 3D with the model trained on true 3D;
* ``3d-lift/lifted-train`` (``--lifted-train N``) the last mode's lifted windows, classified by
              a model trained on N lifted training windows per class (training trials cut into
              ``--segment``-second pieces, each filmed from a random azimuth and lifted the same
              way): what the node sees downstream of the lifter;
* ``3d-true`` k-NN on the ground-truth 3D (what a perfect lifter would give).

Accuracies are printed with a binomial standard error (windows of one trial are correlated, so
the true uncertainty is larger). ``--model-out`` writes the 3D model (trained on true 3D, or with
``--model-input lifted`` on the lifted training windows) for the node
``ros2 run pose_lifter action_recognition``.
"""

from __future__ import annotations

import argparse
import json
import sys
import time
from collections import Counter
from dataclasses import dataclass
from pathlib import Path

import numpy as np
from numpy.typing import NDArray
from pose_lifter.actions import ActionClassifier
from pose_lifter.core import Lifter, LifterOptions, p_mpjpe
from pose_lifter.core.errors import PoseLifterError
from pose_lifter.core.track.policy import TrackPolicy
from pose_lifter.mocap.cmu import load_trial, read_manifest, resolve_data_dir

CLASSES = ("walk", "run", "dance", "basketball", "playground")
FPS = 30.0  # mocap 120 Hz subsampled by 4
WINDOW = 4
STEP_S = 0.1  # 3 frames at 30 Hz
MAX_SECONDS = 20.0  # per trial, to keep long dance/basketball takes from dominating
TRAIN_STRIDE = 6  # frames between training windows (0.2 s)
TRAIN_AZIMUTHS = np.arange(0.0, 360.0, 45.0)


def trials_by_class(data_dir: Path) -> dict[str, list[str]]:
    out: dict[str, set[str]] = {c: set() for c in CLASSES}
    for t in read_manifest(data_dir):
        if t.action in out:
            out[t.action].add(t.trial)
    return {c: sorted(v) for c, v in out.items()}


def split(trials: list[str]) -> tuple[list[str], list[str]]:
    test = trials[1::3]
    return [t for t in trials if t not in test], test


def windows(poses: NDArray[np.float64], stride: int) -> NDArray[np.float64]:
    """(n, WINDOW, 12, 3) windows of a (F, 12, 3) clip, newest pose last."""
    lag = round(STEP_S * FPS)
    span = (WINDOW - 1) * lag
    ends = np.arange(span, len(poses), stride)
    idx = ends[:, None] - lag * np.arange(WINDOW - 1, -1, -1)[None, :]
    return np.asarray(poses[idx])


def camera(azimuth_deg: float, elevation_deg: float = 10.0) -> NDArray[np.float64]:
    """World (Y up) -> camera optical frame (x right, y down, z forward) rotation."""
    from scipy.spatial.transform import Rotation

    # a camera looking along world -Z (x right, y down) then orbiting about the vertical
    base = np.diag([1.0, -1.0, -1.0])
    orbit = Rotation.from_euler("yx", [azimuth_deg, -elevation_deg], degrees=True).as_matrix()
    return np.asarray(base @ orbit.T)


def film(poses: NDArray[np.float64], rotation: NDArray[np.float64], rng: np.random.Generator,
         noise_px: float, px_per_m: float = 160.0) -> NDArray[np.float64]:
    """Scaled-orthographic pixels of poses (..., 12, 3) -> (..., 12, 2)."""
    cam = poses @ rotation.T
    xy = cam[..., :2] * px_per_m + np.array([320.0, 240.0])
    return np.asarray(xy + noise_px * rng.normal(size=xy.shape))


def lift_window(lifter: Lifter, points: NDArray[np.float64]) -> NDArray[np.float64]:
    """Lift a window of 2D frames (W, 12, 2) in order, warm-starting each from the previous
    (the old, untracked evaluation: no temporal prior, no gate)."""
    out = []
    warm = None
    for p in points:
        res = lifter.lift(p, np.ones(len(p)), warm=warm)
        warm = res.warm_start()
        out.append(res.pose_camera)
    return np.stack(out)


def lift_track(lifter: Lifter, points: NDArray[np.float64]) -> NDArray[np.float64]:
    """Lift a 30 Hz sequence of one person (F, 12, 2) as the lifter node does: one track of a
    :class:`TrackPolicy` (warm starts, the causal temporal prior, the outlier gate, per-joint
    carry-over), with the node's default settings.

    Returns
    -------
    ndarray, shape (F, 12, 3)
        Camera-frame poses; a frame the lifter refuses repeats the track's previous pose (the
        action node would take its nearest pose in time).
    """
    policy = TrackPolicy(lifter)
    out = np.full((len(points), 12, 3), np.nan)
    for i, p in enumerate(points):
        try:
            out[i] = policy.lift(0, round(i * 1e9 / FPS), p, np.ones(len(p))).result.pose_camera
        except PoseLifterError:
            if i > 0:
                out[i] = out[i - 1]
    if np.isnan(out).any():  # leading refusals: take the first lifted pose
        ok = np.flatnonzero(~np.isnan(out).any(axis=(1, 2)))
        if len(ok) == 0:
            raise PoseLifterError("no frame of the sequence could be lifted")
        out[: ok[0]] = out[ok[0]]
    return out


def window_index(end: int) -> NDArray[np.int_]:
    """Frame indices (W,) of the window ending at 30 Hz frame ``end``, oldest first."""
    lag = round(STEP_S * FPS)
    return np.asarray(end - lag * np.arange(WINDOW - 1, -1, -1))


def lift_test_window(lifter: Lifter, clip: NDArray[np.float64], end: int, rotation: NDArray[np.float64],
                     rng: np.random.Generator, noise_px: float, lead_in: int, how: str
                     ) -> tuple[NDArray[np.float64], NDArray[np.float64]]:
    """Film and lift one test window of a (F, 12, 3) clip ending at frame ``end``.

    ``how="track"``: every 30 Hz frame from ``lead_in`` frames before the window's first pose
    (fewer at the clip's start) to its last is filmed by the same camera and lifted as one track;
    the window's poses are taken from that output. ``how="window"``: only the W poses are lifted
    (:func:`lift_window`).

    Returns
    -------
    points : ndarray, shape (W, 12, 2)
        The window's 2D keypoints (what the 2D baseline sees).
    lifted : ndarray, shape (W, 12, 3)
    """
    idx = window_index(end)
    start = max(0, int(idx[0]) - lead_in)
    pts = film(clip[start: end + 1], rotation, rng, noise_px)
    win_pts = pts[idx - start]
    if how == "window":
        return win_pts, lift_window(lifter, win_pts)
    return win_pts, lift_track(lifter, pts)[idx - start]


def lift_training(lifter: Lifter, clips: list[NDArray[np.float64]], per_class: int, segment: int,
                  lead_in: int, rng: np.random.Generator, noise_px: float, how: str
                  ) -> NDArray[np.float64]:
    """Lifted training windows of one class, shape (per_class, W, 12, 3).

    Each clip is cut into segments of ``segment`` frames, each filmed from its own random azimuth
    and lifted as one track from ``lead_in`` frames before the segment (``how="track"``); the
    windows lying inside a segment (stride 0.1 s) are kept. Passes with new azimuths are added
    until the class has ``per_class`` windows, then ``per_class`` are picked evenly.
    ``how="window"`` lifts each window's W poses alone (:func:`lift_window`).
    """
    lag = round(STEP_S * FPS)
    span = (WINDOW - 1) * lag
    out: list[NDArray[np.float64]] = []
    n = 0
    while n < per_class:
        for clip in clips:
            for s0 in range(0, len(clip) - span, segment):
                s1 = min(len(clip), s0 + segment)
                ends = np.arange(s0 + span, s1, lag)
                if len(ends) == 0:
                    continue
                rot = camera(float(rng.uniform(0.0, 360.0)))
                if how == "window":
                    for e in ends:
                        idx = window_index(int(e))
                        out.append(lift_window(lifter, film(clip[idx], rot, rng, noise_px))[None])
                else:
                    a = max(0, s0 - lead_in)
                    lifted = lift_track(lifter, film(clip[a:s1], rot, rng, noise_px))
                    out.append(lifted[np.stack([window_index(int(e)) for e in ends]) - a])
                n += len(ends)
    allw = np.concatenate(out)
    return np.asarray(allw[np.linspace(0, len(allw) - 1, per_class).round().astype(int)])


def test_windows_of(clips: list[NDArray[np.float64]], per_class: int) -> list[tuple[int, int]]:
    """(clip index, window end frame) of ``per_class`` test windows spread evenly over the clips
    (the same number from each held-out trial, as far as its length allows), then evenly in time."""
    span = (WINDOW - 1) * round(STEP_S * FPS)
    avail = [max(0, len(c) - span) for c in clips]
    quota = [0] * len(clips)
    for _ in range(per_class):  # round-robin over the trials that have windows left
        cands = [i for i in range(len(clips)) if quota[i] < avail[i]]
        if not cands:
            break
        i = min(cands, key=lambda k: (quota[k], k))
        quota[i] += 1
    return [(i, span + int(e)) for i, q in enumerate(quota) if q > 0
            for e in np.linspace(0, avail[i] - 1, q).round().astype(int)]


def paired_se(a: NDArray[np.bool_], b: NDArray[np.bool_]) -> float:
    """Standard error of the accuracy difference of two classifiers on the same windows (n,)."""
    d = np.asarray(a, dtype=np.float64) - np.asarray(b, dtype=np.float64)
    return float(d.std(ddof=1) / np.sqrt(len(d))) if len(d) > 1 else float("nan")


def prior_trials(lifters: list[Lifter]) -> set[str]:
    """Trials the lifters' learned priors (single-frame and temporal) were trained on, from their
    metadata: a test trial among them would flatter the lifted 3D."""
    out: set[str] = set()
    for lf in lifters:
        if lf.options.mode == "paper":
            continue
        for prior in (lf.prior, lf.temporal_prior):
            if prior is not None:
                out |= {str(t) for t in prior.metadata.get("training_trials", [])}
    return out


def binomial_se(p: float, n: int) -> float:
    """Standard error of an accuracy ``p`` measured on ``n`` windows (binomial; windows of one
    trial are correlated, so this is a lower bound)."""
    return float(np.sqrt(p * (1.0 - p) / n)) if n > 0 else float("nan")


def _parser() -> argparse.ArgumentParser:
    """The command line (the module docstring)."""
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--data", default=None, help="CMU data dir (default ../shared/data/cmu or "
                    "$POSE_LIFTER_CMU_DATA)")
    ap.add_argument("--model-out", default=None, help="write the 3D model (.npz) here")
    ap.add_argument("--test-windows", type=int, default=100,
                    help="test windows per class (0: only train and write the model)")
    ap.add_argument("--max-test-trials", type=int, default=0,
                    help="held-out trials per class used (0: all)")
    ap.add_argument("--noise-px", type=float, default=2.0, help="2D Gaussian noise, pixels (std)")
    ap.add_argument("--n-starts", type=int, default=LifterOptions().n_starts, help="lifter cold starts")
    ap.add_argument("--lift", choices=["track", "window"], default="track",
                    help="track: lift every 30 Hz frame of a window's span as one tracked person (the node); "
                         "window: only the window's poses")
    ap.add_argument("--lead-in", type=float, default=1.0,
                    help="seconds tracked before a test window (and a training segment)")
    ap.add_argument("--segment", type=float, default=2.0,
                    help="seconds of a lifted training segment (one camera azimuth each)")
    ap.add_argument("--neighbors", type=int, default=3, help="k of the 3D k-NN")
    ap.add_argument("--neighbors-2d", type=int, default=5, help="k of the 2D k-NN")
    ap.add_argument("--depth-weight", type=float, default=0.25,
                    help="3D features: weight of the body frame's forward coordinate")
    ap.add_argument("--lifted-train", type=int, default=0,
                    help="also train a 3D model on this many lifted training windows per class")
    ap.add_argument("--model-input", choices=["true", "lifted"], default="true",
                    help="--model-out writes the 3D model trained on true 3D or on the lifted training "
                         "windows (needs --lifted-train; what the node sees downstream of the lifter)")
    ap.add_argument("--seed", type=int, default=0)
    ap.add_argument("--modes", nargs="+", default=["paper", "learned", "hybrid"],
                    choices=["paper", "learned", "hybrid"], help="lifter modes compared (the last one "
                    "lifts the training windows)")
    ap.add_argument("--json", default=None, help="write the results as JSON here")
    return ap


@dataclass(frozen=True)
class _Windows:
    """The training and test data of every class.

    Attributes
    ----------
    train_windows : ndarray, shape (N, W, 12, 3)
        The true 3D training windows (world frame, metres).
    labels : ndarray, shape (N,)
        Their classes.
    train_clips : dict of str to list of ndarray, shape (F, 12, 3)
        Each class's training trials at 30 Hz.
    tests : list of (str, str, ndarray (F, 12, 3), list of int)
        Class, trial, clip and window end frames of each test trial.
    dropped : list of str
        Held-out trials left untested: a lifter's prior was trained on them.
    """

    train_windows: NDArray[np.float64]
    labels: NDArray[np.str_]
    train_clips: dict[str, list[NDArray[np.float64]]]
    tests: list[tuple[str, str, NDArray[np.float64], list[int]]]
    dropped: list[str]


def _load_windows(args: argparse.Namespace, data: Path, per_class: dict[str, list[str]], seen: set[str]
                  ) -> _Windows:
    """Every class's training windows and test windows (:func:`split`, :func:`test_windows_of`);
    the held-out trials in ``seen`` are not tested."""
    step = round(120.0 / FPS)
    max_frames = int(MAX_SECONDS * FPS)
    dropped: list[str] = []
    train_w: list[NDArray[np.float64]] = []
    train_y: list[str] = []
    train_clips: dict[str, list[NDArray[np.float64]]] = {}
    tests: list[tuple[str, str, NDArray[np.float64], list[int]]] = []  # (class, trial, clip, window ends)
    for cls, trials in per_class.items():
        train, test = split(trials)
        train_clips[cls] = [load_trial(t, data, step=step, max_frames=max_frames) for t in train]
        for clip in train_clips[cls]:
            w = windows(clip, TRAIN_STRIDE)
            train_w.append(w)
            train_y += [cls] * len(w)
        if args.test_windows > 0:
            dropped += [t for t in test if t in seen]
            test = [t for t in test if t not in seen]
            test = test[: args.max_test_trials] if args.max_test_trials > 0 else test
            clips = [load_trial(t, data, step=step, max_frames=max_frames) for t in test]
            picks = test_windows_of(clips, args.test_windows)
            for i, trial in enumerate(test):
                ends = [e for k, e in picks if k == i]
                if ends:
                    tests.append((cls, trial, clips[i], ends))
    return _Windows(np.concatenate(train_w), np.asarray(train_y), train_clips, tests, dropped)


@dataclass(frozen=True)
class _Models:
    """The classifiers: ``model_3d`` trained on true 3D, ``model_2d`` on its projections,
    ``lifted`` (``--lifted-train``) on lifted training windows, lifted in ``train_lift_s`` seconds."""

    model_3d: ActionClassifier
    model_2d: ActionClassifier
    lifted: ActionClassifier | None
    train_lift_s: float

    def chosen(self, model_input: str) -> ActionClassifier:
        """The 3D model ``--model-out`` writes: trained on ``model_input`` ("true" or "lifted") 3D."""
        chosen = self.lifted if model_input == "lifted" else self.model_3d
        assert chosen is not None
        return chosen


def _train_models(args: argparse.Namespace, win: _Windows, lifter: Lifter, rng: np.random.Generator,
                  command: str) -> _Models:
    """The classifiers of :class:`_Models`; the 2D training views draw their (zero) noise from
    ``rng``, the lifted training windows from a generator of their own."""
    lead_in = round(args.lead_in * FPS)
    segment = max(round(args.segment * FPS), WINDOW * round(STEP_S * FPS))

    def classifier(trained_on: str) -> ActionClassifier:
        return ActionClassifier("3d", WINDOW, STEP_S, args.neighbors, args.depth_weight, metadata={
            "classes": list(CLASSES), "fps": FPS, "trained_on": trained_on, "command": command})

    model_3d = classifier("true 3D").fit(win.train_windows, win.labels)
    rots = [camera(a) for a in TRAIN_AZIMUTHS]
    train_2d = np.concatenate([film(win.train_windows, r, rng, 0.0) for r in rots])
    model_2d = ActionClassifier("2d", WINDOW, STEP_S, args.neighbors_2d).fit(
        train_2d, np.tile(win.labels, len(rots)))

    model_lifted = None
    train_lift_s = 0.0
    if args.lifted_train > 0:
        # a 3D model trained on lifted training windows: it shares the lifter's errors
        t0 = time.perf_counter()
        rng_train = np.random.default_rng(args.seed + 1)  # the test views stay those of other runs
        lw = [lift_training(lifter, win.train_clips[cls], args.lifted_train, segment, lead_in, rng_train,
                            args.noise_px, args.lift) for cls in CLASSES]
        model_lifted = classifier(f"{args.lifted_train} lifted windows per class ({args.modes[-1]} mode, "
                                  f"--lift {args.lift})")
        model_lifted.fit(np.concatenate(lw), np.repeat(np.asarray(CLASSES), [len(w) for w in lw]))
        train_lift_s = time.perf_counter() - t0
    return _Models(model_3d, model_2d, model_lifted, train_lift_s)


@dataclass(frozen=True)
class _Predictions:
    """Every test window's class by each input (``pred``, in window order), the true classes
    (``truth``), each mode's lifted P-MPJPE per window (metres), the trials' votes and the seconds
    the lifts took."""

    pred: dict[str, list[str]]
    truth: list[str]
    lift_err: dict[str, list[float]]
    per_trial: list[dict[str, object]]
    lift_s: float


def _classify_tests(args: argparse.Namespace, tests: list[tuple[str, str, NDArray[np.float64], list[int]]],
                    lifters: dict[str, Lifter], lifter: Lifter, models: _Models, rng: np.random.Generator
                    ) -> _Predictions:
    """Film every test window from a random azimuth (drawn from ``rng``), lift it in each mode
    (the same 2D for every mode) and classify it every way."""
    lead_in = round(args.lead_in * FPS)
    pred: dict[str, list[str]] = {"2d": [], **{f"3d-lift/{mode}": [] for mode in args.modes}, "3d-true": []}
    if models.lifted is not None:
        pred["3d-lift/lifted-train"] = []
    truth: list[str] = []
    lift_err: dict[str, list[float]] = {mode: [] for mode in args.modes}
    per_trial: list[dict[str, object]] = []
    t0 = time.perf_counter()
    for cls, trial, clip, ends in tests:
        votes: dict[str, Counter[str]] = {k: Counter() for k in pred}
        for end in ends:
            rot = camera(float(rng.uniform(0.0, 360.0)))
            state = rng.bit_generator.state  # every mode sees the same 2D
            window = clip[window_index(end)]
            got: dict[str, str] = {"3d-true": str(models.model_3d.predict(window[None])[0])}
            for mode, lf in lifters.items():
                rng.bit_generator.state = state
                pts, lifted = lift_test_window(lf, clip, end, rot, rng, args.noise_px, lead_in, args.lift)
                got[f"3d-lift/{mode}"] = str(models.model_3d.predict(lifted[None])[0])
                lift_err[mode].append(float(np.mean(p_mpjpe(lifted, window))))
                if models.lifted is not None and lf is lifter:
                    got["3d-lift/lifted-train"] = str(models.lifted.predict(lifted[None])[0])
            got["2d"] = str(models.model_2d.predict(pts[None])[0])
            truth.append(cls)
            for k, v in got.items():
                pred[k].append(v)
                votes[k][v] += 1
        per_trial.append({"class": cls, "trial": trial, "windows": len(ends),
                          **{k: v.most_common(1)[0][0] for k, v in votes.items()}})
    return _Predictions(pred, truth, lift_err, per_trial, time.perf_counter() - t0)


@dataclass(frozen=True)
class _Scores:
    """The accuracies of each input (``pred``'s keys): per window (``acc``), per trial vote
    (``votes_acc``) and per class (``per_cls``); each mode's mean lifted P-MPJPE in mm; each
    input's accuracy minus the 2D baseline's with its paired standard error (``vs_2d``); the
    number of test windows ``n``."""

    acc: dict[str, float]
    votes_acc: dict[str, float]
    per_cls: dict[str, dict[str, float]]
    lift_err_mm: dict[str, float]
    vs_2d: dict[str, tuple[float, float]]
    n: int


def _score(preds: _Predictions) -> _Scores:
    """The accuracies of :class:`_Scores`."""
    pred, per_trial = preds.pred, preds.per_trial
    y = np.asarray(preds.truth)
    acc = {k: float(np.mean(np.asarray(v) == y)) for k, v in pred.items()}
    votes_acc = {k: float(np.mean([t[k] == t["class"] for t in per_trial])) for k in pred}
    per_cls = {k: {c: float(np.mean(np.asarray(v)[y == c] == c)) for c in CLASSES} for k, v in pred.items()}
    lift_err_mm = {mode: 1e3 * float(np.mean(v)) for mode, v in preds.lift_err.items()}
    right = {k: np.asarray(v) == y for k, v in pred.items()}
    vs_2d = {k: (acc[k] - acc["2d"], paired_se(right[k], right["2d"])) for k in pred if k != "2d"}
    return _Scores(acc, votes_acc, per_cls, lift_err_mm, vs_2d, len(y))


def _result(args: argparse.Namespace, command: str, win: _Windows, preds: _Predictions, scores: _Scores,
            models: _Models) -> dict[str, object]:
    """The results as ``--json`` writes them."""
    labels, per_trial, acc = win.labels, preds.per_trial, scores.acc
    return {
        "command": command, "classes": list(CLASSES), "train_windows": len(labels),
        "train_windows_per_class": dict(Counter(labels.tolist())),
        "test_trials": {c: [str(t["trial"]) for t in per_trial if t["class"] == c] for c in CLASSES},
        "test_trials_dropped_prior_trained": win.dropped,
        "test_windows": scores.n, "noise_px": args.noise_px, "n_starts": args.n_starts, "lift": args.lift,
        "lead_in_s": args.lead_in, "window": WINDOW, "step_s": STEP_S, "neighbors": args.neighbors,
        "neighbors_2d": args.neighbors_2d, "depth_weight": args.depth_weight, "seed": args.seed,
        "window_accuracy": acc,
        "window_accuracy_se": {k: binomial_se(v, scores.n) for k, v in acc.items()},
        "minus_2d": {k: {"difference": d, "paired_se": se} for k, (d, se) in scores.vs_2d.items()},
        "per_class_window_accuracy": scores.per_cls,
        "trial_vote_accuracy": scores.votes_acc,
        "per_trial": per_trial,
        "lift_seconds": preds.lift_s, "train_lift_seconds": models.train_lift_s,
        "lifted_p_mpjpe_mm": scores.lift_err_mm,
        "lifted_train_windows_per_class": args.lifted_train,
    }


def _print_report(args: argparse.Namespace, win: _Windows, preds: _Predictions, scores: _Scores,
                  models: _Models) -> None:
    """The training and test set-up and the accuracy table."""
    labels, acc, vs_2d, lift_s = win.labels, scores.acc, scores.vs_2d, preds.lift_s
    lifted = f"; {args.lifted_train} lifted per class in {models.train_lift_s:.0f} s" if models.lifted else ""
    print(f"train: {len(labels)} windows {dict(Counter(labels.tolist()))}" + lifted)
    if win.dropped:
        print(f"held-out trials not tested (the lifter's prior was trained on them): {' '.join(win.dropped)}")
    print(f"test: {scores.n} windows from {len(preds.per_trial)} unseen trials, random azimuth, noise "
          f"{args.noise_px} px, --lift {args.lift} (lead-in {args.lead_in} s); lifted in {lift_s:.0f} s, "
          "lifted P-MPJPE " + ", ".join(f"{k} {v:.1f} mm" for k, v in scores.lift_err_mm.items()))
    print(f"{'input':22s}{'window acc':>16s}{'minus 2d':>18s}{'trial vote acc':>16s}   per class")
    for k in preds.pred:
        cls_txt = " ".join(f"{c}={scores.per_cls[k][c]:.2f}" for c in CLASSES)
        diff = f"{vs_2d[k][0]:+9.3f} +-{vs_2d[k][1]:.3f}" if k in vs_2d else " " * 16
        se = binomial_se(acc[k], scores.n)
        print(f"{k:22s}{acc[k]:9.3f} +-{se:.3f}  {diff}{scores.votes_acc[k]:16.3f}   {cls_txt}")


def main(argv: list[str] | None = None) -> int:
    ap = _parser()
    args = ap.parse_args(argv)

    if args.model_input == "lifted" and args.lifted_train <= 0:
        ap.error("--model-input lifted needs --lifted-train > 0")
    data = resolve_data_dir(args.data)
    rng = np.random.default_rng(args.seed)
    per_class = trials_by_class(data)
    command = " ".join(["tools/action_recognition_eval.py", *(argv if argv is not None else sys.argv[1:])])

    # n_starts is the paper mode's own (refused in another mode)
    lifters = {mode: Lifter(options=LifterOptions(mode=mode, **({"n_starts": args.n_starts} if mode == "paper"
                                                                else {})))
               for mode in args.modes}
    lifter = lifters[args.modes[-1]]
    win = _load_windows(args, data, per_class, prior_trials(list(lifters.values())))
    models = _train_models(args, win, lifter, rng, command)
    if not win.tests:
        if args.model_out:
            models.chosen(args.model_input).save(args.model_out)
            labels = win.labels
            print(f"train: {len(labels)} windows {dict(Counter(labels.tolist()))}; wrote {args.model_out} "
                  f"({args.model_input} 3D)")
        return 0

    preds = _classify_tests(args, win.tests, lifters, lifter, models, rng)
    scores = _score(preds)
    result = _result(args, command, win, preds, scores, models)
    _print_report(args, win, preds, scores, models)
    if args.model_out:
        models.chosen(args.model_input).save(args.model_out)
        print(f"wrote {args.model_out} ({args.model_input} 3D)")
    if args.json:
        Path(args.json).parent.mkdir(parents=True, exist_ok=True)
        Path(args.json).write_text(json.dumps(result, indent=2))
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
