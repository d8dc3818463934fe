#!/usr/bin/env bash
# The shipped model's recipe, up to three stages; each stage resumes: rerun the same command to continue.
#   stage 1: low resolution (~4x decimated, the paper's choice), collision term from 2/3 of the run;
#   finetune (FINETUNE_EPOCHS > 0): from stage 1's best weights, low resolution, lr FINETUNE_LR, the collision
#            term from the first step, the same augmentations and pair term;
#   fabric (FABRIC_EPOCHS > 0): from the last stage's model, low resolution, lr 1e-4, the heavy smoothed
#            paired-fabric term and the fold term (docs/studies/v08_fabric.md);
#   stage 2 (STAGE2_EPOCHS > 0): from the last stage's model, both resolutions (the decimated and the simulated
#            meshes, 120 to 2,500 vertices); collision term on.
# With SOUP=1 the fine-tune and fabric stages' models are their best weights averaged half and half with the
# weights they started from (garsim average, WiSE-FT: docs/studies/soup_crest.md), in <stage>/soup.
#   DATA=~/garsim-data/v4 OUT=~/garsim-runs/v1 bash examples/train_v1.sh
# Settings (environment; defaults in brackets):
#   PROCS [2]          DDP processes (torchrun on CPU); 1 runs `garsim train` in one process
#   BATCH [4]          samples per batch and process
#   LR [1e-3]          peak learning rate of stage 1 (stage 2: 3e-4)
#   STAGE1_EPOCHS [300], FINETUNE_EPOCHS [0], STAGE2_EPOCHS [40]
#   FINETUNE_LR [2e-4]
#   REMESH [0]         remeshed variants of every training sample in stage 1 (garsim train --remesh-copies)
#   PAIR [0]           weight of the paired-fabric term (garsim train --pair-weight)
#   PAIR_SMOOTH [0]    smoothing rounds of that term's residual (garsim train --pair-smooth; docs/studies/pair_weight.md)
#   MIRROR [0]         1: every training sample also mirrored left to right in stage 1 (garsim train --mirror)
#   FABRIC_EPOCHS [0]  epochs of the fabric stage
#   SOUP [0]           1: average each fine-tuning stage with its start (above)
#   INIT []            a model folder: skip stage 1 and fine-tune that model instead (e.g. garsim/weights on a
#                      grown dataset folder)
# v0.6 and later (garsim/weights/MODEL_CARD.md): PROCS=2 BATCH=4 LR=5e-4 STAGE1_EPOCHS=12 FINETUNE_EPOCHS=4
# STAGE2_EPOCHS=0 REMESH=2 MIRROR=1 PAIR=1 (shipped from $OUT/finetune/best).
# v0.5: PROCS=1 BATCH=8 LR=5e-4 STAGE1_EPOCHS=30 STAGE2_EPOCHS=0 REMESH=2 (and PAIR=2:
# the paired-fabric candidate of docs/studies/pair_loss.md, not shipped).
# v0.8 was v0.7 averaged with its 6-epoch fine-tune on v5; v0.9 is v0.8 fine-tuned with INIT (FINETUNE_EPOCHS=6
# FINETUNE_LR=3e-4 FABRIC_EPOCHS=3 REMESH=1 MIRROR=1 PAIR=1 SOUP=1; garsim/weights/MODEL_CARD.md).
# The script prints the last stage's model folder (and writes it to $OUT/model.txt); ship it with: .venv/bin/python -c "from garsim.model.garsim
#   import GarSimModel; GarSimModel.load('<that folder>').save('garsim/weights')"
set -euo pipefail
cd "$(dirname "$0")/.."
DATA=${DATA:-~/garsim-data/v4}
OUT=${OUT:-~/garsim-runs/v1}
PROCS=${PROCS:-2}
export OMP_NUM_THREADS=1
if [ "$PROCS" -gt 1 ]; then
  LAUNCH=(.venv/bin/torchrun --nproc_per_node="$PROCS" -m garsim.cli)
else
  LAUNCH=(.venv/bin/garsim)
fi
TRAIN=("${LAUNCH[@]}" train --data "$DATA" --batch-size "${BATCH:-4}" --quiet --collision-weight 10
  --collision-eps 0.002 --pair-weight "${PAIR:-0}" --pair-smooth "${PAIR_SMOOTH:-0}")
EPOCHS1=${STAGE1_EPOCHS:-300}
MIRROR_FLAG=()
if [ "${MIRROR:-0}" = 1 ]; then MIRROR_FLAG=(--mirror); fi
if [ -n "${INIT:-}" ]; then
  MODEL=$INIT
else
  "${TRAIN[@]}" --out "$OUT/stage1" --resolution low --epochs "$EPOCHS1" --lr "${LR:-1e-3}" --head displacement \
    --collision-start $((EPOCHS1 * 2 / 3)) --remesh-copies "${REMESH:-0}" "${MIRROR_FLAG[@]}"
  MODEL="$OUT/stage1/best"
fi
finish() {  # $1: a fine-tuning stage's folder -> MODEL: its best weights, or with SOUP=1 their average with MODEL
  if [ "${SOUP:-0}" = 1 ]; then
    .venv/bin/garsim average --models "$MODEL" "$1/best" --out "$1/soup" > /dev/null
    MODEL="$1/soup"
  else
    MODEL="$1/best"
  fi
}
EPOCHS_FT=${FINETUNE_EPOCHS:-0}
if [ "$EPOCHS_FT" -gt 0 ]; then
  "${TRAIN[@]}" --out "$OUT/finetune" --resolution low --epochs "$EPOCHS_FT" --lr "${FINETUNE_LR:-2e-4}" \
    --head displacement --collision-start 0 --remesh-copies "${REMESH:-0}" "${MIRROR_FLAG[@]}" --init "$MODEL"
  finish "$OUT/finetune"
fi
EPOCHS_FAB=${FABRIC_EPOCHS:-0}
if [ "$EPOCHS_FAB" -gt 0 ]; then
  "${TRAIN[@]}" --out "$OUT/fabric" --resolution low --epochs "$EPOCHS_FAB" --lr 1e-4 --head displacement \
    --collision-start 0 --remesh-copies "${REMESH:-0}" "${MIRROR_FLAG[@]}" --pair-weight 20 --pair-smooth 20 \
    --fold-weight 0.3 --init "$MODEL"
  finish "$OUT/fabric"
fi
EPOCHS2=${STAGE2_EPOCHS:-40}
if [ "$EPOCHS2" -gt 0 ]; then
  "${TRAIN[@]}" --out "$OUT/stage2" --resolution both --epochs "$EPOCHS2" --lr 3e-4 --collision-start 0 \
    --init "$MODEL"
  MODEL="$OUT/stage2/best"
fi
echo "$MODEL" > "$OUT/model.txt"
echo "$MODEL"
