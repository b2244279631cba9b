"""Train the downstream action-recognition example on CMU mocap and compare 3D vs 2D input.

    .venv/bin/python tools/action_recognition_eval.py [--data ../shared/data/cmu]
        [--model-out ros2_ws/src/pose_lifter/pose_lifter/data/actions_knn.npz] [--json out.json]

Classes are the MANIFEST actions with at least two trials: walk, run, dance, basketball and
playground (subject 01: climb, swing, hang, jump down). Per class, every third trial (sorted by
id) is held out; the others train. The test trials are never seen in training (same subjects,
different recordings: dance is all subject 05, basketball all subject 06). By default the first
3 held-out trials per class are evaluated, 6 windows each (``--max-test-trials``, ``--test-windows``).

Every test window is filmed from a random camera azimuth (uniform 0-360 deg, 10 deg elevation,
scaled orthographic, optional Gaussian pixel noise) and classified three ways:

* ``2d``      k-NN on normalised 2D keypoints, trained on projections of the training windows
              from 8 azimuths (the 2D baseline: no lifter);
* ``3d-lift/MODE`` the 2D is lifted with the core Lifter in each ``--modes`` mode (paper,
              learned, hybrid; per-window sequence, warm-started), then k-NN on view-normalised
              3D (the lifter plugged in upstream, as in the ROS graph);
* ``3d-true`` k-NN on the ground-truth 3D (what a perfect lifter would give).

The 3D model (trained on ground-truth windows) is what ``--model-out`` writes, for the node
``ros2 run pose_lifter action_recognition``.
"""

from __future__ import annotations

import argparse
import json
import sys
import time
from collections import Counter
from pathlib import Path

import numpy as np
from numpy.typing import NDArray
from pose_lifter.core import Lifter, LifterOptions, p_mpjpe
from pose_lifter.examples.actions import ActionClassifier
from pose_lifter.mocap import load_trial, read_manifest, resolve_data_dir

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
    return poses[idx]


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
    """Lift a window of 2D frames (W, 12, 2) in order, warm-starting each from the previous."""
    out = []
    warm = None
    for p in points:
        res = lifter.lift(p, np.ones(len(p)), warm=warm)
        warm = res.warm_start()
        out.append(res.pose_camera)
    return np.stack(out)


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--data", default=None, help="CMU data dir (default ../shared/data/cmu or "
                    "$POSE_LIFTER_CMU_DATA)")
    ap.add_argument("--model-out", default=None, help="write the 3D model (.npz) here")
    ap.add_argument("--test-windows", type=int, default=6,
                    help="test windows per test trial (0: only train and write the model)")
    ap.add_argument("--max-test-trials", type=int, default=3, help="held-out trials per class used")
    ap.add_argument("--noise-px", type=float, default=2.0, help="2D Gaussian noise, pixels (std)")
    ap.add_argument("--n-starts", type=int, default=4, help="lifter cold starts")
    ap.add_argument("--neighbors", type=int, default=5)
    ap.add_argument("--lifted-train", type=int, default=0,
                    help="also train a 3D model on this many lifted training windows per class")
    ap.add_argument("--model-input", choices=["true", "lifted"], default="true",
                    help="--model-out writes the 3D model trained on true 3D or on the lifted training "
                         "windows (needs --lifted-train; what the node sees downstream of the lifter)")
    ap.add_argument("--seed", type=int, default=0)
    ap.add_argument("--modes", nargs="+", default=["paper", "learned", "hybrid"],
                    choices=["paper", "learned", "hybrid"], help="lifter modes compared")
    ap.add_argument("--json", default=None, help="write the results as JSON here")
    args = ap.parse_args(argv)

    if args.model_input == "lifted" and (args.lifted_train <= 0 or args.test_windows <= 0):
        ap.error("--model-input lifted needs --lifted-train > 0 and --test-windows > 0")
    data = resolve_data_dir(args.data)
    rng = np.random.default_rng(args.seed)
    step = round(120.0 / FPS)
    max_frames = int(MAX_SECONDS * FPS)
    per_class = trials_by_class(data)

    train_w: list[NDArray[np.float64]] = []
    train_y: list[str] = []
    tests: list[tuple[str, str, NDArray[np.float64]]] = []  # (class, trial, windows)
    for cls, trials in per_class.items():
        train, test = split(trials)
        for trial in train:
            w = windows(load_trial(trial, data, step=step, max_frames=max_frames), TRAIN_STRIDE)
            train_w.append(w)
            train_y += [cls] * len(w)
        for trial in (test[: args.max_test_trials] if args.test_windows > 0 else []):
            w = windows(load_trial(trial, data, step=step, max_frames=max_frames), 1)
            pick = np.linspace(0, len(w) - 1, min(args.test_windows, len(w))).round().astype(int)
            tests.append((cls, trial, w[pick]))
    train_windows = np.concatenate(train_w)
    labels = np.asarray(train_y)

    model_3d = ActionClassifier("3d", WINDOW, STEP_S, args.neighbors,
                                metadata={"classes": list(CLASSES), "fps": FPS,
                                          "command": " ".join(["tools/action_recognition_eval.py",
                                                               *(argv or sys.argv[1:])])})
    model_3d.fit(train_windows, labels)
    rots = [camera(a) for a in TRAIN_AZIMUTHS]
    train_2d = np.concatenate([film(train_windows, r, rng, 0.0) for r in rots])
    model_2d = ActionClassifier("2d", WINDOW, STEP_S, args.neighbors).fit(
        train_2d, np.tile(labels, len(rots)))

    if not tests:
        if args.model_out:
            model_3d.save(args.model_out)
            print(f"train: {len(labels)} windows {dict(Counter(labels.tolist()))}; wrote {args.model_out}")
        return 0

    lifters = {mode: Lifter(options=LifterOptions(mode=mode, n_starts=args.n_starts)) for mode in args.modes}
    lifter = lifters[args.modes[-1]]
    pred: dict[str, list[str]] = {"2d": [], **{f"3d-lift/{mode}": [] for mode in args.modes}, "3d-true": []}
    model_lifted = None
    if args.lifted_train > 0:
        # a 3D model trained on lifted training windows: it shares the lifter's bias (its bases
        # were learned on the playground class only)
        lw, ly = [], []
        rng_train = np.random.default_rng(args.seed + 1)  # the test views stay those of other runs
        for cls in CLASSES:
            sel = np.flatnonzero(labels == cls)
            for i in sel[np.linspace(0, len(sel) - 1, args.lifted_train).round().astype(int)]:
                rot = camera(float(rng_train.uniform(0.0, 360.0)))
                lw.append(lift_window(lifter, film(train_windows[i], rot, rng_train, args.noise_px)))
                ly.append(cls)
        model_lifted = ActionClassifier("3d", WINDOW, STEP_S, args.neighbors, metadata={
            "classes": list(CLASSES), "fps": FPS, "trained_on": f"lifted ({args.modes[-1]} mode)",
            "command": " ".join(["tools/action_recognition_eval.py", *(argv or sys.argv[1:])])})
        model_lifted.fit(np.stack(lw), np.asarray(ly))
        pred["3d-lift/lifted-train"] = []
    truth: list[str] = []
    lift_err: dict[str, list[float]] = {mode: [] for mode in args.modes}
    per_trial: list[dict[str, object]] = []
    t0 = time.perf_counter()
    n_lifts = 0
    for cls, trial, w in tests:
        votes: dict[str, Counter[str]] = {k: Counter() for k in pred}
        for window in w:
            rot = camera(float(rng.uniform(0.0, 360.0)))
            pts = film(window, rot, rng, args.noise_px)
            got = {"2d": model_2d.predict(pts[None])[0], "3d-true": model_3d.predict(window[None])[0]}
            for mode, lf in lifters.items():
                lifted = lift_window(lf, pts)
                n_lifts += len(pts)
                got[f"3d-lift/{mode}"] = model_3d.predict(lifted[None])[0]
                lift_err[mode].append(float(np.mean(p_mpjpe(lifted, window))))
            if model_lifted is not None:
                got["3d-lift/lifted-train"] = model_lifted.predict(lift_window(lifter, pts)[None])[0]
            truth.append(cls)
            for k, v in got.items():
                pred[k].append(str(v))
                votes[k][str(v)] += 1
        per_trial.append({"class": cls, "trial": trial, "windows": len(w),
                          **{k: v.most_common(1)[0][0] for k, v in votes.items()}})
    lift_s = time.perf_counter() - t0

    y = np.asarray(truth)
    result: dict[str, object] = {
        "classes": list(CLASSES), "train_windows": len(labels),
        "train_windows_per_class": dict(Counter(labels.tolist())),
        "test_trials": {c: [str(t["trial"]) for t in per_trial if t["class"] == c] for c in CLASSES},
        "test_windows": len(y), "noise_px": args.noise_px, "n_starts": args.n_starts,
        "window": WINDOW, "step_s": STEP_S, "neighbors": args.neighbors, "seed": args.seed,
        "window_accuracy": {k: float(np.mean(np.asarray(v) == y)) for k, v in pred.items()},
        "per_class_window_accuracy": {
            k: {c: float(np.mean(np.asarray(v)[y == c] == c)) for c in CLASSES} for k, v in pred.items()},
        "trial_vote_accuracy": {k: float(np.mean([t[k] == t["class"] for t in per_trial])) for k in pred},
        "per_trial": per_trial,
        "lift_seconds": lift_s, "lifts": n_lifts,
        "lifted_p_mpjpe_mm": {mode: 1e3 * float(np.mean(v)) for mode, v in lift_err.items()},
        "lifted_train_windows_per_class": args.lifted_train,
    }
    lift_err_mm = {mode: 1e3 * float(np.mean(v)) for mode, v in lift_err.items()}
    print(f"train: {len(labels)} windows {dict(Counter(labels.tolist()))}")
    print(f"test: {len(y)} windows from {len(per_trial)} unseen trials, random azimuth, "
          f"noise {args.noise_px} px; {n_lifts} lifts in {lift_s:.1f} s, "
          "lifted P-MPJPE " + ", ".join(f"{k} {v:.0f} mm" for k, v in lift_err_mm.items()))
    print(f"{'input':22s}{'window acc':>12s}{'trial vote acc':>16s}   per class")
    acc = result["window_accuracy"]
    votes_acc = result["trial_vote_accuracy"]
    per_cls = result["per_class_window_accuracy"]
    assert isinstance(acc, dict) and isinstance(votes_acc, dict) and isinstance(per_cls, dict)
    for k in pred:
        cls_txt = " ".join(f"{c}={per_cls[k][c]:.2f}" for c in CLASSES)
        print(f"{k:22s}{acc[k]:12.3f}{votes_acc[k]:16.3f}   {cls_txt}")
    if args.model_out:
        if args.model_input == "lifted":
            if model_lifted is None:
                ap.error("--model-input lifted needs --lifted-train > 0")
            model_lifted.save(args.model_out)
        else:
            model_3d.save(args.model_out)
        print(f"wrote {args.model_out} ({args.model_input} 3D)")
    if args.json:
        Path(args.json).parent.mkdir(parents=True, exist_ok=True)
        Path(args.json).write_text(json.dumps(result, indent=2))
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
