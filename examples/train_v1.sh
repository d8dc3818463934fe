#!/usr/bin/env bash
# The shipped model's recipe on the v2 dataset, two stages, DDP over 2 CPU processes. Each stage resumes:
# rerun the same command to continue.
#   stage 1: low resolution (~4x decimated, the paper's choice), 300 epochs, collision term from epoch 200
#            (~13 min on 2 cores for 212 samples);
#   stage 2: from stage 1's best weights, both resolutions (the decimated and the simulated meshes, 120 to
#            2,500 vertices), so that the model sees the mesh densities users bring; collision term on.
#   DATA=~/garsim-data/v3 OUT=~/garsim-runs/v1 bash examples/train_v1.sh
# STAGE1_EPOCHS / STAGE2_EPOCHS set the stages' lengths (default 300 / 40); REMESH=N adds N remeshed variants of
# every training sample to stage 1 (garsim train --remesh-copies; each epoch is then N+1 times longer). Then ship: .venv/bin/python -c "from garsim.model.garsim
# import GarSimModel; GarSimModel.load('$OUT/stage2/best').save('garsim/weights')"
set -euo pipefail
cd "$(dirname "$0")/.."
DATA=${DATA:-~/garsim-data/v3}
OUT=${OUT:-~/garsim-runs/v1}
export OMP_NUM_THREADS=1
TRAIN=(.venv/bin/torchrun --nproc_per_node=2 -m garsim.cli train --data "$DATA" --batch-size 4 --quiet
  --collision-weight 10 --collision-eps 0.002)
EPOCHS1=${STAGE1_EPOCHS:-300}
"${TRAIN[@]}" --out "$OUT/stage1" --resolution low --epochs "$EPOCHS1" --lr 1e-3 --head displacement \
  --collision-start $((EPOCHS1 * 2 / 3)) --remesh-copies "${REMESH:-0}"
"${TRAIN[@]}" --out "$OUT/stage2" --resolution both --epochs "${STAGE2_EPOCHS:-40}" --lr 3e-4 --collision-start 0 \
  --init "$OUT/stage1/best"
