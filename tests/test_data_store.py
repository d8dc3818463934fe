import numpy as np
import pytest
from store_fixtures import make_record

from garsim.data.sample import Sample
from garsim.data.store import REJECTED, DatasetStore, StoreError


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
    assert info["sequences"] == 3 and info["samples"] == 2 + 3 + 4 and info["garment_instances"] == 3
    assert info["samples_by"]["split=train"] == 5 and info["sequences_by"]["split=test"] == 1
    assert info["per_family"]["skirt"]["jobs"] == 3 and info["per_family"]["skirt"]["acceptance_rate"] == 1.0
    assert info["bytes"] == sum((tmp_path / e["file"]).stat().st_size for e in store.entries())


def test_info_refuses_a_folder_that_is_not_a_dataset(tmp_path):
    with pytest.raises(StoreError, match="not a garsim dataset"):
        DatasetStore(tmp_path).info()


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
        rec = make_record(f"s{i}", seed=i, k=4)
        rec.meta["settled"] = [False, False, False, True]  # as the generator stores them, with their description
        described = {"construction": "implicit", "num_settled": 1, "paired": True, "job": "j"}
        src.append_manifest({**src.write_sequence(rec), **described})
    sub = src.export_subset(tmp_path / "sub", ["s2", "s0"], frames=2, resolutions=("low",))
    recs = list(sub.sequences())
    entry = sub.entries()[0]
    assert entry["construction"] == "implicit" and entry["paired"] and entry["num_frames"] == 2
    assert entry["num_settled"] == 1 and recs[0].meta["settled"] == [False, True]
    assert sub.info()["samples_by"]["construction=implicit"] == 4
    assert [r.seq_id for r in recs] == ["s2", "s0"] and set(recs[0].levels) == {"low"}
    full = next(r for r in src.sequences() if r.seq_id == "s2")
    np.testing.assert_array_equal(recs[0].levels["low"].targets, full.levels["low"].targets[-2:])
    assert recs[0].frames.tolist() == full.frames[-2:].tolist() and sub.verify() == []
    with pytest.raises(StoreError, match="no sequences"):
        src.export_subset(tmp_path / "x", ["nope"])


def _store_with(tmp_path, n: int = 3) -> DatasetStore:
    store = DatasetStore(tmp_path)
    for i in range(n):
        store.append_manifest(store.write_sequence(make_record(f"s{i}", seed=i)))
    return store


def test_verify_reports_a_truncated_body_faces_file_and_goes_on(tmp_path):
    store = _store_with(tmp_path)
    faces = next((tmp_path / "body_faces").iterdir())
    faces.write_bytes(faces.read_bytes()[:-7])
    p2 = tmp_path / "sequences/s2.npz"
    p2.write_bytes(p2.read_bytes()[:-10])
    problems = store.verify()
    assert len(problems) == 2, problems  # the shared faces file once, then the truncated sample
    assert faces.name in problems[0] and "truncated or corrupt" in problems[0]
    assert "s2.npz: truncated" in problems[1]
    with pytest.raises(StoreError, match=faces.name):
        store.read_sequence(store.entries()[0])


def test_verify_reports_corrupt_body_faces(tmp_path):
    store = _store_with(tmp_path, 1)
    faces = next((tmp_path / "body_faces").iterdir())
    faces.write_bytes(b"garbage, not an npy file")
    assert len(problems := store.verify()) == 1 and faces.name in problems[0] and "corrupt" in problems[0]
    np.save(faces, np.array([[0, 1, 2], [1, 3, 2], [4, 5, 7]]))  # loads, but not the faces it was named after
    assert len(problems := store.verify()) == 1 and f"{faces.name}: checksum mismatch" in problems[0]


def test_verify_reports_manifest_lines_with_missing_keys(tmp_path):
    import json

    store = _store_with(tmp_path)
    lines = (tmp_path / "manifest.jsonl").read_text().splitlines()
    e0, e1 = json.loads(lines[0]), json.loads(lines[1])
    del e0["file"], e1["sha256"]
    lines[0], lines[1] = json.dumps(e0), json.dumps(e1)
    (tmp_path / "manifest.jsonl").write_text("\n".join(lines) + "\n")
    problems = store.verify()
    assert any("line 1" in p and "'s0'" in p and "missing keys ['file']" in p for p in problems), problems
    assert any("line 2" in p and "'s1'" in p and "missing keys ['sha256']" in p for p in problems), problems
    assert any(p.startswith("orphan") and "s0.npz" in p for p in problems), problems  # no line lists s0.npz now
    assert not any("s2" in p for p in problems)
    with pytest.raises(StoreError, match="lacks keys"):
        store.read_sequence(e0)


def test_verify_reports_an_unreadable_sample_file(tmp_path):
    import hashlib
    import json

    store = _store_with(tmp_path)
    p1 = tmp_path / "sequences/s1.npz"
    junk = b"PK\x03\x04" + bytes(range(256)) * 8  # a zip signature, then garbage
    p1.write_bytes(junk)
    lines = (tmp_path / "manifest.jsonl").read_text().splitlines()
    e1 = json.loads(lines[1])  # as if the sample had been written corrupt: sizes and checksum match the junk
    e1.update(bytes=len(junk), sha256=hashlib.sha256(junk).hexdigest())
    lines[1] = json.dumps(e1)
    (tmp_path / "manifest.jsonl").write_text("\n".join(lines) + "\n")
    problems = store.verify()
    assert len(problems) == 1 and "s1.npz is truncated or corrupt" in problems[0], problems
    assert "\n" not in problems[0]


def test_verify_reports_torn_lines_and_orphans_and_everything_else(tmp_path):
    store = _store_with(tmp_path)
    rec = make_record("s3", seed=3)
    store.write_sequence(rec)  # a killed run: the file is written, its manifest line never appended
    with open(tmp_path / "manifest.jsonl", "a") as fh:
        fh.write("[1, 2]\n")
        fh.write('{"id": "s4", "fi')  # an interrupted append
    (tmp_path / "sequences/s0.npz").unlink()
    problems = store.verify()
    assert len(problems) == 4, problems
    assert "s0.npz: missing" in problems[0]
    assert "line 4" in problems[1] and "not a JSON object" in problems[1]
    assert "line 5" in problems[2] and "torn" in problems[2]
    assert problems[3].startswith("orphan") and "s3.npz" in problems[3]
    assert [e["id"] for e in store.entries()] == ["s0", "s1", "s2"]  # readers skip what verify reports


def test_reading_a_folder_that_is_not_a_dataset_or_an_unknown_split_is_refused(tmp_path):
    from pathlib import Path

    with pytest.raises(StoreError, match="not a garsim dataset folder"):
        DatasetStore(tmp_path / "typo").samples()
    with pytest.raises(ValueError, match="split must be one of train, test, ood"):
        DatasetStore(Path(__file__).parent / "fixtures" / "dataset_v2").samples("bogus")
