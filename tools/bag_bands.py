"""Errors of the committed bags at the tests' replay settings (bags/README.md, "Error bands").

Usage: .venv/bin/python tools/bag_bands.py [--every 10] [--max-messages 4] [--starts 3] [--mode hybrid]

Lifts frames 0, every, 2*every, ... of each bag in bags/ with warm starts per track and the
packaged bases (``LifterOptions`` defaults otherwise) and prints a markdown table: P-MPJPE,
MPJPE (mm), the paper's normalised error, and the two floors over the same skeletons.
"""

from __future__ import annotations

import argparse
import tempfile
from pathlib import Path

from pose_lifter.core import Lifter, LifterOptions, PoseBases
from pose_lifter.offline.evaluate import evaluate_bag
from pose_lifter.offline.lift import lift_bag
from pose_lifter.offline.settings import LiftSettings

REPO = Path(__file__).resolve().parents[1]


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--every", type=int, default=10)
    ap.add_argument("--max-messages", type=int, default=4)
    ap.add_argument("--starts", type=int, default=3, help="n_starts of the paper mode (--mode paper)")
    ap.add_argument("--mode", choices=("hybrid", "paper", "learned"), default="hybrid")
    args = ap.parse_args()
    bases = PoseBases.load()
    print("| bag | P-MPJPE mm | MPJPE mm | normalised | flat floor P-MPJPE | mean-pose floor P-MPJPE |")
    print("|---|---|---|---|---|---|")
    with tempfile.TemporaryDirectory() as tmp:
        for bag in sorted((REPO / "bags").glob("*.mcap")):
            # the mode's bases; n_starts is the paper mode's own (refused in another mode)
            starts = {"n_starts": args.starts} if args.mode == "paper" else {}
            lifter = Lifter(None, LifterOptions(mode=args.mode, **starts))
            out = Path(tmp) / bag.name
            settings = LiftSettings(every=args.every, max_messages=args.max_messages, smoothing_s=0.0)
            lift_bag(bag, out, lifter, settings, progress=False)
            t = evaluate_bag(out, bases).table()
            print(f"| `{bag.stem}` | {t['lifter']['p_mpjpe_mm']:.0f} | {t['lifter']['mpjpe_mm']:.0f} | "
                  f"{t['lifter']['normalised']:.2f} | {t['flat_floor']['p_mpjpe_mm']:.0f} | "
                  f"{t['mean_pose_floor']['p_mpjpe_mm']:.0f} |", flush=True)


if __name__ == "__main__":
    main()
