"""Export the committed test fixture (a few MB) from generated datasets (v5 for training, v5test for testing):
from the test store one low-resolution record per garment family and construction, every canonical pose and
fabric, and one complete paired-fabric group;
from the training store one record of each of four families (skirt, t-shirt, trousers, dress: a few training jobs
for the trainer's and the studies' tests, no top so that a family stays unseen); last settled state of each, with its
manifest description (construction, canonical pose, paired, phenotype).

Run: .venv/bin/python examples/make_fixture.py --data ~/garsim-data/v5test --train-data ~/garsim-data/v5
     [--out tests/fixtures/dataset_v2]
"""

from __future__ import annotations

import argparse
import shutil
from pathlib import Path

from garsim.data.store import DatasetStore

TRAIN_FAMILIES = ("skirt", "tshirt", "trousers", "dress")


def test_ids(store: DatasetStore) -> list[str]:
    """One record per family/construction, canonical pose and fabric, plus the first complete paired group."""
    entries = [e for e in store.entries() if e["split"] in ("test", "ood")]
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
    return sorted(set(chosen.values()) | (set(complete[0]) if complete else set()))


def train_ids(store: DatasetStore) -> list[str]:
    """The first training record of each of ``TRAIN_FAMILIES``, unpaired where the family has one (a folder made
    with ``--paired-first`` may hold only paired groups of a family so far: then one copy of the first)."""
    chosen: dict[str, str] = {}
    for e in sorted(store.entries(), key=lambda e: (bool(e.get("paired")), e["id"])):
        if e["split"] == "train" and e["garment_type"] in TRAIN_FAMILIES:
            chosen.setdefault(e["garment_type"], e["id"])
    return sorted(chosen.values())


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__)
    parser.add_argument("--data", required=True, help="dataset with the test (and ood) split")
    parser.add_argument("--train-data", required=True, help="dataset with the training split")
    parser.add_argument("--out", default="tests/fixtures/dataset_v2")
    args = parser.parse_args()
    out = Path(args.out)
    if out.exists():
        shutil.rmtree(out)
    n = 0
    for src, pick in ((args.data, test_ids), (args.train_data, train_ids)):
        store = DatasetStore(src)
        ids = pick(store)
        store.export_subset(out, ids, frames=1, resolutions=("low",))
        n += len(ids)
    size = sum(p.stat().st_size for p in out.rglob("*") if p.is_file())
    print(f"{out}: {n} records, {size / 2**20:.1f} MB")


if __name__ == "__main__":
    main()
