"""Learned priors alone, side by side, on held-out training-split trials.

    .venv/bin/python tools/prior_validation.py PRIOR.npz [PRIOR.npz ...] [--data ../shared/data/cmu]
        [--samples 20000] [--per-trial 3000] [--seed 1]

The trials are the first prior's ``validation_trials`` (metadata; tools/train_prior.py holds them
out of the fit: every 8th training trial and the action example's test trials), at 60 Hz for a
single-frame prior and 30 Hz (the node's rate) for temporal ones (the priors must all be
single-frame or all temporal). Each trial is re-filmed from random views as in training
(:func:`pose_lifter.mocap.prior_training.make_batch` with the views-only augmentation, the same
seed for every prior: the same samples for priors of one window): ``views`` with its detector
corruptions, ``views clean`` without noise, missing joints or outliers, ``noise`` (white noise
only, its spread per 64 samples uniform in 0-0.1 lower-leg lengths: 0.05 on average),
``detector`` (the same spreads scaled per joint like the COCO sigmas and correlated 0.7 over
the window's frames), then per trial (clean).
A prior trained to lift a frame before its window's last (``tools/train_prior.py --future F``,
metadata ``future_frames``) is given the windows whose frame ``window - 1 - F`` is the target.
Prints P-MPJPE in mm (similarity-aligned per sample).
"""

from __future__ import annotations

import argparse
import warnings
from dataclasses import replace

import numpy as np
from pose_lifter.core.model.prior import PosePrior
from pose_lifter.mocap.cmu import load_trial
from pose_lifter.mocap.prior_training import Augmentation, _evaluate, make_batch
from threadpoolctl import threadpool_limits


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("priors", nargs="+")
    ap.add_argument("--data", default=None, help="CMU data dir (default ../shared/data/cmu)")
    ap.add_argument("--samples", type=int, default=20_000, help="samples over all trials")
    ap.add_argument("--per-trial", type=int, default=3_000, help="samples per trial")
    ap.add_argument("--seed", type=int, default=1)
    args = ap.parse_args()
    warnings.simplefilter("ignore")
    priors = [PosePrior.load(p) for p in args.priors]
    window = priors[0].window
    if any((p.window == 1) != (window == 1) for p in priors):
        ap.error("the priors must all be single-frame or all temporal")
    step = 2 if window == 1 else 4
    ids = list(priors[0].metadata["validation_trials"])
    seqs = [load_trial(t, args.data, step=step) for t in ids]
    clean = Augmentation(p_noise=0.0, p_missing=0.0, p_outliers=0.0)
    white = Augmentation(p_noise=1.0, noise_max=0.1, p_missing=0.0, p_outliers=0.0)
    print(f"{len(ids)} held-out trials at step {step}; P-MPJPE mm of: "
          + ", ".join(f"{a} (window {p.window}, future {p.metadata.get('future_frames', 0)})"
                      for a, p in zip(args.priors, priors, strict=True)))
    rows = [("views", Augmentation(), seqs, args.samples), ("views clean", clean, seqs, args.samples),
            ("noise", white, seqs, args.samples),
            ("detector", replace(white, p_detector=1.0, detector_correlation=(0.7, 0.7)), seqs, args.samples)]
    rows += [(f"  {t}", clean, [s], args.per_trial) for t, s in zip(ids, seqs, strict=True)]
    with threadpool_limits(1):
        for name, aug, sources, n in rows:
            figures = []
            for p in priors:
                batch = make_batch(sources, n, np.random.default_rng(args.seed), aug, p.window,
                                   int(p.metadata.get("future_frames", 0)))
                figures.append(_evaluate(p, batch)[0])
            print(f"{name:14s} " + " ".join(f"{f:6.1f}" for f in figures), flush=True)


if __name__ == "__main__":
    main()
