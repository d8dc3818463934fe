"""Training data from a store: whole sequences held out for validation; low, full or both resolutions."""

import pytest
from store_fixtures import make_record

from garsim.data.store import DatasetStore
from garsim.train.data import train_val_samples


@pytest.fixture()
def store_dir(tmp_path):
    store = DatasetStore(tmp_path)
    for i, split in enumerate(["train", "train", "train", "test"]):
        store.append_manifest(store.write_sequence(make_record(f"{split}-{i}", split, k=2, seed=i)))
    return tmp_path


def test_validation_holds_whole_sequences(store_dir):
    train, val = train_val_samples(store_dir, "low", val_every=3)
    assert {s.meta["seq_id"] for s in train} == {"train-0", "train-1"}
    assert {s.meta["seq_id"] for s in val} == {"train-2"}  # the test split is never used
    assert len(train) == 4 and all(len(s.garment) == 4 for s in train)  # 12 // 3 low-res vertices


def test_both_resolutions(store_dir):
    train, val = train_val_samples(store_dir, "both", val_every=3)
    assert sorted(len(s.garment) for s in train) == [4, 4, 4, 4, 12, 12, 12, 12]
    assert len(val) == 4
    with pytest.raises(ValueError, match="resolution must be one of"):
        train_val_samples(store_dir, "medium")
