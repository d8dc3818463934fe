"""The prior's error by height band over a dataset split, per family, construction and canonical pose.

Where the simulated upper-body garments move away from the skinned prior (band 4: the top quarter of the
template's height: shoulders, straps, neckline); ``docs/studies/anatomy.md``. Trains and predicts nothing.

    .venv/bin/python examples/prior_bands.py --data ~/garsim-data/v5 --split train --json OUT
"""

from __future__ import annotations

import argparse
import json
from collections import defaultdict
from pathlib import Path

import numpy as np

from garsim.atomic import atomic_write_bytes
from garsim.data.store import DatasetStore
from garsim.eval.studies import ANATOMY_BANDS, anatomy_row

UPPER_BODY = ("top", "dress", "tshirt", "longsleeve")
KEYS = ("prior_mm", *(f"prior_band{b}_mm" for b in range(ANATOMY_BANDS)))


def prior_bands(data: Path, split: str, families: tuple[str, ...] = UPPER_BODY) -> dict[str, dict[str, float]]:
    """Mean prior error (mm) overall and per height band, keyed ``family/construction/canonical pose`` and
    ``family/construction/all``, with the sample count."""
    store = DatasetStore(data)
    rows: dict[str, list[list[float]]] = defaultdict(list)
    for entry in store.entries():
        if entry["split"] != split or entry["garment_type"] not in families:
            continue
        rec = store.read_sequence(entry)
        for s in rec.samples("low"):
            r = anatomy_row(s.garment, s.prior, s.prior, s.target, s.body_target, s.body_faces)
            group = f"{s.garment_type}/{rec.meta['construction']}"
            for key in (f"{group}/{rec.meta['canonical_pose']}", f"{group}/all"):
                rows[key].append([r[k] for k in KEYS])
    if not rows:
        raise ValueError(f"{data}: no {split!r} samples of {', '.join(families)}")
    return {
        k: {"samples": len(v), **dict(zip(KEYS, np.mean(v, axis=0).round(1).tolist()))} for k, v in sorted(rows.items())
    }


def main() -> None:
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("--data", type=Path, required=True, help="dataset folder")
    p.add_argument("--split", default="train")
    p.add_argument("--json", type=Path, help="write the table here")
    args = p.parse_args()
    result = prior_bands(args.data, args.split)
    print("| group | samples | prior error | " + " | ".join(f"band {b + 1}" for b in range(ANATOMY_BANDS)) + " |")
    print("|---|---|---|" + "---|" * ANATOMY_BANDS)
    for k, r in result.items():
        print(f"| {k} | {r['samples']} | " + " | ".join(f"{r[c]:.1f}" for c in KEYS) + " |")
    if args.json:
        atomic_write_bytes(args.json, json.dumps(result, indent=1).encode())


if __name__ == "__main__":
    main()
