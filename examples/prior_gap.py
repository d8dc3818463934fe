"""The API's prior (bone transforms recovered from the two body meshes) against the dataset's stored prior (skinned
with the known pose), and the raw network's error with each, per garment family of a split.

Run: OMP_NUM_THREADS=1 .venv/bin/python examples/prior_gap.py --data ~/garsim-data/v5test --split test
"""

from __future__ import annotations

import argparse
import dataclasses
from collections import defaultdict

import numpy as np

from garsim.api import GarSim, make_sample
from garsim.data.store import DatasetStore


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--data", required=True, help="a garsim dataset folder")
    parser.add_argument("--split", default="test")
    parser.add_argument("--model", default=None, help="model folder (default: the shipped model)")
    args = parser.parse_args()
    model = (GarSim.load(args.model) if args.model else GarSim.pretrained()).model
    rows: dict[str, list[list[float]]] = defaultdict(list)
    for s in DatasetStore(args.data).samples(args.split, "low"):
        fabric = dict(s.fabric_values) if s.fabric_values else s.fabric
        bodies = (s.body_canonical, s.body_faces), (s.body_target, s.body_faces)
        api_prior = make_sample(*bodies, (s.garment, s.garment_faces), fabric=fabric, pinned=s.pinned).prior
        truth = s.target.astype(np.float64)

        def error(x: np.ndarray) -> float:
            return 1000.0 * float(np.linalg.norm(np.asarray(x, np.float64) - truth, axis=1).mean())

        gap = 1000.0 * np.linalg.norm(api_prior.astype(np.float64) - s.prior, axis=1)
        row = [error(s.prior), error(api_prior), error(model.predict(s))]
        row += [error(model.predict(dataclasses.replace(s, prior=api_prior))), gap.mean(), gap.max()]
        for key in (s.garment_type, "all"):
            rows[key].append(row)
    print("| family | n | prior: stored / API (mm) | raw network on the stored / API prior | prior gap mean / max |")
    print("|---|---|---|---|---|")
    for key, values in sorted(rows.items()):
        v = np.array(values)
        print(
            f"| {key} | {len(v)} | {v[:, 0].mean():.2f} / {v[:, 1].mean():.2f} | {v[:, 2].mean():.2f} / "
            f"{v[:, 3].mean():.2f} | {v[:, 4].mean():.2f} / {v[:, 5].max():.1f} |"
        )


if __name__ == "__main__":
    main()
