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


def test_families_and_fraction_pick_whole_jobs(tmp_path):
    store = DatasetStore(tmp_path)
    for i in range(8):
        rec = make_record(f"train-{i}", "train", k=1, seed=i)
        rec.garment_type = ("skirt", "top", "dress", "trousers")[i % 4]
        store.append_manifest(store.write_sequence(rec))

    def ids(**kw) -> tuple[set[str], set[str]]:
        return tuple({s.meta["seq_id"] for s in part} for part in train_val_samples(tmp_path, **kw))

    # jobs 0, 1, 4, 5 are skirts and tops; every 2nd of them is held out
    assert ids(val_every=2, families=["skirt", "top"]) == ({"train-0", "train-4"}, {"train-1", "train-5"})
    with pytest.raises(ValueError, match="unknown garment families"):
        train_val_samples(tmp_path, families=["cape"])
    parts = {f: ids(val_every=4, fraction=f) for f in (0.2, 0.5, 1.0)}
    assert [len(parts[f][0]) for f in (0.2, 0.5, 1.0)] == [1, 3, 6]
    assert parts[0.2][0] < parts[0.5][0] < parts[1.0][0]  # nested subsets of whole jobs
    assert parts[0.2][1] == parts[1.0][1] == {"train-3", "train-7"}  # validation unchanged
    assert ids(val_every=4, fraction=0.5, seed=1)[0] != parts[0.5][0]
