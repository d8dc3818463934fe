#!/usr/bin/env bash
# The shipped interim model's recipe, one stage on the v2 dataset, DDP over 2 CPU processes (resumable:
# rerun the same command to continue). ~13 min on 2 cores for 212 samples.
#   DATA=~/garsim-data/v2 OUT=~/garsim-runs/v1 bash examples/train_v1.sh
# then: .venv/bin/python -c "from garsim.model.garsim import GarSimModel; GarSimModel.load('$OUT/best').save('garsim/weights')"
set -euo pipefail
cd "$(dirname "$0")/.."
DATA=${DATA:-~/garsim-data/v2}
OUT=${OUT:-~/garsim-runs/v1}
export OMP_NUM_THREADS=1
.venv/bin/torchrun --nproc_per_node=2 -m garsim.cli train --data "$DATA" --out "$OUT" --resolution low \
  --epochs 300 --batch-size 4 --lr 1e-3 --head displacement \
  --collision-start 200 --collision-weight 10 --collision-eps 0.002 --quiet "$@"
