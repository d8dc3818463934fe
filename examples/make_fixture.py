"""Export the committed test fixture (a few MB) from a generated v2 dataset: one low-resolution record per
garment family and construction, every canonical pose, one record with physical fabric values and one
complete paired-fabric group (last settled state of each).

Run: .venv/bin/python examples/make_fixture.py --data ~/garsim-data/v3 [--out tests/fixtures/dataset_v2]
"""

from __future__ import annotations

import argparse
import shutil
from pathlib import Path

from garsim.data.store import DatasetStore


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__)
    parser.add_argument("--data", required=True)
    parser.add_argument("--out", default="tests/fixtures/dataset_v2")
    args = parser.parse_args()
    store = DatasetStore(args.data)
    entries = [e for e in store.entries() if e["split"] in ("test", "ood", "train")]
    chosen: dict[str, str] = {}
    for e in sorted(entries, key=lambda e: (e["split"] != "test", e["id"])):
        for key in (
            f"{e['garment_type']}/{e.get('construction')}",
            f"pose/{e.get('canonical_pose')}",
            f"fabric/{e.get('fabric_name')}",
        ):
            chosen.setdefault(key, e["id"])
    groups: dict[str, list[str]] = {}
    for e in entries:
        if e.get("paired"):
            groups.setdefault(e["job"], []).append(e["id"])
    complete = sorted((g for g in groups.values() if len(g) == 4), key=lambda g: g[0])
    ids = sorted(set(chosen.values()) | (set(complete[0]) if complete else set()))
    out = Path(args.out)
    if out.exists():
        shutil.rmtree(out)
    store.export_subset(out, ids, frames=1, resolutions=("low",))
    size = sum(p.stat().st_size for p in out.rglob("*") if p.is_file())
    print(f"{out}: {len(ids)} records, {size / 2**20:.1f} MB")


if __name__ == "__main__":
    main()
