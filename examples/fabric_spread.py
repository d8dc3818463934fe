"""Paired fabrics of one split (one template, four preset fabrics, same body and pose): the simulated and predicted
mean distance to the body (mm) and mean fold angle (deg) per fabric, averaged over the complete groups, beside
``paired_fabric_agreement``'s ordering agreement, spread ratio and midway check.

Any split works, the training one too: a spread that is as small on the groups the model was trained on as on the
test groups is underfitting, not a failure to generalise.

Run: .venv/bin/python examples/fabric_spread.py --model garsim/weights --data ~/garsim-data/v4 --split train \
    --json docs/studies/pair_weight/v07_train.json
"""

from __future__ import annotations

import argparse
import json
from pathlib import Path

import numpy as np

from garsim.eval.experiments import FABRICS, paired_fabric_agreement
from garsim.model.garsim import GarSimModel


def summarise(result: dict) -> dict:
    """Per-fabric means over the groups of ``paired_fabric_agreement``'s rows, and its headline figures."""
    rows = result["rows"]
    out = {k: v for k, v in result.items() if k != "rows"}
    for key in ("sim_distance_mm", "pred_distance_mm", "sim_fold_deg", "pred_fold_deg"):
        values = np.array([r[key] for r in rows])
        out[key] = dict(zip(FABRICS, np.round(values.mean(0), 3).tolist()))
        spread = float((values[:, -1] - values[:, 0]).mean())
        out[key.replace("_mm", "").replace("_deg", "") + "_spread"] = round(spread, 3)
    return out


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    parser.add_argument("--model", default="garsim/weights")
    parser.add_argument("--data", required=True)
    parser.add_argument("--split", default="test")
    parser.add_argument("--json", help="write the summary here")
    args = parser.parse_args()
    summary = summarise(paired_fabric_agreement(GarSimModel.load(args.model), args.data, split=args.split))
    text = json.dumps(summary, indent=1)
    print(text)
    if args.json:
        Path(args.json).parent.mkdir(parents=True, exist_ok=True)
        Path(args.json).write_text(text + "\n")


if __name__ == "__main__":
    main()
