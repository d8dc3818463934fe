"""The network in the target body's root frame (``garsim.api.root_frame``): what it changes on the data the model was
trained for, and what it buys when the target body is moved or turned alone (an avatar's root motion).

On every ``--every``-th stored sample of a split (low resolution, the dataset's own prior), the raw network
(``GarSim.raw``: no post-process) with and without the root frame: the mean error against the simulator, the root
frame's turn and move, and the largest change of any vertex between the two; then, without the root frame, the largest
change when the target body and the prior are moved 1 cm along x (the network's own sensitivity to where the target
stands). Through the API's defaults, the target body alone turned 90 degrees and moved 2 m on each sample: the largest
change after turning and moving the result back, with and without the root frame.

Run: OMP_NUM_THREADS=1 .venv/bin/python examples/root_frame.py --data ~/garsim-data/v5test --every 6 \\
         --json docs/studies/root_frame/v5test.json
"""

from __future__ import annotations

import argparse
import dataclasses
import json
from pathlib import Path

import numpy as np

import garsim.api as api
from garsim.atomic import atomic_write
from garsim.data.store import DatasetStore
from garsim.eval.robustness import MOVES, turn_about_vertical


def moved(sample, degrees: float, shift) -> object:
    """``sample`` with its target body and prior turned about the vertical and moved (the canonical body stays)."""
    return dataclasses.replace(
        sample,
        body_target=turn_about_vertical(sample.body_target, degrees, shift).astype(np.float32),
        prior=turn_about_vertical(sample.prior, degrees, shift).astype(np.float32),
    )


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--data", required=True, help="a garsim dataset folder")
    parser.add_argument("--split", default="test")
    parser.add_argument("--every", type=int, default=6, help="take every N-th sample of the split")
    parser.add_argument("--model", default=None, help="model folder (default: the shipped model)")
    parser.add_argument("--json", type=Path, help="write the rows and the summary here")
    args = parser.parse_args()
    sim = api.GarSim.load(args.model) if args.model else api.GarSim.pretrained()
    plain = api.root_frame

    def without_root(fn):
        api.root_frame = lambda sample: None
        try:
            return fn()
        finally:
            api.root_frame = plain

    rows = []
    for i, s in enumerate(DatasetStore(args.data).samples(args.split, "low")):
        if i % args.every:
            continue
        truth = s.target.astype(np.float64)

        def err(x):
            return 1000.0 * float(np.linalg.norm(np.asarray(x, np.float64) - truth, axis=1).mean())

        with_root = sim.raw(s).astype(np.float64)
        bare = without_root(lambda: sim.raw(s)).astype(np.float64)
        step = moved(s, 0.0, np.array([0.01, 0.0, 0.0]))
        stepped = without_root(lambda: sim.raw(step)).astype(np.float64) - [0.01, 0.0, 0.0]
        rot, shift = api.root_frame(s)
        row = {
            "name": str(s.meta.get("name", i)),
            "garment_type": s.garment_type,
            "prior_mm": err(s.prior),
            "raw_mm": err(bare),
            "raw_root_frame_mm": err(with_root),
            "root_turn_deg": abs(float(np.degrees(np.arctan2(rot[1, 0], rot[0, 0])))),  # its size
            "root_move_mm": 1000.0 * float(np.linalg.norm(shift)),
            "root_frame_change_max_mm": 1000.0 * float(np.abs(with_root - bare).max()),
            "target_1cm_change_max_mm": 1000.0 * float(np.abs(stepped - bare).max()),
        }
        for check in ("target_turn_90", "target_shift_2m"):
            degrees, shift, _ = MOVES[check]
            turned = moved(s, degrees, shift)
            for label, run in (("root_frame", lambda f: f()), ("bare", without_root)):
                ref = run(lambda: sim.predict(s))
                out = run(lambda m=turned: sim.predict(m))
                back = turn_about_vertical(out - (0.0 if shift is None else shift), -degrees)
                row[f"{check}_{label}_max_mm"] = 1000.0 * float(np.abs(back - ref).max())
        rows.append(row)
        print(json.dumps({k: round(v, 4) if isinstance(v, float) else v for k, v in row.items()}), flush=True)
    keys = [k for k in rows[0] if k not in ("name", "garment_type")]
    summary = {"n": len(rows)}
    for k in keys:
        v = np.array([r[k] for r in rows])
        summary[k] = {"mean": float(v.mean()), "median": float(np.median(v)), "max": float(np.abs(v).max())}
    print(json.dumps(summary, indent=1))
    if args.json:
        args.json.parent.mkdir(parents=True, exist_ok=True)
        atomic_write(args.json, lambda p: Path(p).write_text(json.dumps({"summary": summary, "rows": rows}, indent=1)))


if __name__ == "__main__":
    main()
