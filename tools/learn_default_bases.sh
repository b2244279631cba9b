#!/usr/bin/env bash
# Re-learn the packaged basis files from the CMU data (called by `make bases`).
#   bash tools/learn_default_bases.sh [CMU_DATA_DIR]     (default ../shared/data/cmu)
# Both: sparse bases (200, the paper's choice), every 8th 120 Hz frame, 30 multi-start poses.
#   bases_sparse200.npz         the paper's mode and experiments: the paper's training split
#                               (MANIFEST paper_split=train: subject 01 playground)
#   bases_hybrid_sparse200.npz  the hybrid mode: the trials the packaged prior was fitted on
#                               (training split minus the prior's validation trials), every
#                               frame's limbs scaled by up to +-20 % (other proportions)
set -euo pipefail
cd "$(dirname "$0")/.."
DATA="${1:-../shared/data/cmu}"
PY="${PYTHON:-.venv/bin/python}"
OUT=ros2_ws/src/pose_lifter/pose_lifter/data
export OMP_NUM_THREADS=1 OPENBLAS_NUM_THREADS=1 MKL_NUM_THREADS=1 PYTHONHASHSEED=0
"$PY" -m pose_lifter.cli learn-bases --data "$DATA" --method sparse --n-bases 200 --sparsity 0.1 \
    --step 8 --starts 30 --seed 0 --out "$OUT/bases_sparse200.npz"
"$PY" -m pose_lifter.cli learn-bases --data "$DATA" --method sparse --n-bases 200 --sparsity 0.1 \
    --step 8 --starts 30 --seed 0 --split prior --limb-spread 0.2 --out "$OUT/bases_hybrid_sparse200.npz"
