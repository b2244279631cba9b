"""Cross-action fold models: a learned prior (single-frame and causal temporal) and hybrid bases
trained without one motion class of MANIFEST.csv, for measuring the lifter on motion unlike its
training motions.

    .venv/bin/python tools/fold_models.py --exclude dance --out out/folds/dance \
        [--epochs 10] [--samples 40000] [--bases-iter 200] [--skip-temporal] [--data ...]

Training trials: the packaged prior's (its metadata ``training_trials``, the training split minus
its validation trials) without the excluded class; validation: the packaged prior's validation
trials without the class (the fold prior's per-joint uncertainty). The excluded class's trials
are then unseen by all three files. Writes ``prior.npz``, ``prior_w4.npz`` and ``bases.npz`` to
``--out`` (use them with ``tools/accuracy.py --set prior_file=... --set temporal_prior_file=...
--bases ...``). A smaller budget than ``make prior`` (a quick fold, not a shipped model): the
figures it gives are for comparing lifter settings on one fold, not the shipped priors' accuracy.
Deterministic for a seed (one BLAS thread).
"""

from __future__ import annotations

import argparse
import os
import sys
import time
import warnings
from dataclasses import replace
from pathlib import Path

os.environ.setdefault("OMP_NUM_THREADS", "1")
os.environ.setdefault("OPENBLAS_NUM_THREADS", "1")

import numpy as np
from pose_lifter.core.model.bases import learn_sparse_bases
from pose_lifter.core.model.prior import PosePrior
from pose_lifter.core.model.skeleton import normalise_pose
from pose_lifter.mocap.cmu import load_trial, read_manifest
from pose_lifter.mocap.prior_training import train_prior
from pose_lifter.mocap.views import limb_scale_factors, scale_limbs


def train(args: argparse.Namespace, fit_ids: list[str], val_ids: list[str], command: str,
          window: int) -> None:
    """Train and save the fold prior of ``window`` frames (1: ``prior.npz``, 4: ``prior_w4.npz``)."""
    step, name = (2, "prior.npz") if window == 1 else (4, "prior_w4.npz")
    t0 = time.perf_counter()
    fit = [load_trial(t, args.data, step=step) for t in fit_ids]
    val = [load_trial(t, args.data, step=step) for t in val_ids]
    prior = train_prior(fit, val, epochs=args.epochs, samples_per_epoch=args.samples, window=window,
                        seed=args.seed, log=lambda s: print(s, flush=True))
    meta = dict(prior.metadata)
    meta.update({"command": command, "training_trials": fit_ids, "validation_trials": val_ids,
                 "frame_step": step, "fold_excluded_action": args.exclude})
    replace(prior, metadata=meta).save(args.out / name)
    print(f"{name}: window {window}, validation P-MPJPE {meta['validation_p_mpjpe_mm']} mm, "
          f"{time.perf_counter() - t0:.0f} s", flush=True)


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--exclude", required=True, help="MANIFEST action class left out (e.g. dance)")
    ap.add_argument("--data", default=None)
    ap.add_argument("--epochs", type=int, default=10)
    ap.add_argument("--samples", type=int, default=40_000)
    ap.add_argument("--bases-iter", type=int, default=200)
    ap.add_argument("--skip-temporal", action="store_true")
    ap.add_argument("--seed", type=int, default=0)
    ap.add_argument("--out", type=Path, required=True)
    args = ap.parse_args(argv)
    warnings.simplefilter("ignore")
    action = {t.trial: t.action for t in read_manifest(args.data)}
    shipped = PosePrior.load().metadata
    fit_ids = [t for t in shipped["training_trials"] if action.get(t) != args.exclude]
    val_ids = [t for t in shipped["validation_trials"] if action.get(t) != args.exclude]
    held = sorted(t for t, a in action.items() if a == args.exclude)
    print(f"fold '{args.exclude}': training on {len(fit_ids)} trials, validation {val_ids}, "
          f"held out {held}", flush=True)
    args.out.mkdir(parents=True, exist_ok=True)
    command = "python tools/fold_models.py " + " ".join(argv if argv is not None else sys.argv[1:])
    train(args, fit_ids, val_ids, command, 1)
    t0 = time.perf_counter()
    rng = np.random.default_rng(args.seed)
    clips = []
    for t in fit_ids:  # as `pose-lifter learn-bases --split prior --limb-spread 0.2 --step 8`
        world = load_trial(t, args.data, step=8)
        world = scale_limbs(world, limb_scale_factors(len(world), 0.2, rng))
        clips.append(normalise_pose(world))
    bases = learn_sparse_bases(np.concatenate(clips), n_bases=200, sparsity=0.1, n_starts=30, seed=args.seed,
                               n_iter=args.bases_iter,
                               metadata={"command": command, "training_trials": fit_ids, "frame_step": 8,
                                         "source_fps": 120, "split": "fold", "limb_spread": 0.2,
                                         "fold_excluded_action": args.exclude})
    bases.save(args.out / "bases.npz")
    print(f"bases.npz: {bases.n_bases} bases, {time.perf_counter() - t0:.0f} s", flush=True)
    if not args.skip_temporal:
        train(args, fit_ids, val_ids, command, 4)
    return 0


if __name__ == "__main__":
    sys.exit(main())
