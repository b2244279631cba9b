"""Record hybrid tracks frame by frame (the node's per-track policy, as ``tools/accuracy.py``
films them) and score causal output rules on the recording, without lifting again.

    .venv/bin/python tools/output_update_study.py record --out rec.npz [accuracy.py's track options:
        --split eval --frames 30 --views 2 | --action dance --azimuths 0 90 180 270 --distance 6]
        [--conditions clean outliers20 ...] [--set NAME=VALUE ...]
    .venv/bin/python tools/output_update_study.py score rec.npz

``record`` lifts every track with the options given and ``measurement_update`` off, and keeps per
frame the published pose, the fit's own pose, the prior's pose, the 2D, the weights the lift used
and the track's 2D noise, plus the learned prior alone (``--set measurement_update=...`` is
ignored). ``score`` replays on the recording, without lifting again (the smoothing and the update
are output-only: the fits do not change): the output smoothing restarted on a re-initialised frame
(as before) and carried over it (now), the measurement update
(:class:`pose_lifter.core.track.measurement.MeasurementUpdate`, as :class:`TrackPolicy` runs it; with
``--variant depth=...,gate=...`` other settings too), and ``pose-lifter lift``'s centred
smoothing of the fit's own poses and of the published ones; it prints P-MPJPE, MPJPE and the
acceleration error (mm, mm/frame^2) per condition, as ``tools/accuracy.py`` computes them.
"""

from __future__ import annotations

import argparse
import os
import sys
import time
import warnings
from pathlib import Path
from typing import Any

os.environ.setdefault("OMP_NUM_THREADS", "1")
os.environ.setdefault("OPENBLAS_NUM_THREADS", "1")

import numpy as np
from numpy.typing import NDArray

sys.path.insert(0, str(Path(__file__).resolve().parent))
import accuracy as acc
from pose_lifter.core import Lifter, LifterOptions, PoseBases, p_mpjpe
from pose_lifter.core.errors import PoseLifterError
from pose_lifter.core.model.bases import default_bases_path
from pose_lifter.core.model.skeleton import RIGHT_LOWER_LEG, limb_lengths
from pose_lifter.core.track.policy import TrackPolicy
from pose_lifter.core.track.smoothing import prior_in_camera

FIELDS = ("truth", "leg", "pub", "fit", "prior", "learned", "centre", "scale", "px", "conf", "weights",
          "noise", "follows", "ok", "track")


def record(args: argparse.Namespace) -> int:
    warnings.simplefilter("ignore")
    settings = acc._parse(args.set)
    settings["measurement_update"] = False  # the recording keeps the pose before it
    opts = LifterOptions().replace(**settings)
    bases = PoseBases.load(args.bases or default_bases_path("hybrid"))
    hybrid = Lifter(bases, opts)
    hybrid.warm_up()
    learned = Lifter(bases, opts.replace(mode="learned"))
    trials = args.trials
    if args.action:
        from pose_lifter.mocap.cmu import read_manifest, split_trials
        known = set(split_trials("train", args.data)) | set(split_trials("eval", args.data))
        trials = sorted({t.trial for t in read_manifest(args.data)
                         if t.action == args.action and t.trial in known})
    cameras = [(a, 0.0, "perspective") for a in args.azimuths] if args.azimuths else None
    tracks = acc._tracks(args.split, args.data, args.frames, args.views, trials, cameras)
    acc._STATE["distance"] = args.distance
    out: dict[str, list[Any]] = {}
    for cond in args.conditions:
        rows: dict[str, list[Any]] = {k: [] for k in (*FIELDS, "noise_now")}
        for k, track in enumerate(tracks):
            rng = np.random.default_rng(track.seed)
            px, conf, world, cam_pose = acc.film_track(track, acc.CONDITIONS[cond], rng)
            n = len(world)
            truth = cam_pose - cam_pose.mean(axis=1, keepdims=True)
            leg = limb_lengths(world)[:, RIGHT_LOWER_LEG]
            policy = TrackPolicy(hybrid, track_timeout=1e9)
            for i in range(n):
                nan3 = np.full((12, 3), np.nan)
                row: dict[str, Any] = {"truth": truth[i], "leg": leg[i], "px": px[i], "conf": conf[i],
                                       "pub": nan3, "fit": nan3, "prior": nan3, "learned": nan3,
                                       "centre": np.full(2, np.nan), "scale": np.nan,
                                       "weights": np.zeros(12), "noise": 0.0, "noise_now": 0.0,
                                       "follows": False, "ok": False,
                                       "track": k}
                try:
                    lr = learned.lift(px[i], conf[i])
                    row["learned"] = lr.pose_camera
                except PoseLifterError:
                    pass
                try:
                    tl = policy.lift(0, i * 33_333_333, px[i], conf[i])
                except PoseLifterError:
                    for f in rows:
                        rows[f].append(row[f])
                    continue
                r = tl.result
                st = policy._tracks[0]
                prior = prior_in_camera(r)
                row.update(pub=r.pose_camera, fit=tl.fit_pose_camera if tl.fit_pose_camera is not None
                           else r.pose_camera, prior=nan3 if prior is None else prior,
                           centre=r.camera.project(r.pose).mean(axis=0), scale=float(r.camera.scale),
                           weights=r.weights, noise=st.noise_level(),
                           noise_now=float(np.median(np.asarray(st.noise))) if st.noise else 0.0,
                           follows=tl.warm_started and not tl.reinitialised, ok=True)
                for f in rows:
                    rows[f].append(row[f])
        for f in (*FIELDS, "noise_now"):
            out[f"{cond}/{f}"] = np.asarray(rows[f])
        print(f"{cond}: {len(rows['ok'])} frames", flush=True)
    np.savez_compressed(args.out, conditions=np.array(args.conditions), **out)
    return 0


def metrics(pred: NDArray[np.float64], truth: NDArray[np.float64], leg: NDArray[np.float64],
            track: NDArray[np.int64]) -> tuple[float, float, float]:
    """P-MPJPE, MPJPE, acceleration error (mm) of camera-frame poses (n, 12, 3) in model units,
    scaled by the true leg, as tools/accuracy.py scores them (acceleration within tracks)."""
    p = pred - np.nanmean(pred, axis=1, keepdims=True)
    p = p * leg[:, None, None]
    ok = np.isfinite(p).all(axis=(1, 2))
    pm = 1000 * float(np.mean(p_mpjpe(p[ok], truth[ok])))
    mp = 1000 * float(np.mean(np.linalg.norm(p[ok] - truth[ok], axis=-1).mean(axis=-1)))
    accs = []
    for t in np.unique(track):
        sel = np.flatnonzero(track == t)
        if len(sel) < 3:
            continue
        a = p[sel[2:]] - 2 * p[sel[1:-1]] + p[sel[:-2]]
        b = truth[sel[2:]] - 2 * truth[sel[1:-1]] + truth[sel[:-2]]
        e = np.linalg.norm(a - b, axis=-1).mean(axis=-1)
        accs += e[np.isfinite(e)].tolist()
    return pm, mp, 1000 * float(np.mean(accs))


def early_noise(d: dict[str, NDArray[Any]], lifter: Lifter) -> NDArray[np.float64]:
    """Per frame the track's 2D noise as the output update reads it (the median of its frames'
    2D accelerations so far, ``_Track.observe_noise``; 0 before the first), from the recorded 2D
    and the joints each frame's lift used (recordings before ``noise_now`` was kept)."""
    out = np.zeros(len(d["px"]))
    samples: list[float] = []
    for i in range(len(out)):
        if i == 0 or d["track"][i] != d["track"][i - 1]:
            samples = []
        if i >= 2 and d["track"][i - 2] == d["track"][i]:
            v = (d["weights"][i - 2] > 0) & (d["weights"][i - 1] > 0) & (d["weights"][i] > 0)
            if v.sum() >= 3:
                x0, x1, x = d["px"][i - 2], d["px"][i - 1], d["px"][i]
                a = np.linalg.norm(x[v] - 2 * x1[v] + x0[v], axis=1) / np.sqrt(6.0)
                spread = float(lifter.input_scales(x[None], v[None].astype(float))[0])
                if not np.isnan(spread):
                    samples = [*samples, float(np.median(a)) / spread][-30:]
        out[i] = float(np.median(samples)) if samples else 0.0
    return out


def replay_update(d: dict[str, NDArray[Any]], base: NDArray[np.float64], noise: NDArray[np.float64],
                  depth: float = 0.5, gate: float = 0.3) -> NDArray[np.float64]:
    """:class:`pose_lifter.core.track.measurement.MeasurementUpdate` on ``base`` (the published poses
    before it) track by track, as ``TrackPolicy`` runs it: a new state on a track's first frame
    and after a frame that could not be lifted; no update before the track's first noise sample."""
    from pose_lifter.core.track.measurement import MeasurementUpdate, compile_kernels
    compile_kernels()
    out = base.copy()
    state = MeasurementUpdate()
    for i in range(len(out)):
        if i == 0 or d["track"][i] != d["track"][i - 1] or not d["ok"][i - 1]:
            state = MeasurementUpdate()
        if d["ok"][i] and noise[i] > 0:
            t0 = time.perf_counter()
            out[i] = state.update(base[i], d["px"][i], d["weights"][i] > 0, float(noise[i]), depth, gate)
            TIMES.append(time.perf_counter() - t0)
    return out


#: Seconds of each measurement update replayed (``score`` prints their median).
TIMES: list[float] = []


def replay_smoother(d: dict[str, NDArray[Any]], b: float = 0.7, low: float = 0.55, keep: bool = False
                    ) -> NDArray[np.float64]:
    """The track's output smoother (core.track.smoothing.CausalSmoother) again on the recorded fits and priors
    (``keep``: not restarted when a warm track's frame was solved cold)."""
    from pose_lifter.core.track import policy as tr
    from pose_lifter.core.track import state as tk
    from pose_lifter.core.track.smoothing import CausalSmoother
    out = d["fit"].copy()
    sm = None
    shares: list[float] = []
    prev_track = -1
    for i in range(len(out)):
        new_track = d["track"][i] != prev_track
        prev_track = d["track"][i]
        if new_track:
            shares = []
            sm = None
        if not d["ok"][i]:
            sm = None
            continue
        shares = [*shares, float(np.count_nonzero(d["weights"][i] <= 0)) / 12.0][-tk.DISTURBANCE_FRAMES:]
        noise = float(d["noise"][i])
        dw = 1.0 if noise <= 0 else float(np.clip(tk.NOISE_REFERENCE / max(noise, 1e-12),
                                                  tk.NOISE_MIN_WEIGHT, 1.0))
        prior = d["prior"][i]
        if not np.isfinite(prior).all():
            sm = None
            continue
        if sm is None or (not d["follows"][i] and not keep):
            sm = CausalSmoother()
        dist = max(sum(shares) / len(shares), tr.NOISE_DISTURBANCE * (1.0 - dw))
        gain = 1.0 - min(1.0, dist / tr.DISTURBANCE_FULL) * (1.0 - low)
        out[i] = sm.update(d["fit"][i], prior, b, gain)
    return out


def score(args: argparse.Namespace) -> int:
    """Print P-MPJPE / MPJPE / acceleration error per condition for the output rules."""
    from pose_lifter.core.track.smoothing import OFFLINE_SMOOTHING_S, centred_smoothing
    data = np.load(args.recording)
    lifter = Lifter()
    extra = [acc._parse(v.split(",")) for v in args.variant]
    for cond in data["conditions"]:
        d = {f: data[f"{cond}/{f}"] for f in FIELDS}
        key = f"{cond}/noise_now"
        noise = data[key] if key in data else early_noise(d, lifter)
        rows: list[tuple[str, NDArray[np.float64]]] = [("learned (the prior alone)", d["learned"]),
                                                       ("fit (its own pose)", d["fit"])]
        restart = replay_smoother(d, keep=False)
        kept = replay_smoother(d, keep=True)
        rows += [("smoothed, restarted on a re-initialised frame", restart),
                 ("smoothed, carried over (published, update off)", kept),
                 ("+ measurement update (default)", replay_update(d, kept, noise))]
        for kw in extra:
            name = "+ update " + ",".join(f"{k}={v}" for k, v in kw.items())
            rows.append((name, replay_update(d, kept, noise, **kw)))
        stamps = np.arange(len(d["ok"]), dtype=np.int64) * 33_333_333
        for name, seq in (("offline: centred(fit)", d["fit"]), ("offline: centred(published)", rows[4][1])):
            sm = np.full_like(seq, np.nan)
            for t in np.unique(d["track"]):
                sel = np.flatnonzero(d["track"] == t)
                ok = np.isfinite(seq[sel]).all(axis=(1, 2))
                sm[sel] = centred_smoothing(np.nan_to_num(seq[sel]), stamps[sel], ok,
                                            OFFLINE_SMOOTHING_S, 1.0)
                sm[sel[~ok]] = np.nan
            rows.append((name, sm))
        print(f"{cond} ({len(d['ok'])} frames): P-MPJPE / MPJPE mm, acceleration error mm/frame^2")
        for name, seq in rows:
            pm, mp, ac = metrics(seq, d["truth"], d["leg"], d["track"])
            print(f"  {name:52s} {pm:6.1f} {mp:6.1f} {ac:6.1f}", flush=True)
    print(f"measurement update: {len(TIMES)} frames, median {1e6 * float(np.median(TIMES)):.1f} us a frame")
    return 0


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    sub = ap.add_subparsers(dest="cmd", required=True)
    r = sub.add_parser("record")
    r.add_argument("--out", type=Path, required=True)
    r.add_argument("--data", default=None)
    r.add_argument("--split", choices=("eval", "val"), default="eval")
    r.add_argument("--frames", type=int, default=30)
    r.add_argument("--views", type=int, default=2)
    r.add_argument("--trials", nargs="+", default=None)
    r.add_argument("--action", default=None)
    r.add_argument("--azimuths", type=float, nargs="+", default=None)
    r.add_argument("--distance", type=float, default=acc.DISTANCE)
    r.add_argument("--conditions", nargs="+", default=["clean", "outliers20"])
    r.add_argument("--set", action="append", default=[])
    r.add_argument("--bases", default=None)
    s = sub.add_parser("score")
    s.add_argument("recording", type=Path)
    s.add_argument("--variant", action="append", default=[],
                   help="depth=...,gate=...: the update with other settings too")
    args = ap.parse_args(argv)
    return record(args) if args.cmd == "record" else score(args)


if __name__ == "__main__":
    sys.exit(main())
