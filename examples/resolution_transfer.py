"""How well the learned correction carries across resolutions (the API's ``max_vertices`` path).

On the test split at full resolution (the stored garment, 300-2,500 vertices), compare the network run on
the garment itself with the network run on a ~4x decimated copy whose correction is carried back barycentrically (what
``GarSim`` does for garments denser than ``max_vertices``), and the prior. Errors against Newton.

Run: .venv/bin/python examples/resolution_transfer.py --data ~/garsim-data/v4test --out docs/results_resolution.json
"""

from __future__ import annotations

import argparse
import json
import time
from collections import defaultdict
from pathlib import Path

import numpy as np

from garsim.api import GarSim
from garsim.atomic import atomic_write
from garsim.data.store import DatasetStore
from garsim.eval.metrics import euclidean_error_mm


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__)
    parser.add_argument("--data", required=True)
    parser.add_argument("--model", default=None, help="model folder (default: the shipped model)")
    parser.add_argument("--split", default="test")
    parser.add_argument(
        "--coarse", type=int, nargs="+", default=[250, 500], help="max_vertices of the carried-back variants"
    )
    parser.add_argument("--out", default=None)
    args = parser.parse_args()
    model = (GarSim.load(args.model) if args.model else GarSim.pretrained()).model
    methods = {
        "network at full resolution": GarSim(model, collision_margin=None, max_vertices=None),
        **{
            f"network at {c} v, carried back": GarSim(model, collision_margin=None, max_vertices=c) for c in args.coarse
        },
        "prior": GarSim.prior_only(),
    }
    errors: dict[str, dict[str, list[float]]] = {m: defaultdict(list) for m in methods}
    cpu: dict[str, list[float]] = defaultdict(list)
    for s in DatasetStore(args.data).samples(args.split, "full"):
        for name, sim in methods.items():
            t0 = time.process_time()
            pred = sim.predict(s)
            cpu[name].append(1000.0 * (time.process_time() - t0))
            e = euclidean_error_mm(pred, s.target)
            errors[name][s.garment_type].append(e)
            errors[name]["all"].append(e)
    table = {
        m: {**{k: float(np.mean(v)) for k, v in sorted(per.items())}, "cpu_ms": float(np.median(cpu[m]))}
        for m, per in errors.items()
    }
    for m, per in table.items():
        print(f"{m:40s} " + "  ".join(f"{k} {v:.1f}" + ("" if k == "cpu_ms" else " mm") for k, v in per.items()))
    if args.out:
        atomic_write(Path(args.out), lambda p: Path(p).write_text(json.dumps(table, indent=1)))


if __name__ == "__main__":
    main()
