"""Measure the bias of a track's limb-proportion estimate (``TrackPolicy``, ``prior_limbs``).

    .venv/bin/python tools/limb_calibration.py [--data ../shared/data/cmu] [--bases PATH]
        [--frames 90] [--views 2] [--spread 0.2]

Held-out training-split tracks (the learned prior's validation trials: never trained on, never
the evaluation split) have their limbs scaled per person by up to ``--spread``; each is tracked
at 30 Hz with the hybrid lifter, and the median of the prior's limb proportions over the track
(the raw estimate, before :data:`pose_lifter.core.track.state.LIMB_CALIBRATION`) is compared with
the person's true proportions. Per bone group (upper arm, forearm, thigh, shin), on the
log-proportions with the mean over the groups removed, it prints the error of the bases'
proportions, of the raw and the calibrated estimate, and the least-squares line
``truth = slope * estimate + offset`` (the values of ``LIMB_CALIBRATION``).
"""

from __future__ import annotations

import argparse
import sys
import warnings
from pathlib import Path

import numpy as np
from numpy.typing import NDArray

sys.path.insert(0, str(Path(__file__).resolve().parent))

import accuracy
from pose_lifter.core import Lifter, LifterOptions
from pose_lifter.core.model.bases import PoseBases
from pose_lifter.core.model.skeleton import LEFT_LIMBS, RIGHT_LIMBS
from pose_lifter.core.track.policy import TrackPolicy
from pose_lifter.core.track.state import calibrated_limb_proportions
from pose_lifter.mocap.views import film, limb_scale_factors, scale_limbs, view_rotation

GROUPS = ("upper arm", "forearm", "thigh", "shin")


def _groups(props: NDArray[np.float64]) -> NDArray[np.float64]:
    """Log-proportions of the 4 bone groups (left/right averaged), mean removed: (..., 4)."""
    p = np.asarray(props, dtype=np.float64)
    g = np.log(0.5 * (p[..., list(LEFT_LIMBS)] + p[..., list(RIGHT_LIMBS)]))
    return np.asarray(g - g.mean(axis=-1, keepdims=True))


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--data", default=None)
    ap.add_argument("--bases", default=None, help="basis file (default: the packaged one)")
    ap.add_argument("--frames", type=int, default=90, help="frames per track at 30 Hz")
    ap.add_argument("--views", type=int, default=2, help="cameras per trial")
    ap.add_argument("--spread", type=float, default=0.2, help="per-person limb scaling, +- fraction")
    args = ap.parse_args(argv)
    warnings.simplefilter("ignore")
    bases = PoseBases.load(args.bases)
    lifter = Lifter(bases, LifterOptions(mode="hybrid", prior_limbs=True))
    lifter.warm_up()
    truth, raw = [], []
    tracks = accuracy._tracks("val", args.data, args.frames, args.views)
    for tr in tracks:
        rng = np.random.default_rng(tr.seed)
        world = scale_limbs(tr.world, limb_scale_factors(1, args.spread, rng)[0])
        n = len(world)
        az, el, proj = tr.camera
        rots = np.repeat(view_rotation(az, el)[None], n, axis=0)
        pts, _, _ = film(world, rots, np.full(n, accuracy.DISTANCE), np.full(n, proj == "perspective"))
        px = accuracy.FOCAL * pts + accuracy.CENTRE
        policy = TrackPolicy(lifter, track_timeout=10**18)
        estimates = []
        for i in range(n):
            r = policy.lift(0, i * 33_333_333, px[i], np.ones(12)).result
            if r.prior_pose is not None:
                estimates.append(Lifter.limb_proportions_of(r.prior_pose))
        truth.append(_groups(Lifter.limb_proportions_of(world[0])))
        raw.append(np.median(np.stack(estimates), axis=0))
    t = np.stack(truth)
    e = _groups(np.stack(raw))
    c = _groups(np.stack([calibrated_limb_proportions(x) for x in raw]))
    b = _groups(np.asarray(bases.limb_proportions))
    print(f"{len(tracks)} held-out tracks x {args.frames} frames, limbs scaled by up to +-{args.spread:.0%}; "
          "log-proportion errors (rms):")
    print(f"{'group':10s}{'bases':>8s}{'raw':>8s}{'calibrated':>12s}{'slope':>8s}{'offset':>8s}")
    slopes, offsets = [], []
    for k, name in enumerate(GROUPS):
        design = np.column_stack([e[:, k], np.ones(len(e))])
        slope, offset = np.linalg.lstsq(design, t[:, k], rcond=None)[0]
        slopes.append(slope)
        offsets.append(offset)
        rms = [float(np.sqrt(np.mean((t[:, k] - x) ** 2))) for x in (b[k], e[:, k], c[:, k])]
        print(f"{name:10s}{rms[0]:8.3f}{rms[1]:8.3f}{rms[2]:12.3f}{slope:8.2f}{offset:8.3f}")
    print(f"LIMB_CALIBRATION = (np.array({np.round(slopes, 2).tolist()}), "
          f"np.array({np.round(offsets, 3).tolist()}))")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
