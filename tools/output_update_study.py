"""Record hybrid tracks frame by frame (the node's per-track policy, as ``tools/accuracy.py``
films them) and score causal output rules on the recording, without lifting again.

    .venv/bin/python tools/output_update_study.py record --out rec.npz [accuracy.py's track options:
        --split eval --frames 30 --views 2 | --action dance --azimuths 0 90 180 270 --distance 6]
        [--conditions clean outliers20 ...] [--set NAME=VALUE ...]
    .venv/bin/python tools/output_update_study.py score rec.npz

``record`` lifts every track with the options given and ``measurement_update`` off, and keeps per
frame the published (smoothed) pose, the fit's own pose, the prior's pose, the camera, the 2D, the
weights the lift used and the track's noise estimate, plus the learned prior alone. ``score``
applies :func:`pose_lifter.core.measurement.measurement_update` with a few settings to the
recording (the update is output-only, so the fits do not change) and prints P-MPJPE, MPJPE and the
acceleration error (mm, mm/frame^2) per condition, as ``tools/accuracy.py`` computes them.
"""

from __future__ import annotations

import argparse
import os
import sys
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
from pose_lifter.core.bases import default_bases_path
from pose_lifter.core.errors import PoseLifterError
from pose_lifter.core.skeleton import RIGHT_LOWER_LEG, limb_lengths
from pose_lifter.core.tracking import TrackPolicy, _prior_camera

FIELDS = ("truth", "leg", "pub", "fit", "prior", "learned", "centre", "scale", "px", "conf", "weights",
          "noise", "follows", "ok", "track")


def record(args: argparse.Namespace) -> int:
    warnings.simplefilter("ignore")
    settings = acc._parse(args.set)
    if "measurement_update" in LifterOptions.__dataclass_fields__:
        settings.setdefault("measurement_update", False)  # the recording keeps the pose before it
    opts = LifterOptions().replace(**settings)
    bases = PoseBases.load(args.bases or default_bases_path("hybrid"))
    hybrid = Lifter(bases, opts)
    hybrid.warm_up()
    learned = Lifter(bases, opts.replace(mode="learned"))
    trials = args.trials
    if args.action:
        from pose_lifter.mocap import read_manifest, split_trials
        known = set(split_trials("train", args.data)) | set(split_trials("eval", args.data))
        trials = sorted({t.trial for t in read_manifest(args.data) if t.action == args.action and t.trial in known})
    cameras = [(a, 0.0, "perspective") for a in args.azimuths] if args.azimuths else None
    tracks = acc._tracks(args.split, args.data, args.frames, args.views, trials, cameras)
    acc._STATE["distance"] = args.distance
    out: dict[str, list[Any]] = {}
    for cond in args.conditions:
        rows: dict[str, list[Any]] = {k: [] for k in FIELDS}
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
                                       "weights": np.zeros(12), "noise": 0.0, "follows": False, "ok": False,
                                       "track": k}
                try:
                    lr = learned.lift(px[i], conf[i])
                    row["learned"] = lr.pose_camera
                except PoseLifterError:
                    pass
                try:
                    tl = policy.lift(0, i * 33_333_333, px[i], conf[i])
                except PoseLifterError:
                    for f in FIELDS:
                        rows[f].append(row[f])
                    continue
                r = tl.result
                st = policy._tracks[0]
                prior = _prior_camera(r)
                row.update(pub=r.pose_camera, fit=tl.fit_pose_camera if tl.fit_pose_camera is not None
                           else r.pose_camera, prior=nan3 if prior is None else prior,
                           centre=r.camera.project(r.pose).mean(axis=0), scale=float(r.camera.scale),
                           weights=r.weights, noise=st.noise_level(),
                           follows=tl.warm_started and not tl.reinitialised, ok=True)
                for f in FIELDS:
                    rows[f].append(row[f])
        for f in FIELDS:
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


def replay(d: dict[str, NDArray[Any]], k: float = 1.0, sigma: float = 0.0, gate: float = 1e9,
           depth: str = "keep", base: str = "pub", noise_c: float = 1.0, soft: float = 0.0) -> NDArray[np.float64]:
    """The output rule on every recorded frame (stateless per frame)."""
    pose = d[base].copy()
    obs = (d["px"] - d["centre"][:, None, :]) / d["scale"][:, None, None]
    used = (d["weights"] > 0) & d["ok"][:, None]
    r = obs - pose[..., :2]
    rn = np.linalg.norm(r, axis=-1)
    # the gain: the fit's xy uncertainty sigma (model units) against the track's 2D noise
    nz = noise_c * d["noise"][:, None]
    gain = np.full(rn.shape, k)
    if sigma > 0:
        gain = k * sigma**2 / (sigma**2 + nz**2)
    if soft > 0:
        gain = gain * np.clip((gate + soft - rn) / soft, 0.0, 1.0)
    else:
        gain = np.where(rn > gate, 0.0, gain)
    gain = np.where(used, gain, 0.0)
    new = pose.copy()
    new[..., :2] += gain[..., None] * np.nan_to_num(r)
    if depth == "bones":
        from pose_lifter.core.skeleton import LIMBS
        for a, b in LIMBS:  # parent a, child b, in chain order
            L = np.linalg.norm(pose[:, b] - pose[:, a], axis=-1)
            dxy = np.linalg.norm(new[:, b, :2] - new[:, a, :2], axis=-1)
            dz0 = pose[:, b, 2] - pose[:, a, 2]
            dz = np.sign(dz0) * np.sqrt(np.maximum(L**2 - dxy**2, 0.0))
            new[:, b, 2] = new[:, a, 2] + dz
    return new - new.mean(axis=1, keepdims=True)


def replay_state(d: dict[str, NDArray[Any]], drift: float = 0.05, base: Any = "pub", noise_c: float = 1.0,
                 rel: float = 0.0, keep: bool = False, **kw: Any) -> NDArray[np.float64]:
    """The stateful rule (core.measurement.MeasurementUpdate), track by track."""
    from pose_lifter.core import measurement as mm
    from pose_lifter.core.measurement import MeasurementUpdate
    for key in ("SPAN_MIN_FRAMES", "SPAN_EVERY"):
        if key.lower() in kw:
            setattr(mm, key, kw.pop(key.lower()))
    pose = d[base] if isinstance(base, str) else base
    out = pose.copy()
    state = None
    prev_track = -1
    sig = np.full(12, drift)
    if rel:
        from pose_lifter.core.prior import PosePrior
        e = PosePrior.load(REL_PRIOR).abs_error[:, :2].mean(axis=1)
        sig = drift * (e / e.mean()) ** rel
    for i in range(len(pose)):
        if d["track"][i] != prev_track or (not d["follows"][i] and not keep) or (i > 0 and not d["ok"][i - 1]):
            state = MeasurementUpdate()
            prev_track = d["track"][i]
        if not d["ok"][i]:
            continue
        assert state is not None
        out[i] = state.update(pose[i], d["px"][i], d["weights"][i] > 0, noise_c * float(d["noise"][i]), sig,
                              **kw)
    return out


def replay_smoother(d: dict[str, NDArray[Any]], b: float = 0.7, low: float = 0.55, keep: bool = False
                    ) -> NDArray[np.float64]:
    """The track's output smoother (core.tracking._Smoother) again on the recorded fits and priors
    (``keep``: not restarted when a warm track's frame was solved cold)."""
    from pose_lifter.core import tracking as tr
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
        shares = (shares + [float(np.count_nonzero(d["weights"][i] <= 0)) / 12.0])[-tr.DISTURBANCE_FRAMES:]
        noise = float(d["noise"][i])
        dw = 1.0 if noise <= 0 else float(np.clip(tr.NOISE_REFERENCE / max(noise, 1e-12), tr.NOISE_MIN_WEIGHT, 1.0))
        prior = d["prior"][i]
        if not np.isfinite(prior).all():
            sm = None
            continue
        if sm is None or (not d["follows"][i] and not keep):
            sm = tr._Smoother()
        dist = max(sum(shares) / len(shares), tr.NOISE_DISTURBANCE * (1.0 - dw))
        gain = 1.0 - min(1.0, dist / tr.DISTURBANCE_FULL) * (1.0 - low)
        out[i] = sm.update(d["fit"][i], prior, b, gain)
    return out


REL_PRIOR: str | None = None


def score(args: argparse.Namespace) -> int:
    data = np.load(args.recording)
    variants: dict[str, dict[str, Any]] = {"published": {}}
    for spec in args.variant:
        variants[spec] = acc._parse(spec.split(","))
    for cond in data["conditions"]:
        d = {f: data[f"{cond}/{f}"] for f in FIELDS}
        print(f"{cond} ({len(d['ok'])} frames)")
        pm, mp, ac = metrics(d["learned"], d["truth"], d["leg"], d["track"])
        print(f"  {'learned':40s} {pm:6.1f} {mp:6.1f} {ac:6.1f}")
        pm, mp, ac = metrics(d["fit"], d["truth"], d["leg"], d["track"])
        print(f"  {'fit (unsmoothed)':40s} {pm:6.1f} {mp:6.1f} {ac:6.1f}")
        for name, kw in variants.items():
            pred = d["pub"].copy()
            kw = dict(kw)
            if kw.pop("state", False):
                pred = replay_state(d, **kw)
            elif kw:
                pred = replay(d, **kw)
            pm, mp, ac = metrics(pred, d["truth"], d["leg"], d["track"])
            print(f"  {name:40s} {pm:6.1f} {mp:6.1f} {ac:6.1f}")
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
    s.add_argument("--variant", action="append", default=[], help="k=v,k=v: replay() keywords")
    args = ap.parse_args(argv)
    return record(args) if args.cmd == "record" else score(args)


if __name__ == "__main__":
    sys.exit(main())
