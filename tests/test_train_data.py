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


def test_rest_samples_teach_a_still_body_to_leave_the_template(tmp_path):
    import numpy as np

    store = DatasetStore(tmp_path)
    for i in range(3):
        rec = make_record(f"train-{i}", "train", k=2, seed=i)
        rec.meta["settle"] = {"settled": True}
        store.append_manifest(store.write_sequence(rec))
    train, val = train_val_samples(tmp_path, "low", val_every=3)
    rest = [s for s in train if s.meta.get("rest")]
    assert len(rest) == 2 and not any(s.meta.get("rest") for s in val)  # one per settled training record
    for s in rest:
        np.testing.assert_array_equal(s.body_target, s.body_canonical)
        np.testing.assert_array_equal(s.target, s.garment)
        np.testing.assert_array_equal(s.prior, s.garment)
    assert len(train_val_samples(tmp_path, "low", val_every=3, rest=False)[0]) == 4
