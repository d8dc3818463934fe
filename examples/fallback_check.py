"""The refinement's fallback on stored samples: the raw network, the API's post-process (``postprocess``) and the
same post-process without the fallback to the skinning prior, per family.

Scored: mean error to the simulation (mm) and the share of garment edges whose segment meets the body (%). The
before/after figures of ``docs/studies/fallback_side.md`` come from running this script on the checkout before and
after the change, on the same samples (``--limit`` takes the first N of a split, in the folder's order, so a folder
that has grown since gives the same set).

Run: .venv/bin/python examples/fallback_check.py --data ~/garsim-data/v4 --split train --limit 260 \
    --json docs/studies/fallback_side/train260_after.json
"""

from __future__ import annotations

import argparse
import json
from collections import defaultdict
from pathlib import Path

import numpy as np

from garsim.api import GarSim, postprocess
from garsim.data.store import DatasetStore
from garsim.geometry.inside import segment_hits
from garsim.geometry.mesh import unique_edges


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    parser.add_argument("--data", required=True)
    parser.add_argument("--split", nargs="+", default=["train"])
    parser.add_argument("--limit", type=int, default=None, help="the first N samples of each split")
    parser.add_argument("--json", default=None)
    args = parser.parse_args()
    model = GarSim.pretrained().model
    report = {}
    for split in args.split:
        samples = DatasetStore(args.data).samples(split, "low")[: args.limit]
        rows: dict[str, dict[str, list[float]]] = defaultdict(lambda: defaultdict(list))
        for s in samples:
            raw = model.predict(s)
            edges = unique_edges(s.garment_faces)
            methods = {"raw": raw, "defaults": postprocess(raw, s), "no fallback": postprocess(raw, s, fallback=False)}
            for name, p in methods.items():
                err = 1000.0 * float(np.linalg.norm(p - s.target, axis=1).mean())
                through = 100.0 * float(
                    segment_hits(p[edges[:, 0]], p[edges[:, 1]], s.body_target, s.body_faces).mean()
                )
                for fam in (s.garment_type, "all"):
                    rows[fam][f"{name} mm"].append(err)
                    rows[fam][f"{name} through %"].append(through)
        report[split] = {
            fam: {k: float(np.mean(v)) for k, v in d.items()} | {"n": len(d["raw mm"])} for fam, d in rows.items()
        }
        for fam, d in sorted(report[split].items()):
            print(f"{split} {fam:10s} n={d['n']:3d} " + " ".join(f"{k}: {v:.2f}" for k, v in d.items() if k != "n"))
    if args.json:
        Path(args.json).write_text(json.dumps(report, indent=1) + "\n")


if __name__ == "__main__":
    main()
