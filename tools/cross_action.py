"""Accuracy on motion the prior has never seen: leave-one-class-out over the motion classes of the
CMU manifest (``make cross-action``).

    .venv/bin/python tools/cross_action.py [--data ../shared/data/cmu] [--classes walk run ...]
        [--model residual|mlp] [--augment generalise|views] [--epochs 8] [--samples 50000]
        [--width 512] [--blocks 2] [--hidden 768 768] [--frames 90] [--views 2] [--segments 8]
        [--conditions clean noise0.1 ...] [--methods flat learned hybrid hybrid-offline] [--workers 1]
        [--folds DIR] [--out out/cross_action]
    .venv/bin/python tools/cross_action.py --merge RUN1/cross_action.json RUN2/... --out DIR

Folds: for each motion class C of ``MANIFEST.csv`` among the usable trials
(:func:`pose_lifter.mocap.cmu.trials_by_action`: walk, run, jump, punch, dance, basketball,
playground, other; a class whose only trial is reserved has no fold), a prior is trained on every
usable trial *not* of class C (every 8th of them, sorted, held out of the fit for its validation
figure and per-joint uncertainty), seeded, at the fixed budget given, and saved as
``DIR/<C>.npz`` (reused when its metadata match the requested training). Class C is then lifted
as ``make accuracy`` lifts the evaluation split (:mod:`pose_lifter.mocap.evaluation`): tracks at
30 Hz of at most ``--frames`` frames (``--segments`` segments spread over C's trials, each filmed
from ``--views`` of its 32 cameras), its conditions (clean, noise, confident outliers,
missing joints, and the detector / camera faults: left/right swaps, the lower body out of the
image, a camera at 2 m, a camera 50 degrees above; and every fault of a real detector together,
``detector6m`` / ``detector3m``: :mod:`pose_lifter.mocap.detector_model`). Methods: ``flat`` (the
2D with zero depth), ``learned`` (the fold's prior alone, per frame), ``learned-t`` (the prior
alone tracked, as the node runs ``mode: learned``), ``learned-offline`` (the prior alone tracked
and smoothed over past and future frames: ``pose-lifter lift --mode learned``) and ``hybrid``
(the default mode tracked by :class:`pose_lifter.core.track.policy.TrackPolicy`, with the fold's
prior as its single-frame prior and the temporal prior off: the packaged temporal prior has seen
every class; with ``--temporal`` each fold also trains its own temporal prior,
``DIR/<C>_w4.npz``, and every tracked method uses it, as the node does; with ``--offline`` also
its offline prior, ``DIR/<C>_w7c.npz`` (as ``make prior-offline``: 3 frames before the lifted
one and 3 after), which the ``-offline`` methods read, as ``pose-lifter lift`` does).

The hybrid's pose bases are the packaged ``bases_hybrid_sparse200.npz`` (or ``--bases``); their
training trials are read from the file and each fold's row says whether they include class C.

Prints per class and the mean over classes (each class weighs the same); writes
``cross_action.json`` and ``cross_action.md`` to ``--out``. Deterministic (seeded training on one
thread, seeded corruption).
"""

from __future__ import annotations

import argparse
import json
import os
import sys
import time
import warnings
from dataclasses import replace
from pathlib import Path
from typing import Any

import numpy as np

os.environ.setdefault("OMP_NUM_THREADS", "1")
os.environ.setdefault("OPENBLAS_NUM_THREADS", "1")

from pose_lifter.core.errors import PriorFileError
from pose_lifter.core.model.bases import PoseBases, default_bases_path
from pose_lifter.core.model.loading import cut_partner
from pose_lifter.core.model.prior import PosePrior
from pose_lifter.mocap import evaluation as ev
from pose_lifter.mocap.cmu import load_trial, trials_by_action
from pose_lifter.mocap.prior_training import GENERALISE, Augmentation, train_prior, train_prior_residual

DEFAULT_CONDITIONS = ("detector6m", "detector3m", "clean", "noise0.05", "noise0.1", "outliers20", "missing15",
                      "lrswap", "lowercut", "close", "above")
METHODS = ("flat", "learned", "learned-t", "learned-offline", "hybrid", "hybrid-lag", "hybrid-offline")
AUGMENTATIONS: dict[str, Augmentation] = {"views": Augmentation(), "generalise": GENERALISE}
#: Dropout of a fold's temporal priors (``make prior-temporal``'s, ``make prior-offline``'s).
TEMPORAL_DROPOUT = 0.05
#: The share of a cut bodies' prior's samples cut by the image's borders (``make prior-temporal-cut``).
CUT_SHARE = 0.1
#: A fold's offline prior: its window and the frames of it after the lifted one (``make prior-offline``).
OFFLINE_WINDOW, OFFLINE_FUTURE = 7, 3


def fold_training(args: argparse.Namespace) -> dict[str, Any]:
    """The training settings a fold's prior is identified by (a saved fold is reused only when
    its metadata hold the same)."""
    spec: dict[str, Any] = {"model": args.model, "augment": args.augment, "epochs": args.epochs,
                            "samples_per_epoch": args.samples, "seed": args.seed, "frame_step": args.step,
                            "augmentation": _augmentation_spec(AUGMENTATIONS[args.augment])}
    if args.model == "residual":
        spec.update(width=args.width, blocks=args.blocks, dropout=args.dropout)
    else:
        spec.update(hidden=list(args.hidden))
    return spec


def _augmentation_spec(aug: Augmentation) -> dict[str, Any]:
    """An augmentation's fields as a fold prior's metadata hold them; the crop's (off by default)
    only when on, so the priors saved before it existed are reused."""
    spec = dict(aug.__dict__)
    if not spec.get("p_crop"):
        spec.pop("p_crop", None)
        spec.pop("crop_max", None)
    return spec


def train_fold(cls: str, pool: dict[str, list[str]], args: argparse.Namespace, path: Path, window: int = 1,
               future: int = 0, crop: float = 0.0) -> PosePrior:
    """Train (or reuse) the prior of the fold without class ``cls``, saved to ``path``; with
    ``window`` > 1 its temporal variant (as ``make prior-temporal``: the track's last ``window``
    frames at 30 Hz, dropout 0.05; with ``future`` > 0 as ``make prior-offline``, ``future`` of
    them after the lifted one); with ``crop`` that share of its samples cut by the image's borders
    (``Augmentation.p_crop``, as ``make prior-temporal-cut``)."""
    aug = replace(AUGMENTATIONS[args.augment], p_crop=crop)
    spec = fold_training(args)
    spec["augmentation"] = _augmentation_spec(aug)
    step, dropout = args.step, args.dropout
    if window > 1:
        step, dropout = 4, TEMPORAL_DROPOUT
        spec.update(window=window, frame_step=step, dropout=dropout)
    if future:
        spec.update(future=future)
    spec = json.loads(json.dumps(spec))  # as the file's metadata hold it
    if path.is_file():
        try:
            old = PosePrior.load(path)
            if old.metadata.get("fold_training") == spec and old.metadata.get("held_out_class") == cls:
                print(f"[{cls}] reusing {path}", flush=True)
                return old
        except PriorFileError:
            pass
    trials = sorted(t for c, ts in pool.items() if c != cls for t in ts)
    val_ids = trials[7::8]
    fit_ids = [t for t in trials if t not in val_ids]
    fit = [load_trial(t, args.data, step=step) for t in fit_ids]
    val = [load_trial(t, args.data, step=step) for t in val_ids]
    print(f"[{cls}] training on {len(fit_ids)} trials ({sum(len(s) for s in fit)} frames), "
          f"validation {len(val_ids)} trials", flush=True)

    def log(s: str) -> None:
        print(f"[{cls}] {s}", flush=True)

    t0 = time.perf_counter()
    if args.model == "residual":
        prior = train_prior_residual(fit, val, width=args.width, blocks=args.blocks, dropout=dropout,
                                     epochs=args.epochs, samples_per_epoch=args.samples, seed=args.seed,
                                     aug=aug, window=window, log=log, future=future)
    else:
        prior = train_prior(fit, val, hidden=tuple(args.hidden), epochs=args.epochs,
                            samples_per_epoch=args.samples, window=window, seed=args.seed, aug=aug, log=log)
    meta = dict(prior.metadata)
    meta.update({"held_out_class": cls, "fold_training": spec, "training_trials": fit_ids,
                 "validation_trials": val_ids, "frame_step": step,
                 "command": "python tools/cross_action.py " + " ".join(sys.argv[1:]),
                 "wall_seconds": round(time.perf_counter() - t0, 1)})
    prior = replace(prior, metadata=meta)
    path.parent.mkdir(parents=True, exist_ok=True)
    prior.save(path)
    print(f"[{cls}] wrote {path} in {time.perf_counter() - t0:.0f} s", flush=True)
    return prior


def class_tracks(trials: list[str], args: argparse.Namespace) -> list[ev.Track]:
    """``--segments`` segments of at most ``--frames`` frames at 30 Hz, spread evenly over the
    non-overlapping segments of ``trials``, each filmed from ``--views`` cameras."""
    segs = []
    for t in trials:
        world = load_trial(t, args.data, step=4)
        for lo in range(0, max(1, len(world) - 29), args.frames):
            part = world[lo:lo + args.frames]
            if len(part) >= 30:
                segs.append((f"{t}[{lo}]", part))
    pick = np.unique(np.round(np.linspace(0, len(segs) - 1, min(args.segments, len(segs)))).astype(int))
    out = []
    for k, i in enumerate(pick):
        name, world = segs[i]
        for v in range(args.views):
            cam = ev.CAMERAS[(k * args.views + v) % len(ev.CAMERAS)]
            out.append(ev.Track(f"{name}@{cam[0]:.0f}/{cam[1]:.0f}/{cam[2]}", world, cam, 1000 * k + v))
    return out


def evaluate_fold(tracks: list[ev.Track], prior_path: Path, args: argparse.Namespace
                  ) -> dict[str, dict[str, dict[str, float]]]:
    """Per condition and method: mean P-MPJPE, MPJPE, jitter over the frames of ``tracks``."""
    temporal = prior_path.with_name(prior_path.stem + "_w4.npz")
    settings: dict[str, Any] = {**ev.parse_settings(args.set), "prior_file": str(prior_path),
                                "temporal_prior": args.temporal}
    if args.temporal:
        settings["temporal_prior_file"] = str(temporal)
    offline = ({"temporal_prior": True,
                "temporal_prior_file": str(prior_path.with_name(prior_path.stem + "_w7c.npz"))}
               if args.offline else None)
    methods = tuple(args.methods)
    jobs = [(t, c) for c in args.conditions for t in tracks]
    results = ev.evaluate_jobs(jobs, methods, settings, ev.Setup(intrinsics=args.intrinsics, lag=args.lag),
                               args.bases, offline, args.workers)
    return ev.summarise(results, args.conditions, methods)


def render(record: dict[str, Any]) -> str:
    """The markdown tables of a run: per condition, P-MPJPE per class and method, and the mean."""
    folds = record["folds"]
    classes = list(folds)
    methods = record["methods"]
    conds = record["conditions"]
    lines = [record["header"], "",
             "P-MPJPE (mm) of each class, lifted by models that never saw it (the fold's prior); "
             "`bases saw C`: the hybrid's pose bases were learned on trials of the class.", ""]
    for m in methods:
        lines += [f"**{m}**", "", "| class | bases saw C | frames | " + " | ".join(conds) + " |",
                  "|---|---|---|" + "---|" * len(conds)]
        for c in classes:
            f = folds[c]
            cells = [f"{f['table'][k][m]['p_mpjpe']:.1f}" for k in conds]
            lines.append(f"| {c} | {'yes' if f['bases_saw_class'] else 'no'} | {f['frames']} | "
                         + " | ".join(cells) + " |")
        mean = [np.mean([folds[c]["table"][k][m]["p_mpjpe"] for c in classes]) for k in conds]
        lines.append("| **mean over classes** | | | " + " | ".join(f"**{v:.1f}**" for v in mean) + " |")
        lines.append("")
    for m in ("hybrid", "hybrid-lag", "hybrid-offline"):
        if m in methods:
            head = f"jitter (mean acceleration error, mm per frame^2), {m}, mean over classes: "
            lines += [head + ", ".join(
                f"{k} {np.mean([folds[c]['table'][k][m]['jitter'] for c in classes]):.1f}"
                for k in conds), ""]
    return "\n".join(lines)


def _parser() -> argparse.ArgumentParser:
    """The command line (the module docstring)."""
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--data", default=None)
    ap.add_argument("--classes", nargs="+", default=None, help="default: every class with usable trials")
    ap.add_argument("--lag", type=int, default=3, help="hybrid-lag: the node's output_lag (frames)")
    ap.add_argument("--model", choices=("residual", "mlp"), default="residual")
    ap.add_argument("--augment", choices=tuple(AUGMENTATIONS), default="generalise")
    ap.add_argument("--epochs", type=int, default=8)
    ap.add_argument("--samples", type=int, default=50_000, help="augmented samples per epoch")
    ap.add_argument("--width", type=int, default=512, help="residual: units per layer")
    ap.add_argument("--blocks", type=int, default=2, help="residual: blocks")
    ap.add_argument("--dropout", type=float, default=0.25, help="residual: dropout")
    ap.add_argument("--hidden", type=int, nargs="+", default=[768, 768], help="mlp: hidden widths")
    ap.add_argument("--step", type=int, default=2, help="mocap frame step of the training (2: 60 Hz)")
    ap.add_argument("--seed", type=int, default=0)
    ap.add_argument("--frames", type=int, default=90)
    ap.add_argument("--views", type=int, default=2)
    ap.add_argument("--segments", type=int, default=8)
    ap.add_argument("--conditions", nargs="+", default=list(DEFAULT_CONDITIONS), choices=list(ev.CONDITIONS))
    ap.add_argument("--methods", nargs="+", default=list(METHODS), choices=list(METHODS))
    ap.add_argument("--workers", type=int, default=1)
    ap.add_argument("--bases", default=None, help="hybrid bases (default: the packaged ones)")
    ap.add_argument("--set", action="append", default=[],
                    help="a LifterOptions field for every lift, e.g. measurement_update=False")
    ap.add_argument("--folds", type=Path, default=None, help="fold priors' directory (default OUT/folds)")
    ap.add_argument("--temporal", action="store_true",
                    help="also train each fold's causal temporal prior and lift with it (as the node does)")
    ap.add_argument("--cut", action="store_true",
                    help="with --temporal, also train each fold's temporal prior for bodies the image cuts "
                    "(NAME_w4_crop.npz: the frames lacking a shoulder are lifted with it, as the packaged "
                    "one lifts them)")
    ap.add_argument("--offline", action="store_true",
                    help="also train each fold's offline prior (past and future frames) and lift the "
                    "-offline methods with it (as pose-lifter lift does)")
    ap.add_argument("--intrinsics", action="store_true",
                    help="tracked lifts of perspective tracks know the camera's intrinsics (camera_info)")
    ap.add_argument("--train-only", action="store_true",
                    help="train (or reuse) the folds' priors, no lifting")
    ap.add_argument("--merge", type=Path, nargs="+", default=None,
                    help="no training or lifting: join runs' cross_action.json (same settings) into --out")
    ap.add_argument("--out", type=Path, default=Path("out/cross_action"))
    return ap


def _merge(paths: list[Path], out: Path) -> int:
    """Join runs' ``cross_action.json`` (same settings) into ``out``: their folds, the first run's
    settings."""
    recs = [json.loads(p.read_text()) for p in paths]
    record = dict(recs[0])
    record["folds"] = {c: f for r in recs for c, f in r["folds"].items()}
    record["header"] = recs[0]["header"] + " (merged: " + ", ".join(str(p) for p in paths) + ")"
    return _write(record, out)


def _train_fold_priors(cls: str, pool: dict[str, list[str]], args: argparse.Namespace, path: Path) -> None:
    """Train (or reuse) the priors of the fold without ``cls``: the single-frame one at ``path``, and
    with ``--temporal`` / ``--offline`` its temporal and offline variants beside it."""
    train_fold(cls, pool, args, path)
    if args.temporal:
        train_fold(cls, pool, args, path.with_name(f"{cls}_w4.npz"), window=4)
        if args.cut:  # its partner for bodies the image cuts, which the lift finds beside it
            cut = cut_partner(path.with_name(f"{cls}_w4.npz"))
            train_fold(cls, pool, args, cut, window=4, crop=CUT_SHARE)
    if args.offline:
        train_fold(cls, pool, args, path.with_name(f"{cls}_w7c.npz"), window=OFFLINE_WINDOW,
                   future=OFFLINE_FUTURE)


def _evaluate_class(cls: str, trials: list[str], args: argparse.Namespace, path: Path, bases_trials: set[str],
                    tf: float) -> dict[str, Any]:
    """The fold of ``cls`` lifted with its prior at ``path`` (:func:`evaluate_fold`): its record
    (its training time counted from ``tf``, ``time.perf_counter``, to the start of the lifts), its
    row printed."""
    tracks = class_tracks(trials, args)
    te = time.perf_counter()
    table = evaluate_fold(tracks, path, args)
    fold = {
        "trials": trials, "tracks": len(tracks), "frames": sum(len(t.world) for t in tracks),
        "bases_saw_class": bool(set(trials) & bases_trials), "prior": str(path), "table": table,
        "train_seconds": round(te - tf, 1), "lift_seconds": round(time.perf_counter() - te, 1)}
    row = ", ".join(f"{k} " + "/".join(f"{table[k][m]['p_mpjpe']:.1f}" for m in args.methods)
                    for k in args.conditions)
    print(f"[{cls}] P-MPJPE ({'/'.join(args.methods)}): {row}; {time.perf_counter() - te:.0f} s",
          flush=True)
    return fold


def main(argv: list[str] | None = None) -> int:
    args = _parser().parse_args(argv)
    if args.merge:
        return _merge(args.merge, args.out)
    warnings.simplefilter("ignore")
    t0 = time.perf_counter()
    pool = trials_by_action(args.data)
    classes = args.classes or list(pool)
    folds_dir = args.folds or args.out / "folds"
    bases_path = Path(args.bases) if args.bases else default_bases_path("hybrid")
    bases_trials = set(PoseBases.load(bases_path).metadata.get("training_trials", []))
    command = " ".join(sys.argv[1:] if argv is None else argv)
    record: dict[str, Any] = {
        "header": (f"Cross-action folds (`tools/cross_action.py {command}`): "
                   f"training {json.dumps(fold_training(args))}; bases `{bases_path.name}`; "
                   f"measured at {ev.run_stamp(Path(__file__).resolve().parents[1])}"),
        "methods": list(args.methods), "conditions": list(args.conditions), "folds": {}}
    for cls in classes:
        if cls not in pool:
            raise SystemExit(f"no usable trials of class {cls!r} (classes: {sorted(pool)})")
        path = folds_dir / f"{cls}.npz"
        tf = time.perf_counter()
        _train_fold_priors(cls, pool, args, path)
        if args.train_only:
            continue
        record["folds"][cls] = _evaluate_class(cls, pool[cls], args, path, bases_trials, tf)
        _write(record, args.out, quiet=True)
    if args.train_only:
        return 0
    record["wall_seconds"] = round(time.perf_counter() - t0, 1)
    return _write(record, args.out)


def _write(record: dict[str, Any], out: Path, quiet: bool = False) -> int:
    text = render(record)
    if not quiet:
        print(text, flush=True)
    out.mkdir(parents=True, exist_ok=True)
    (out / "cross_action.json").write_text(json.dumps(record, indent=1))
    (out / "cross_action.md").write_text(text + "\n")
    return 0


if __name__ == "__main__":
    sys.exit(main())
