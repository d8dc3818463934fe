"""Write the result figures of a trained model into docs/: training curve, fabric awareness,
error maps of test samples (model vs prior).

Run: .venv/bin/python examples/make_report.py --run ~/garsim-runs/v1 --data ~/garsim-data/v2 \
    --results docs/results.json
"""

from __future__ import annotations

import argparse
import json
from pathlib import Path

import numpy as np

from garsim.api import GarSim
from garsim.data.store import DatasetStore
from garsim.eval.plots import plot_bars, plot_training_curve
from garsim.geometry.render import render_grid


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__)
    parser.add_argument("--run", required=True, nargs="+", help="training run folder(s) (log.csv), stages in order")
    parser.add_argument("--model", default=None, help="model folder (default: the shipped model)")
    parser.add_argument("--data", required=True)
    parser.add_argument("--results", required=True, help="JSON written by `garsim eval --out`")
    parser.add_argument("--docs", default="docs")
    parser.add_argument("--samples", type=int, default=4)
    args = parser.parse_args()
    docs = Path(args.docs)
    print(plot_training_curve([Path(r) / "log.csv" for r in args.run], docs / "training_curve.png"))
    results = json.loads(Path(args.results).read_text())
    if "fabric_distance_mm" in results:
        fab = results["fabric_distance_mm"]
        values = {f: {s: fab[s][f] for s in fab if f in fab[s]} for f in fab["garsim"]}
        print(
            plot_bars(
                values,
                "mean garment-to-body distance (mm)",
                "Fabric awareness: the same test skirts predicted in each fabric",
                docs / "fabric_awareness.png",
            )
        )
    sim = GarSim.load(args.model) if args.model else GarSim.pretrained()
    store = DatasetStore(args.data)
    recs = [r for r in store.sequences("test")][: args.samples]
    panels, titles, colors = [], [], []
    for rec in recs:
        s = rec.samples("low")[-1]
        pred = sim.predict(s)
        for name, verts in (("prior", s.prior), ("GarSim", pred), ("ground truth", s.target)):
            err = 1000 * np.linalg.norm(verts - s.target, axis=1)
            panels.append([(s.body_target, s.body_faces), (verts, s.garment_faces)])
            colors.append([None, np.clip(err, 0, 150)])
            titles.append(f"{rec.garment_type}/{rec.fabric} {name}: {err.mean():.0f} mm")
    print(
        render_grid(
            docs / "test_predictions.png",
            panels,
            ncols=3,
            titles=titles,
            views=("front",),
            colors=colors,
            suptitle="Test split (unseen garments, bodies, poses): error to Newton, 0-150 mm",
        )
    )


if __name__ == "__main__":
    main()
