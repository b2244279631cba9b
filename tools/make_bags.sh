#!/usr/bin/env bash
# Regenerate the committed bags in bags/ from the CMU data (called by `make bags`).
#   bash tools/make_bags.sh [CMU_DATA_DIR]     (default ../shared/data/cmu)
# Every trial here is an unseen action (MANIFEST paper_split=test); the output is byte-identical
# on every run (seeded noise, no wall-clock stamps). See bags/README.md.
set -euo pipefail
cd "$(dirname "$0")/.."
DATA="${1:-../shared/data/cmu}"
PY="${PYTHON:-.venv/bin/python}"
export OMP_NUM_THREADS=1 OPENBLAS_NUM_THREADS=1 MKL_NUM_THREADS=1 PYTHONHASHSEED=0
mk() { "$PY" -m pose_lifter.cli make-bag --data "$DATA" --overwrite "$@"; }

# walk (subject 07), camera 30 degrees off the walker's front, clean 2D
mk 07_05 --out bags/walk_clean.mcap --view-angle 30 --frames 120
# walk (subject 02), seen from 60 degrees to the right, Gaussian 2D noise 0.1 right-lower-leg
mk 02_01 --out bags/walk_noisy.mcap --view-angle -60 --noise 0.1 --seed 1
# run (subject 09, BVH), camera orbiting at 30 deg/s, clean
mk 09_12 --out bags/run_orbit.mcap --start 2 --frames 120 --orbit-speed 30
# punch (subject 02), camera 20 degrees off the front, clean
mk 02_05 --out bags/punch_clean.mcap --start 3 --frames 120 --view-angle 20
# punch, detector-like 2D: noise 0.05, 5% gross outliers, 10% missing joints
mk 02_05 --out bags/punch_outliers.mcap --start 8 --frames 120 --view-angle -30 \
    --noise 0.05 --outliers 0.05 --missing 0.1 --seed 2
# two people: a walker (track 0, subject 07) and a boxer (track 1, subject 02), noise 0.05
mk 07_01 02_05 --out bags/two_people.mcap --frames 75 --view-angle 15 --noise 0.05 --seed 3
# five people (the speed target's scene, tools/bench_node.py): walkers (tracks 0, 2, 3, 4) and a boxer (1),
# 2.7 s at 30 Hz, noise 0.03
mk 07_05 02_05 02_01 07_04 07_03 --out bags/five_people.mcap --frames 80 --view-angle 20 --noise 0.03 --seed 4
# RGB-D (bags/rgbd/): punch (subject 02), camera 3 m away, 20 degrees off the front, noise 0.05, and the
# depth image of each frame (16UC1, the D435-like sensor of pose_lifter.mocap.depth_model). 4 frames: a
# realistic depth image does not compress below ~0.4 MB (the sensor's noise), so 4 keep the file < 2 MB.
mk 02_05 --out bags/rgbd/punch_rgbd.mcap --start 3 --frames 4 --view-angle 20 --distance 3 --noise 0.05 \
    --seed 5 --depth --depth-format raw
