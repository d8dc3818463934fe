"""Render ground-truth samples of a generated dataset -> docs/dataset_samples.png.

One settled sample per garment family and construction, the template on its canonical body for each
canonical pose (T, A, in between), one sample per fabric (presets and physical values), and one paired
group side by side (one template, four fabrics, same body and pose).

Run: .venv/bin/python examples/render_dataset.py --data ~/garsim-data/v5 [--out docs/dataset_samples.png]
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
    entries = store.entries()

    def pick(pred) -> dict | None:
        hits = [e for e in entries if pred(e)]
        return hits[int(rng.integers(len(hits)))] if hits else None

    panels, titles = [], []

    def add_target(e: dict, title: str) -> None:
        rec = store.read_sequence(e)
        lv = rec.levels["full"]
        panels.append([(rec.body_targets[-1], rec.body_faces), (lv.targets[-1], lv.faces)])
        titles.append(f"{title} ({len(lv.template)} v)")

    families = sorted({e["garment_type"] for e in entries})
    for fam in families:
        for con in ("template", "implicit"):
            e = pick(lambda x, f=fam, c=con: x["garment_type"] == f and x.get("construction") == c)
            if e:
                add_target(e, f"{fam} / {con} / {e.get('fabric_name', e['fabric'])}")
    for pose in ("tpose", "between", "apose"):
        e = pick(lambda x, p=pose: x.get("canonical_pose") == p)
        if e:
            rec = store.read_sequence(e)
            lv = rec.levels["full"]
            panels.append([(rec.body_canonical, rec.body_faces), (lv.template, lv.faces)])
            titles.append(f"template on canonical {pose} ({rec.garment_type})")
    for name in ("custom",):
        e = pick(lambda x, n=name: x.get("fabric_name") == n)
        if e:
            add_target(e, f"{e['garment_type']} / physical fabric (nearest {e['fabric']})")
    groups: dict[str, list[dict]] = {}
    for e in entries:
        if e.get("paired"):
            groups.setdefault(e["job"], []).append(e)
    full = [g for g in groups.values() if len(g) == 4]
    if full:
        group = sorted(
            full[int(rng.integers(len(full)))], key=lambda e: ["silk", "cotton", "denim", "leather"].index(e["fabric"])
        )
        for e in group:
            add_target(e, f"paired {e['job']}: {e['fabric']}")
    print(
        render_grid(
            args.out,
            panels,
            ncols=4,
            titles=titles,
            views=("front", "side"),
            size=300,
            suptitle="Newton VBD ground truth v2: settled samples on their target poses",
        )
    )


if __name__ == "__main__":
    main()
