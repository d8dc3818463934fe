import numpy as np
import pytest

from garsim.data.sample import Sample
from garsim.data.store import REJECTED, DatasetStore, GarmentLevel, SequenceRecord, StoreError


def make_record(seq_id: str, split: str = "train", k: int = 3, seed: int = 0) -> SequenceRecord:
    rng = np.random.default_rng(seed)
    vb, n = 20, 12
    faces = np.array([[0, 1, 2], [1, 3, 2], [4, 5, 6]])
    levels = {
        res: GarmentLevel(
            template=rng.normal(size=(m, 3)).astype(np.float32),
            faces=np.array([[0, 1, 2], [2, 1, 3]]),
            pinned=np.arange(m) < 2,
            priors=rng.normal(size=(k, m, 3)).astype(np.float32),
            targets=rng.normal(size=(k, m, 3)).astype(np.float32),
        )
        for res, m in (("full", n), ("low", n // 3))
    }
    return SequenceRecord(
        seq_id=seq_id,
        split=split,
        garment_type="skirt",
        fabric="denim",
        body_canonical=rng.normal(size=(vb, 3)).astype(np.float32),
        body_targets=rng.normal(size=(k, vb, 3)).astype(np.float32),
        body_faces=faces,
        frames=np.arange(k) * 5,
        levels=levels,
        meta={"garment_params": {"length": 0.5}, "phenotype": {"gender": 0.3}},
    )


def test_round_trip_and_samples(tmp_path):
    store = DatasetStore(tmp_path)
    rec = make_record("s0")
    store.append_manifest(store.write_sequence(rec))
    back = next(store.sequences())
    np.testing.assert_array_equal(back.body_targets, rec.body_targets)
    np.testing.assert_array_equal(back.levels["low"].targets, rec.levels["low"].targets)
    np.testing.assert_array_equal(back.body_faces, rec.body_faces)
    assert back.meta == rec.meta
    samples = store.samples("train", "full")
    assert len(samples) == 3 and all(isinstance(s, Sample) for s in samples)
    np.testing.assert_array_equal(samples[2].target, rec.levels["full"].targets[2])
    assert samples[1].meta["frame"] == 5 and samples[1].meta["seq_id"] == "s0"
    assert store.samples("test") == []


def test_info_counts(tmp_path):
    store = DatasetStore(tmp_path)
    for i, split in enumerate(["train", "train", "test"]):
        store.append_manifest(store.write_sequence(make_record(f"s{i}", split, k=2 + i, seed=i)))
    info = store.info()
    assert info["sequences"] == 3 and info["frames"] == 2 + 3 + 4
    assert info["frames_by"]["split=train"] == 5 and info["sequences_by"]["split=test"] == 1
    assert info["bytes"] == sum((tmp_path / e["file"]).stat().st_size for e in store.entries())


def test_resume_skips_done_and_rejected_and_torn_line(tmp_path):
    store = DatasetStore(tmp_path)
    store.append_manifest(store.write_sequence(make_record("a")))
    store.append_manifest({"id": "b", "reason": "exploded"}, REJECTED)
    with open(tmp_path / "manifest.jsonl", "a") as fh:  # an interrupted append
        fh.write('{"id": "c", "fi')
    assert store.done_ids() == {"a", "b"}


def test_verify_detects_truncated_and_corrupt(tmp_path):
    store = DatasetStore(tmp_path)
    for i in range(3):
        store.append_manifest(store.write_sequence(make_record(f"s{i}", seed=i)))
    assert store.verify() == []
    p0, p1 = tmp_path / "sequences/s0.npz", tmp_path / "sequences/s1.npz"
    p0.write_bytes(p0.read_bytes()[:-100])
    data = bytearray(p1.read_bytes())
    data[len(data) // 2] ^= 0xFF
    p1.write_bytes(bytes(data))
    problems = store.verify()
    assert len(problems) == 2
    assert "s0.npz: truncated" in problems[0] and "s1.npz: checksum" in problems[1]
    with pytest.raises(StoreError, match="truncated or corrupt"):
        store.read_sequence(store.entries()[0])


def test_verify_on_non_dataset(tmp_path):
    assert "not a garsim dataset" in DatasetStore(tmp_path).verify()[0]


def test_export_subset(tmp_path):
    src = DatasetStore(tmp_path / "src")
    for i in range(3):
        src.append_manifest(src.write_sequence(make_record(f"s{i}", seed=i, k=4)))
    sub = src.export_subset(tmp_path / "sub", ["s2", "s0"], frames=2, resolutions=("low",))
    recs = list(sub.sequences())
    assert [r.seq_id for r in recs] == ["s2", "s0"] and set(recs[0].levels) == {"low"}
    full = next(r for r in src.sequences() if r.seq_id == "s2")
    np.testing.assert_array_equal(recs[0].levels["low"].targets, full.levels["low"].targets[-2:])
    assert recs[0].frames.tolist() == full.frames[-2:].tolist() and sub.verify() == []
    with pytest.raises(StoreError, match="no sequences"):
        src.export_subset(tmp_path / "x", ["nope"])
