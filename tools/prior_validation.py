"""Learned priors alone, side by side, on held-out training-split trials.

    .venv/bin/python tools/prior_validation.py PRIOR.npz [PRIOR.npz ...] [--data ../shared/data/cmu]
        [--samples 20000] [--per-trial 3000] [--seed 1]

The trials are the first prior's ``validation_trials`` (metadata; tools/train_prior.py holds them
out of the fit: every 8th training trial and the action example's test trials), at 60 Hz for a
single-frame prior and 30 Hz (the node's rate) for a temporal one; the priors must share a window.
Each trial is re-filmed from random views as in training (:func:`pose_lifter.mocap.prior_training.make_batch`
with the views-only augmentation, the same samples for every prior): ``views`` with its detector
corruptions, ``views clean`` without noise, missing joints or outliers, then per trial (clean).
Prints P-MPJPE in mm (similarity-aligned per sample).
"""

from __future__ import annotations

import argparse
import warnings

import numpy as np
from pose_lifter.core.prior import PosePrior
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
    if any(p.window != window for p in priors):
        ap.error("the priors must have the same window")
    step = 2 if window == 1 else 4
    ids = list(priors[0].metadata["validation_trials"])
    seqs = [load_trial(t, args.data, step=step) for t in ids]
    clean = Augmentation(p_noise=0.0, p_missing=0.0, p_outliers=0.0)
    print(f"window {window}, {len(ids)} held-out trials at step {step}; P-MPJPE mm of: "
          + ", ".join(args.priors))
    rows = [("views", Augmentation(), seqs, args.samples), ("views clean", clean, seqs, args.samples)]
    rows += [(f"  {t}", clean, [s], args.per_trial) for t, s in zip(ids, seqs, strict=True)]
    with threadpool_limits(1):
        for name, aug, sources, n in rows:
            batch = make_batch(sources, n, np.random.default_rng(args.seed), aug, window)
            print(f"{name:12s} " + " ".join(f"{_evaluate(p, batch)[0]:6.1f}" for p in priors), flush=True)


if __name__ == "__main__":
    main()
