#!/usr/bin/env bash
# Re-learn the packaged default basis file from the CMU data (called by `make bases`).
#   bash tools/learn_default_bases.sh [CMU_DATA_DIR]     (default ../shared/data/cmu)
# Sparse bases (200, the paper's choice) from the paper's training split (MANIFEST
# paper_split=train: subject 01 playground), every 8th 120 Hz frame, 30 multi-start poses.
set -euo pipefail
cd "$(dirname "$0")/.."
DATA="${1:-../shared/data/cmu}"
PY="${PYTHON:-.venv/bin/python}"
export OMP_NUM_THREADS=1 OPENBLAS_NUM_THREADS=1 MKL_NUM_THREADS=1 PYTHONHASHSEED=0
"$PY" -m pose_lifter.cli learn-bases --data "$DATA" --method sparse --n-bases 200 --sparsity 0.1 \
    --step 8 --starts 30 --seed 0 --out ros2_ws/src/pose_lifter/pose_lifter/data/bases_sparse200.npz
