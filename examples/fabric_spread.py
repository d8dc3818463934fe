"""Paired fabrics of one split (one template, four preset fabrics, same body and pose): the simulated and predicted
mean distance to the body (mm) and mean fold angle (deg) per fabric, averaged over the complete groups, beside
``paired_fabric_agreement``'s ordering agreement, spread ratio and midway check.

Also, per vertex, how far each fabric's drape lies from its group's mean drape (mm, averaged over vertices, fabrics
and groups): simulated, predicted, and the residual the paired-fabric loss sees (``train.losses.fabric_pair_loss``);
and the simulated deviation after smoothing it over the mesh (``SMOOTHING`` rounds of x <- x - L x / 2, L the uniform
Laplacian), the part of it that is not wrinkles.

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

from garsim.eval.experiments import FABRICS, paired_fabric_agreement, paired_groups
from garsim.geometry.mesh import uniform_laplacian
from garsim.model.garsim import GarSimModel

SMOOTHING = (5, 20, 80)


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


def fabric_deviation(model: GarSimModel, groups: list) -> dict:
    """Mean per-vertex distance (mm) of each fabric's drape to its group's mean: simulated, predicted, residual,
    and simulated after ``SMOOTHING`` rounds of smoothing."""
    sim, pred, resid, smooth = [], [], [], {k: [] for k in SMOOTHING}

    def dev(x: np.ndarray) -> np.ndarray:  # (fabrics, V, 3) -> each fabric's offset from the group's mean
        return x - x.mean(0)

    for samples in groups:
        truth = np.stack([s.target for s in samples]).astype(np.float64)
        guess = np.stack(model.predict(samples)).astype(np.float64)
        sim.append(np.linalg.norm(dev(truth), axis=-1).mean())
        pred.append(np.linalg.norm(dev(guess), axis=-1).mean())
        resid.append(np.linalg.norm(dev(guess - truth), axis=-1).mean())
        lap = uniform_laplacian(samples[0].garment_faces, truth.shape[1])
        x, done = dev(truth), 0
        for rounds in SMOOTHING:
            for _ in range(rounds - done):
                x = x - 0.5 * np.stack([lap @ xi for xi in x])
            done = rounds
            smooth[rounds].append(np.linalg.norm(x, axis=-1).mean())
    out = {"sim_deviation_mm": sim, "pred_deviation_mm": pred, "residual_deviation_mm": resid}
    out.update({f"sim_deviation_smoothed{k}_mm": v for k, v in smooth.items()})
    return {k: round(1000.0 * float(np.mean(v)), 3) if v else None for k, v in out.items()}


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    parser.add_argument("--model", default="garsim/weights")
    parser.add_argument("--data", required=True)
    parser.add_argument("--split", default="test")
    parser.add_argument("--json", help="write the summary here")
    args = parser.parse_args()
    model = GarSimModel.load(args.model)
    summary = summarise(paired_fabric_agreement(model, args.data, split=args.split))
    summary.update(fabric_deviation(model, paired_groups(args.data, args.split)))
    text = json.dumps(summary, indent=1)
    print(text)
    if args.json:
        Path(args.json).parent.mkdir(parents=True, exist_ok=True)
        Path(args.json).write_text(text + "\n")


if __name__ == "__main__":
    main()
