#!/bin/bash
# A/B of the rest samples: one per training record (the code as it is) against one per job (commit 6b0d56c, withdrawn),
# 8 epochs from scratch on v5snap1, one process each, both at once. Run from the repository root after
#   git worktree add /tmp/dedup 6b0d56c
# then score each run's best/ at rest as tests/test_api_stability.py does (docs/studies/training_cost.md).
export OMP_NUM_THREADS=1
ROOT=$(pwd)
OUT=${OUT:-$HOME/garsim-runs/s29/restab}
ARGS="train --data $HOME/garsim-data/v5snap1 --resolution low --epochs 8 --lr 5e-4 --batch-size 8 --head displacement
  --collision-start 5 --collision-weight 10 --collision-eps 0.002 --pair-weight 1 --mirror --quiet"
.venv/bin/garsim $ARGS --out "$OUT/record" > "$OUT/record.log" 2>&1 &
(cd /tmp/dedup && PYTHONPATH=/tmp/dedup "$ROOT/.venv/bin/python" -m garsim.cli $ARGS --out "$OUT/job" > "$OUT/job.log" 2>&1) &
wait
