"""Render ground-truth samples of a generated dataset: one random final frame per garment type
and fabric -> docs/dataset_samples.png.

Run: .venv/bin/python examples/render_dataset.py --data ~/garsim-data/v1 [--out docs/dataset_samples.png]
"""

from __future__ import annotations

import argparse

import numpy as np

from garsim.data.store import DatasetStore
from garsim.geometry.render import render_grid


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__)
    parser.add_argument("--data", required=True)
    parser.add_argument("--out", default="docs/dataset_samples.png")
    parser.add_argument("--seed", type=int, default=0)
    args = parser.parse_args()
    store = DatasetStore(args.data)
    rng = np.random.default_rng(args.seed)
    by_key: dict[tuple[str, str], list[dict]] = {}
    for e in store.entries():
        by_key.setdefault((e["garment_type"], e["fabric"]), []).append(e)
    panels, titles = [], []
    for (kind, fabric), entries in sorted(by_key.items()):
        rec = store.read_sequence(entries[rng.integers(len(entries))])
        lv = rec.levels["full"]
        panels.append([(rec.body_targets[-1], rec.body_faces), (lv.targets[-1], lv.faces)])
        titles.append(f"{kind} / {fabric} ({rec.split}, {rec.seq_id})")
    print(render_grid(args.out, panels, ncols=4, titles=titles, views=("front", "side"), size=320,
                      suptitle="Newton VBD ground truth: final settled frame on the target pose"))


if __name__ == "__main__":
    main()
