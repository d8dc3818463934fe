"""Issue 13's acceptance figures on single drapes: the external check set and a split of our own dataset.

Every sample is draped through the public API, as a client would: ``GarSim.pretrained().drape(...)`` (or
``GarSim.load(DIR)``) with the defaults (the refinement on) and with ``collision_margin=None`` (the raw network),
on (vertices, faces) pairs, with the sample's fabric and, for our dataset, its pinned vertices (the external set
gives none). Per garment type and over all samples: the stretch figures of ``garsim.eval.metrics.constraint_figures``
(edges with a template rest length >= 5 mm and a free end: the max, and the 99th percentile of all the group's edges
beside the worst sample's), inside %
and edges through the body %, and the mean Euclidean error against the simulator of both, so that one can see that
the refinement does not make the drape worse. The refinement's bounds (max <= 1.5, p99 <= 1.15, inside <= 0.5 %,
edges through <= 0.2 %) are what it enforces: these figures check the refinement, not the network.

Usage: python examples/refine_accept.py [--model DIR] [--external ../shared/external-eval/data]
       [--data ~/garsim-data/v4test --split test --resolution full] [--out docs/refine_accept.json]
"""

from __future__ import annotations

import argparse
import glob
import json
import os
from collections import defaultdict
from pathlib import Path

import numpy as np

from garsim.api import GarSim
from garsim.data.store import DatasetStore
from garsim.eval.metrics import MIN_REST, constraint_figures, euclidean_error_mm

BOUNDS = {"max_stretch": 1.5, "p99_stretch": 1.15, "inside_pct": 0.5, "edges_through_pct": 0.2}
"""The issue's bounds on the refined drapes."""


def external_cases(folder: Path) -> list[dict]:
    """The external set's samples as drape inputs (the checker's reading of them: no pins)."""
    body_faces = np.load(folder / "body_faces.npy")
    cases = []
    for path in sorted(glob.glob(str(folder / "[hr][0-9]*.npz"))):
        d = np.load(path)
        name = os.path.basename(path)[:-4]
        cases.append(
            {
                "name": name,
                "type": str(d["garment_type"]) + ("@hires" if name.startswith("r") else ""),
                "canonical": d["body_canonical"],
                "target": d["body_target"],
                "body_faces": body_faces,
                "template": d["garment_template"],
                "faces": d["garment_faces"],
                "pinned": np.zeros(len(d["garment_template"]), dtype=bool),
                "fabric": str(d["fabric"]),
                "truth": d["garment_target_gt"],
            }
        )
    return cases


def dataset_cases(data: Path, split: str, resolution: str) -> list[dict]:
    """A split of a garsim dataset as drape inputs: physical fabric values where the sample has them."""
    cases = []
    for s in DatasetStore(data).samples(split, resolution):
        fabric = s.fabric_values if s.fabric_values else s.fabric
        cases.append(
            {
                "name": s.meta["name"],
                "type": s.garment_type,
                "canonical": s.body_canonical,
                "target": s.body_target,
                "body_faces": s.body_faces,
                "template": s.garment,
                "faces": s.garment_faces,
                "pinned": s.pinned,
                "fabric": fabric,
                "truth": s.target,
            }
        )
    return cases


def score(cases: list[dict], sims: dict[str, GarSim]) -> dict[str, dict]:
    """{type or 'all': {n, and per sim name: constraint figures pooled over the samples + mean error}}."""
    per: dict[str, dict[str, list]] = defaultdict(lambda: defaultdict(list))
    pooled: dict[str, dict[str, list]] = defaultdict(lambda: defaultdict(list))
    for c in cases:
        for name, sim in sims.items():
            pin = c["pinned"] if c["pinned"].any() else None
            pred = sim.drape(
                (c["canonical"], c["body_faces"]),
                (c["target"], c["body_faces"]),
                (c["template"], c["faces"]),
                fabric=c["fabric"],
                pinned=pin,
            )
            ratios: list = []
            fig = constraint_figures(
                pred[None],
                c["template"],
                c["faces"],
                c["pinned"],
                c["target"][None],
                c["body_faces"],
                ratios_out=ratios,
            )
            fig["euclid_mm"] = euclidean_error_mm(pred, c["truth"])
            for group in (c["type"], "all"):
                per[group][name].append(fig)
                pooled[group][name].extend(ratios)
    out: dict[str, dict] = {}
    for group in sorted(per, key=lambda g: (g == "all", g)):
        out[group] = {"n": len(next(iter(per[group].values())))}
        for name, figs in per[group].items():
            out[group][name] = {
                "max_stretch": max(f["max_stretch"] for f in figs),
                "p99_stretch": float(np.percentile(np.concatenate(pooled[group][name]), 99)),  # of all counted edges
                "worst_sample_p99_stretch": max(f["p99_stretch"] for f in figs),
                "edges_over_1.5_pct": 100.0 * float(np.mean(np.concatenate(pooled[group][name]) > 1.5)),
                "inside_pct": float(np.mean([f["inside_pct"] for f in figs])),
                "edges_through_pct": float(np.mean([f["edges_through_pct"] for f in figs])),
                "euclid_mm": float(np.mean([f["euclid_mm"] for f in figs])),
            }
        ref = out[group]["refined"]
        out[group]["within_bounds"] = all(ref[k] <= v for k, v in BOUNDS.items())
    return out


def print_table(title: str, table: dict[str, dict]) -> None:
    print(f"\n{title}\nraw > refined; p99 of all the group's edges (the worst sample's after refinement)")
    head = ("type", "n", "max", "p99 (worst)", "inside %", "through %", "error mm")
    print(" ".join(f"{h:{w}s}" for h, w in zip(head, (13, 4, 11, 21, 11, 11, 13))))
    for group, row in table.items():
        a, b = row["raw"], row["refined"]
        cells = [
            f"{group:13s} {row['n']:4d}",
            f"{a['max_stretch']:5.2f}>{b['max_stretch']:5.2f}",
            f"{a['p99_stretch']:6.3f}>{b['p99_stretch']:6.3f} ({b['worst_sample_p99_stretch']:5.3f})",
            f"{a['inside_pct']:5.2f}>{b['inside_pct']:5.2f}",
            f"{a['edges_through_pct']:5.2f}>{b['edges_through_pct']:5.2f}",
            f"{a['euclid_mm']:6.2f}>{b['euclid_mm']:6.2f}",
        ]
        print(" ".join(cells) + ("" if row["within_bounds"] else "  OUT OF BOUNDS"))


def main() -> None:
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("--model", help="a trained model folder (default: the shipped model)")
    here = Path(__file__).resolve().parents[1]
    p.add_argument("--external", type=Path, default=here.parent / "shared" / "external-eval" / "data")
    p.add_argument("--data", type=Path, help="a garsim dataset folder (its --split is scored too)")
    p.add_argument("--split", default="test")
    p.add_argument("--resolution", default="full", choices=("full", "low"))
    p.add_argument("--out", type=Path, default=Path("docs/refine_accept.json"))
    args = p.parse_args()
    load = (lambda **kw: GarSim.load(args.model, **kw)) if args.model else GarSim.pretrained
    sims = {"raw": load(collision_margin=None), "refined": load()}
    report: dict = {"model": args.model or "shipped", "bounds": BOUNDS, "min_rest_m": MIN_REST}
    if args.external.exists():
        report["external"] = score(external_cases(args.external), sims)
        print_table(f"external set ({args.external})", report["external"])
    if args.data is not None:
        key = f"{args.split}@{args.resolution}"
        report[key] = score(dataset_cases(args.data, args.split, args.resolution), sims)
        report["data"] = str(args.data)
        print_table(f"{args.data} {key}", report[key])
    args.out.parent.mkdir(parents=True, exist_ok=True)
    args.out.write_text(json.dumps(report, indent=1) + "\n")


if __name__ == "__main__":
    main()
