"""Train the packaged learned priors (``make prior``, ``make prior-temporal``, ``make prior-offline``)
on the training split.

    .venv/bin/python tools/train_prior.py [--data ../shared/data/cmu] [--model residual|mlp]
        [--augment generalise|views] [--aug NAME=VALUE ...] [--epochs 24] [--samples 100000]
        [--width 512] [--blocks 2] [--dropout 0.25] [--hidden 768 768] [--holdout every8|action]
        [--window 1] [--future 0] [--seed 0] [--out PATH]

The defaults give the packaged ``data/prior_mlp.npz`` (``make prior``): a residual MLP
(:func:`pose_lifter.mocap.prior_training.train_prior_residual`: 512 units, 2 residual blocks, dropout
0.25, PyTorch, the optional extra ``train``) trained on 24 epochs x 100 000 freshly augmented
samples with the augmentation ``GENERALISE`` (random views and detector corruptions, mirrored
people, arms or legs transplanted from another frame, limbs turned about their joints, the lower
body out of the image on 10 % of samples), seed 0. ``--window 4 --dropout 0.05 --out
.../data/prior_mlp_w4.npz`` gives its causal temporal variant (``make prior-temporal``; with
dropout 0.25 the temporal variant gained almost nothing from the past frames on held-out runs);
``--window 7 --future 3 --dropout 0.05 --out .../data/prior_mlp_w7c.npz`` its offline variant,
which reads 3 frames before the lifted one and 3 after it (``make prior-offline``; what
``pose-lifter lift`` reads). Each took 11-22 min on one thread of the 2-core machine. ``--model
mlp --augment views --epochs 30`` is the earlier recipe (scikit-learn MLP 2 x 768, views and
corruptions only); the cross-action folds (``tools/cross_action.py``, docs/cross_action.md) chose
the residual model and ``GENERALISE``; ``--aug NAME=VALUE`` changes one field of the augmentation.

Training trials: :func:`pose_lifter.mocap.cmu.split_trials` ("train": subjects 01, 03, 05, 06 and
09_01-09_11). Held out of the fit: the action-recognition example's test trials (so that its
figure with lifted 3D is on unseen motion) and, with ``--holdout every8`` (default), every 8th
training trial (sorted, from the 8th); they give the validation figure and the prior's per-joint
uncertainty. The evaluation split (02, 07, 08, 09_12) is never read, so the accuracy of the evaluation
split (``make accuracy``) is measured with the shipped priors themselves.

Frames at 60 Hz (``--step 2`` of the 120 Hz originals) for single frames, 30 Hz (step 4) for the
temporal variant. Deterministic for a seed (one BLAS / torch thread). The file's metadata records
the command, the training and validation trials and every setting.
"""

from __future__ import annotations

import argparse
import ast
import sys
import time
import warnings
from dataclasses import replace
from pathlib import Path

import numpy as np
from pose_lifter.core.model.prior import DEFAULT_PRIOR_PATH
from pose_lifter.mocap.cmu import load_trial, resolve_data_dir, split_trials
from pose_lifter.mocap.prior_training import GENERALISE, Augmentation, train_prior, train_prior_residual
from threadpoolctl import threadpool_limits


def augmentation(base: str, overrides: list[str]) -> Augmentation:
    """The augmentation ``base`` (``"generalise"``: ``GENERALISE``, ``"views"``: views and
    corruptions only) with ``NAME=VALUE`` overrides of its fields (Python literals).

    Raises
    ------
    ValueError
        An unknown field or a value that does not parse.
    """
    aug = GENERALISE if base == "generalise" else Augmentation()
    for item in overrides:
        key, _, value = (part.strip() for part in item.partition("="))
        if key not in Augmentation.__dataclass_fields__:
            raise ValueError(f"--aug {item}: no Augmentation field {key!r}")
        try:
            parsed = ast.literal_eval(value)
        except (ValueError, SyntaxError) as exc:
            raise ValueError(f"--aug {item}: {value!r} is not a literal") from exc
        aug = replace(aug, **{key: type(getattr(aug, key))(parsed)})
    return aug


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--data", default=None, help="CMU data dir (default ../shared/data/cmu)")
    ap.add_argument("--epochs", type=int, default=24)
    ap.add_argument("--samples", type=int, default=100_000, help="augmented samples per epoch")
    ap.add_argument("--model", choices=("residual", "mlp"), default="residual")
    ap.add_argument("--augment", choices=("generalise", "views"), default="generalise")
    ap.add_argument("--aug", action="append", default=[], metavar="NAME=VALUE",
                    help="override one Augmentation field of --augment, e.g. p_transplant=0")
    ap.add_argument("--holdout", choices=("action", "every8"), default="every8",
                    help="trials held out of the fit: the action example's test trials (and every 8th)")
    ap.add_argument("--hidden", type=int, nargs="+", default=[768, 768], help="mlp: hidden widths")
    ap.add_argument("--width", type=int, default=512, help="residual: units per layer")
    ap.add_argument("--blocks", type=int, default=2, help="residual: blocks")
    ap.add_argument("--dropout", type=float, default=0.25, help="residual: dropout")
    ap.add_argument("--window", type=int, default=1, help="frames per input (> 1: causal temporal variant)")
    ap.add_argument("--future", type=int, default=0,
                    help="frames of the window after the target one (> 0: an offline prior, past and future, "
                         "which only pose-lifter lift reads)")
    ap.add_argument("--step", type=int, default=None,
                    help="mocap frame step (default 2, or 4 with --window > 1)")
    ap.add_argument("--seed", type=int, default=0)
    ap.add_argument("--threads", type=int, default=1, help="BLAS threads (1: deterministic)")
    ap.add_argument("--out", type=Path, default=DEFAULT_PRIOR_PATH)
    args = ap.parse_args()
    step = args.step or (2 if args.window == 1 else 4)
    warnings.simplefilter("ignore")
    trials = split_trials("train", args.data)
    # held out: every 8th training trial, and the action-recognition example's test trials
    # (tools/action_recognition_eval.py: per class every third trial, the first 3 of them), so
    # that example's figure with lifted 3D is on motion the prior has not seen
    from action_recognition_eval import split as action_split
    from action_recognition_eval import trials_by_class
    action_test = {t for ts in trials_by_class(resolve_data_dir(args.data)).values()
                   for t in action_split(ts)[1][:3]}
    every8 = set(trials[7::8]) if args.holdout == "every8" else set()
    val_ids = sorted(every8 | (action_test & set(trials)))
    fit_ids = [t for t in trials if t not in val_ids]
    fit = [load_trial(t, args.data, step=step) for t in fit_ids]
    val = [load_trial(t, args.data, step=step) for t in val_ids]
    print(f"training on {len(fit_ids)} trials ({sum(len(s) for s in fit)} frames at step {step}), "
          f"validation {val_ids} ({sum(len(s) for s in val)} frames)", flush=True)
    t0 = time.perf_counter()
    try:
        aug = augmentation(args.augment, args.aug)
    except ValueError as exc:
        ap.error(str(exc))
    with threadpool_limits(args.threads):
        if args.model == "residual":
            prior = train_prior_residual(fit, val, width=args.width, blocks=args.blocks,
                                         dropout=args.dropout, epochs=args.epochs,
                                         samples_per_epoch=args.samples, window=args.window,
                                         seed=args.seed, aug=aug, log=lambda s: print(s, flush=True),
                                         future=args.future)
        else:
            prior = train_prior(fit, val, hidden=tuple(args.hidden), epochs=args.epochs,
                                samples_per_epoch=args.samples, window=args.window, seed=args.seed, aug=aug,
                                log=lambda s: print(s, flush=True), future=args.future)
    meta = dict(prior.metadata)
    meta.update({"command": "python tools/train_prior.py " + " ".join(sys.argv[1:]),
                 "training_trials": fit_ids, "validation_trials": val_ids, "frame_step": step})
    prior = replace(prior, metadata=meta)
    args.out.parent.mkdir(parents=True, exist_ok=True)
    prior.save(args.out)
    print(f"wrote {args.out} ({args.out.stat().st_size / 1e6:.2f} MB) in {time.perf_counter() - t0:.0f} s; "
          f"validation P-MPJPE {meta['validation_p_mpjpe_mm']} mm; mean |error| per output "
          f"{np.round(prior.abs_error.mean(axis=0), 4).tolist()} (x, y, z)")


if __name__ == "__main__":
    main()
